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
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from flownav.builders import build_flow, compose_config
from flownav.checkpoint import load_policy
from flownav.envs import ListTask
from flownav.evaluation.protocol import EvalSpec, evaluate
from flownav.evaluation.scripted import SCRIPTED, scripted_view
from flownav.paths import REPO_ROOT

POLICIES = ("checkpoints/generalist_student.pt", "checkpoints/generalist_student_noisy.pt", "scripted:head_to_target")


def zoo_case(deg: float):
    """(flow config, start box, target box) of the zoo case ``wake_turned_<deg>``."""
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf" / "evaluate"), version_base="1.3"):
        cfg = compose("config", overrides=["+experiment=generalization"])
    case = cfg.suite.generalization.cases[f"wake_turned_{deg:g}"]
    return OmegaConf.to_container(case.flow, resolve=True), case.task.start, case.task.target


def turned(points: torch.Tensor, deg: float, centre) -> torch.Tensor:
    """``points`` turned by ``deg`` about z through ``centre`` (x, y)."""
    a = math.radians(deg)
    x, y = points[:, 0] - centre[0], points[:, 1] - centre[1]
    out = points.clone()
    out[:, 0] = centre[0] + math.cos(a) * x - math.sin(a) * y
    out[:, 1] = centre[1] + math.sin(a) * x + math.cos(a) * y
    return out


def uniform_in(box, n: int, g: torch.Generator) -> torch.Tensor:
    lo, hi = torch.tensor(list(box[0])), torch.tensor(list(box[1]))
    return lo + torch.rand(n, 3, generator=g) * (hi - lo)


def compare(policy, view: str, deg: float, episodes: int) -> dict:
    """The protocol's summaries of ``policy`` (reading ``view``) in the two cases, by case name."""
    turned_wake, start_box, target_box = zoo_case(deg)
    centre = turned_wake["rotate_center"]
    posed_wake = {k: v for k, v in turned_wake.items() if k not in ("rotate_deg", "rotate_center")}
    g = torch.Generator().manual_seed(123)
    starts, targets = uniform_in(start_box, episodes, g), uniform_in(target_box, episodes, g)
    cases = {
        f"the wake turned by {deg:g}, the paper's task": (turned_wake, 0.0),
        f"the wake as posed, the task turned by {-deg:g}": (posed_wake, -deg),
    }
    env_cfg = compose_config([]).env
    out = {}
    for case, (flow_cfg, task_deg) in cases.items():
        task = ListTask(turned(starts, task_deg, centre), turned(targets, task_deg, centre))
        spec = EvalSpec(build_flow(OmegaConf.create(flow_cfg)), task, env_cfg, episodes)
        out[case] = evaluate(policy, view, spec).summary
    return out


def main(deg: float = 135.0, episodes: int = 10_000) -> None:
    torch.set_num_threads(1)
    for name in POLICIES:
        if name.startswith("scripted:"):
            policy = SCRIPTED[name.split(":", 1)[1]]()
            view = scripted_view(policy)
        else:
            policy, payload = load_policy(REPO_ROOT / name)
            view = payload["obs"]
        for case, r in compare(policy, view, deg, episodes).items():
            lo, hi = r["success_ci95"]
            fails = ", ".join(f"{k} {v['count']}" for k, v in r["failures"].items())
            print(f"{name} | {case}: {100 * r['success_rate']:.2f}% [{100 * lo:.2f}, {100 * hi:.2f}] ({fails})")


if __name__ == "__main__":
    main(float(sys.argv[1]) if len(sys.argv) > 1 else 135.0, int(sys.argv[2]) if len(sys.argv) > 2 else 10_000)
