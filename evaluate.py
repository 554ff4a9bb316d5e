"""Evaluate navigation policies: one checkpoint on any flow and task, or every experiment of the paper.

    python evaluate.py checkpoint=checkpoints/student.pt                          # training flow, 10,000 episodes
    python evaluate.py checkpoint=checkpoints/teacher.pt env.misalignment_deg=90  # a misaligned wake
    python evaluate.py checkpoint=checkpoints/student.pt flow=abc task=abc env.swim_speed_scale=0.1
    python evaluate.py checkpoint=scripted:head_to_target flow=uniform  # a scripted reference, same episodes
    python evaluate.py +experiment=paper ship=true       # the whole paper -> REPORT.md, results/paper.json
    python evaluate.py +experiment=paper_misalignment ship=true    # one experiment (merged into the report)
    python evaluate.py +experiment=paper flow=vortex_street max_episodes=500      # a quick dry run (run dir only)

Without ``ship=true`` (or an explicit ``report=`` / ``results=`` / ``figures_dir=``) the suite writes its report,
results and figures into its own run directory (Hydra's output dir); shipping a reduced episode count
(``max_episodes``, or ``suite.<name>.episodes=`` on the command line) is refused.

Episodes are deterministic (the policy's mean action) and counted exactly: one per env slot, no
auto-reset. See docs/evaluation.md.
"""

from __future__ import annotations

import json
import shlex
import sys
import time
from pathlib import Path

import hydra
import torch
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf

from flownav import schema
from flownav.atomic import atomic_write_text
from flownav.errors import ConfigError, reported_as_one_line
from flownav.evaluation.protocol import EvalSpec, evaluate
from flownav.evaluation.scripted import load_evaluated
from flownav.evaluation.tables import log_line
from flownav.paths import REPO_ROOT, resolve
from flownav.shipping import is_shipped


def command_line() -> str:
    return "python evaluate.py " + " ".join(shlex.quote(a) for a in sys.argv[1:])


def evaluate_checkpoint(cfg: DictConfig, log=print) -> dict:
    """Evaluate ``cfg.checkpoint`` on ``cfg.flow`` / ``cfg.task`` / ``cfg.env`` for ``cfg.episodes`` episodes."""
    policy, payload = load_evaluated(str(cfg.checkpoint), expect_obs=cfg.get("expect_obs"), device=cfg.device)
    obs = payload["obs"]
    t0 = time.time()
    out = evaluate(policy, obs, EvalSpec.from_config(cfg), progress=bool(cfg.progress)).summary
    out.update(
        seconds=round(time.time() - t0, 2),
        checkpoint=str(cfg.checkpoint),
        obs=obs,
        role=payload["role"],
        command=command_line(),
    )
    log(f"{cfg.checkpoint} ({payload['role']}, {obs}): {log_line(out)} ({out['seconds']} s)")
    if cfg.get("output"):
        # named explicitly (a shipped place only with the full count: run())
        atomic_write_text(str(cfg.output), json.dumps(out, indent=1))
    return out


def run_dir() -> Path:
    """Hydra's output directory of this run (outside Hydra, e.g. evaluate.run() from Python: a fresh one)."""
    try:
        return Path(HydraConfig.get().runtime.output_dir)
    except ValueError:
        return REPO_ROOT / "outputs" / "evaluate" / time.strftime("%Y-%m-%d_%H-%M-%S")


SUITE_OUTPUTS = {"results": "results/paper.json", "report": "REPORT.md", "figures_dir": "results/figures"}


def suite_outputs(cfg: DictConfig) -> None:
    """Fill in where the suite writes: an explicit path as given; else the shipped place with ship=true, else
    the run directory. Writing a shipped place (results/, REPORT.md) with a reduced episode count is refused."""
    here = None
    for key, shipped in SUITE_OUTPUTS.items():
        if not cfg.get(key):
            here = here or run_dir()
            cfg[key] = str(resolve(shipped) if cfg.get("ship") else here / Path(shipped).name)
    for spec in cfg.suite.values():  # an experiment's own file (e.g. results/student_loss.json)
        if spec is not None and spec.get("json") and is_shipped(spec.json) and not cfg.get("ship"):
            here = here or run_dir()
            spec.json = str(here / Path(str(spec.json)).name)
    shipped = [str(cfg[k]) for k in SUITE_OUTPUTS if is_shipped(cfg[k])]
    refuse_in_a_sweep(shipped)
    if shipped and cfg.get("max_episodes"):
        raise ConfigError(
            f"max_episodes={cfg.max_episodes} caps the episode count: a reduced run never writes {shipped[0]}; "
            "drop ship=true (and the explicit report=/results=/figures_dir=) for a try, or drop max_episodes"
        )
    keys = [(o, o.split("=")[0].lstrip("+~")) for o in command_line_overrides()]
    changed = [
        o
        for o, k in keys
        if k.startswith(("suite.", "policies.")) and any(part.endswith("episodes") for part in k.split("."))
    ]
    if shipped and changed:
        raise ConfigError(
            f"{changed[0]} changes an experiment's episode count: only the counts in conf/evaluate/experiment/ "
            f"write {shipped[0]}; drop ship=true (and the explicit report=/results=/figures_dir=) for a try"
        )
    if is_shipped(cfg.results):
        refuse_dropping_shipped_rows(cfg)


