"""The oracle's success and cost against its search settings, on the ABC test as posed and periodic.

    python scripts/oracle_settings.py                       # 64 episodes per setting, one chunk
    python scripts/oracle_settings.py 128 periodic          # only the periodic test

Prints, per setting: success, left domain, timeout, mean success time and seconds (wall, one torch thread).
docs/oracle.md quotes it.
"""

from __future__ import annotations

import sys
import time

import torch
from omegaconf import OmegaConf

from flownav.builders import build_task
from flownav.envs import NavigationEnv
from flownav.evaluation.metrics import summarize
from flownav.evaluation.oracle import Oracle
from flownav.evaluation.rollout import run_episodes
from flownav.flows.analytic import ABCFlow
from flownav.flows.base import make_periodic
from flownav.paths import REPO_ROOT

SETTINGS = ({}, {"horizon": 100, "candidates": 48, "iterations": 2}, {"horizon": 30})


def main(argv: list[str]) -> None:
    torch.set_num_threads(1)
    episodes = int(argv[0]) if argv else 64
    tests = argv[1:] or ["periodic", "as_posed"]
    for test in tests:
        flow = make_periodic(ABCFlow(), ["y", "z"]) if test == "periodic" else ABCFlow()
        task = build_task(OmegaConf.load(REPO_ROOT / "conf" / "task" / "abc.yaml"), flow)
        limit = 100.0 if test == "periodic" else 60.0

        def make_env(n, chunk, flow=flow, task=task, limit=limit):
            kw = {"time_limit": limit, "swim_speed_scale": 0.1, "seed": chunk}
            return NavigationEnv(flow, task, num_envs=n, views=("geo",), **kw)

        for kw in SETTINGS:
            t0 = time.time()
            ep = run_episodes(Oracle(**kw), "geo", make_env, episodes, episodes)
            s = summarize(ep.status, ep.time)
            f = s["failures"]
            print(
                f"{test} {kw or 'defaults'}: success {100 * s['success_rate']:.1f}% of {episodes}, left "
                f"{100 * f['left_domain']['rate']:.1f}%, timeout {100 * f['timeout']['rate']:.1f}%, mean success "
                f"time {s['mean_success_time'] or 0:.1f}, {time.time() - t0:.0f} s",
                flush=True,
            )


if __name__ == "__main__":
    main(sys.argv[1:])
