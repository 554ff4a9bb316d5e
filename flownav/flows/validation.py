"""Validation flows: held-out flows for choosing between recipes, views and seeds, never for reporting.

The zoo (:mod:`flownav.flows.zoo`) is evaluation only: a choice made by reading it would tune on it. These flows
are of kinds in neither the zoo nor the training families, so a choice made on them is judged out of
distribution without touching the zoo (``python evaluate.py +experiment=validation``, docs/evaluation.md). Each is
a :class:`~flownav.flows.FlowField` on its own box, incompressible (div u = 0, tested numerically), weaker than
the swimmer on average (mean speed 0.4-0.8 of U_max = 1) but locally stronger; x, y, z are the flow's own
coordinates.

* :class:`BickleyJet` (del-Castillo-Negrete & Morrison 1993; Rypina et al. 2007): a meandering zonal jet of
  width L carrying three travelling waves, layered in z; stream function, with Y = (y - y0) / L,
      psi = -U L tanh Y + U L sech^2 Y sum_n eps_n cos(k_n (x - c_n t)),  u = -d psi / dy,  v = d psi / dx,  w = 0,
  k_n = n k_1, the amplitudes eps_n and speeds c_n / U of Rypina et al. The waves' speeds share no period, so
  every episode starts at t = 0 (the starts and targets differ).
* :class:`HillVortex` (Hill 1894): Hill's spherical vortex of radius a held in a uniform stream of speed U(t) along
  -x (its axis), U(t) = U (1 + eps sin(omega t)); Stokes stream function about the axis (rho the distance to it,
  R to the centre), u_axial = (1 / rho) d psi / d rho, u_rho = -(1 / rho) d psi / d x_axial,
      psi = (3/4) U rho^2 (1 - R^2 / a^2) inside,  psi = -(1/2) U rho^2 (1 - a^3 / R^3) outside.
* :class:`LambDipole` (Lamb 1906, Chaplygin 1903): the Lamb-Chaplygin dipole of radius a moving at its own speed U
  along +x through fluid at rest, layered in z; in its frame, with (r, theta) about its centre,
      psi = -2 U J1(k r) / (k J0(k a)) sin theta inside (k a = 3.8317, the first zero of J1),
      psi = -U (r - a^2 / r) sin theta outside,  u = d psi / dy + U,  v = -d psi / dx.
  Its centre crosses the box and comes back every ``spacing / U`` (the flow's period): images ``spacing`` apart
  along x, four on each side, so that the far field jumps at each return by less than 0.3% of U.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from flownav.flows.base import Box
from flownav.flows.zoo import _Analytic

JET_BOX = Box((0.0, -8.0, -4.0), (16.0, 8.0, 4.0))
STREAM_BOX = Box((0.0, -8.0, -5.0), (16.0, 8.0, 5.0))
J1_ZERO = 3.8317059702075125  # the first positive zero of the Bessel function J1


class _BesselJ01(torch.autograd.Function):
    """(J0(x), J1(x)) with their derivatives (torch.special's Bessel functions have none): J0' = -J1,
    J1' = J0 - J1 / x (1/2 at x = 0), so that the flow can be differentiated (its divergence test, autograd users)."""

    @staticmethod
    def forward(ctx, x: Tensor) -> tuple[Tensor, Tensor]:
        j0, j1 = torch.special.bessel_j0(x), torch.special.bessel_j1(x)
        ctx.save_for_backward(x, j0, j1)
        return j0, j1

    @staticmethod
    def backward(ctx, g0: Tensor, g1: Tensor) -> Tensor:
        x, j0, j1 = ctx.saved_tensors
        j1_over_x = torch.where(x.abs() > 1e-6, j1 / x.where(x.abs() > 1e-6, torch.ones_like(x)), 0.5)
        return -g0 * j1 + g1 * (j0 - j1_over_x)


def _sech2(y: Tensor) -> Tensor:
    return 1 / torch.cosh(y) ** 2


class BickleyJet(_Analytic):
    # Rypina et al. (2007): wave amplitudes, and wave speeds over the jet's speed.
    EPS = (0.0075, 0.15, 0.3)
    SPEEDS = (0.1446, 0.205, 0.461)

    def __init__(self, U=1.6, width=2.5, wavenumber=0.556 / 2.5, bounds: Box = JET_BOX):
        self.U, self.L, self.k = float(U), float(width), float(wavenumber)
        self.y0 = bounds.center[1]
        self._finish(bounds, None, False)

    def velocity(self, pos: Tensor, t: Tensor) -> Tensor:
        x, Y = pos[..., 0], (pos[..., 1] - self.y0) / self.L
        t = t.to(pos.dtype)
        cos = sin = 0.0
        for n, (eps, speed) in enumerate(zip(self.EPS, self.SPEEDS, strict=True), start=1):
            phase = n * self.k * (x - speed * self.U * t)
            cos = cos + eps * torch.cos(phase)
            sin = sin + eps * n * self.k * torch.sin(phase)
        s2 = _sech2(Y)
        u = self.U * s2 * (1 + 2 * torch.tanh(Y) * cos)
        v = -self.U * self.L * s2 * sin
        return torch.stack((u, v, torch.zeros_like(u)), -1)


class HillVortex(_Analytic):
    def __init__(self, U=0.6, radius=4.0, eps=0.3, omega=0.4, bounds: Box = STREAM_BOX):
        self.U, self.a, self.eps, self.omega = float(U), float(radius), float(eps), float(omega)
        self.center = bounds.center
        self._finish(bounds, omega, eps != 0)

    def velocity(self, pos: Tensor, t: Tensor) -> Tensor:
        rel = pos - pos.new_tensor(self.center)
        x, y, z = rel.unbind(-1)  # x: the axis
        rho2, R2 = y * y + z * z, (rel * rel).sum(-1)
        a2 = self.a**2
        U = -self.U * (1 + self.eps * torch.sin(self.omega * t.to(pos.dtype)))  # the stream along -x
        inside = R2 < a2
        R5 = R2.clamp_min(1e-12) ** 2.5
        # u_axial and u_rho / rho from the two stream functions (the stream's sign in U)
        axial = torch.where(
            inside, -1.5 * U * (1 - (2 * rho2 + x * x) / a2), U - 0.5 * U * a2 * self.a * (2 * R2 - 3 * rho2) / R5
        )
        radial = torch.where(inside, -1.5 * U * x / a2, -1.5 * U * a2 * self.a * x / R5)
        return torch.stack((axial, radial * y, radial * z), -1)


class LambDipole(_Analytic):
    IMAGES = 4  # on each side

    def __init__(self, U=0.6, radius=5.0, spacing=24.0, bounds: Box = JET_BOX):
        self.U, self.a, self.spacing = float(U), float(radius), float(spacing)
        self.k = J1_ZERO / self.a
        self.c = 2 * self.U / (self.k * float(torch.special.bessel_j0(torch.tensor(J1_ZERO, dtype=torch.float64))))
        self.start = (bounds.lo[0], bounds.center[1])  # the centre at t = 0
        self._finish(bounds, 2 * math.pi * self.U / self.spacing, True)  # period spacing / U: speeds over all of it

    def velocity(self, pos: Tensor, t: Tensor) -> Tensor:
        travelled = torch.remainder(self.U * t.to(pos.dtype), self.spacing)
        y = pos[..., 1] - self.start[1]  # the same for every image
        u = torch.zeros_like(y)
        v = torch.zeros_like(y)
        for m in range(-self.IMAGES, self.IMAGES + 1):
            x = pos[..., 0] - (self.start[0] + travelled + m * self.spacing)
            r2 = (x * x + y * y).clamp_min(1e-12)
            r = r2.sqrt()
            kr = self.k * r
            j0, j1 = _BesselJ01.apply(kr)
            # psi = g(r) y: d psi / dy = g + (g' / r) y^2, d psi / dx = (g' / r) x y; dg is g' / r
            g_in, dg_in = -self.c * j1 / r, -self.c * (kr * j0 - 2 * j1) / (r2 * r)
            g_out, dg_out = -self.U * (1 - self.a**2 / r2), -2 * self.U * self.a**2 / (r2 * r2)
            inside = r2 < self.a**2
            g, dg = torch.where(inside, g_in, g_out), torch.where(inside, dg_in, dg_out)
            u = u + g + dg * y * y + self.U
            v = v - dg * x * y
        return torch.stack((u, v, torch.zeros_like(u)), -1)


# name -> class: the validation flows (``flow.type: validation`` with ``flow.name``).
VALIDATION = {"bickley_jet": BickleyJet, "hill_vortex": HillVortex, "lamb_dipole": LambDipole}