def refuse_dropping_shipped_rows(cfg: DictConfig) -> None:
    """A policy whose checkpoint is missing here would lose the rows it has in the shipped results (an entry is
    rewritten whole): refused before anything runs."""
    from flownav.evaluation.experiments import Suite

    path = resolve(str(cfg.results))
    try:
        shipped = json.loads(path.read_text()).get("experiments", {}) if path.is_file() else {}
    except json.JSONDecodeError:
        return
    suite = Suite(cfg, log=lambda *_: None)
    for name, spec in cfg.suite.items():
        if spec is None or not spec.get("enabled", True) or name not in shipped:
            continue
        for pol, why in suite.missing(name, spec).items():
            if pol in (shipped[name].get("policies") or {}):
                raise ConfigError(
                    f"{why}; {cfg.results} has {pol}'s rows of {name}, which this run would drop: restore it, or "
                    "drop ship=true (and the explicit report=/results=/figures_dir=) for a try"
                )


def refuse_in_a_sweep(shipped: list[str]) -> None:
    """The jobs of a -m sweep would race for one shipped file (REPORT.md, results/...): refused."""
    try:
        multirun = HydraConfig.get().mode == RunMode.MULTIRUN
    except ValueError:  # outside Hydra (evaluate.run() from Python): one run
        return
    if multirun and shipped:
        raise ConfigError(
            f"a -m sweep writing {shipped[0]}: its jobs would race for one file; drop ship=true (and the explicit "
            "report=/results=/figures_dir=/output=) and ship one run"
        )


def command_line_overrides() -> list[str]:
    """The overrides this run was started with (none outside Hydra, e.g. evaluate.run() from Python)."""
    try:
        return list(HydraConfig.get().overrides.task)
    except ValueError:
        return []


def run_paper(cfg: DictConfig, log=print) -> dict:
    """Run the suite, merge it into ``cfg.results`` and rewrite ``cfg.report`` (see :func:`suite_outputs`)."""
    from flownav.evaluation.experiments import run_suite
    from flownav.evaluation.report import merge_results, write_report
    from flownav.provenance import provenance

    suite_outputs(cfg)
    cmd = command_line()
    # Before the run: its own outputs (figures, results) are tracked files and would mark the commit dirty.
    prov = provenance(cmd)
    t0 = time.time()
    results = run_suite(cfg, log=log, provenance=prov)
    results_path = resolve(str(cfg.results))
    data = merge_results(results_path, results, prov, log=log)
    report_path = resolve(str(cfg.report))
    report = write_report(data, report_path, cmd, seconds=time.time() - t0, commit=prov["commit"], results=results_path)
    log(f"wrote {cfg.results} and {report} in {time.time() - t0:.1f} s")
    return results


def run(cfg: DictConfig, log=print) -> dict:
    unknown = set(cfg.keys()) - KNOWN_KEYS
    if unknown:
        raise ConfigError(
            f"unknown top-level key(s) {sorted(unknown)} in the evaluate config; known: {sorted(KNOWN_KEYS)}"
        )
    schema.check_evaluate(cfg)
    if cfg.threads:
        torch.set_num_threads(int(cfg.threads))
    if cfg.get("suite"):
        return run_paper(cfg, log)
    refuse_in_a_sweep([str(cfg.output)] if cfg.get("output") and is_shipped(cfg.output) else [])
    if cfg.get("output") and is_shipped(cfg.output) and int(cfg.episodes) < FULL_EPISODES:
        raise ConfigError(
            f"episodes={cfg.episodes} is below the {FULL_EPISODES} a shipped result ({cfg.output}) needs; "
            "write output= outside results/ for a try"
        )
    return evaluate_checkpoint(cfg, log)


FULL_EPISODES = 10_000  # the held-out count of every shipped evaluation


KNOWN_KEYS = {
    "flow",
    "task",
    "env",
    "checkpoint",
    "expect_obs",
    "episodes",
    "output",
    "chunk_size",
    "seed",
    "threads",
    "device",
    "max_episodes",
    "progress",
    "policies",
    "suite",
    "results",
    "report",
    "figures_dir",
    "ship",
}


@hydra.main(version_base="1.3", config_path="conf/evaluate", config_name="config")
def main(cfg: DictConfig) -> None:
    OmegaConf.set_readonly(cfg, False)
    with reported_as_one_line():  # bad input: one line, exit status 2 (FLOWNAV_DEBUG=1: the traceback)
        run(cfg)


if __name__ == "__main__":
    main()
