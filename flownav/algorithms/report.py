"""Held-out success of trained policies (and shipping the best seed), reward curves over seeds.

    # success on 10,000 held-out episodes of the training task, one entry per checkpoint
    python -m flownav.algorithms.report eval --name teacher --out results/teacher.json \\
        multirun/teacher/<date>/seed*/checkpoints/last.pt
    # the same, and ship the best of them (by this held-out success) to checkpoints/, atomically: only
    # finished runs of the experiment's full budget, scored on the full --episodes (flownav/shipping.py)
    python -m flownav.algorithms.report eval --name teacher --out results/teacher.json \\
        --ship checkpoints/teacher.pt multirun/teacher/<date>/seed*/checkpoints/last.pt
    # mean +- std of the training reward over seeds (paper Fig. 2b), teacher and baseline
    python -m flownav.algorithms.report curves --out results/figures/reward_curves.png \\
        --group "teacher (-geo)" multirun/teacher/<date>/seed* \\
        --group "baseline (-ego)" multirun/baseline_ego/<date>/seed*

Evaluation is deliberately minimal (the full suite is flownav.evaluation): the deterministic policy
(tanh of the TanhNormal location), a fixed seed, exactly ``--episodes`` episodes, one per env slot,
no auto-reset; the env is composed from the same Hydra groups as training (``--override`` adds more).
"""

from __future__ import annotations

import argparse
import csv
import datetime as dt
import json
import math
import shlex
import sys
from pathlib import Path

import torch

from flownav.atomic import atomic_write_text
from flownav.paths import REPO_ROOT

EVAL_SEED = 1_000_003  # held-out: training seeds are small integers
EPISODES = 10_000  # held-out episodes per checkpoint; shipping needs at least these


def compose_config(overrides=()):
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        return compose("config", overrides=list(overrides))


def evaluate_checkpoint(path, episodes: int = 10_000, overrides=(), chunk: int = 10_000, seed: int = EVAL_SEED):
    from flownav.algorithms.ppo import evaluate_policy
    from flownav.builders import build_env, build_flow, build_task
    from flownav.checkpoint import load_policy

    policy, payload = load_policy(path)
    obs = payload["obs"]
    train_cfg = payload.get("meta", {}).get("config", {})
    # The training run's flow / task / env groups, unless overridden.
    from omegaconf import OmegaConf, open_dict

    cfg = compose_config(list(overrides))
    with open_dict(cfg):
        for group in ("flow", "task", "env"):
            if group in train_cfg and not any(o.startswith((f"{group}=", f"{group}.")) for o in overrides):
                cfg[group] = OmegaConf.create(train_cfg[group])
    flow = build_flow(cfg.flow)
    task = build_task(cfg.task, flow)

    def make_env(n, chunk):
        return build_env(cfg.env, flow, task, [obs], num_envs=n, seed=seed + chunk)

    res = evaluate_policy(policy, make_env, obs, episodes, chunk=chunk)
    res.update(checkpoint=str(path), obs=obs, role=payload["role"], frames=payload.get("meta", {}).get("frames"))
    return res


def _mean_std(xs):
    xs = [x for x in xs if x is not None and not math.isnan(x)]
    if not xs:
        return None, None
    m = sum(xs) / len(xs)
    return m, (sum((x - m) ** 2 for x in xs) / len(xs)) ** 0.5


