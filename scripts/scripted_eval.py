"""Evaluate a scripted reference policy (head_to_target, passive) the way ``evaluate.py checkpoint=...`` evaluates a
checkpoint: the same config, the same protocol, the same episodes.

    python scripts/scripted_eval.py head_to_target flow=uniform flow.velocity=[0.0,0.8,0.0]
    python scripts/scripted_eval.py head_to_target flow=family_mix task=family episodes=10000
"""

from __future__ import annotations

import sys

import torch

from flownav.builders import build_flow, build_task, compose_config
from flownav.evaluation.protocol import EvalSpec, evaluate
from flownav.evaluation.scripted import SCRIPTED


def main(argv: list[str]) -> None:
    if not argv or argv[0] not in SCRIPTED or argv[0] == "oracle":
        names = "|".join(k for k in SCRIPTED if k != "oracle")
        raise SystemExit(f"usage: python scripts/scripted_eval.py <{names}> [overrides]")
    torch.set_num_threads(1)
    name, overrides = argv[0], argv[1:]
    episodes = next((int(o.split("=", 1)[1]) for o in overrides if o.startswith("episodes=")), 10_000)
    cfg = compose_config([o for o in overrides if not o.startswith("episodes=")])
    flow = build_flow(cfg.flow)
    result = evaluate(SCRIPTED[name](), "geo", EvalSpec(flow, build_task(cfg.task, flow), cfg.env, episodes))
    lo, hi = result.summary["success_ci95"]
    rate = f"{100 * result.success_rate:.2f}% [{100 * lo:.2f}, {100 * hi:.2f}]"
    print(f"{name} {' '.join(overrides)}: success {rate} of {episodes}")


if __name__ == "__main__":
    main(sys.argv[1:])
