"""A scripted local rule that uses the flow: swim towards w = r + tau (grad u)^T r, r the unit vector to the target,
(grad u)_ij = du_i / dx_j from the privileged view ``geo_priv``: the direction in which the flow's component towards
the target grows, added to the target's. tau is picked on the periodic random flows with the ABC task (never on
ABC), then the picked rule runs once on the well-posed ABC test. docs/oracle.md quotes it.

    python scripts/gradient_climber.py                    # tau in 0, 1, 3, 10, 30; 2,000 episodes each, ABC 10,000
    python scripts/gradient_climber.py 500 2000           # fewer episodes (selection, ABC)
"""

from __future__ import annotations

import sys

import torch
from torch import Tensor, nn

from flownav.agents.prior import head_to_target, target_and_heading
from flownav.builders import compose_config
from flownav.envs.observations import GEO_PRIV_FLOW
from flownav.evaluation.protocol import EvalSpec, evaluate

GRADIENT = slice(GEO_PRIV_FLOW.stop, GEO_PRIV_FLOW.stop + 9)  # geo_priv keeps du_i/dx_j right after the flow
TAUS = (0.0, 1.0, 3.0, 10.0, 30.0)
SELECTION = ["flow=family_fourier_periodic", "task=abc", "env=abc_periodic"]  # random flows on ABC's domain
TEST = ["flow=abc_periodic", "task=abc", "env=abc_periodic"]


class GradientClimber(nn.Module):
    """``geo_priv`` -> the action that turns towards r + tau (grad u)^T r at full speed (tau = 0: head-to-target)."""

    view = "geo_priv"

    def __init__(self, tau: float):
        super().__init__()
        self.tau = float(tau)

    def forward(self, obs: Tensor) -> Tensor:
        d, theta, psi = target_and_heading(obs, self.view)
        r = d / d.norm(dim=-1, keepdim=True).clamp_min(1e-6)
        grad = obs[..., GRADIENT].unflatten(-1, (3, 3))
        climb = (r[..., :, None] * grad).sum(-2)  # sum_i r_i du_i/dx_j
        return head_to_target(r + self.tau * climb, theta, psi)


def spec(overrides: list[str], episodes: int) -> EvalSpec:
    return EvalSpec.from_config(compose_config(overrides, app="evaluate"), episodes)


def main(selection_episodes: int = 2000, test_episodes: int = 10_000) -> dict:
    torch.set_num_threads(1)
    pick = spec(SELECTION, selection_episodes)
    rates = {tau: evaluate(GradientClimber(tau), "geo_priv", pick).success_rate for tau in TAUS}
    for tau, rate in rates.items():
        print(f"periodic random flows, tau = {tau:g}: {100 * rate:.2f}% of {selection_episodes}", flush=True)
    best = max(rates, key=rates.get)
    summary = evaluate(GradientClimber(best), "geo_priv", spec(TEST, test_episodes)).summary
    lo, hi = summary["success_ci95"]
    print(f"well-posed ABC, tau = {best:g}: {100 * summary['success_rate']:.2f}% [{100 * lo:.2f}, {100 * hi:.2f}]")
    return {"selection": rates, "tau": best, "abc": summary}


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:3]))
