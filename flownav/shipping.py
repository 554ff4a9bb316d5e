"""Shipped files (checkpoints/, results/, REPORT.md, data/) change only by an explicit, named action.

Every run writes into its own run directory. ``ship=true`` (train.py, evaluate.py), an explicit
``report=`` / ``results=`` path (evaluate.py) or ``python -m flownav.evaluation.selection --ship`` (the
best of several seeds) copies a result to a shipped place, and only a result of the full budget: a run
whose training budget is below its experiment's, or an evaluation with fewer episodes, is refused.
"""

from __future__ import annotations

from pathlib import Path

from omegaconf import OmegaConf

from flownav.atomic import atomic_copy
from flownav.checkpoint import load_policy, ship_checkpoint
from flownav.errors import ConfigError
from flownav.paths import CHECKPOINT_DIR, DATA_DIR, REPO_ROOT, RESULTS_DIR, resolve

SHIPPED = (CHECKPOINT_DIR, RESULTS_DIR, REPO_ROOT / "REPORT.md", DATA_DIR)
CONF = REPO_ROOT / "conf"

# The settings that make a training run's budget (steps, data, updates, evaluation episodes), per algorithm.
BUDGET = {
    "ppo": ("total_frames", "final_eval_episodes"),
    "dagger": ("iterations", "num_envs", "steps_per_iteration", "updates_per_iteration", "final_eval_episodes"),
    "oracle_dagger": ("iterations", "episodes", "epochs", "eval_episodes"),
}
# The counter of last.pt's train_state that says how far a run got, and the setting it must reach.
PROGRESS = {
    "ppo": ("frames", "total_frames"),
    "dagger": ("iteration", "iterations"),
    "oracle_dagger": ("iteration", "iterations"),
}


def is_shipped(path) -> bool:
    """True for a path in checkpoints/, results/ or data/, or REPORT.md, of this repository."""
    p = resolve(str(path)).resolve()
    return any(p == s or s in p.parents for s in SHIPPED)


def experiment_budget(name: str, algo: str) -> dict:
    """The budget settings of ``conf/experiment/<name>.yaml``: its own values over those of the experiments it
    builds on (its ``defaults``, in order), over its algo group's."""
    base = OmegaConf.load(CONF / "algo" / f"{algo}.yaml")
    own = _experiment_section(name, "algo")
    return {k: own.get(k, base.get(k)) for k in BUDGET[algo]}


def experiment_requirements(name: str) -> dict:
    """The held-out checks a policy of ``conf/experiment/<name>.yaml`` must pass to be shipped (its
    ``ship_requires`` over those of the experiments it builds on): check name -> {"overrides": [Hydra overrides
    of its training flow, task and env], "min_success": the least held-out success}. {} for a run of no
    experiment."""
    if not (CONF / "experiment" / f"{name}.yaml").is_file():
        return {}
    reqs = _experiment_section(name, "ship_requires")
    for key, req in reqs.items():
        if set(req) != {"overrides", "min_success"} or not 0.0 <= float(req["min_success"]) <= 1.0:
            raise ConfigError(
                f"ship_requires.{key} of experiment {name}: give {{overrides: [...], min_success: <0..1>}}, got {req}"
            )
    return reqs


def _experiment_section(name: str, section: str) -> dict:
    exp_file = CONF / "experiment" / f"{name}.yaml"
    if not exp_file.is_file():
        raise ConfigError(
            f"ship=true needs a run of an experiment (name={name} has no conf/experiment/{name}.yaml); "
            "run python train.py +experiment=<name> ship=true"
        )
    exp = OmegaConf.load(exp_file)
    out: dict = {}
    for parent in exp.get("defaults") or []:
        if isinstance(parent, str) and parent != "_self_":  # another experiment (groups come as overrides)
            out.update(_experiment_section(parent, section))
    out.update(OmegaConf.to_container(exp.get(section) or OmegaConf.create({})))
    return out


def failed_requirements(checks: dict) -> list[str]:
    """The checks (``{name: {"success_rate", "min_success", ...}}``) a policy failed, as "name (rate < min)"."""
    return [
        f"{k} ({c['success_rate']:.4f} < {c['min_success']})"
        for k, c in checks.items()
        if not c["success_rate"] >= c["min_success"]
    ]


def require_full_budget(cfg) -> None:
    """Refuse (one line, naming the key) a run whose budget is below its experiment's."""
    algo = str(cfg["algo"]["name"])
    for key, full in experiment_budget(str(cfg["name"]), algo).items():
        if full is not None and float(cfg["algo"][key]) < float(full):
            raise ConfigError(
                f"shipping refused: algo.{key}={cfg['algo'][key]} is below experiment {cfg['name']}'s {full} "
                "(a partial budget); drop ship=true for a try, or train with the experiment's budget"
            )


def require_shippable(payload: dict, what) -> None:
    """Refuse the checkpoint of a run that stopped before its budget (interrupted, resumed but unfinished) or
    whose budget is below its experiment's."""
    cfg = payload.get("meta", {}).get("config") or {}
    algo = (cfg.get("algo") or {}).get("name")
    st = payload.get("train_state") or {}
    if algo not in PROGRESS:
        raise ConfigError(f"{what} is not the checkpoint of a training run (no training config in it); cannot ship it")
    counter, setting = PROGRESS[algo]
    done, budget = int(st.get(counter, 0)), int(float(cfg["algo"][setting]))
    if done < budget:
        raise ConfigError(
            f"{what} stopped at {counter} {done} of algo.{setting}={budget} (an unfinished run); "
            "resume it to the end (resume=<run dir>) before shipping"
        )
    require_full_budget(cfg)


def train_targets(cfg, multirun: bool) -> dict:
    """Where ``ship=true`` will copy this run's results, checked before the run starts; {} without ship."""
    if not cfg.get("ship"):
        return {}
    targets = {"checkpoint": cfg.get("output_checkpoint"), "results": cfg.algo.get("results_json")}
    targets = {k: str(v) for k, v in targets.items() if v}
    if not targets:
        raise ConfigError(
            "ship=true but this run names nothing to ship (output_checkpoint, algo.results_json are null); "
            "set output_checkpoint=<path> or drop ship=true"
        )
    if multirun:
        raise ConfigError(
            "ship=true in a -m sweep: the seeds would race for one file; drop ship=true and ship the best seed "
            "with python -m flownav.evaluation.selection --ship <path> <run>/checkpoints/last.pt ..."
        )
    require_full_budget(cfg)
    return targets


def refuse_failed_requirements(checks: dict, what, name: str) -> None:
    """Refuse (one line) to ship ``what`` when it failed one of its experiment's ``ship_requires`` checks."""
    failed = failed_requirements(checks)
    if failed:
        raise ConfigError(
            f"shipping refused: {what} fails experiment {name}'s ship_requires: {'; '.join(failed)} "
            f"(conf/experiment/{name}.yaml); nothing was shipped"
        )


def ship_run(run_dir: Path, targets: dict) -> dict:
    """Copy a finished run's policy and results record to the shipped places named by ``targets``."""
    from flownav.evaluation.selection import requirement_checks

    last = Path(run_dir) / "checkpoints" / "last.pt"
    policy, payload = load_policy(last)
    require_shippable(payload, last)
    refuse_failed_requirements(requirement_checks(policy, payload), last, payload["meta"]["config"]["name"])
    shipped = {}
    if "checkpoint" in targets:
        shipped["checkpoint"] = str(ship_checkpoint(last, resolve(targets["checkpoint"])))
    if "results" in targets:
        shipped["results"] = str(atomic_copy(Path(run_dir) / "results.json", resolve(targets["results"])))
    return shipped
