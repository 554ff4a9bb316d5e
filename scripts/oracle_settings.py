"""The oracle's success and cost against its search settings, on the ABC test as posed and periodic.

    python scripts/oracle_settings.py                       # 64 episodes per setting, one chunk
    python scripts/oracle_settings.py 128 periodic          # only the periodic test

Prints, per setting: success, left domain, timeout, mean success time and seconds (wall, one torch thread), on
the protocol's episodes (flownav.evaluation.protocol, seed EVAL_SEED) of env/default.yaml with the ABC swimmer.
docs/oracle.md quotes it.
"""

from __future__ import annotations

import sys
import time

import torch
from omegaconf import OmegaConf

from flownav.builders import build_task
from flownav.evaluation.oracle import Oracle
from flownav.evaluation.protocol import EvalSpec, evaluate
from flownav.flows.analytic import ABCFlow
from flownav.flows.base import make_periodic
from flownav.paths import REPO_ROOT

ABC_ENV = {"swim_speed_scale": 0.1}  # the ABC test's swimmer (conf/evaluate/experiment/paper_abc.yaml)
SETTINGS = ({}, {"horizon": 100, "candidates": 48, "iterations": 2}, {"horizon": 30})


def main(argv: list[str]) -> None:
    torch.set_num_threads(1)
    episodes = int(argv[0]) if argv else 64
    tests = argv[1:] or ["periodic", "as_posed"]
    for test in tests:
        flow = make_periodic(ABCFlow(), ["y", "z"]) if test == "periodic" else ABCFlow()
        task = build_task(OmegaConf.load(REPO_ROOT / "conf" / "task" / "abc.yaml"), flow)
        limit = 100.0 if test == "periodic" else 60.0
        env = OmegaConf.merge(OmegaConf.load(REPO_ROOT / "conf/env/default.yaml"), ABC_ENV, {"time_limit": limit})
        spec = EvalSpec(flow, task, env, episodes, chunk_size=episodes)
        for kw in SETTINGS:
            t0 = time.time()
            s = evaluate(Oracle(**kw), "geo", spec).summary
            f = s["failures"]
            print(
                f"{test} {kw or 'defaults'}: success {100 * s['success_rate']:.1f}% of {episodes}, left "
                f"{100 * f['left_domain']['rate']:.1f}%, timeout {100 * f['timeout']['rate']:.1f}%, mean success "
                f"time {s['mean_success_time'] or 0:.1f}, {time.time() - t0:.0f} s",
                flush=True,
            )


if __name__ == "__main__":
    main(sys.argv[1:])
