"""Lattice velocity sets (D3Q19, D3Q27) and the second-order equilibrium.

Populations are stored as one tensor ``f[Q, Nx, Ny, Nz]``; velocities ``c[Q, 3]`` are small
integers, weights ``w[Q]`` sum to one, and ``opposite[i]`` is the index of ``-c[i]``.
The lattice speed of sound is ``cs^2 = 1/3`` for both sets.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import torch
from torch import Tensor

from flownav.errors import ConfigError

CS2 = 1.0 / 3.0


@dataclass(frozen=True)
class Lattice:
    name: str
    c: tuple[tuple[int, int, int], ...]
    w: tuple[float, ...]

    @property
    def q(self) -> int:
        return len(self.c)

    @property
    def opposite(self) -> tuple[int, ...]:
        return tuple(self.c.index(tuple(-a for a in ci)) for ci in self.c)

    def c_tensor(self, dtype=torch.float32, device="cpu") -> Tensor:
        return torch.tensor(self.c, dtype=dtype, device=device)

    def w_tensor(self, dtype=torch.float32, device="cpu") -> Tensor:
        return torch.tensor(self.w, dtype=dtype, device=device)


def _make(name: str) -> Lattice:
    # Weight by the number of non-zero components: rest, faces, edges, corners.
    weights = {"D3Q19": (1 / 3, 1 / 18, 1 / 36, 0.0), "D3Q27": (8 / 27, 2 / 27, 1 / 54, 1 / 216)}[name]
    cs, ws = [], []
    for ci in itertools.product((0, 1, -1), repeat=3):
        wi = weights[sum(a != 0 for a in ci)]
        if wi > 0:
            cs.append(ci)
            ws.append(wi)
    return Lattice(name, tuple(cs), tuple(ws))


LATTICES = {name: _make(name) for name in ("D3Q19", "D3Q27")}


def get_lattice(name: str) -> Lattice:
    if name not in LATTICES:
        raise ConfigError(f"unknown lattice {name!r}; choose one of {sorted(LATTICES)}")
    return LATTICES[name]


def shear_coefficients(ci) -> list[int]:
    """Coefficients of the second-moment components (xx, yy, zz, xy, xz, yz) in c.P.c.

    Off-diagonal terms are counted twice; the KBC shear part of population i is
    (9/2) w_i sum_k coeffs_k P_k, in torch (collision.py) and in the generated C (ckernel.py).
    """
    return [ci[0] ** 2, ci[1] ** 2, ci[2] ** 2, 2 * ci[0] * ci[1], 2 * ci[0] * ci[2], 2 * ci[1] * ci[2]]


def equilibrium(lat: Lattice, rho: Tensor, u: Tensor) -> Tensor:
    """Second-order equilibrium ``f_eq[Q, ...]`` of density ``rho[...]``, velocity ``u[3, ...]``."""
    c = lat.c_tensor(rho.dtype, rho.device)
    w = lat.w_tensor(rho.dtype, rho.device)
    cu = torch.einsum("qd,d...->q...", c, u)
    usq = (u * u).sum(0)
    shape = (-1,) + (1,) * rho.dim()
    return w.view(shape) * rho * (1 + 3 * cu + 4.5 * cu * cu - 1.5 * usq)


def moments(lat: Lattice, f: Tensor) -> tuple[Tensor, Tensor]:
    """Density ``rho[...]`` and velocity ``u[3, ...]`` of populations ``f[Q, ...]``."""
    c = lat.c_tensor(f.dtype, f.device)
    rho = f.sum(0)
    u = torch.einsum("qd,q...->d...", c, f) / rho
    return rho, u
