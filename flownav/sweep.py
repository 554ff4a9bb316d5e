"""Summary of a multirun (``python train.py -m ... seed=0,1,2``), written to the sweep directory at its end.

A Hydra callback (registered in conf/config.yaml under ``hydra.callbacks``) reads every job's run directory
(``final_metrics.json`` from train.py, ``.hydra/overrides.yaml`` from Hydra) and writes
``sweep_summary.json`` and ``sweep_summary.md``: one row per job, and per configuration (the overrides
other than ``seed``) the mean +- std of the held-out success over its seeds and the best seed.

The score is the first of :data:`SCORE_KEYS` that a run wrote (PPO's final evaluation, DAgger's student),
or ``metric`` when the callback is given one. The same summary of an existing sweep directory:
``python -m flownav.sweep <sweep dir>``.
"""

from __future__ import annotations

import json
import math
import statistics
import sys
from pathlib import Path

import yaml
from hydra.experimental.callback import Callback

from flownav.atomic import atomic_write_text

# Held-out success, in order of preference: the final deterministic evaluation, then the best periodic one.
SCORE_KEYS = ("eval/success_rate", "eval/student_success_rate", "best_success")


def read_runs(sweep_dir) -> list[dict]:
    """One record per job directory of the sweep (those holding Hydra's .hydra/overrides.yaml)."""
    runs = []
    for overrides_file in sorted(Path(sweep_dir).glob("*/.hydra/overrides.yaml")):
        job_dir = overrides_file.parent.parent
        overrides = [str(o) for o in yaml.safe_load(overrides_file.read_text()) or []]
        seed = next((int(o.split("=", 1)[1]) for o in overrides if o.split("=", 1)[0] == "seed"), None)
        if seed is None:  # the config's seed when the sweep does not set it
            cfg_file = job_dir / ".hydra" / "config.yaml"
            seed = (yaml.safe_load(cfg_file.read_text()) or {}).get("seed") if cfg_file.is_file() else None
        final_file = job_dir / "final_metrics.json"
        final = json.loads(final_file.read_text()) if final_file.is_file() else None
        runs.append({"job": job_dir.name, "seed": seed, "overrides": overrides, "final": final})
    return runs


def _score(final: dict | None, metric: str | None) -> tuple[str | None, float | None]:
    if final is None:
        return None, None
    for key in (metric,) if metric else SCORE_KEYS:
        value = final.get(key)
        if isinstance(value, int | float) and not math.isnan(value):
            return key, float(value)
    return None, None


def summarize_sweep(runs: list[dict], metric: str | None = None) -> dict:
    """Per-job rows and, per configuration, n / mean / std (sample, n - 1) / best seed of the score.

    A configuration is a job's overrides other than ``seed`` and those shared by every job (``common``)."""
    common = [o for o in (runs[0]["overrides"] if runs else []) if all(o in r["overrides"] for r in runs)]
    rows = []
    for r in runs:
        config = " ".join(o for o in r["overrides"] if o not in common and o.split("=", 1)[0] != "seed")
        key, score = _score(r["final"], metric)
        final = r["final"] or {}
        rows.append(
            {
                "job": r["job"],
                "seed": r["seed"],
                "config": config or "(all)",
                "score": score,
                "score_key": key,
                "steps": final.get("frames"),
                "wall_time_s": final.get("wall_time_s"),
                "status": "done" if r["final"] is not None else "no final_metrics.json (failed or unfinished)",
            }
        )
    groups = {}
    for config in dict.fromkeys(r["config"] for r in rows):
        scored = [r for r in rows if r["config"] == config and r["score"] is not None]
        scores = [r["score"] for r in scored]
        best = max(scored, key=lambda r: r["score"], default=None)
        groups[config] = {
            "n": len(scores),
            "mean": statistics.fmean(scores) if scores else None,
            "std": statistics.stdev(scores) if len(scores) > 1 else None,
            "best_seed": best["seed"] if best else None,
            "best_job": best["job"] if best else None,
            "best_score": best["score"] if best else None,
        }
    return {"metric": metric or " | ".join(SCORE_KEYS), "common": common, "runs": rows, "configs": groups}


def _pct(x) -> str:
    return "-" if x is None else f"{x:.2%}"


def summary_markdown(summary: dict, title: str) -> str:
    lines = [f"# Sweep {title}", "", f"Score: held-out success ({summary['metric']}).", ""]
    if summary["common"]:
        lines += [f"Every job: `{' '.join(summary['common'])}`", ""]
    lines += ["| config | seeds | mean | std | best seed | best |", "| --- | --- | --- | --- | --- | --- |"]
    for config, g in summary["configs"].items():
        stats = f"{_pct(g['mean'])} | {_pct(g['std'])} | {g['best_seed']} | {_pct(g['best_score'])}"
        lines.append(f"| {config} | {g['n']} | {stats} |")
    lines += ["", "| job | seed | config | score | steps | wall time (min) | status |"]
    lines += ["| --- | --- | --- | --- | --- | --- | --- |"]
    for r in summary["runs"]:
        wall = "-" if r["wall_time_s"] is None else f"{r['wall_time_s'] / 60:.1f}"
        lines.append(
            f"| {r['job']} | {r['seed']} | {r['config']} | {_pct(r['score'])} | {r['steps'] or '-'} | {wall} | "
            f"{r['status']} |"
        )
    return "\n".join(lines) + "\n"


def write_sweep_summary(sweep_dir, metric: str | None = None) -> dict:
    sweep_dir = Path(sweep_dir)
    summary = summarize_sweep(read_runs(sweep_dir), metric)
    atomic_write_text(sweep_dir / "sweep_summary.json", json.dumps(summary, indent=2))
    atomic_write_text(sweep_dir / "sweep_summary.md", summary_markdown(summary, str(sweep_dir)))
    return summary


class SweepSummary(Callback):
    """``hydra.callbacks.sweep_summary: {_target_: flownav.sweep.SweepSummary, metric: null}``."""

    def __init__(self, metric: str | None = None):
        self.metric = metric

    def on_multirun_end(self, config, **kwargs) -> None:
        sweep_dir = Path(str(config.hydra.sweep.dir))
        summary = write_sweep_summary(sweep_dir, self.metric)
        print(summary_markdown(summary, str(sweep_dir)), flush=True)


if __name__ == "__main__":
    if len(sys.argv) != 2 or not Path(sys.argv[1]).is_dir():
        sys.exit("usage: python -m flownav.sweep <sweep dir>  (a multirun directory, e.g. multirun/teacher/<date>)")
    print(summary_markdown(write_sweep_summary(sys.argv[1]), sys.argv[1]))
