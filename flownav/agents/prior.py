"""Head-to-target: the reference controller, and the prior a policy's network can correct.

``head_to_target(d, theta, psi, u_max)`` turns the heading (theta, psi) towards the target direction ``d``
and swims at full speed when facing it. It is the scripted reference of every evaluation
(:class:`flownav.evaluation.scripted.HeadToTarget`) and, as :class:`HeadToTargetPrior`, the starting point of
the generalist's networks: their output is added to head-to-target's action before the tanh squash, so an
untrained (zero-output) network already swims straight at the target, and training learns where the flow
makes another action better. Where the network has learned nothing (a flow unlike any it saw) the policy
falls back towards head-to-target rather than towards an arbitrary action.

Every view carries the target direction: geo views in the inertial frame with the heading's angles, ego views
in the body frame, where the heading is (theta, psi) = (0, 0) by construction. In the body frame the turn
rates are the inertial ones up to cos psi (the yaw turns about the inertial vertical), which is enough for a
prior: the network corrects the rest.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor, nn

from flownav.envs.core import DPSI_MAX, DTHETA_MAX
from flownav.envs.kinematics import heading_vector, wrap_angle

# How head-to-target yaws towards the target (the heading error e = target's azimuth - theta, in (-pi, pi]):
# TURN_SHORT: tanh(3 e), the shorter way round. TURN_LEFT_BIASED: tanh(3 f(e)), f(e) = sin e + (1 - cos e) / 2,
# continuous at e = +-pi but zero only at e = 0, so for e in (-180, -127) degrees it turns left, the long way
# (up to 53 degrees more). Against a current of 0.8 across the paper's task that detour costs 3.5% of the episodes
# (96.51% against 99.95%): swimmers drift out of the box while they turn (docs/generalist.md). A policy config
# without ``prior_turn`` means the left-biased rule (DeterministicPolicy's ``prior_turn``).
TURN_SHORT, TURN_LEFT_BIASED = "short", "left_biased"
TURNS = (TURN_SHORT, TURN_LEFT_BIASED)


def check_turn(turn: str) -> str:
    if turn not in TURNS:
        raise ValueError(f"head-to-target turn {turn!r}: choose one of {TURNS}")
    return turn


def head_to_target(
    d: Tensor,
    theta: Tensor,
    psi: Tensor,
    u_max: float = 1.0,
    speed_fraction: float = 0.98,
    turn: str = TURN_SHORT,
) -> Tensor:
    """Action (speed, dtheta, dpsi) ``[..., 3]`` that turns the heading (theta, psi) towards ``d``.

    Speed: ``u_max * speed_fraction`` times the cosine between heading and target direction (at least 5%):
    slow while facing away, so the swimmer turns on the spot instead of orbiting the target. Every component
    stays inside the action box (0.95 of the turn bounds), so a tanh-squashed output can represent it. ``turn``:
    :data:`TURN_SHORT` or :data:`TURN_LEFT_BIASED` (above)."""
    dist = d.norm(dim=-1).clamp_min(1e-6)
    theta_d = torch.atan2(d[..., 1], d[..., 0])
    psi_d = torch.asin((d[..., 2] / dist).clamp(-1, 1))
    err = wrap_angle(theta_d - theta)
    if check_turn(turn) == TURN_LEFT_BIASED:
        err = torch.sin(err) + 0.5 * (1 - torch.cos(err))
    dtheta = DTHETA_MAX * 0.95 * torch.tanh(3 * err)
    dpsi = DPSI_MAX * 0.95 * torch.tanh(3 * (psi_d - psi))
    facing = (heading_vector(theta, psi) * d).sum(-1) / dist
    speed = u_max * speed_fraction * facing.clamp(0.05, 1.0)
    return torch.stack((speed, dtheta, dpsi), -1)


def check_prior_view(view: str) -> str:
    if not view.startswith(("ego", "geo")):
        raise ValueError(f"view {view!r} carries no target direction for the head-to-target prior; use geo or ego")
    return view


def target_and_heading(obs: Tensor, view: str) -> tuple[Tensor, Tensor, Tensor]:
    """(target direction, theta, psi) read from an observation of a geo or ego ``view``."""
    d = obs[..., :3]
    if view.startswith("ego"):  # body frame: the heading is the x axis
        zero = torch.zeros_like(d[..., 0])
        return d, zero, zero
    if view in ("geo", "geo_flow"):  # (d, velocity, theta, psi)
        return d, obs[..., 6], obs[..., 7]
    return d, torch.atan2(obs[..., 7], obs[..., 6]), obs[..., 8]  # (d, velocity, cos theta, sin theta, psi, ...)


class HeadToTargetPrior(nn.Module):
    """Observation of ``view`` -> head-to-target's action (yawing by ``turn``) in the network's pre-tanh
    coordinates (the inverse of :class:`~flownav.agents.networks.SquashedAction`)."""

    def __init__(self, view: str, low: Sequence[float], high: Sequence[float], turn: str = TURN_SHORT):
        super().__init__()
        self.view = check_prior_view(view)
        self.turn = check_turn(turn)
        # The box is in the policy's config; not persistent, so a checkpoint's state_dict is the weights alone.
        self.register_buffer("low", torch.as_tensor(low, dtype=torch.float32), persistent=False)
        self.register_buffer("high", torch.as_tensor(high, dtype=torch.float32), persistent=False)

    def forward(self, obs: Tensor) -> Tensor:
        d, theta, psi = target_and_heading(obs, self.view)
        action = head_to_target(d, theta, psi, u_max=float(self.high[0]), turn=self.turn)
        unit = (2 * (action - self.low) / (self.high - self.low) - 1).clamp(-0.999, 0.999)
        return torch.atanh(unit)
