"""Policy checkpoints: one format for teachers, baselines and students.

A checkpoint is a ``torch.save`` dict with ``format == "flownav-policy-v1"``:

* ``policy``: the :class:`~flownav.agents.DeterministicPolicy` constructor config and
  ``state_dict`` (normaliser statistics included);
* ``obs``: the observation view it reads (a key of ``flownav.envs.observations.VIEWS``);
* ``role``: ``teacher``, ``baseline`` or ``student``; ``meta``: free (config, step, metrics);
* ``train_state``: anything a resumed run needs (optimiser, step counters, RNG, the env's state, a
  trainer's own data such as DAgger's aggregated pairs), optional. A run's ``last.pt`` is that one file:
  a resumed run continues bit for bit (:func:`training_state`, :func:`restore_training_state`).

Writes are atomic (temporary file, then rename), so a kill never leaves half a checkpoint, and a checkpoint
holding a NaN or an infinity is never written (:class:`~flownav.errors.NonFiniteError`).
Reads never run code: :func:`safe_torch_load` unpickles tensors and plain containers only
(``weights_only=True``) and refuses anything else with a :class:`CheckpointError`.
"""

from __future__ import annotations

import os
import pickle
import re
from pathlib import Path

import torch

from flownav.agents.networks import DeterministicPolicy, warm_start_state
from flownav.atomic import atomic_write
from flownav.envs.observations import observation_size
from flownav.errors import CheckpointError, ConfigError, NonFiniteError

__all__ = ["CheckpointError", "load_checkpoint", "load_policy", "safe_torch_load", "save_policy_checkpoint"]

FORMAT = "flownav-policy-v1"


def atomic_torch_save(obj, path: str | os.PathLike) -> Path:
    return atomic_write(path, lambda f: torch.save(obj, f))


def non_finite_entries(obj, prefix: str = "") -> list[str]:
    """Names of the floating-point tensors in a nested dict / list that hold a NaN or an infinity."""
    if torch.is_tensor(obj):
        return [prefix] if obj.is_floating_point() and not torch.isfinite(obj).all() else []
    items = obj.items() if isinstance(obj, dict) else enumerate(obj) if isinstance(obj, list | tuple) else ()
    return [name for k, v in items for name in non_finite_entries(v, f"{prefix}.{k}" if prefix else str(k))]


def _first_names(names: list[str]) -> str:
    return ", ".join(names[:3]) + (" ..." if len(names) > 3 else "")


def require_finite_payload(payload: dict, path) -> None:
    bad = non_finite_entries({"policy": payload["policy"], "train_state": payload.get("train_state") or {}})
    if bad:
        raise NonFiniteError(f"refusing to write {path}: {_first_names(bad)} hold NaN or infinity")


def save_policy_checkpoint(
    path, policy: DeterministicPolicy, obs: str, role: str, meta: dict | None = None, train_state: dict | None = None
) -> Path:
    if observation_size(obs) != policy.config["obs_dim"]:
        raise CheckpointError(
            f"policy reads {policy.config['obs_dim']} numbers but view {obs!r} has {observation_size(obs)}"
        )
    payload = {
        "format": FORMAT,
        "obs": obs,
        "role": role,
        "policy": {"config": policy.config, "state_dict": policy.state_dict()},
        "meta": meta or {},
        "train_state": train_state,
    }
    require_finite_payload(payload, path)
    return atomic_torch_save(payload, path)


def safe_torch_load(path, safe_globals=()):
    """``torch.load`` that never runs code from the file: tensors, numbers, strings and containers only,
    plus the ``safe_globals`` a caller allows by name. Anything else is a one-line :class:`CheckpointError`."""
    try:
        with torch.serialization.safe_globals(list(safe_globals)):
            return torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as e:  # what weights_only refuses: a global it does not allow
        found = re.search(r"GLOBAL (\S+)|but got <class '([^']+)'>", str(e))
        if not found:  # no refused global named: not a pickle, or opcodes weights_only never reads
            raise CheckpointError(_unreadable(path, "nothing a weights-only load can read")) from e
        raise CheckpointError(
            f"refused to load {path}: it asks for {found.group(1) or found.group(2)}, which loading could run as "
            "code; load only checkpoints written by flownav (tensors, numbers, strings, lists, dicts)"
        ) from e
    except Exception as e:  # noqa: BLE001 - any other unpickling failure means a corrupt file
        raise CheckpointError(_unreadable(path, " ".join(str(e).split()).split(". ")[0][:160])) from e


