"""Through which face of the box the episodes of a generalisation-suite case leave it, per policy: the protocol's
episodes of ``+experiment=generalization``'s case, counted by the face their final position lies beyond.
docs/oracle.md quotes it for the double gyre, and for the planner without the walls on the zoo's cases.

    python scripts/where_episodes_leave.py double_gyre generalist_student generalist_teacher head_to_target
    python scripts/where_episodes_leave.py double_gyre generalist_student --episodes 1000
    python scripts/where_episodes_leave.py double_gyre blind --episodes 200 \
        --set '+policies.blind={scripted: oracle, obs: geo, settings: {knows_walls: false}}'
"""

from __future__ import annotations

import argparse

import torch
from omegaconf import OmegaConf
from torch import Tensor

from flownav.builders import build_task, compose_config
from flownav.envs.core import Status
from flownav.evaluation.experiments import Suite
from flownav.evaluation.protocol import EvalSpec, evaluate


def faces(final: Tensor, lo, hi) -> dict[str, int]:
    """How many of the positions ``final`` [N, 3] lie beyond each face of the box [lo, hi]."""
    lo, hi = torch.tensor(lo, dtype=final.dtype), torch.tensor(hi, dtype=final.dtype)
    out = {}
    for a, axis in enumerate("xyz"):
        out[f"-{axis}"] = int((final[:, a] < lo[a]).sum())
        out[f"+{axis}"] = int((final[:, a] > hi[a]).sum())
    return out


def leaving(case: str, policies: list[str], episodes: int, overrides: tuple[str, ...] = ()) -> dict[str, dict]:
    """Per policy: episodes, successes, episodes that leave, by face, and their median time of leaving.
    ``overrides``: Hydra overrides of the suite's config (a policy defined on the command line)."""
    suite = Suite(compose_config(["+experiment=generalization", *overrides], app="evaluate"))
    cfg = suite.cfg.suite.generalization.cases[case]
    flow = suite.flow(OmegaConf.to_container(cfg.flow, resolve=True))
    spec = EvalSpec(flow, build_task(cfg.task, flow), suite.cfg.env, episodes)
    out = {}
    for name in policies:
        policy, view, _ = suite.policy(name)
        ep = evaluate(policy, view, spec).episodes
        left = ep.status == Status.LEFT_DOMAIN
        out[name] = {
            "episodes": len(ep),
            "success": int(ep.success.sum()),
            "left": int(left.sum()),
            "faces": faces(ep.final_position[left], flow.bounds.lo, flow.bounds.hi),
            "median_time_left": float(ep.time[left].median()) if left.any() else None,
        }
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("case")
    parser.add_argument("policies", nargs="+")
    parser.add_argument("--episodes", type=int, default=4000)
    parser.add_argument("--set", action="append", default=[], metavar="OVERRIDE", help="a Hydra override (repeatable)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    for name, r in leaving(args.case, args.policies, args.episodes, tuple(args.set)).items():
        print(
            f"{name}: {r['success']} of {r['episodes']} succeed, {r['left']} leave the box {r['faces']}, "
            f"median time of leaving {r['median_time_left']}"
        )


if __name__ == "__main__":
    main()
