"""The zoo's turned wakes seen by a policy whose view turns with the swimmer: the wake turned by an angle about
(9, 0) with the paper's task, against the wake as posed with the task turned back by that angle. An ego view reads
the flow and the target in the body frame and the vertical, so it cannot tell the two apart (rotations about z):
its success must agree up to rounding, and its failure in a turned wake is a failure on a task in the wake it
was trained in. Head-to-target (geo view) only reads the direction to the target, so it agrees too.

    python scripts/turned_wake_as_task.py                  # 135 degrees, 10,000 episodes, the generalist students
    python scripts/turned_wake_as_task.py 180 2000         # another angle, fewer episodes

Same starts and targets in both (uniform in the zoo case's Region 1 and Region 2, seed 123), the protocol's
headings and flow phases (seed EVAL_SEED). docs/generalist.md quotes it.
"""

from __future__ import annotations

import math
import sys

import torch
from omegaconf import OmegaConf

from flownav.builders import build_flow, compose_config
from flownav.checkpoint import load_policy
from flownav.envs import ListTask
from flownav.evaluation.protocol import EvalSpec, evaluate
from flownav.evaluation.scripted import SCRIPTED, scripted_view
from flownav.paths import REPO_ROOT

CENTRE = (9.0, 0.0)  # the zoo's turned wakes turn about it (conf/evaluate/experiment/generalization.yaml)
START = ((8.0, 2.0, 3.0), (12.0, 4.0, 7.0))  # the zoo case's task: Region 1 -> Region 2
TARGET = ((8.0, -4.0, 3.0), (12.0, -2.0, 7.0))
POLICIES = ("checkpoints/generalist_student.pt", "checkpoints/generalist_student_noisy.pt", "scripted:head_to_target")


def turned(points: torch.Tensor, deg: float) -> torch.Tensor:
    """``points`` turned by ``deg`` about z through CENTRE."""
    a = math.radians(deg)
    x, y = points[:, 0] - CENTRE[0], points[:, 1] - CENTRE[1]
    out = points.clone()
    out[:, 0] = CENTRE[0] + math.cos(a) * x - math.sin(a) * y
    out[:, 1] = CENTRE[1] + math.sin(a) * x + math.cos(a) * y
    return out


def uniform_in(box, n: int, g: torch.Generator) -> torch.Tensor:
    lo, hi = torch.tensor(box[0]), torch.tensor(box[1])
    return lo + torch.rand(n, 3, generator=g) * (hi - lo)


def compare(policy, view: str, deg: float, episodes: int) -> dict:
    """The protocol's summaries of ``policy`` (reading ``view``) in the two cases, by case name."""
    g = torch.Generator().manual_seed(123)
    starts, targets = uniform_in(START, episodes, g), uniform_in(TARGET, episodes, g)
    wake = {"type": "grid", "path": str(REPO_ROOT / "data" / "cylinder_re300")}
    turned_wake = wake | {"rotate_deg": deg, "rotate_center": list(CENTRE)}
    cases = {
        f"the wake turned by {deg:g}, the paper's task": (turned_wake, 0.0),
        f"the wake as posed, the task turned by {-deg:g}": (wake, -deg),
    }
    env_cfg = compose_config([]).env
    out = {}
    for case, (flow_cfg, task_deg) in cases.items():
        task = ListTask(turned(starts, task_deg), turned(targets, task_deg))
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