def _unreadable(path, reason: str) -> str:
    return (
        f"cannot read checkpoint {path}: it is truncated, corrupt or not a torch file ({reason}); "
        "use a checkpoint written by flownav (a run's checkpoints/last.pt or best.pt)"
    )


# ----------------------------------------------------------------------------- training state (exact resume)
def training_state(env, optimizer, counters: dict, generators: dict | None = None, **extra) -> dict:
    """What every trainer's ``last.pt`` carries to resume bit for bit: counters, optimiser, torch RNG (and the
    trainer's own ``generators``, by name), env state, and the trainer's ``extra`` entries."""
    rng = {"torch": torch.get_rng_state()} | {k: g.get_state() for k, g in (generators or {}).items()}
    return {**counters, "optimizer": optimizer.state_dict(), "rng": rng, "env": env.state_dict(), **extra}


def restore_training_state(payload: dict, policy, optimizer, env, generators: dict | None = None) -> dict:
    """Put the policy, optimiser, env state and RNGs of a ``last.pt`` back; return its train_state."""
    st = payload["train_state"]  # checked by load_resume_checkpoint
    policy.load_state_dict(payload["policy"]["state_dict"])
    optimizer.load_state_dict(st["optimizer"])
    env.load_state_dict(st["env"])
    torch.set_rng_state(st["rng"]["torch"])
    for name, g in (generators or {}).items():
        g.set_state(st["rng"][name])
    return st


class RunCheckpoints:
    """A training run's checkpoints (``<run>/checkpoints/last.pt``, ``best.pt``), written and resumed one way for
    every trainer: the policy with its view and role; ``meta`` with the run's resolved config, counters and
    metrics; the training state (:func:`training_state`) with the trainer's own entries."""

    def __init__(self, directory, policy, obs: str, role: str, config: dict, env, optimizer, generators=None):
        self.directory, self.policy, self.obs, self.role, self.config = Path(directory), policy, obs, role, config
        self.env, self.optimizer, self.generators = env, optimizer, dict(generators or {})

    def save(self, name: str, counters: dict, metrics: dict, meta: dict | None = None, **extra) -> Path:
        """Write ``name`` (``counters``: frames, iteration, wall_time; ``extra``: the trainer's resume entries)."""
        train_state = training_state(self.env, self.optimizer, counters, self.generators, **extra)
        info = {"config": self.config, "frames": counters["frames"], "iteration": counters["iteration"]}
        info |= {"metrics": metrics, **(meta or {})}
        return save_policy_checkpoint(self.directory / name, self.policy, self.obs, self.role, info, train_state)

    def restore(self, payload: dict) -> dict:
        """Continue from a ``last.pt`` (:func:`load_resume_checkpoint`'s payload); return its train_state."""
        return restore_training_state(payload, self.policy, self.optimizer, self.env, self.generators)


RESUME_ONLY = ("env", "buffer", "pairs")  # train_state entries only a resumed run reads: a shipped copy drops them


def ship_checkpoint(src, dst) -> Path:
    """Copy a run's checkpoint to a shipped place (e.g. checkpoints/student.pt), atomically, without the
    entries only a resume needs; refused if it holds a NaN or an infinity."""
    payload = load_checkpoint(src)
    if payload.get("train_state"):
        payload["train_state"] = {k: v for k, v in payload["train_state"].items() if k not in RESUME_ONLY}
    require_finite_payload(payload, dst)
    return atomic_torch_save(payload, dst)


