"""Swimmer kinematics of the paper (eq. 1-3) and the body frame of the ego view.

Heading (theta, psi): theta is the angle in the x-y plane, psi the elevation above it, so
the unit heading is e_x = (cos psi cos theta, cos psi sin theta, sin psi) (eq. 1).
One step of length dt with action (U, dtheta, dpsi):

    theta' = wrap(theta + dtheta dt),   psi' = clip(psi + dpsi dt, -pi/2, pi/2)
    v      = U e_x(theta', psi') + v_flow(P, t)          (eq. 2)
    P'     = P + v dt                                    (eq. 3)

The heading turns first, then the swimmer moves along the new heading.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor


def wrap_angle(a: Tensor) -> Tensor:
    """Map angles to [-pi, pi)."""
    return torch.remainder(a + math.pi, 2 * math.pi) - math.pi


def heading_vector(theta: Tensor, psi: Tensor) -> Tensor:
    cp = torch.cos(psi)
    return torch.stack((cp * torch.cos(theta), cp * torch.sin(theta), torch.sin(psi)), -1)


def body_frame(theta: Tensor, psi: Tensor) -> Tensor:
    """Rotation ``[N, 3, 3]`` whose columns are the body axes in the inertial frame.

    x: the heading; y: horizontal, to the left of the heading; z = x cross y. Built from
    (theta, psi) alone, so rotating the scene about the inertial z axis by phi (theta ->
    theta + phi) rotates the three axes with it and leaves body-frame components unchanged.
    """
    ct, st, cp, sp = torch.cos(theta), torch.sin(theta), torch.cos(psi), torch.sin(psi)
    zero = torch.zeros_like(theta)
    ex = torch.stack((cp * ct, cp * st, sp), -1)
    ey = torch.stack((-st, ct, zero), -1)
    ez = torch.stack((-sp * ct, -sp * st, cp), -1)
    return torch.stack((ex, ey, ez), -1)


def to_body(frame: Tensor, vec: Tensor) -> Tensor:
    """Components of inertial vectors ``[N, 3]`` (or ``[N, K, 3]``, K per swimmer) in the body frame (R^T v)."""
    if vec.dim() == 3:
        return (frame[:, None] * vec[:, :, :, None]).sum(2)
    return (frame * vec[:, :, None]).sum(1)  # elementwise: faster than einsum/bmm for 3x3


def from_body(frame: Tensor, vec: Tensor) -> Tensor:
    """Inertial vectors ``[N, 3]`` from their body-frame components (R v; the inverse of :func:`to_body`)."""
    return (frame * vec[:, None, :]).sum(-1)


def turn(theta: Tensor, psi: Tensor, dtheta: Tensor, dpsi: Tensor, dt: float) -> tuple[Tensor, Tensor]:
    return wrap_angle(theta + dtheta * dt), (psi + dpsi * dt).clamp(-math.pi / 2, math.pi / 2)


def move(pos: Tensor, swim_velocity: Tensor, flow_velocity: Tensor, dt: float) -> tuple[Tensor, Tensor]:
    """Advance positions by one explicit Euler step; returns (new position, total velocity)."""
    v = swim_velocity + flow_velocity
    return pos + v * dt, v


def step_reaches(to_target: Tensor, step: Tensor, radius: float) -> Tensor:
    """Whether a straight step passes within ``radius`` of the target (segment against sphere).

    ``to_target``: target - P at the start of the step, ``step``: P' - P (both ``[N, 3]``). The closest
    point of the segment P + s (P' - P), s in [0, 1], to the target decides, so a step longer than the
    success ball is wide cannot jump over it.
    """
    s = ((to_target * step).sum(-1) / (step * step).sum(-1).clamp_min(1e-12)).clamp(0.0, 1.0)
    return (to_target - s[:, None] * step).norm(dim=-1) < radius
