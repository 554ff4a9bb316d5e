"""The oracle's success and cost against its search settings, on the ABC test as posed and periodic.

    python scripts/oracle_settings.py                       # 64 episodes per setting, one chunk
    python scripts/oracle_settings.py 128 periodic          # only the periodic test

Prints, per setting: success, left domain, timeout, mean success time and seconds (wall, one torch thread), on
the protocol's episodes (flownav.evaluation.protocol, seed EVAL_SEED) of the ABC test as the configs define it
(flow, task and env groups; the suite's paper_abc entry for the test as posed). docs/oracle.md quotes it.
"""

from __future__ import annotations

import sys
import time

import torch
from omegaconf import OmegaConf

from flownav.builders import build_flow, build_task, compose_config
from flownav.evaluation.oracle import Oracle
from flownav.evaluation.protocol import EvalSpec, evaluate
from flownav.paths import REPO_ROOT

SETTINGS = ({}, {"horizon": 100, "candidates": 48, "iterations": 2}, {"horizon": 30})


def abc_config(test: str):
    """The ABC test's flow, task and env as the configs define them: the well-posed test
    (flow/env abc_periodic) or the paper's as posed (the suite's paper_abc entry)."""
    if test == "periodic":
        return compose_config(["flow=abc_periodic", "task=abc", "env=abc_periodic"])
    cfg = compose_config(["flow=abc", "task=abc"])
    suite = OmegaConf.load(REPO_ROOT / "conf" / "evaluate" / "experiment" / "paper_abc.yaml").suite.abc
    cfg.env = OmegaConf.merge(cfg.env, suite.env)
    return cfg


def main(argv: list[str]) -> None:
    torch.set_num_threads(1)
    episodes = int(argv[0]) if argv else 64
    tests = argv[1:] or ["periodic", "as_posed"]
    for test in tests:
        cfg = abc_config(test)
        flow = build_flow(cfg.flow)
        spec = EvalSpec(flow, build_task(cfg.task, flow), cfg.env, episodes, chunk_size=episodes)
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
