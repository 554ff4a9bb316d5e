"""Policy checkpoints: one format for teachers, baselines and students.

A checkpoint is a ``torch.save`` dict with ``format == "flownav-policy-v1"``:

* ``policy``: the :class:`~flownav.agents.DeterministicPolicy` constructor config and
  ``state_dict`` (normaliser statistics included);
* ``obs``: the observation view it reads (a key of ``flownav.envs.observations.VIEWS``);
* ``role``: ``teacher``, ``baseline`` or ``student``; ``meta``: free (config, step, metrics);
* ``train_state``: anything a resumed run needs (optimiser, step counters, RNG), optional.

Writes are atomic (temporary file, then rename), so a kill never leaves half a checkpoint.
Reads never run code: :func:`safe_torch_load` unpickles tensors and plain containers only
(``weights_only=True``) and refuses anything else with a :class:`CheckpointError`.
"""

from __future__ import annotations

import os
import pickle
import re
from pathlib import Path

import torch
from tensordict.nn import TensorDictModule

from flownav.agents.networks import DeterministicPolicy
from flownav.atomic import atomic_write
from flownav.envs.observations import observation_size
from flownav.errors import CheckpointError, ConfigError

__all__ = ["CheckpointError", "load_checkpoint", "load_policy", "safe_torch_load", "save_policy_checkpoint"]

FORMAT = "flownav-policy-v1"


def atomic_torch_save(obj, path: str | os.PathLike) -> Path:
    return atomic_write(path, lambda f: torch.save(obj, f))


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
    return atomic_torch_save(payload, path)


def safe_torch_load(path, safe_globals=()):
    """``torch.load`` that never runs code from the file: tensors, numbers, strings and containers only,
    plus the ``safe_globals`` a caller allows by name. Anything else is a one-line :class:`CheckpointError`."""
    try:
        with torch.serialization.safe_globals(list(safe_globals)):
            return torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as e:  # what weights_only refuses: a global it does not allow
        found = re.search(r"GLOBAL (\S+)|but got <class '([^']+)'>", str(e))
        what = (found.group(1) or found.group(2)) if found else "an object that is not a tensor or plain data"
        raise CheckpointError(
            f"refused to load {path}: it asks for {what}, which loading could run as code; "
            "load only checkpoints written by flownav (tensors, numbers, strings, lists, dicts)"
        ) from e
    except Exception as e:  # noqa: BLE001 - any other unpickling failure means a corrupt file
        raise CheckpointError(f"cannot read checkpoint {path} ({e}); it is corrupt or not a flownav checkpoint") from e


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
    return payload


def find_resume_checkpoint(resume) -> Path:
    """The checkpoint a ``resume=`` value names: a file, or a run directory's ``checkpoints/last.pt``.

    A wrong value is a config error (``ConfigError``), reported at start like any other bad key.
    """
    path = Path(str(resume)).expanduser()
    if path.is_dir():
        for candidate in (path / "checkpoints" / "last.pt", path / "last.pt"):
            if candidate.is_file():
                return candidate
        raise ConfigError(f"resume={resume}: no checkpoints/last.pt in that run directory")
    if not path.is_file():
        raise ConfigError(f"resume={resume}: no such run directory or checkpoint file")
    return path


def load_resume_checkpoint(resume, expect_obs: str) -> tuple[Path, dict]:
    """The checkpoint ``resume=`` names (path, payload), refused (a config error) if it was trained on another view."""
    path = find_resume_checkpoint(resume)
    payload = load_checkpoint(path)
    if payload["obs"] != expect_obs:
        raise ConfigError(
            f"resume={resume}: that run trained a {payload['role']} on {payload['obs']!r} observations but this "
            f"config asks for {expect_obs!r}; resume with the same obs (obs={payload['obs']})"
        )
    return path, payload


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


def policy_module(policy: DeterministicPolicy, obs: str, out_key: str = "action") -> TensorDictModule:
    """Wrap a deterministic policy to read ``obs`` and write ``out_key`` in a tensordict."""
    return TensorDictModule(policy, in_keys=[obs], out_keys=[out_key])
