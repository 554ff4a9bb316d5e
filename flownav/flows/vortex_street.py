"""An analytic 3D Karman vortex street behind the wake's cylinder: a cheap stand-in for the CFD wake.

Same box (``WAKE_BOUNDS``), same cylinder (diameter 1 at x = y = 0, axis z), inflow 1 along +x.
It is not a solution of the Navier-Stokes equations; it has the features a swimmer meets in the
real wake (a slow wake behind the cylinder, two staggered rows of counter-rotating vortices that
advect downstream slower than the free stream, periodic shedding, weak spanwise structure), is
exactly time-periodic, and costs a few dozen flops per swimmer. Velocity (u, v, w) at (x, y, z, t):

1. Potential flow past the cylinder (radius R = 0.5), free stream U = 1:
       u0 = U (1 - R^2 (x^2 - y^2) / r^4),   v0 = -2 U R^2 x y / r^4,   r^2 = x^2 + y^2.
2. Mean wake deficit (x > 0), Gaussian across y, widening and decaying downstream:
       u -= D(x) exp(-y^2 / (2 s(x)^2)),  D(x) = deficit ramp(x / 1.5) / sqrt(1 + x / 8),  s(x) = 0.5 + 0.04 x.
3. Two staggered rows of Lamb-Oseen vortices. With shedding period T (St = D / (U T) ~ 0.2 for T = 5),
   advection speed c (~0.85 U), wavelength lambda = c T and phase phi = (t mod T) / T, vortex k of the
   upper row (y = +a(x), clockwise, -Gamma) sits at x = x_s + lambda (k + phi + delta(z)); the lower row
   (y = -a(x), counter-clockwise, +Gamma) at x = x_s + lambda (k + frac(phi + 1/2) + delta(z)).
   A vortex of circulation G at distance rho induces the swirl  G / (2 pi rho) (1 - exp(-rho^2 / rc^2)).
   Its strength ramps in from zero over 2 D after birth at x_s and fades out at x_end > 20 (outside the
   box), so the field is continuous in time and exactly T-periodic. Spanwise modulation: the shedding
   line is bent, delta(z) = eps_z sin(2 pi z / lambda_z), and the cores carry a weak spanwise velocity
       w = w_amp * sum_k sign_k * ramp_k * exp(-rho_k^2 / rc^2) * cos(2 pi z / lambda_z).
   Half row spacing a(x) = a0 + a1 x (the street widens downstream).
4. Zero velocity inside the cylinder.

The swirl between the rows points upstream (-x), so the wake is the slow lane a swimmer of speed
U_max = 1 must use to go upstream, as in the paper's three-stage strategy.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from flownav.flows.base import WAKE_BOUNDS, Box, Cylinder, FlowField


def _smoothstep(x: Tensor) -> Tensor:
    x = x.clamp(0.0, 1.0)
    return x * x * (3 - 2 * x)


class VortexStreetFlow(FlowField):
    def __init__(
        self,
        period: float = 5.0,
        advection: float = 0.85,
        circulation: float = 1.8,
        core_radius: float = 0.4,
        half_spacing: float = 0.45,
        spreading: float = 0.03,
        deficit: float = 0.3,
        birth_x: float = 1.0,
        spanwise_wavelength: float = 4.0,
        spanwise_shift: float = 0.05,
        spanwise_w: float = 0.1,
        bounds: Box = WAKE_BOUNDS,
    ):
        if not period > 0 or not advection > 0 or not core_radius > 0:
            raise ValueError("vortex street needs period > 0, advection > 0, core_radius > 0")
        self.T, self.c, self.gamma, self.rc = float(period), float(advection), float(circulation), float(core_radius)
        self.a0, self.a1, self.deficit, self.x_s = float(half_spacing), float(spreading), float(deficit), float(birth_x)
        self.lz, self.eps_z, self.w_amp = float(spanwise_wavelength), float(spanwise_shift), float(spanwise_w)
        self.lam = self.c * self.T
        self.radius = 0.5
        self.bounds = bounds
        self.obstacles = (Cylinder((0.0, 0.0), self.radius),)
        self.period = self.T
        # Enough vortices per row to cover the box plus a fade-out margin beyond it.
        self.n_per_row = int(math.ceil((bounds.hi[0] + 6.0 - self.x_s) / self.lam)) + 1
        self.x_end = self.x_s + self.lam * self.n_per_row
        self.max_speed = self._estimate_max_speed()

    def velocity(self, pos: Tensor, t: Tensor) -> Tensor:
        x, y, z = pos.unbind(-1)
        t = t.to(pos.dtype)
        R2 = self.radius**2
        r2 = (x * x + y * y).clamp_min(1e-6)
        r4 = r2 * r2
        u = 1.0 - R2 * (x * x - y * y) / r4
        v = -2.0 * R2 * x * y / r4
        w = torch.zeros_like(x)

        # Mean wake deficit.
        xp = x.clamp_min(0.0)
        s = 0.5 + 0.04 * xp
        u = u - self.deficit * _smoothstep(x / 1.5) / torch.sqrt(1 + xp / 8) * torch.exp(-(y * y) / (2 * s * s))

        # Vortex rows: [N, K] positions.
        phi = torch.remainder(t, self.T) / self.T
        kz = 2 * math.pi * z / self.lz
        shift = self.eps_z * torch.sin(kz)
        k = torch.arange(self.n_per_row, dtype=pos.dtype, device=pos.device)
        rc2 = self.rc**2
        for sign, offset in ((-1.0, 0.0), (1.0, 0.5)):
            frac = torch.remainder(phi + offset, 1.0)
            xv = self.x_s + self.lam * (k[None, :] + frac[:, None] + shift[:, None])  # [N, K]
            yv = sign * -1.0 * (self.a0 + self.a1 * (xv - self.x_s))  # upper row (sign -1) at +a
            strength = _smoothstep((xv - self.x_s) / 2.0) * _smoothstep((self.x_end - xv) / 2.0)
            dx, dy = x[:, None] - xv, y[:, None] - yv
            rho2 = (dx * dx + dy * dy).clamp_min(1e-9)
            core = torch.exp(-rho2 / rc2)
            swirl = sign * self.gamma * strength * (1 - core) / (2 * math.pi * rho2)
            u = u - (swirl * dy).sum(-1)
            v = v + (swirl * dx).sum(-1)
            w = w + self.w_amp * (sign * strength * core).sum(-1) * torch.cos(kz)

        vel = torch.stack((u, v, w), -1)
        inside = r2 < R2
        return torch.where(inside[:, None], torch.zeros_like(vel), vel)

    def _estimate_max_speed(self, n: int = 40, n_t: int = 6) -> float:
        lo, hi = self.bounds.lo, self.bounds.hi
        axes = [torch.linspace(lo[i], hi[i], n if i < 2 else 6) for i in range(3)]
        pos = torch.stack(torch.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
        best = 0.0
        for t in torch.linspace(0, self.T, n_t + 1)[:-1]:
            best = max(best, float(self.velocity(pos, t.expand(pos.shape[0])).norm(dim=-1).max()))
        return best
