"""Flow transforms: rotation about z (the misaligned wake) and speed scaling (U_max / V_max)."""

from __future__ import annotations

import math

import torch
from torch import Tensor

from flownav.flows.base import FlowField


def rotate_z(vec: Tensor, angle: float, center: tuple[float, float] | None = None) -> Tensor:
    """Rotate vectors ``[..., 3]`` by ``angle`` radians about the z axis through ``center``."""
    c, s = math.cos(angle), math.sin(angle)
    x, y, z = vec.unbind(-1)
    if center is not None:
        x, y = x - center[0], y - center[1]
    xr, yr = c * x - s * y, s * x + c * y
    if center is not None:
        xr, yr = xr + center[0], yr + center[1]
    return torch.stack((xr, yr, z), -1)


class RotatedFlow(FlowField):
    """The base flow rotated by ``angle_deg`` about the z axis through ``center``.

    Domain and obstacles rotate with it: a position is inside when its pre-image is.
    """

    def __init__(self, base: FlowField, angle_deg: float, center: tuple[float, float] = (0.0, 0.0)):
        self.base = base
        self.angle = math.radians(angle_deg)
        self.center = tuple(center)
        self.bounds = base.bounds  # in the base frame; use in_domain for rotated positions
        self.obstacles = base.obstacles
        self.max_speed = base.max_speed
        self.period = base.period
        if angle_deg and set(base.periodic_axes) & {0, 1}:
            raise ValueError("a flow periodic in x or y cannot be rotated about z (misalignment_deg must be 0)")
        self.periodic_axes = base.periodic_axes  # z only: rotation about z leaves it unchanged

    def to_base(self, pos: Tensor) -> Tensor:
        return rotate_z(pos, -self.angle, self.center)

    def velocity(self, pos: Tensor, t: Tensor) -> Tensor:
        return rotate_z(self.base.velocity(self.to_base(pos), t), self.angle)

    def in_domain(self, pos: Tensor) -> Tensor:
        return self.base.in_domain(self.to_base(pos))

    def in_obstacle(self, pos: Tensor) -> Tensor:
        return self.base.in_obstacle(self.to_base(pos))

    def to(self, device) -> RotatedFlow:
        self.base = self.base.to(device)
        return self


class ScaledFlow(FlowField):
    """The base flow with every velocity multiplied by ``factor`` (same geometry and period)."""

    def __init__(self, base: FlowField, factor: float):
        if not factor > 0:
            raise ValueError(f"speed factor must be positive, got {factor}")
        self.base = base
        self.factor = float(factor)
        self.bounds = base.bounds
        self.obstacles = base.obstacles
        self.max_speed = base.max_speed * self.factor
        self.period = base.period
        self.periodic_axes = base.periodic_axes

    def velocity(self, pos: Tensor, t: Tensor) -> Tensor:
        return self.factor * self.base.velocity(pos, t)

    def in_domain(self, pos: Tensor) -> Tensor:
        return self.base.in_domain(pos)

    def in_obstacle(self, pos: Tensor) -> Tensor:
        return self.base.in_obstacle(pos)

    def to(self, device) -> ScaledFlow:
        self.base = self.base.to(device)
        return self
