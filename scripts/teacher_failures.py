"""Where and why a geo policy fails in the training task: exits per face, timeouts, success by geometry.

    python scripts/teacher_failures.py checkpoints/teacher.pt                  # 4,000 held-out episodes
    python scripts/teacher_failures.py checkpoints/teacher.pt time_limit=100   # any env/default.yaml key

Prints the outcome counts, the domain face each exit went through, where timed-out swimmers end, and
the success rate binned by the target's y and by (target x - start x). The episodes are the protocol's
(flownav.evaluation.protocol, seed EVAL_SEED): the ones ``python evaluate.py episodes=4000`` measures.
docs/training.md quotes it.
"""

from __future__ import annotations

import sys
from collections import Counter

import torch
from omegaconf import OmegaConf

from flownav.builders import build_flow, build_task
from flownav.checkpoint import load_policy
from flownav.envs.navigation import Status
from flownav.envs.observations import GEO_VIEWS
from flownav.evaluation.protocol import EvalSpec, evaluate
from flownav.paths import REPO_ROOT

EPISODES = 4000


def episodes(checkpoint, overrides: list[str], n: int = EPISODES):
    """The protocol's ``n`` episodes of a geo checkpoint in the training flow and task, and the flow; ``overrides``
    are ``key=value`` of env/default.yaml."""
    policy, payload = load_policy(checkpoint)
    view = payload["obs"]
    if view not in GEO_VIEWS:
        raise SystemExit(f"{checkpoint} reads {view!r}: this script analyses a geo teacher")
    conf = REPO_ROOT / "conf"
    env_cfg = OmegaConf.to_container(OmegaConf.load(conf / "env/default.yaml"))
    for key, value in (a.split("=", 1) for a in overrides):
        env_cfg[key] = float(value)
    flow = build_flow(OmegaConf.to_container(OmegaConf.load(conf / "flow/cylinder.yaml")))
    task = build_task(OmegaConf.to_container(OmegaConf.load(conf / "task/regions.yaml")), flow)
    return evaluate(policy, view, EvalSpec(flow, task, env_cfg, n)).episodes, flow


def main(argv: list[str]) -> None:
    torch.set_num_threads(1)
    ep, flow = episodes(argv[0], argv[1:])
    status, final = ep.status, ep.final_position
    print(f"success {ep.success.float().mean():.4f}, mean success time {ep.time[ep.success].mean():.2f}")
    print("outcomes:", {Status(k).name: v for k, v in sorted(Counter(status.tolist()).items())})
    left = status == Status.LEFT_DOMAIN
    lo, hi = torch.tensor(flow.bounds.lo), torch.tensor(flow.bounds.hi)
    for i, axis in enumerate("xyz"):
        print(
            f"left through {axis} = {lo[i]:g}: {int((left & (final[:, i] < lo[i])).sum())}, "
            f"{axis} = {hi[i]:g}: {int((left & (final[:, i] > hi[i])).sum())}"
        )
    out = status == Status.TIMEOUT
    if out.any():
        q = torch.tensor([0.1, 0.5, 0.9])
        qx, qy = torch.quantile(final[out, 0], q).tolist(), torch.quantile(final[out, 1], q).tolist()
        dist = (final[out] - ep.target[out]).norm(dim=-1).mean()
        print(f"timeouts end {dist:.2f} from the target; final x quantiles {qx}, y {qy}")
    dx = ep.target[:, 0] - ep.start[:, 0]
    for a in range(-4, 4):
        m = (dx >= a) & (dx < a + 1)
        rate = ep.success[m].float().mean()
        print(f"target x - start x in [{a}, {a + 1}): {int(m.sum())} episodes, success {rate:.3f}")
    for a in (-4.0, -3.5, -3.0, -2.5):
        m = (ep.target[:, 1] >= a) & (ep.target[:, 1] < a + 0.5)
        print(f"target y in [{a}, {a + 0.5}): success {ep.success[m].float().mean():.3f}")


if __name__ == "__main__":
    main(sys.argv[1:])
