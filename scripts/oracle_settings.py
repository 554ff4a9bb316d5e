"""The oracle's success and cost against its search settings, on the ABC test as posed and periodic and on
the extended domain of the wake.

    python scripts/oracle_settings.py                       # 64 episodes per setting of both ABC tests, one chunk
    python scripts/oracle_settings.py 128 periodic          # only the periodic test
    python scripts/oracle_settings.py 400 extended          # the extended domain, with its success by start x

Prints, per setting: success, left domain, timeout, mean success time and seconds (wall, one torch thread), on
the protocol's episodes (flownav.evaluation.protocol, seed EVAL_SEED) of each test as the configs define it
(flow, task and env groups; the suite's paper_abc entry for the ABC test as posed). docs/oracle.md quotes it.
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

ABC_SETTINGS = ({}, {"horizon": 100, "candidates": 48, "iterations": 2}, {"horizon": 30})
# The extended domain: the default settings, wider searches, then longer horizons with finer blocks.
EXTENDED_SETTINGS = (
    {},
    {"candidates": 256, "iterations": 4},
    {"candidates": 512, "iterations": 6},
    {"candidates": 256, "iterations": 4, "replan_every": 2},
    {"horizon": 100, "blocks": 5, "candidates": 128, "iterations": 3},
    {"horizon": 150, "blocks": 6, "candidates": 128, "iterations": 3},
)
SETTINGS = {"periodic": ABC_SETTINGS, "as_posed": ABC_SETTINGS, "extended": EXTENDED_SETTINGS}
START_X_BANDS = ((-4.0, 4.0, "upstream"), (4.0, 12.0, "around the regions"), (12.0, 22.0, "downstream of the target"))


def test_config(test: str):
    """A test's flow, task and env as the configs define them: the well-posed ABC test (flow/env abc_periodic),
    the paper's ABC test as posed (the suite's paper_abc entry) or the wake's extended domain (task=extended)."""
    if test == "extended":
        return compose_config(["flow=cylinder", "task=extended"])
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
        cfg = test_config(test)
        flow = build_flow(cfg.flow)
        spec = EvalSpec(flow, build_task(cfg.task, flow), cfg.env, episodes, chunk_size=episodes)
        for kw in SETTINGS[test]:
            t0 = time.time()
            run = evaluate(Oracle(**kw), "geo", spec)
            s, f = run.summary, run.summary["failures"]
            print(
                f"{test} {kw or 'defaults'}: success {100 * s['success_rate']:.1f}% of {episodes}, left "
                f"{100 * f['left_domain']['rate']:.1f}%, timeout {100 * f['timeout']['rate']:.1f}%, mean success "
                f"time {s['mean_success_time'] or 0:.1f}, {time.time() - t0:.0f} s",
                flush=True,
            )
            if test == "extended":
                x, ok = run.episodes.start[:, 0], run.episodes.success
                for lo, hi, name in START_X_BANDS:
                    band = (x >= lo) & (x < hi)
                    n = int(band.sum())
                    print(f"  start x {lo:g} to {hi:g} ({name}): {100 * float(ok[band].sum()) / max(n, 1):.1f}% of {n}")


if __name__ == "__main__":
    main(sys.argv[1:])
