"""The zoo's turned wakes seen by a policy whose view turns with the swimmer: the zoo case ``wake_turned_<angle>``
(the wake turned by that angle about its centre, the paper's task) against the wake turned by another angle ``a``
with the task turned by ``a - angle`` (by default ``a = 0``: the wake as posed, the task turned back). An ego view
reads the flow and the target in the body frame and the vertical, and the initial headings are uniform at random
in every row, so the rows are the same navigation problem in distribution (not episode by episode: a heading is
drawn in the frame of the box, not of the flow): an ego policy's success rates agree within sampling error, and a
failure in a turned wake is a failure on a task in the wake the policy was trained in. Head-to-target reads only
the direction to the target, so it agrees too. A geo view reads the box's frame: run at wake angles inside the
families' range (-90..90), it shows how the experts that label those states in training do on that problem.

    python scripts/turned_wake_as_task.py                  # 135 degrees, 10,000 episodes, the generalist students
    python scripts/turned_wake_as_task.py 180 2000         # another zoo angle, fewer episodes
    python scripts/turned_wake_as_task.py 135 2000 --wake-angles 90 0 -90 --policies generalist_student wake \
        --set '+policies.wake={checkpoint: checkpoints/generalist_wake_expert.pt, obs: geo_priv}'

The case's flow and task come from conf/evaluate/experiment/generalization.yaml, the policies from its `policies`.
Same starts and targets in every row (uniform in the task's boxes, seed 123), the protocol's headings and flow
phases (seed EVAL_SEED). docs/generalist.md and docs/generalist_variants.md quote it.
"""

from __future__ import annotations

import argparse
import math

import torch
from omegaconf import OmegaConf

from flownav.builders import build_task, compose_config
from flownav.envs import ListTask
from flownav.evaluation.experiments import Suite
from flownav.evaluation.protocol import EvalSpec, evaluate
from flownav.flows.transforms import rotate_z

POLICIES = ("generalist_student", "generalist_student_noisy", "head_to_target")  # names in the suite's `policies`


def zoo_suite(overrides: tuple[str, ...] = ()) -> Suite:
    """The generalisation suite (its cases, policies and env), to load flows and policies once."""
    return Suite(compose_config(["+experiment=generalization", *overrides], app="evaluate"))


def compare(suite: Suite, name: str, deg: float, episodes: int, wake_angles: tuple[float, ...] = (0.0,)) -> dict:
    """The protocol's summaries of the suite's policy ``name``: the zoo case, then the wake turned by each of
    ``wake_angles`` with the task turned by (that angle - ``deg``); by row label."""
    policy, view, _ = suite.policy(name)
    case = suite.cfg.suite.generalization.cases[f"wake_turned_{deg:g}"]
    turned_wake = OmegaConf.to_container(case.flow, resolve=True)
    centre = turned_wake["rotate_center"]
    task = build_task(case.task, suite.flow(turned_wake))
    starts, targets = task.sample(episodes, torch.Generator().manual_seed(123))
    out = {}
    for a in (deg, *wake_angles):
        if a == deg:
            label, flow_cfg = f"the wake turned by {deg:g}, the paper's task", turned_wake
        elif a == 0:
            label = f"the wake as posed, the task turned by {-deg:g}"
            flow_cfg = {k: v for k, v in turned_wake.items() if k not in ("rotate_deg", "rotate_center")}
        else:
            label, flow_cfg = (
                f"the wake turned by {a:g}, the task turned by {a - deg:g}",
                turned_wake | {"rotate_deg": a},
            )
        angle = math.radians(a - deg)
        task = ListTask(rotate_z(starts, angle, centre), rotate_z(targets, angle, centre))
        out[label] = evaluate(policy, view, EvalSpec(suite.flow(flow_cfg), task, suite.cfg.env, episodes)).summary
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("angle", nargs="?", type=float, default=135.0, help="the zoo case: wake_turned_<angle>")
    parser.add_argument("episodes", nargs="?", type=int, default=10_000)
    parser.add_argument("--wake-angles", nargs="+", type=float, default=[0.0], help="the other rows' wake angles")
    parser.add_argument("--policies", nargs="+", default=list(POLICIES), help="names in the suite's policies")
    parser.add_argument("--set", action="append", default=[], metavar="OVERRIDE", help="a Hydra override (repeatable)")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    suite = zoo_suite(tuple(args.set))
    for name in args.policies:
        for case, r in compare(suite, name, args.angle, args.episodes, tuple(args.wake_angles)).items():
            lo, hi = r["success_ci95"]
            fails = ", ".join(f"{k} {v['count']}" for k, v in r["failures"].items())
            print(f"{name} | {case}: {100 * r['success_rate']:.2f}% [{100 * lo:.2f}, {100 * hi:.2f}] ({fails})")


if __name__ == "__main__":
    main()
