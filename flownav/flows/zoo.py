"""Held-out flows from the literature for the generalisation suite (evaluation only, never trained on).

Each is a :class:`~flownav.flows.FlowField` on its own box, scaled so that the flow is weaker than the
swimmer on average (mean speed about 0.4-0.8 of U_max = 1) but locally as strong as it or stronger.
All are incompressible (div u = 0, tested numerically); x, y, z are the flow's own coordinates.

* :class:`TaylorGreenFlow` (Taylor & Green 1937): cellular vortices of cell size L, k = pi / L,
      u = a(t) U sin kx cos ky cos kz,  v = -a(t) U cos kx sin ky cos kz,  w = 0,  a(t) = 1 + eps sin(omega t).
* :class:`DoubleGyreFlow` (Shadden, Lekien & Marsden 2005), layered in z: with X = x / L in [0, 2], Y = y / L,
  f(X, t) = e(t) X^2 + (1 - 2 e(t)) X, e(t) = eps sin(omega t), g(z) = 1 + 0.3 sin(2 pi z / H),
      u = -pi A sin(pi f) cos(pi Y) g(z),  v = pi A cos(pi f) sin(pi Y) f'(X) g(z),  w = 0.
* :class:`BurgersVortex` (Burgers 1948): a stretched vortex on the z axis through (x0, y0), r the distance to it,
      u_r = -alpha r / 2,  u_z = alpha (z - z0),  u_theta = Gamma / (2 pi r) (1 - exp(-r^2 / delta^2)).
* :class:`StuartVortexRow` (Stuart 1967, Kelvin's cat's eyes): a row of like-signed vortices in a mixing layer,
  advected at speed c: with s = k (x - c t), q = k (y - y0), D = cosh q - rho cos s,
      u = U sinh q / D,  v = -U rho sin s / D,  w = 0.
* :class:`VortexTubes`: two Lamb-Oseen vortex tubes (Oseen 1912), one along x and one along y, at different
  heights, with circulations Gamma_i(t) = Gamma (1 + 0.3 sin(omega t + phi_i)); a tube through p along e gives
      u = Gamma_i / (2 pi r^2) (1 - exp(-r^2 / delta^2)) e x r,  r = (pos - p) - ((pos - p).e) e.
* :class:`PoiseuilleChannel`: plane Poiseuille flow between walls z = z0 +- h, pulsating (Womersley-like),
      u = a(t) U (1 - ((z - z0) / h)^2),  v = w = 0,  a(t) = 1 + eps sin(omega t).
* :class:`BeltramiShell`: random Beltrami flow whose modes all lie on one shell |k| = k0 (so curl u = -k0 u at
  every time), random directions, phases and frequencies: for mode j with unit wave vector n_j, a_j ⊥ n_j,
      u = A sum_j [a_j cos(k0 n_j.x + phi_j + omega_j t) + (n_j x a_j) sin(k0 n_j.x + phi_j + omega_j t)],
  A set so that the rms speed is ``rms``. A single-shell spectrum, unlike the broadband training modes.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from flownav.flows.base import Box, FlowField

# Default boxes: 16 x 16 in the horizontal, so that starts and targets 8-12 apart fit with room around them.
FLAT_BOX = Box((0.0, 0.0, -4.0), (16.0, 16.0, 4.0))
CENTRED_BOX = Box((-8.0, -8.0, -5.0), (8.0, 8.0, 5.0))
LAYER_BOX = Box((0.0, -8.0, 0.0), (16.0, 8.0, 8.0))
CUBE_BOX = Box((0.0, 0.0, 0.0), (16.0, 16.0, 10.0))


def estimate_max_speed(flow: FlowField, n: int = 20_000, times: int = 8, seed: int = 0) -> tuple[float, float]:
    """(max, mean) flow speed over random points of the box and times of one period (or 0..20)."""
    g = torch.Generator().manual_seed(seed)
    span = flow.period or 20.0
    best, total = 0.0, 0.0
    for i in range(times):
        pos = flow.bounds.sample(n, g)
        speed = flow.velocity(pos, torch.full((n,), span * i / times)).norm(dim=-1)
        best, total = max(best, float(speed.max())), total + float(speed.mean())
    return best, total / times


class _Analytic(FlowField):
    """Shared set-up: box, no obstacles, period from omega, speeds estimated by sampling."""

    def _finish(self, bounds: Box, omega: float | None, unsteady: bool):
        self.bounds = bounds
        self.obstacles = ()
        self.period = 2 * math.pi / omega if unsteady and omega else None
        self.max_speed, self.mean_speed = estimate_max_speed(self)


class TaylorGreenFlow(_Analytic):
    def __init__(self, U=1.2, cell=4.0, eps=0.3, omega=0.5, bounds: Box = FLAT_BOX):
        self.U, self.k, self.eps, self.omega = float(U), math.pi / float(cell), float(eps), float(omega)
        self._finish(bounds, omega, eps != 0)

    def velocity(self, pos: Tensor, t: Tensor) -> Tensor:
        x, y, z = (self.k * pos).unbind(-1)
        a = self.U * (1 + self.eps * torch.sin(self.omega * t.to(pos.dtype)))
        u = a * torch.sin(x) * torch.cos(y) * torch.cos(z)
        v = -a * torch.cos(x) * torch.sin(y) * torch.cos(z)
        return torch.stack((u, v, torch.zeros_like(u)), -1)


class DoubleGyreFlow(_Analytic):
    def __init__(self, A=0.35, L=8.0, eps=0.25, omega=2 * math.pi / 10, height=8.0):
        self.A, self.L, self.eps, self.omega, self.height = float(A), float(L), float(eps), float(omega), float(height)
        self._finish(Box((0.0, 0.0, 0.0), (2 * self.L, self.L, self.height)), omega, eps != 0)

    def velocity(self, pos: Tensor, t: Tensor) -> Tensor:
        X, Y, z = pos[..., 0] / self.L, pos[..., 1] / self.L, pos[..., 2]
        e = self.eps * torch.sin(self.omega * t.to(pos.dtype))
        f = e * X * X + (1 - 2 * e) * X
        df = 2 * e * X + (1 - 2 * e)
        g = 1 + 0.3 * torch.sin(2 * math.pi * z / self.height)
        pa = math.pi * self.A
        u = -pa * torch.sin(math.pi * f) * torch.cos(math.pi * Y) * g
        v = pa * torch.cos(math.pi * f) * torch.sin(math.pi * Y) * df * g
        return torch.stack((u, v, torch.zeros_like(u)), -1)


class BurgersVortex(_Analytic):
    def __init__(self, circulation=12.0, core=1.5, strain=0.08, bounds: Box = CENTRED_BOX):
        self.gamma, self.core, self.alpha = float(circulation), float(core), float(strain)
        self.center = bounds.center
        self._finish(bounds, None, False)

    def velocity(self, pos: Tensor, t: Tensor) -> Tensor:
        x, y, z = (pos - pos.new_tensor(self.center)).unbind(-1)
        r2 = (x * x + y * y).clamp_min(1e-12)
        swirl = self.gamma / (2 * math.pi * r2) * (1 - torch.exp(-r2 / self.core**2))  # u_theta / r
        u = -0.5 * self.alpha * x - swirl * y
        v = -0.5 * self.alpha * y + swirl * x
        return torch.stack((u, v, self.alpha * z), -1)


class StuartVortexRow(_Analytic):
    def __init__(
        self,
        U=0.7,
        wavelength=8.0,
        rho=0.6,
        advection=0.2,
        bounds: Box = LAYER_BOX,
    ):
        self.U, self.k, self.rho, self.c = float(U), 2 * math.pi / float(wavelength), float(rho), float(advection)
        self.y0 = bounds.center[1]
        self._finish(bounds, None, False)
        if self.c:  # the pattern repeats after one wavelength
            self.period = float(wavelength) / abs(self.c)

    def velocity(self, pos: Tensor, t: Tensor) -> Tensor:
        s = self.k * (pos[..., 0] - self.c * t.to(pos.dtype))
        q = self.k * (pos[..., 1] - self.y0)
        d = torch.cosh(q) - self.rho * torch.cos(s)
        u = self.U * torch.sinh(q) / d
        v = -self.U * self.rho * torch.sin(s) / d
        return torch.stack((u, v, torch.zeros_like(u)), -1)


class VortexTubes(_Analytic):
    def __init__(
        self,
        circulation=8.0,
        core=1.2,
        omega=0.4,
        bounds: Box = CENTRED_BOX,
    ):
        self.gamma, self.core, self.omega = float(circulation), float(core), float(omega)
        # (point on the axis, axis direction, phase): one tube along x below the middle, one along y above it.
        self.tubes = (((0.0, 2.0, -1.5), (1.0, 0.0, 0.0), 0.0), ((-2.0, 0.0, 1.5), (0.0, 1.0, 0.0), math.pi / 2))
        self._finish(bounds, omega, True)

    def velocity(self, pos: Tensor, t: Tensor) -> Tensor:
        out = torch.zeros_like(pos)
        for point, axis, phase in self.tubes:
            e = pos.new_tensor(axis)
            rel = pos - pos.new_tensor(point)
            r = rel - (rel * e).sum(-1, keepdim=True) * e
            r2 = (r * r).sum(-1, keepdim=True).clamp_min(1e-12)
            gamma = self.gamma * (1 + 0.3 * torch.sin(self.omega * t.to(pos.dtype) + phase))[:, None]
            out = out + gamma / (2 * math.pi * r2) * (1 - torch.exp(-r2 / self.core**2)) * torch.cross(
                e.expand_as(r), r, -1
            )
        return out


class PoiseuilleChannel(_Analytic):
    def __init__(self, U=0.8, half_width=5.0, eps=0.3, omega=0.3, length=16.0, span=16.0):
        self.U, self.h, self.eps, self.omega = float(U), float(half_width), float(eps), float(omega)
        self._finish(Box((0.0, 0.0, -self.h), (float(length), float(span), self.h)), omega, eps != 0)

    def velocity(self, pos: Tensor, t: Tensor) -> Tensor:
        a = self.U * (1 + self.eps * torch.sin(self.omega * t.to(pos.dtype)))
        u = a * (1 - (pos[..., 2] / self.h) ** 2)
        zero = torch.zeros_like(u)
        return torch.stack((u, zero, zero), -1)


class BeltramiShell(_Analytic):
    K0 = 2.0  # wavelength pi: shorter than any trained mode (4-24)

    def __init__(
        self,
        seed=1000,
        modes=16,
        k0=K0,
        rms=0.6,
        omega=(0.1, 0.4),
        bounds: Box = CUBE_BOX,
    ):
        g = torch.Generator().manual_seed(int(seed))
        n = torch.randn(modes, 3, generator=g, dtype=torch.float64)  # float64: exact Beltrami modes at any precision
        n = n / n.norm(dim=-1, keepdim=True)
        a = torch.linalg.cross(n, torch.randn(modes, 3, generator=g, dtype=torch.float64))
        a = a / a.norm(dim=-1, keepdim=True)
        self.seed, self.k0 = int(seed), float(k0)
        self.n, self.a, self.b = n, a, torch.linalg.cross(n, a)
        self.phase = torch.rand(modes, generator=g, dtype=torch.float64) * 2 * math.pi
        self.freq = omega[0] + (omega[1] - omega[0]) * torch.rand(modes, generator=g, dtype=torch.float64)
        # Each mode has |u|^2 = 1 and the modes are uncorrelated: rms speed sqrt(modes) before scaling.
        self.amp = float(rms) / math.sqrt(modes)
        self._finish(bounds, None, False)

    def velocity(self, pos: Tensor, t: Tensor) -> Tensor:
        arg = self.k0 * pos @ self.n.to(pos).T + self.phase.to(pos) + t.to(pos.dtype)[:, None] * self.freq.to(pos)
        return self.amp * (torch.cos(arg) @ self.a.to(pos) + torch.sin(arg) @ self.b.to(pos))


# name -> class: the zoo's flow types (``flow.type: zoo`` with ``flow.name``).
ZOO = {
    "taylor_green": TaylorGreenFlow,
    "double_gyre": DoubleGyreFlow,
    "burgers_vortex": BurgersVortex,
    "stuart_vortex_row": StuartVortexRow,
    "vortex_tubes": VortexTubes,
    "poiseuille_channel": PoiseuilleChannel,
    "beltrami_shell": BeltramiShell,
}