def load_checkpoint(path) -> dict:
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(
            f"no checkpoint at {path}: train one (python train.py +experiment=teacher) or fix the path"
        )
    payload = safe_torch_load(path)
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise CheckpointError(f"{path} is not a {FORMAT} checkpoint")
    policy = payload.get("policy")
    missing = [k for k in ("obs", "role", "policy") if k not in payload]
    missing += [f"policy.{k}" for k in ("config", "state_dict") if not isinstance(policy, dict) or k not in policy]
    if missing:
        raise CheckpointError(
            f"{path} lacks {missing[0]!r}: it is an incomplete {FORMAT} checkpoint; use the run's last.pt or "
            "best.pt, or a file written by save_policy_checkpoint"
        )
    require_consistent_policy(path, policy)
    # weights holding a NaN or an infinity would act, teach or export nonsense (an infinite normaliser mean does it
    # silently: every normalised input is clamped to its bound)
    if bad := non_finite_entries(policy["state_dict"], "policy.state_dict"):
        raise NonFiniteError(
            f"{path} has NaN or infinity in {_first_names(bad)}; use a checkpoint written by flownav (it refuses to "
            "save such weights)"
        )
    return payload


def require_consistent_policy(path, policy: dict) -> None:
    """Refuse (one line) a checkpoint whose ``policy.config`` builds no policy or whose ``policy.state_dict`` is not
    that policy's: a key missing or extra, or a tensor of another shape (a corrupt or hand-edited file)."""
    fix = "the file is corrupt or was edited; use the run's last.pt or best.pt, or a file written by flownav"
    try:  # shapes only: on the meta device, and the RNG as it was (a run's seeded draws must not move)
        with torch.random.fork_rng(devices=[]), torch.device("meta"):
            expected = DeterministicPolicy(**policy["config"]).state_dict()
    except (TypeError, ValueError) as e:
        raise CheckpointError(f"{path}: policy.config builds no flownav policy ({e}); {fix}") from e
    saved = policy["state_dict"]
    if not isinstance(saved, dict):
        raise CheckpointError(f"{path}: policy.state_dict is a {type(saved).__name__}, not a dict of tensors; {fix}")
    missing = sorted(set(expected) - set(saved))
    extra = sorted(set(saved) - set(expected))
    if missing or extra:
        what = f"lacks {missing[:3]}" if missing else f"has unknown entries {extra[:3]}"
        raise CheckpointError(f"{path}: policy.state_dict {what} for its policy.config; {fix}")
    for key, t in expected.items():
        if not torch.is_tensor(saved[key]) or saved[key].shape != t.shape:
            shape = tuple(saved[key].shape) if torch.is_tensor(saved[key]) else type(saved[key]).__name__
            raise CheckpointError(
                f"{path}: policy.state_dict.{key} is {shape}, its policy.config makes it {tuple(t.shape)}; {fix}"
            )


RUN_CONFIGS = ("config.yaml", ".hydra/config.yaml")  # what train.py (and Hydra) write into every run directory


def find_resume(resume) -> tuple[Path, Path]:
    """The run directory and checkpoint a ``resume=`` value names: a run directory (one that holds its
    config.yaml) or its ``checkpoints/last.pt``. Anything else (a shipped policy, a stray file) is a config
    error (``ConfigError``), reported before anything is written.
    """
    path = Path(str(resume)).expanduser()
    if path.is_file() and path.parent.name == "checkpoints":
        run_dir, ckpt = path.parent.parent, path
    elif path.is_dir():
        run_dir, ckpt = path, path / "checkpoints" / "last.pt"
    else:
        raise ConfigError(f"resume={resume}: no such run directory; pass a run directory (outputs/<name>/<run>)")
    if not any((run_dir / c).is_file() for c in RUN_CONFIGS):
        raise ConfigError(
            f"resume={resume}: {run_dir.resolve()} is not a run directory (no config.yaml); pass the directory of "
            "the run to continue (outputs/<name>/<run>), not a shipped checkpoint"
        )
    if not ckpt.is_file():
        raise ConfigError(f"resume={resume}: no {ckpt.relative_to(run_dir)} in that run directory")
    return run_dir, ckpt


