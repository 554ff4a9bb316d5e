"""The oracle's cost and the grid-flow look-up that dominates it: the C look-up against the torch path, side by side.

    python benchmarks/oracle_throughput.py      # -> benchmarks/results/oracle_throughput.json

1. The look-up in the shipped wake (data/cylinder_re300) at the oracle's batch: ``swimmers`` positions with
   ``candidates`` rows each scattered around them (the candidate plans of one replan), per-swimmer times; the C
   kernel (flownav/flows/gridkernel.py) and ``GridFlow.velocity_torch``, with 1 and 2 threads, and whether the two
   agree bit for bit.
2. One replan of the oracle at the far-start labeller's search (``+experiment=generalist_away_expert``: 256
   candidates x 4 rounds, 60 steps ahead) for ``swimmers`` fresh episodes, with either look-up, and whether the
   plans agree bit for bit.
3. The env step of the wake's flows at a training batch (benchmarks/family_throughput.py's cases: the plain wake with
   the teacher's view, the students' family with their DAgger views, the far-start labeller's posed wake with the
   privileged views), windows of each look-up interleaved, 1 thread.
The oracle imitators' training (flownav/algorithms/oracle_dagger.py) spends most of its time in such replans.
"""

from __future__ import annotations

import argparse
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from common import machine, write_result  # noqa: E402
from family_throughput import make_stepper, window_rate  # noqa: E402

from flownav.algorithms.oracle_dagger import oracle_settings  # noqa: E402
from flownav.builders import build_env, build_flow, build_task, compose_config  # noqa: E402
from flownav.evaluation.oracle import Oracle  # noqa: E402
from flownav.flows.grid import GridFlow, load_grid_flow  # noqa: E402


@contextmanager
def torch_look_up():
    """Every GridFlow looks up with the torch path meanwhile."""
    fast = GridFlow.velocity
    GridFlow.velocity = GridFlow.velocity_torch
    try:
        yield
    finally:
        GridFlow.velocity = fast


def best_time(fn, rounds: int) -> float:
    fn()  # warm-up (and the kernel's build)
    times = []
    for _ in range(rounds):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def look_up(flow: GridFlow, swimmers: int, candidates: int, rounds: int, threads: int) -> dict:
    torch.set_num_threads(threads)
    gen = torch.Generator().manual_seed(0)
    lo, hi = torch.tensor(flow.bounds.lo), torch.tensor(flow.bounds.hi)
    centre = lo + (hi - lo) * torch.rand(swimmers, 3, generator=gen)
    pos = centre.repeat_interleave(candidates, 0) + torch.randn(swimmers * candidates, 3, generator=gen)
    t = (torch.rand(swimmers, generator=gen) * 100).repeat_interleave(candidates)
    c_s = best_time(lambda: flow.velocity(pos, t), rounds)
    torch_s = best_time(lambda: flow.velocity_torch(pos, t), rounds)
    return {
        "threads": threads,
        "rows": len(pos),
        "c_ms": 1e3 * c_s,
        "torch_ms": 1e3 * torch_s,
        "speedup": torch_s / c_s,
        "bit_identical": bool(torch.equal(flow.velocity(pos, t), flow.velocity_torch(pos, t))),
    }


def replan(swimmers: int, threads: int, overrides: list[str]) -> dict:
    torch.set_num_threads(threads)
    cfg = compose_config(["+experiment=generalist_away_expert", *overrides])
    flow = build_flow(cfg.flow)
    env = build_env(cfg.env, flow, build_task(cfg.task, flow), [str(cfg.obs.view)], num_envs=swimmers, seed=7000)
    env.reset()
    slots, settings = torch.arange(swimmers), oracle_settings(cfg.algo)

    def plan() -> torch.Tensor:
        return Oracle(**settings).act_privileged(env, slots)

    c_s = best_time(plan, 1)
    with torch_look_up():
        torch_s = best_time(plan, 1)
        reference = plan()
    return {
        "threads": threads,
        "swimmers": swimmers,
        "settings": settings,
        "c_s": c_s,
        "torch_s": torch_s,
        "speedup": torch_s / c_s,
        "bit_identical": bool(torch.equal(plan(), reference)),
    }


ENV_CASES = {  # flow -> the views its trainer's env computes
    "cylinder": ("geo_sincos",),
    "family_mix_turned": ("ego_mem_grad", "geo_priv_scene"),
    "family_wake_posed": ("geo_priv", "geo_priv_critic"),
}


def env_step(batch: int, seconds: float, rounds: int) -> list[dict]:
    torch.set_num_threads(1)
    rows = []
    for flow, views in ENV_CASES.items():
        step = make_stepper(flow, views, batch)
        c_rates, torch_rates = [], []
        for _ in range(rounds):  # interleaved windows: the machine's drift falls on both alike
            c_rates.append(window_rate(step, batch, seconds))
            with torch_look_up():
                torch_rates.append(window_rate(step, batch, seconds))
        c, t = sorted(c_rates)[rounds // 2], sorted(torch_rates)[rounds // 2]
        rows.append({"flow": flow, "views": list(views), "batch": batch, "c_steps_per_s": c, "torch_steps_per_s": t})
        rows[-1]["speedup"] = c / t
    return rows


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--swimmers", type=int, default=512)
    p.add_argument("--candidates", type=int, default=256)
    p.add_argument("--rounds", type=int, default=10)
    p.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    p.add_argument("--override", nargs="*", default=[], help="config overrides of the replan (e.g. small tests)")
    p.add_argument("--batch", type=int, default=4096, help="env slots of the env-step cases")
    p.add_argument("--seconds", type=float, default=2.0, help="length of one env-step window")
    p.add_argument("--out", default="oracle_throughput", help="the result's name in benchmarks/results")
    a = p.parse_args(argv)
    flow = load_grid_flow(ROOT / "data" / "cylinder_re300")
    looks = [look_up(flow, a.swimmers, a.candidates, a.rounds, n) for n in a.threads]
    plans = [replan(a.swimmers, n, a.override) for n in a.threads]
    steps = env_step(a.batch, a.seconds, max(a.rounds // 2, 1))
    result = {
        "what": __doc__.splitlines()[0],
        "command": "python benchmarks/oracle_throughput.py " + " ".join(sys.argv[1:] if argv is None else argv),
        "look_up": looks,
        "replan": plans,
        "env_step": steps,
        "machine": machine(),
        "headline": {
            "look_up_speedup": {str(r["threads"]): round(r["speedup"], 2) for r in looks},
            "replan_speedup": {str(r["threads"]): round(r["speedup"], 2) for r in plans},
            "env_step_speedup": {r["flow"]: round(r["speedup"], 2) for r in steps},
            "bit_identical": all(r["bit_identical"] for r in looks + plans),
        },
    }
    write_result(a.out, result)
    return result


if __name__ == "__main__":
    main()
