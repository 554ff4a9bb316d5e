"""The zoo's turned wakes seen by a policy whose view turns with the swimmer: the zoo case ``wake_turned_<angle>``
(the wake turned by that angle about its centre, the paper's task) against the wake as posed with the task turned
back by that angle. An ego view reads the flow and the target in the body frame and the vertical, and the initial
headings are uniform at random in both, so the two are the same navigation problem in distribution (not episode by
episode: a heading is drawn in the frame of the box, not of the flow): the success rates agree within sampling
error, and a failure in a turned wake is a failure on a task in the wake the policy was trained in. Head-to-target
reads only the direction to the target, so it agrees too.

    python scripts/turned_wake_as_task.py                  # 135 degrees, 10,000 episodes, the generalist students
    python scripts/turned_wake_as_task.py 180 2000         # another zoo angle, fewer episodes

The case's flow and task come from conf/evaluate/experiment/generalization.yaml. Same starts and targets in both
(uniform in the task's boxes, seed 123), the protocol's headings and flow phases (seed EVAL_SEED). docs/generalist.md
quotes it.
"""

from __future__ import annotations

import math
import sys

import torch
from omegaconf import OmegaConf

from flownav.builders import build_task, compose_config
from flownav.envs import ListTask
from flownav.evaluation.experiments import Suite
from flownav.evaluation.protocol import EvalSpec, evaluate
from flownav.flows.transforms import rotate_z

POLICIES = ("generalist_student", "generalist_student_noisy", "head_to_target")  # names in the suite's `policies`


def zoo_suite() -> Suite:
    """The generalisation suite (its cases, policies and env), to load flows and policies once."""
    return Suite(compose_config(["+experiment=generalization"], app="evaluate"))


def compare(suite: Suite, name: str, deg: float, episodes: int) -> dict:
    """The protocol's summaries of the suite's policy ``name`` in the two cases, by case name."""
    policy, view, _ = suite.policy(name)
    case = suite.cfg.suite.generalization.cases[f"wake_turned_{deg:g}"]
    turned_wake = OmegaConf.to_container(case.flow, resolve=True)
    centre = turned_wake["rotate_center"]
    posed_wake = {k: v for k, v in turned_wake.items() if k not in ("rotate_deg", "rotate_center")}
    task = build_task(case.task, suite.flow(turned_wake))
    starts, targets = task.sample(episodes, torch.Generator().manual_seed(123))
    out = {}
    for label, flow_cfg, task_deg in (
        (f"the wake turned by {deg:g}, the paper's task", turned_wake, 0.0),
        (f"the wake as posed, the task turned by {-deg:g}", posed_wake, -deg),
    ):
        angle = math.radians(task_deg)
        task = ListTask(rotate_z(starts, angle, centre), rotate_z(targets, angle, centre))
        out[label] = evaluate(policy, view, EvalSpec(suite.flow(flow_cfg), task, suite.cfg.env, episodes)).summary
    return out


def main(deg: float = 135.0, episodes: int = 10_000) -> None:
    torch.set_num_threads(1)
    suite = zoo_suite()
    for name in POLICIES:
        for case, r in compare(suite, name, deg, episodes).items():
            lo, hi = r["success_ci95"]
            fails = ", ".join(f"{k} {v['count']}" for k, v in r["failures"].items())
            print(f"{name} | {case}: {100 * r['success_rate']:.2f}% [{100 * lo:.2f}, {100 * hi:.2f}] ({fails})")


if __name__ == "__main__":
    main(float(sys.argv[1]) if len(sys.argv) > 1 else 135.0, int(sys.argv[2]) if len(sys.argv) > 2 else 10_000)