def cmd_eval(args) -> dict:
    from flownav.builders import ConfigError
    from flownav.checkpoint import load_checkpoint, ship_checkpoint
    from flownav.shipping import is_shipped, require_shippable

    if args.ship or is_shipped(args.out):  # refused before the (long) evaluation
        if args.episodes < EPISODES:
            raise ConfigError(
                f"--episodes {args.episodes} is below the {EPISODES} a shipped result needs; drop --ship "
                "(and write --out outside results/) for a try"
            )
        for p in args.checkpoints:
            require_shippable(load_checkpoint(p), p)
    torch.set_num_threads(args.threads)
    runs = [evaluate_checkpoint(p, args.episodes, args.override, args.chunk) for p in args.checkpoints]
    m, s = _mean_std([r["success_rate"] for r in runs])
    mt, _ = _mean_std([r["mean_success_time"] for r in runs])
    out = {
        "name": args.name,
        "command": "python -m flownav.algorithms.report " + " ".join(shlex.quote(a) for a in sys.argv[1:]),
        "date": dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "episodes_per_checkpoint": args.episodes,
        "eval_seed": EVAL_SEED,
        "success_rate_mean": m,
        "success_rate_std": s,
        "mean_success_time_mean": mt,
        "paper": {
            "teacher": {"success_rate": 0.9469, "mean_success_time": 26.92},
            "baseline_ego": {"success_rate": 0.0},
        },
        "runs": runs,
    }
    if args.ship:  # the rule for every shipped policy: the best seed by held-out success
        best = max(runs, key=lambda r: r["success_rate"])
        ship_checkpoint(best["checkpoint"], args.ship)
        out["shipped"] = {"checkpoint": best["checkpoint"], "to": args.ship, "success_rate": best["success_rate"]}
        print(f"shipped {best['checkpoint']} ({best['success_rate']:.4f}) -> {args.ship}")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(args.out, json.dumps(out, indent=2))
    print(json.dumps({k: v for k, v in out.items() if k != "runs"}, indent=2))
    for r in runs:
        print(f"{r['checkpoint']}: success {r['success_rate']:.4f}, mean success time {r['mean_success_time']}")
    return out


def read_curve(run_dir: Path, key: str):
    rows = list(csv.DictReader(open(Path(run_dir) / "metrics.csv", newline="")))
    pts = {}
    for r in rows:  # one value per step (the first), in step order
        if r.get(key) not in (None, "", "nan"):
            pts.setdefault(float(r["step"]), float(r[key]))
    steps = sorted(pts)
    return steps, [pts[s] for s in steps]


def cmd_curves(args) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, axes = plt.subplots(1, len(args.key), figsize=(5.5 * len(args.key), 4), squeeze=False)
    for ax, key in zip(axes[0], args.key, strict=True):
        for label, dirs in args.group:
            curves = [read_curve(d, key) for d in dirs]
            curves = [c for c in curves if c[0]]
            if not curves:
                continue
            end = min(c[0][-1] for c in curves)
            grid = np.linspace(0, end, 200)
            ys = np.stack([np.interp(grid, c[0], c[1]) for c in curves])
            mean, std = ys.mean(0), ys.std(0)
            (line,) = ax.plot(grid, mean, label=f"{label} (n={len(curves)})")
            ax.fill_between(grid, mean - std, mean + std, color=line.get_color(), alpha=0.25)
        ax.set_xlabel("training steps (swimmer steps)")
        ax.set_ylabel(key.split("/")[-1].replace("_", " "))
        ax.grid(alpha=0.3)
        ax.legend()
    fig.suptitle("PPO training: mean +- std over seeds")
    fig.tight_layout()
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=120)
    print(f"wrote {args.out}")


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m flownav.algorithms.report", description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    e = sub.add_parser("eval", help="held-out success of checkpoints")
    e.add_argument("checkpoints", nargs="+")
    e.add_argument("--name", required=True)
    e.add_argument("--out", required=True)
    e.add_argument("--episodes", type=int, default=EPISODES)
    e.add_argument("--chunk", type=int, default=10_000, help="episodes stepped together")
    e.add_argument("--override", action="append", default=[], help="Hydra override, e.g. flow=vortex_street")
    e.add_argument("--threads", type=int, default=2)
    e.add_argument("--ship", default=None, help="copy the best checkpoint (held-out success) here, atomically")
    c = sub.add_parser("curves", help="mean +- std training curves over seeds")
    c.add_argument("--group", nargs="+", action="append", required=True, metavar=("LABEL", "RUN_DIR"))
    c.add_argument("--key", action="append", default=None, help="metrics.csv column(s)")
    c.add_argument("--out", required=True, help="the PNG to write (results/figures/... only when shipping)")
    args = p.parse_args(argv)
    if args.cmd == "eval":
        from flownav.builders import ConfigError
        from flownav.checkpoint import CheckpointError

        try:
            cmd_eval(args)
        except (ConfigError, CheckpointError) as e:  # a bad argument: one line, no traceback
            sys.exit(f"error: {e}")
    else:
        args.group = [(g[0], g[1:]) for g in args.group]
        args.key = args.key or ["train/episode_reward", "train/success_rate"]
        cmd_curves(args)


if __name__ == "__main__":
    main()
