"""KBC entropic multi-relaxation collision (Karlin, Boesch, Chikatamarla 2014).

The non-equilibrium part ``df = f - f_eq`` is split into a shear part ``ds`` (the traceless
second moment, projected with the Hermite weights) and the rest ``dh`` (bulk and higher
moments). Shear relaxes with the viscosity, ``dh`` with the stabiliser ``gamma`` chosen so
the post-collision entropy is maximal; this damps the under-resolved high modes that make
plain BGK blow up near ``tau = 0.5`` on coarse grids, while leaving the viscosity unchanged.

``f' = f - beta (2 ds + gamma dh)``,  ``beta = 1 / (2 tau)``,
``gamma = 1/beta - (2 - 1/beta) <ds|dh> / <dh|dh>``,  ``<a|b> = sum_i a_i b_i / f_eq_i``.
``gamma = 2`` is BGK. The code works on a list of ``Q`` same-shape tensors with the lattice
velocities as Python constants, so torch.compile fuses the whole collision into one loop.
"""

from __future__ import annotations

import torch
from torch import Tensor

from flownav.cfd.lattice import Lattice, shear_coefficients

# Pairs (a, b) of the symmetric second moment, in the order xx, yy, zz, xy, xz, yz.
_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


def _dot(coeffs, terms):
    """sum_k coeffs[k] * terms[k], skipping zeros and not multiplying by +-1."""
    out = None
    for a, t in zip(coeffs, terms, strict=True):
        if a == 0:
            continue
        v = t if a == 1 else (-t if a == -1 else a * t)
        out = v if out is None else out + v
    return out


def macroscopic(lat: Lattice, f: list[Tensor]) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    rho = f[0]
    for fi in f[1:]:
        rho = rho + fi
    inv = 1.0 / rho
    ux = _dot([c[0] for c in lat.c], f) * inv
    uy = _dot([c[1] for c in lat.c], f) * inv
    uz = _dot([c[2] for c in lat.c], f) * inv
    return rho, ux, uy, uz


def kbc(lat: Lattice, f: list[Tensor], beta: Tensor | float) -> list[Tensor]:
    """Post-collision populations; ``beta`` may be a tensor broadcasting to the lattice (sponge)."""
    rho, ux, uy, uz = macroscopic(lat, f)
    usq15 = 1.5 * (ux * ux + uy * uy + uz * uz)
    feq, df = [], []
    for ci, wi, fi in zip(lat.c, lat.w, f, strict=True):
        cu = _dot(ci, (ux, uy, uz))
        feq_i = wi * rho * (1 - usq15) if cu is None else wi * rho * (1 + 3 * cu + 4.5 * cu * cu - usq15)
        feq.append(feq_i)
        df.append(fi - feq_i)
    # Non-equilibrium second moment and its traceless part.
    pi = [_dot([ci[a] * ci[b] for ci in lat.c], df) for a, b in _PAIRS]
    tr3 = (pi[0] + pi[1] + pi[2]) * (1.0 / 3.0)
    pd = [pi[0] - tr3, pi[1] - tr3, pi[2] - tr3, pi[3], pi[4], pi[5]]
    ds, dh = [], []
    for ci, wi, dfi in zip(lat.c, lat.w, df, strict=True):
        # c.Pd.c with off-diagonal terms counted twice; the Hermite projection weight is 9/2.
        coeffs = shear_coefficients(ci)
        cpc = _dot(coeffs, pd)
        dsi = None if cpc is None else (4.5 * wi) * cpc  # the rest population has no shear part
        ds.append(dsi)
        dh.append(dfi if dsi is None else dfi - dsi)
    sh = None
    hh = None
    for dsi, dhi, fe in zip(ds, dh, feq, strict=True):
        inv = 1.0 / fe
        b = dhi * dhi * inv
        hh = b if hh is None else hh + b
        if dsi is not None:
            a = dsi * dhi * inv
            sh = a if sh is None else sh + a
    inv_beta = 1.0 / beta
    gamma = inv_beta - (2.0 - inv_beta) * sh / (hh + 1e-30)
    # Where dh vanishes gamma is irrelevant; bound it so round-off cannot inject energy.
    gamma = torch.minimum(gamma.clamp(min=0.0), 2.0 * torch.as_tensor(inv_beta))
    two_beta = 2.0 * beta
    beta_gamma = beta * gamma
    return [
        fi - beta_gamma * dhi if dsi is None else fi - two_beta * dsi - beta_gamma * dhi
        for fi, dsi, dhi in zip(f, ds, dh, strict=True)
    ]