def load_resume_checkpoint(resume, expect_obs: str, needs=()) -> tuple[Path, dict]:
    """The checkpoint ``resume=`` names (path, payload), refused (a config error) if it was trained on another
    view or lacks the training state (``needs``: a trainer's own entries) a bit-exact resume reads."""
    _, path = find_resume(resume)
    payload = load_checkpoint(path)
    if payload["obs"] != expect_obs:
        raise ConfigError(
            f"resume={resume}: that run trained a {payload['role']} on {payload['obs']!r} observations but this "
            f"config asks for {expect_obs!r}; resume with the same obs (obs={payload['obs']})"
        )
    st = payload.get("train_state") or {}
    missing = [k for k in ("optimizer", "rng", "env", *needs) if k not in st]
    if missing:
        raise ConfigError(
            f"resume={resume}: {path} holds no training state to resume from (no {', '.join(missing)}); "
            "resume from the run directory of a run of this version"
        )
    return path, payload


# What a resume may change: the budget, where and how it runs, logging and shipping. Anything else would not
# continue the run it names (another env size, network, flow, optimiser setting, ...).
RESUME_MAY_CHANGE = (
    "resume",
    "threads",
    "device",
    "checkpoint_every",
    "ship",
    "ship_requires",
    "output_checkpoint",
    "teacher_checkpoint",
    "logger",
    "algo.total_frames",
    "algo.iterations",
    "algo.results_json",
    "algo.final_eval_episodes",
)


def _flat(tree, prefix=""):
    if isinstance(tree, dict):
        out = {}
        for k, v in tree.items():
            out |= _flat(v, f"{prefix}{k}.")
        return out or {prefix[:-1]: {}}
    return {prefix[:-1]: tree}


def check_resume_settings(resume, payload: dict, config: dict) -> None:
    """Refuse (a config error) a resume whose config differs from the run's own (``payload['meta']['config']``)
    in a key outside :data:`RESUME_MAY_CHANGE`, naming the keys with both values. A key the run's config does
    not have counts as the same when it is null here (a setting added since, left at its default)."""
    saved = (payload.get("meta") or {}).get("config")
    if not isinstance(saved, dict):
        raise ConfigError(f"resume={resume}: its checkpoint records no config; resume a run of this version")
    there, here = _flat(saved), _flat(config)
    allowed = lambda key: any(key == k or key.startswith(k + ".") for k in RESUME_MAY_CHANGE)  # noqa: E731

    def same(key) -> bool:
        if key in there and key in here:
            return there[key] == here[key]
        return key not in there and here[key] is None  # a setting added since, left at its default (off)

    differ = [k for k in sorted(there.keys() | here.keys()) if not allowed(k) and not same(k)]
    if differ:
        shown = "; ".join(
            f"{k}={there[k] if k in there else '(unset)'} there, {here[k] if k in here else '(unset)'} here"
            for k in differ[:3]
        )
        raise ConfigError(
            f"resume={resume}: this config differs from the run's ({shown}{'; ...' if len(differ) > 3 else ''}); "
            "a resume continues that run with its settings: drop these overrides (a resume may change only "
            "the budget algo.total_frames / algo.iterations, threads, device, logger, checkpoint_every and shipping)"
        )


def warm_start(policy, path, view: str) -> dict:
    """Start ``policy`` (it reads ``view``) from the network of the checkpoint at ``path`` (``algo.init_from``):
    its weights and normaliser. Returns the checkpoint."""
    payload = load_checkpoint(path)
    if payload["obs"] != view:
        raise ConfigError(
            f"algo.init_from={path} reads {payload['obs']!r}, this run reads {view!r}: start from a checkpoint of "
            f"the run's view or set obs={payload['obs']}"
        )
    policy.load_state_dict(warm_start_state(policy, payload["policy"]))
    return payload


def load_policy(path, expect_obs: str | None = None, device="cpu") -> tuple[DeterministicPolicy, dict]:
    """Rebuild the deterministic policy of a checkpoint; refuse one that reads another view."""
    payload = load_checkpoint(path)
    if expect_obs is not None and payload["obs"] != expect_obs:
        raise CheckpointError(
            f"checkpoint {path} is a {payload['role']} reading {payload['obs']!r} observations "
            f"({observation_size(payload['obs'])} numbers), but this run needs {expect_obs!r} "
            f"({observation_size(expect_obs)} numbers): pass a checkpoint trained on {expect_obs!r}"
        )
    policy = DeterministicPolicy(**payload["policy"]["config"])
    policy.load_state_dict(payload["policy"]["state_dict"])
    policy.eval().requires_grad_(False)
    return policy.to(device), payload
