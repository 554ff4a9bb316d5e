"""What the env's finite checks cost per step, against the step of env_throughput.py.

Run: ``PYTHONPATH=. python benchmarks/env_checks.py [--batch 4096] [--threads 1]``. Writes
``benchmarks/results/env_checks.json``.

Each step checks the action, the flow velocity and the reward (``flownav.errors.require_finite``). Both the
step (geo+ego views, ``step_and_maybe_reset``) and the three checks on tensors of the step's shapes are timed
as the fastest of many repeats, the figure a shared machine's load disturbs least; the throughput ratio is
``(step - checks) / step``. (Whole runs of env_throughput.py before and after differ by more than the checks
cost on a loaded machine.)
"""

from __future__ import annotations

import argparse
import sys
import timeit
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import env_stepper, machine, write_result  # noqa: E402
from env_throughput import DT_FRAME, SHAPE  # noqa: E402

from flownav.envs.navigation import NavigationEnv  # noqa: E402
from flownav.errors import require_finite  # noqa: E402
from flownav.flows import GridFlow  # noqa: E402
from flownav.flows.synthetic import synthetic_wake_grid  # noqa: E402


def fastest(fn, number: int, repeats: int) -> float:
    return min(timeit.repeat(fn, number=number, repeat=repeats)) / number


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--batch", type=int, default=4096)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--repeats", type=int, default=20)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    T, nx, ny, nz = SHAPE
    flow = GridFlow(**synthetic_wake_grid(frames=T, cells=(nx, ny), span_cells=nz, span=20.0, frame_dt=DT_FRAME))
    env = NavigationEnv(flow, num_envs=args.batch, views=("geo", "ego"), seed=0)
    step = env_stepper(env)
    tensors = (env.action_spec.rand(), torch.rand(args.batch, 3), torch.rand(args.batch))  # action, flow, reward

    def checks():
        for x in tensors:
            require_finite(x, "x", "")

    step_s = fastest(step, 20, args.repeats)
    checks_s = fastest(checks, 200, args.repeats)
    ratio = (step_s - checks_s) / step_s  # throughput with the checks / without
    print(f"B = {args.batch}: step {1e3 * step_s:.3f} ms, its three checks {1e6 * checks_s:.1f} us ({ratio:.4f})")
    write_result(
        "env_checks",
        {
            "what": "the env's finite checks (action, flow velocity, reward) per step of "
            "NavigationEnv.step_and_maybe_reset (geo+ego views); fastest of repeats",
            "command": "PYTHONPATH=. python benchmarks/env_checks.py " + " ".join(sys.argv[1:]),
            "machine": machine(),
            "batch": args.batch,
            "step_s": step_s,
            "checks_s": checks_s,
            "headline": {"throughput_ratio_with_vs_without_checks": ratio},
        },
    )


if __name__ == "__main__":
    main()
