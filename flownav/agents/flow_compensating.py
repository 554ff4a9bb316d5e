"""The flow-compensating expert: head-to-target for a swimmer that knows the local flow and its own swim speed.

It reads the privileged view ``geo_priv`` (flownav/envs/observations.py) and is a scripted reference of the
evaluation (``scripted:flow_compensating``) and, in the paper's wake, the label source of the episodes that start
upstream of the paper's regions (flownav/agents/scene_router.py).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn

from flownav.agents.prior import head_to_target, target_and_heading
from flownav.envs.observations import GEO_PRIV_FLOW, GEO_PRIV_SWIM_SPEED


class FlowCompensating(nn.Module):
    """Privileged view ``geo_priv`` -> the action that makes the swimmer's *total* velocity point at the target.

    With the local flow u, the unit target direction r and the full swim speed U, the swim velocity
    w = sqrt(U^2 - |u_c|^2) r - u_c cancels the flow's cross-target part u_c = u - (u.r) r and puts the rest of U
    towards the target (in a uniform current the straight, fastest track; head-to-target instead curves
    downstream and, against a strong current, leaves the domain). Where |u_c| >= U it swims straight against
    u_c. With ``min_progress`` p > 0 it spends at most sqrt(1 - p^2) U against u_c and at least p U towards the
    target: where the cross flow is stronger than that, fighting it all would hold the swimmer in place, and
    head-to-target's drift with it at least moves on. The heading is then turned towards w as head-to-target
    turns towards the target."""

    view = "geo_priv"

    def __init__(self, u_max: float = 1.0, speed_fraction: float = 0.98, min_progress: float = 0.0):
        super().__init__()
        if not 0.0 <= min_progress <= 1.0:
            raise ValueError(f"min_progress is {min_progress}; choose a fraction of the swim speed in [0, 1]")
        self.u_max, self.speed_fraction, self.min_progress = float(u_max), float(speed_fraction), float(min_progress)

    def forward(self, obs: Tensor) -> Tensor:
        d, theta, psi = target_and_heading(obs, self.view)
        flow, swim = obs[..., GEO_PRIV_FLOW], obs[..., GEO_PRIV_SWIM_SPEED]
        r = d / d.norm(dim=-1, keepdim=True).clamp_min(1e-6)
        cross = flow - (flow * r).sum(-1, keepdim=True) * r
        along = (swim.square() - cross.square().sum(-1, keepdim=True)).clamp_min(0).sqrt()
        w = torch.where(along > 0, along * r - cross, -cross)
        if self.min_progress > 0:
            p = self.min_progress
            cap = swim * math.sqrt(1 - p * p)
            size = cross.norm(dim=-1, keepdim=True)
            w = torch.where(size > cap, p * swim * r - cross * cap / size.clamp_min(1e-9), w)
        return head_to_target(w, theta, psi, self.u_max, self.speed_fraction)
