"""PPO training throughput, TorchRL pipeline vs a plain-torch collection loop, and minutes to 90% success.

    python benchmarks/train_throughput.py                                   # default flow (cylinder if present)
    python benchmarks/train_throughput.py --flow vortex_street --run runs/tune/vs_B

Writes benchmarks/results/train_throughput.json. Measured in one process, same threads:

* ``agent_steps_per_s``: end-to-end PPO of the teacher config (Collector + GAE + ClipPPOLoss epochs +
  normaliser update), swimmer steps per second over ``--iterations`` iterations after one warm-up.
* ``torchrl_collect_steps_per_s``: the Collector alone (policy sampling + env steps + auto-reset).
* ``plain_collect_steps_per_s``: the same physics (flownav.envs.core: the step, the episode sampler, the
  teacher's view) and the same policy MLP (normaliser, TanhNormal sample) as plain tensors, no TensorDict.
* ``torchrl_over_plain``: torchrl / plain collection speed (1.0 = no overhead).
* ``minutes_to_90pct``: wall time from the start of a teacher training run to the first logged
  success >= 0.9, read from that run's metrics.csv (``--run``; a training run of 30+ minutes is not
  repeated inside the benchmark). The success is the periodic deterministic evaluation
  (``eval/success_rate``) when the run logged one, else the training episodes' success. ``null`` if
  no run reached it; ``best_success_reached`` then says how far they got, and when.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from common import machine, write_result  # noqa: E402

from flownav.builders import compose_config  # noqa: E402
from flownav.envs import core  # noqa: E402


def plain_collect(env, policy, steps: int, seed: int = 0, record: list | None = None) -> float:
    """Collection with plain tensors: the physics functions ``env`` wraps (flownav.envs.core) on its settings and
    flow, the same MLP, episodes drawn from a stream seeded with ``seed`` (those of an env built with that seed).
    Every call starts new episodes.

    ``record`` (tests) receives each step's (observation, action).
    """
    settings, flow, B, device = env.settings, env.flow, env.num_envs, env.device
    (view,) = settings.views  # the policy's
    low, high = core.action_bounds(settings, device)
    rng = torch.Generator(device=device).manual_seed(seed)
    state = core.initial_state(B, settings, device)
    state = core.reset(state, torch.arange(B, device=device), flow, settings, rng)
    obs = core.observe(state, flow, settings)[view]
    t_start = time.perf_counter()
    with torch.no_grad():
        for _ in range(steps):
            out = policy.outputs(obs)
            loc, scale = out[:, :3], torch.nn.functional.softplus(out[:, 3:] + 0.0) + 1e-3
            u = torch.tanh(loc + scale * torch.randn_like(loc))
            action = low + (high - low) * (u + 1) / 2
            if record is not None:
                record.append((obs, action))
            logp = torch.distributions.Normal(loc, scale).log_prob(torch.atanh(u.clamp(-0.999, 0.999))).sum(-1)
            del logp
            state, reward = core.step(state, action, flow, settings)
            del reward
            ended = (state.status != core.Status.RUNNING).nonzero().squeeze(-1)
            state = core.reset(state, ended, flow, settings, rng)
            obs = core.observe(state, flow, settings)[view]
    return B * steps / (time.perf_counter() - t_start)


def success_column(rows) -> str:
    """The success a run is judged by: its periodic deterministic evaluation if it logged one."""
    return "eval/success_rate" if any(r.get("eval/success_rate") for r in rows) else "train/success_rate"


def logged_success(run):
    """(success, minutes, step, column) of every row of a run's metrics.csv that logged its success."""
    path = Path(run) / "metrics.csv"
    if not path.is_file():
        return
    rows = list(csv.DictReader(open(path, newline="")))
    col = success_column(rows)
    for r in rows:
        v = r.get(col)
        if v not in (None, "", "nan"):
            yield float(v), float(r["wall_time"]) / 60, int(float(r["step"])), col


def first_reaching(run, target: float = 0.9):
    """(minutes, step, column) of the first logged success >= ``target`` of a run, or None."""
    return next(((m, step, col) for v, m, step, col in logged_success(run) if v >= target), None)


def minutes_to_target(run_dirs, target: float = 0.9):
    """(minutes, run, step, column) of the earliest run to reach ``target`` success, or None."""
    hits = [(hit[0], str(run), *hit[1:]) for run in run_dirs if (hit := first_reaching(run, target))]
    return min(hits, default=None)


def minutes_per_run(run_dirs, target: float = 0.9) -> dict:
    """{run: minutes to ``target`` success, or None}: every run's own time, not just the fastest."""
    out = {}
    for run in run_dirs:
        hit = first_reaching(run, target)
        out[str(run)] = None if hit is None else round(hit[0], 2)
    return out


