"""Curves: success against a swept parameter (Figs. 5e, 6c), and the columns of runs' ``metrics.csv`` over seeds:
DAgger's loss (Fig. 2c) and PPO's training reward and success (Fig. 2b)."""

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
    fig, ax = plt.subplots(figsize=(7.5, 3.8))
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
    ax.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.01, 0.5))  # outside: the curves stay visible
    ax.set_title("\n".join(textwrap.wrap(title, 60)), fontsize=9)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return str(out)


def read_curve(path, key: str, x: str = "step") -> tuple[np.ndarray, np.ndarray]:
    """One column of a run's ``metrics.csv`` against column ``x``: the first value logged at each x, in x order."""
    pts: dict[float, float] = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            if row.get(key) not in (None, "", "nan") and row.get(x) not in (None, ""):
                pts.setdefault(float(row[x]), float(row[key]))
    xs = sorted(pts)
    return np.asarray(xs), np.asarray([pts[v] for v in xs])


def collect_runs(patterns, key: str, x: str = "step") -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """``{run_dir: (x, value)}`` from every ``metrics.csv`` matching the glob patterns that logs ``key``."""
    runs = {}
    for pattern in patterns:
        for path in sorted(glob.glob(str(pattern), recursive=True)):
            xs, ys = read_curve(path, key, x)
            if len(ys):
                runs[str(Path(path).parent)] = (xs, ys)
    return runs


def curve_stats(runs: dict, x: str = "step") -> dict:
    """Mean and std over runs on the x values of the run that ends first (the others interpolated there:
    runs logged at the same x values are averaged as they are)."""
    shortest = min(runs.values(), key=lambda c: c[0][-1])[0]
    stack = np.stack([np.interp(shortest, xs, ys) for xs, ys in runs.values()])
    return {x: shortest.tolist(), "mean": stack.mean(0).tolist(), "std": stack.std(0).tolist(), "runs": len(runs)}


def _band(ax, stats: dict, x: str, label: str, color=None):
    xs, m, s = np.array(stats[x]), np.array(stats["mean"]), np.array(stats["std"])
    (line,) = ax.plot(xs, m, color=color, label=label)
    ax.fill_between(xs, m - s, m + s, color=line.get_color(), alpha=0.25)


def plot_loss_curves(runs: dict, out: Path, key: str = "train/loss") -> tuple[str, dict]:
    """Mean +- std of the DAgger loss over runs, as the paper's Fig. 2c."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    st = curve_stats(runs, "iteration")
    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    _band(ax, st, "iteration", f"student (ego), mean of {st['runs']} runs +- 1 std", color="tab:orange")
    ax.set_xlabel("DAgger iteration")
    ax.set_ylabel(f"imitation loss ({key}, eq. 9)")
    ax.set_yscale("log")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return str(out), st


def plot_training_curves(groups: list[tuple[str, list]], out: Path, keys: list[str]) -> str:
    """Mean +- std over seeds of training columns (paper Fig. 2b), one panel per key, one band per group of
    run directories."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, len(keys), figsize=(5.5 * len(keys), 4), squeeze=False)
    for ax, key in zip(axes[0], keys, strict=True):
        for label, dirs in groups:
            runs = collect_runs([Path(d) / "metrics.csv" for d in dirs], key)
            if runs:
                _band(ax, curve_stats(runs), "step", f"{label} (n={len(runs)})")
        ax.set_xlabel("training steps (swimmer steps)")
        ax.set_ylabel(key.split("/")[-1].replace("_", " "))
        ax.grid(alpha=0.3)
        ax.legend()
    fig.suptitle("PPO training: mean +- std over seeds")
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return str(out)


def main(argv=None) -> None:
    """``python -m flownav.viz.plots loss|training``: the loss curves of DAgger runs (Fig. 2c), or training
    curves over seeds (Fig. 2b)."""
    import argparse
    import json

    from flownav.atomic import atomic_write_text

    p = argparse.ArgumentParser(prog="python -m flownav.viz.plots", description=main.__doc__)
    sub = p.add_subparsers(dest="cmd", required=True)
    lo = sub.add_parser("loss", help="DAgger loss over runs")
    lo.add_argument("globs", nargs="+", help="globs of metrics.csv files, e.g. 'multirun/student/*/*/metrics.csv'")
    lo.add_argument("--key", default="train/loss")
    lo.add_argument("--out", required=True, help="the PNG to write (results/figures/... only when shipping)")
    lo.add_argument("--json", default=None, help="also write the mean and std here")
    tr = sub.add_parser("training", help="training curves over seeds")
    tr.add_argument("--group", nargs="+", action="append", required=True, metavar=("LABEL", "RUN_DIR"))
    tr.add_argument("--key", action="append", default=None, help="metrics.csv column(s)")
    tr.add_argument("--out", required=True, help="the PNG to write (results/figures/... only when shipping)")
    a = p.parse_args(argv)
    if a.cmd == "training":
        keys = a.key or ["train/episode_reward", "train/success_rate"]
        print(f"wrote {plot_training_curves([(g[0], g[1:]) for g in a.group], Path(a.out), keys)}")
        return
    runs = collect_runs(a.globs, a.key, "iteration")
    if not runs:
        raise SystemExit(f"no metrics.csv with {a.key!r} found under {a.globs}")
    fig, st = plot_loss_curves(runs, Path(a.out), a.key)
    if a.json:
        atomic_write_text(a.json, json.dumps(st | {"files": sorted(runs)}, indent=1))
    print(f"{fig}: {st['runs']} runs; final loss {st['mean'][-1]:.4f} +- {st['std'][-1]:.4f}")


if __name__ == "__main__":
    main()
