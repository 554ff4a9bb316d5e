"""Boundaries of the cylinder-in-a-channel lattice.

* Cylinder (axis z): Bouzidi-Firdaouss-Lallemand linear interpolated bounce-back on every
  link that crosses the wall, with the wall distance ``q`` computed exactly for the circle;
  the force on the body follows by momentum exchange on the same links.
* Inflow (x = first plane): equilibrium at the inflow velocity with the density of the
  neighbouring plane (velocity Dirichlet that lets pressure waves set the density).
* Outflow (x = last plane): density 1 (pins the pressure level), velocity and
  non-equilibrium part copied from the previous plane; the sponge in front of it (raised
  viscosity, see :func:`sponge_beta`) damps vortices and reflections before they arrive.
* y and z: periodic through the ghost layers (y far from the wake, z the span).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from flownav.cfd.lattice import Lattice
from flownav.errors import ConfigError


@dataclass
class Links:
    """Wall links of the cylinder, precomputed as flat indices into ``f.view(-1)``."""

    nodes: Tensor  # [B] flat node index of each boundary (fluid) node
    pull: Tensor  # [Q, B] flat index (into f.view(-1)) of the value each population pulls
    src_a: Tensor  # [K] f_i(x_b)
    src_b: Tensor  # [K] f_i(x_b - c_i)
    src_c: Tensor  # [K] f_opp(i)(x_b)
    coef: Tensor  # [K, 3] Bouzidi weights of src_a, src_b, src_c
    target: Tensor  # [K] flat index into the [Q, B] pulled block: opp(i) * B + b
    c_link: Tensor  # [K, 3] lattice velocity c_i of each link (towards the wall)
    solid_nodes: Tensor  # [S] flat indices of solid nodes incl. z ghosts (reset to rest equilibrium)
    ghost_src: Tensor  # boundary nodes on the first/last z layer ...
    ghost_dst: Tensor  # ... and their periodic ghost copies
    beta_index: Tensor  # [B] x-plane of each boundary node (to pick its relaxation rate)


def wall_distance(px, py, cx, cy, radius) -> np.ndarray:
    """Fraction q in (0, 1] of the link p -> p + c at which it meets the circle (lattice units)."""
    # |p + t c|^2 = r^2 (centre at the origin); p outside, p + c inside: smallest root.
    a = cx * cx + cy * cy
    b = 2 * (px * cx + py * cy)
    c = px * px + py * py - radius * radius
    disc = np.sqrt(np.maximum(b * b - 4 * a * c, 0.0))
    return np.clip((-b - disc) / (2 * a), 1e-6, 1.0)


def cylinder_links(lat: Lattice, grid, center_lat, radius_lat, device="cpu") -> Links:
    """Links of a z-invariant circular cylinder on the interior nodes of ``grid``."""
    nx, ny, nz = grid.nx, grid.ny, grid.nz
    ix, iy = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    px, py = ix - center_lat[0], iy - center_lat[1]
    solid2 = px**2 + py**2 < radius_lat**2
    opp = lat.opposite
    node_of = np.full((nx, ny), -1, dtype=np.int64)  # 2D boundary node id
    nodes2, links = [], []  # links: (node id, i, q, pullback-is-fluid)
    for i, (cx, cy, _cz) in enumerate(lat.c):
        if cx == 0 and cy == 0:
            continue
        tx, ty = ix + cx, iy + cy
        inside = (tx >= 0) & (tx < nx) & (ty >= 0) & (ty < ny)
        hit = np.zeros_like(solid2)
        hit[inside] = solid2[tx[inside], ty[inside]]
        hit &= ~solid2
        for a, b in zip(*np.nonzero(hit), strict=True):
            if node_of[a, b] < 0:
                node_of[a, b] = len(nodes2)
                nodes2.append((a, b))
            q = float(wall_distance(px[a, b], py[a, b], cx, cy, radius_lat))
            back = 0 <= a - cx < nx and 0 <= b - cy < ny and not solid2[a - cx, b - cy]
            links.append((node_of[a, b], i, q, back))
    if not links:
        raise ConfigError("the cylinder covers no lattice node; check its position and the resolution")
    nodes2 = np.array(nodes2)
    z = np.arange(nz)
    # Replicate over the span: boundary node (k2, z) has id k2 * nz + z.
    nodes = grid.flat(nodes2[:, 0, None], nodes2[:, 1, None], z[None, :]).reshape(-1)
    shifts = np.array([grid.shift(c) for c in lat.c])
    L = grid.length
    pull = np.arange(lat.q)[:, None] * L + nodes[None, :] - shifts[:, None]
    B = len(nodes)
    ka, kb, kc, coef, target, cl = [], [], [], [], [], []
    for k2, i, q, back in links:
        bid = k2 * nz + z
        n = nodes[bid]
        if q < 0.5 and back:
            w = (2 * q, 1 - 2 * q, 0.0)
        elif q >= 0.5:
            w = (1 / (2 * q), 0.0, 1 - 1 / (2 * q))
        else:  # no fluid node behind: plain half-way bounce-back
            w = (1.0, 0.0, 0.0)
        ka.append(i * L + n)
        kb.append(i * L + n - shifts[i])
        kc.append(opp[i] * L + n)
        coef.append(np.broadcast_to(w, (nz, 3)))
        target.append(opp[i] * B + bid)
        cl.append(np.broadcast_to(lat.c[i], (nz, 3)))
    sx, sy = np.nonzero(solid2)
    solid_nodes = grid.flat(sx[:, None], sy[:, None], np.arange(-1, nz + 1)[None, :]).reshape(-1)
    bx, by = nodes2[:, 0], nodes2[:, 1]
    ghost_src = np.concatenate([grid.flat(bx, by, 0), grid.flat(bx, by, nz - 1)])
    ghost_dst = np.concatenate([grid.flat(bx, by, nz), grid.flat(bx, by, -1)])
    beta_index = np.repeat(nodes2[:, 0], nz)

    def t(a, dtype=torch.int64):
        return torch.as_tensor(np.concatenate(a) if isinstance(a, list) else a, dtype=dtype, device=device)

    return Links(
        nodes=t(nodes),
        pull=t(pull),
        src_a=t(ka),
        src_b=t(kb),
        src_c=t(kc),
        coef=t(coef, torch.float32),
        target=t(target),
        c_link=t(cl, torch.float32),
        solid_nodes=t(solid_nodes),
        ghost_src=t(ghost_src),
        ghost_dst=t(ghost_dst),
        beta_index=t(beta_index),
    )


def sponge_beta(nx: int, tau: float, sponge_cells: int, tau_max: float = 1.0) -> Tensor:
    """Relaxation rate beta = 1/(2 tau) per x-plane; tau ramps to tau_max at the outlet."""
    tau_x = np.full(nx, tau)
    if sponge_cells > 0:
        s = np.clip((np.arange(nx) - (nx - 1 - sponge_cells)) / sponge_cells, 0.0, 1.0)
        tau_x = tau + (max(tau_max, tau) - tau) * s**2
    return torch.as_tensor(1.0 / (2.0 * tau_x), dtype=torch.float32)