def best_reached(run_dirs):
    """(success, minutes, run, column): the highest logged success of any run and when it was first logged."""
    best = None
    for run in run_dirs:
        for v, m, _, col in logged_success(run):
            if best is None or v > best[0]:
                best = (v, m, str(run), col)
    return best


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--flow", default=None, help="flow config (default: cylinder if its dataset exists)")
    p.add_argument("--iterations", type=int, default=5)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--run", action="append", default=[], help="teacher run dir(s) for minutes_to_90pct")
    p.add_argument("--override", action="append", default=[])
    args = p.parse_args(argv)
    torch.set_num_threads(args.threads)

    flow_name = args.flow or ("cylinder" if (ROOT / "data/cylinder_re300/meta.json").exists() else "vortex_street")
    cfg = compose_config(
        ["+experiment=teacher", f"flow={flow_name}", "logger=csv", "logger.progress=false", *args.override]
    )
    from torchrl.collectors import Collector

    from flownav.algorithms.ppo import make_actor_critic
    from flownav.builders import build_env, build_flow, build_task

    flow = build_flow(cfg.flow)
    task = build_task(cfg.task, flow)
    B, T = int(cfg.env.num_envs), int(cfg.algo.rollout_steps)
    view = str(cfg.obs.view)  # the teacher's
    env = build_env(cfg.env, flow, task, [view], num_envs=B, seed=0)
    low, high = env.action_spec.space.low[0], env.action_spec.space.high[0]
    policy, actor, _, _ = make_actor_critic(view, view, low, high, cfg.algo.actor, cfg.algo.critic)

    # 1. TorchRL collection alone
    collector = Collector(env, actor, frames_per_batch=B * T, total_frames=-1, trust_policy=True)
    it = iter(collector)
    next(it)
    t = time.perf_counter()
    for _ in range(args.iterations):
        next(it)
    torchrl_collect = args.iterations * B * T / (time.perf_counter() - t)
    collector.shutdown()

    # 2. plain-torch collection, same physics and MLP
    plain_env = build_env(cfg.env, flow, task, [view], num_envs=B, seed=0)
    plain_collect(plain_env, policy, T)
    plain = sum(plain_collect(plain_env, policy, T) for _ in range(args.iterations)) / args.iterations

    # 3. end-to-end PPO (a short training run through train())
    import tempfile

    from flownav.algorithms.ppo import train

    frames = (args.iterations + 1) * B * T
    cfg_ppo = compose_config(
        [
            "+experiment=teacher",
            f"flow={flow_name}",
            "logger=csv",
            "logger.progress=false",
            f"algo.total_frames={frames}",
            "algo.final_eval_episodes=0",
            "algo.eval_every=0",
            "checkpoint_every=1000",
            *args.override,
        ]
    )
    with tempfile.TemporaryDirectory() as tmp:
        train(cfg_ppo, tmp)
        rows = list(csv.DictReader(open(Path(tmp) / "metrics.csv", newline="")))
    # steady state: skip the first iteration (warm-up)
    dt_wall = float(rows[-1]["wall_time"]) - float(rows[0]["wall_time"])
    e2e = (int(rows[-1]["step"]) - int(rows[0]["step"])) / dt_wall if dt_wall > 0 else math.nan

    reached = minutes_to_target(args.run)
    best = best_reached(args.run)
    payload = {
        "headline": {
            "agent_steps_per_s": round(e2e, 1),
            "minutes_to_90pct": None if reached is None else round(reached[0], 2),
            "torchrl_collect_steps_per_s": round(torchrl_collect, 1),
            "plain_collect_steps_per_s": round(plain, 1),
            "torchrl_over_plain": round(torchrl_collect / plain, 3),
            "target_minutes_to_90pct": 30,
        },
        "minutes_to_90pct_source": None
        if reached is None
        else {"run": reached[1], "step": reached[2], "metric": f"{reached[3]} >= 0.9"},
        # Every run's own time to 90% (the headline is the fastest): the spread over seeds.
        "minutes_to_90pct_per_run": minutes_per_run(args.run),
        # What the runs did reach, when 90% was not: the highest logged success and the wall time to it.
        "best_success_reached": None
        if best is None
        else {"success": round(best[0], 4), "minutes": round(best[1], 2), "run": best[2], "metric": best[3]},
        "flow": flow_name,
        "num_envs": B,
        "rollout_steps": T,
        "iterations": args.iterations,
        "actor_hidden": list(cfg.algo.actor.hidden),
        "command": "python benchmarks/train_throughput.py " + " ".join(sys.argv[1:]),
        "machine": machine(),
        "note": "2 cores, possibly shared with other jobs: see machine.load_average_1min.",
    }
    write_result("train_throughput", payload)


if __name__ == "__main__":
    main()
