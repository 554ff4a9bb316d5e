"""How much of its speed the flow-compensating expert should keep towards the target, on the training families
(never the zoo): success of head-to-target and of the expert with ``min_progress`` p (0: the expert that cancels
all of the cross flow it can; 1: head-to-target) in six regimes of the families, 4,000 episodes each, the family
task without the paper's regions, at full speed or with the weaker swimmers only.

    python scripts/compensation_cap.py               # p = 0.3, 0.5, 0.7
    python scripts/compensation_cap.py 0.5 1.0       # other values

Same episodes for every policy of a regime (the protocol's seeds). docs/generalist.md quotes it;
flownav/agents/scene_router.py's CAPPED_MIN_PROGRESS is its choice.
"""

from __future__ import annotations

import sys

import torch

from flownav.agents.flow_compensating import FlowCompensating
from flownav.builders import compose_config
from flownav.evaluation.protocol import EvalSpec, evaluate
from flownav.evaluation.scripted import HeadToTarget

# the random flows on a current: family_mix without its other members
ONLY_FOURIER_ON_CURRENT = [f"~flow.members.{m}" for m in ("current", "fourier", "paper_wake", "wake", "street")]
REGIMES = {
    "random flows, full speed": ["flow=family_fourier", "task.full_speed_share=1"],
    "random flows, weaker swimmers": ["flow=family_fourier", "task.full_speed_share=0"],
    "every family, full speed": ["flow=family_mix", "task.full_speed_share=1"],
    "every family, weaker swimmers": ["flow=family_mix", "task.full_speed_share=0"],
    "vortex streets, full speed": ["flow=family_vortex_street", "task.full_speed_share=1"],
    "random flows on a current, full speed": ["flow=family_mix", *ONLY_FOURIER_ON_CURRENT, "task.full_speed_share=1"],
}
EPISODES = 4000


def regime_spec(overrides: list[str]) -> EvalSpec:
    return EvalSpec.from_config(
        compose_config([*overrides, "task=family", "task.regions_share=0"], app="evaluate"), EPISODES
    )


def main(progress: list[float]) -> None:
    torch.set_num_threads(2)
    policies = {"head-to-target": HeadToTarget(), "p = 0": FlowCompensating()}
    policies |= {f"p = {p:g}": FlowCompensating(min_progress=p) for p in progress}
    print("| regime | " + " | ".join(policies) + " |")
    print("|---|" + "---|" * len(policies))
    for name, overrides in REGIMES.items():
        spec = regime_spec(overrides)
        rates = [evaluate(p, getattr(p, "view", "geo"), spec).summary["success_rate"] for p in policies.values()]
        print(f"| {name} | " + " | ".join(f"{100 * r:.2f}" for r in rates) + " |", flush=True)


if __name__ == "__main__":
    main([float(a) for a in sys.argv[1:]] or [0.3, 0.5, 0.7])
