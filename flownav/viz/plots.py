"""Curves: success against a swept parameter (Figs. 5e, 6c) and DAgger loss over seeds (Fig. 2c)."""

from __future__ import annotations

import csv
import glob
import textwrap
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from flownav.viz.colors import MARKERS, policy_color


def plot_sweep(results: dict, xs, out: Path, xlabel: str, title: str = "", keyfn=lambda x: f"{x:g}") -> str:
    """``results[policy][keyfn(x)]`` is a summary; plots success (%) with Wilson 95% error bars."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    for i, (name, per) in enumerate(results.items()):
        rates = np.array([100 * per[keyfn(x)]["success_rate"] for x in xs])
        lo = np.array([100 * per[keyfn(x)]["success_ci95"][0] for x in xs])
        hi = np.array([100 * per[keyfn(x)]["success_ci95"][1] for x in xs])
        err = [np.clip(rates - lo, 0, None), np.clip(hi - rates, 0, None)]
        ax.errorbar(
            xs, rates, yerr=err, marker=MARKERS[i % len(MARKERS)], capsize=3, label=name, color=policy_color(name, i)
        )
    ax.set_xlabel(xlabel)
    ax.set_ylabel("success rate (%)")
    ax.set_ylim(-2, 102)
    ax.grid(alpha=0.3)
    ax.legend()
    ax.set_title("\n".join(textwrap.wrap(title, 60)), fontsize=9)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return str(out)


def collect_loss_runs(patterns, key: str = "train/loss") -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """``{run_dir: (iterations, loss)}`` from every ``metrics.csv`` matching the glob patterns."""
    runs = {}
    for pattern in patterns:
        for path in sorted(glob.glob(str(pattern), recursive=True)):
            it, val = [], []
            with open(path, newline="") as f:
                for row in csv.DictReader(f):
                    if row.get(key) not in (None, "", "nan") and row.get("iteration") not in (None, ""):
                        it.append(float(row["iteration"]))
                        val.append(float(row[key]))
            if val:
                runs[str(Path(path).parent)] = (np.asarray(it), np.asarray(val))
    return runs


def loss_stats(runs: dict) -> dict:
    n = min(len(v) for _, v in runs.values())
    it = next(iter(runs.values()))[0][:n]
    stack = np.stack([v[:n] for _, v in runs.values()])
    return {
        "iteration": it.tolist(),
        "mean": stack.mean(0).tolist(),
        "std": stack.std(0).tolist(),
        "runs": len(runs),
    }


def plot_loss_curves(runs: dict, out: Path, key: str = "train/loss") -> tuple[str, dict]:
    """Mean +- std over runs (truncated to the shortest), as the paper's Fig. 2c."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    st = loss_stats(runs)
    it, m, s = np.array(st["iteration"]), np.array(st["mean"]), np.array(st["std"])
    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    ax.plot(it, m, color="tab:orange", label=f"student (ego), mean of {st['runs']} runs")
    ax.fill_between(it, m - s, m + s, color="tab:orange", alpha=0.25, label="+- 1 std")
    ax.set_xlabel("DAgger iteration")
    ax.set_ylabel(f"imitation loss ({key}, eq. 9)")
    ax.set_yscale("log")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return str(out), st


def main(argv=None) -> None:
    """``python -m flownav.viz.plots <run glob> [<run glob> ...]``: loss curves of DAgger runs."""
    import argparse
    import json

    p = argparse.ArgumentParser(description=main.__doc__)
    p.add_argument("globs", nargs="+", help="globs of metrics.csv files, e.g. 'multirun/student/*/*/metrics.csv'")
    p.add_argument("--key", default="train/loss")
    # No default: the shipped results/figures/student_loss.png and results/student_loss.json come from
    # python evaluate.py +experiment=paper_loss_curves ship=true; a try writes where it is told.
    p.add_argument("--out", required=True, help="the PNG to write, e.g. outputs/student_loss.png")
    p.add_argument("--json", required=True, help="the curve's statistics (JSON), e.g. outputs/student_loss.json")
    a = p.parse_args(argv)
    runs = collect_loss_runs(a.globs, a.key)
    if not runs:
        raise SystemExit(f"no metrics.csv with {a.key!r} found under {a.globs}")
    fig, st = plot_loss_curves(runs, Path(a.out), a.key)
    Path(a.json).parent.mkdir(parents=True, exist_ok=True)
    Path(a.json).write_text(json.dumps(st | {"files": sorted(runs)}, indent=1))
    print(f"{fig}: {st['runs']} runs; final loss {st['mean'][-1]:.4f} +- {st['std'][-1]:.4f}")


if __name__ == "__main__":
    main()
