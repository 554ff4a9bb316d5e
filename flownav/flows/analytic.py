"""Analytic flows: the time-periodic ABC flow and a uniform stream.

Time-periodic ABC flow (Arnold-Beltrami-Childress), with A(t) = A (1 + eps sin(omega t)):

    u = A(t) sin z + C cos y
    v = B sin x + A(t) cos z
    w = C sin y + B cos x

Each component is independent of its own coordinate, so div u = 0 exactly for any A(t).
The defaults (A, B, C) = (sqrt 3, sqrt 2, 1) / 3 are the classic chaotic ratios rescaled so
that the steady flow's maximum speed is 2 / sqrt 3 = 1.155 (|u|^2 <= 2 (A^2 + B^2 + C^2));
eps = 0.05, omega = 1 modulate it in time (period 2 pi) and raise the maximum to about 1.18.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from flownav.flows.base import WAKE_BOUNDS, Box, FlowField

ABC_BOUNDS = Box((-2 * math.pi, -math.pi, -math.pi), (2 * math.pi, math.pi, math.pi))


class ABCFlow(FlowField):
    def __init__(
        self,
        A: float = math.sqrt(3) / 3,
        B: float = math.sqrt(2) / 3,
        C: float = 1 / 3,
        eps: float = 0.05,
        omega: float = 1.0,
        bounds: Box = ABC_BOUNDS,
    ):
        self.A, self.B, self.C, self.eps, self.omega = A, B, C, eps, omega
        self.bounds = bounds
        self.obstacles = ()
        self.period = 2 * math.pi / omega if eps != 0 and omega != 0 else None
        self.max_speed = self._estimate_max_speed()

    def velocity(self, pos: Tensor, t: Tensor) -> Tensor:
        x, y, z = pos.unbind(-1)
        a = self.A * (1 + self.eps * torch.sin(self.omega * t.to(pos.dtype)))
        u = a * torch.sin(z) + self.C * torch.cos(y)
        v = self.B * torch.sin(x) + a * torch.cos(z)
        w = self.C * torch.sin(y) + self.B * torch.cos(x)
        return torch.stack((u, v, w), -1)

    def _estimate_max_speed(self, n: int = 48, n_t: int = 8) -> float:
        # The flow is 2 pi periodic in space: a dense sample of one cell bounds the maximum well.
        s = torch.linspace(0, 2 * math.pi, n, dtype=torch.float64)
        pos = torch.stack(torch.meshgrid(s, s, s, indexing="ij"), -1).reshape(-1, 3)
        best = 0.0
        for t in torch.linspace(0, 2 * math.pi / max(self.omega, 1e-12), n_t, dtype=torch.float64):
            v = self.velocity(pos, t.expand(pos.shape[0]))
            best = max(best, float(v.norm(dim=-1).max()))
        return best


class UniformFlow(FlowField):
    """Constant velocity everywhere: a free stream, or still water with zeros."""

    def __init__(self, velocity=(1.0, 0.0, 0.0), bounds: Box = WAKE_BOUNDS):
        self.value = tuple(float(v) for v in velocity)
        self.bounds = bounds
        self.obstacles = ()
        self.max_speed = math.sqrt(sum(v * v for v in self.value))

    def velocity(self, pos: Tensor, t: Tensor) -> Tensor:
        return pos.new_tensor(self.value).expand_as(pos).clone()
