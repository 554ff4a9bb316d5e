"""Lattice-Boltzmann solver for the flow past a circular cylinder (axis z) in lattice units.

Units: the lattice spacing is ``dx = 1 / cells_per_d`` diameters and one step advances time by
``dx * u_lattice`` in D/U. The viscosity follows from ``Re``: ``nu = u_lattice * cells_per_d / Re``,
``tau = 3 nu + 1/2``. Backends: ``"c"`` (fused gcc kernel, CPU) and ``"torch"`` (plain tensor
ops on any device, the GPU path); ``"auto"`` picks C on the CPU.
"""

from __future__ import annotations

import math
import shutil
from dataclasses import asdict, dataclass, field

import numpy as np
import torch
from torch import Tensor

from flownav.cfd import boundaries, ckernel
from flownav.cfd.collision import kbc
from flownav.cfd.lattice import Lattice, equilibrium, get_lattice
from flownav.errors import CheckpointError, ConfigError

# Grid Reynolds number u/nu = Re / cells_per_d above which KBC on D3Q19 is no longer reliably
# stable on this geometry (Re = 300 runs at 37.5 with 8 cells per diameter).
MAX_GRID_RE = 50.0
MAX_U_LATTICE = 0.15  # Mach 0.26: compressibility error ~ Ma^2 stays below ~7%


@dataclass(frozen=True)
class SimConfig:
    """Physical set-up and its discretisation (lengths in D, velocities in U)."""

    re: float = 300.0
    cells_per_d: int = 12  # 10 gave Cd +12% and a weaker 3D wake; 12 fits the time budget
    u_lattice: float = 0.1
    x_range: tuple[float, float] = (-8.0, 28.0)  # inflow 8 D upstream, outflow 6 D past x = 22
    y_half: float = 9.0  # lateral period 18 D (periodic, 2 D beyond the navigation box)
    span: float | None = 4.0  # periodic span Lz (mode A ~4 D, mode B ~1 D); None = a 2D run
    sponge: float = 3.0  # outlet sponge length: x in [25, 28] by default
    lattice: str = "D3Q19"
    perturb: float = 0.1  # amplitude of the initial asymmetric, span-modulated kick
    seed: int = 0

    def __post_init__(self):
        if not (self.re > 0 and math.isfinite(self.re)):
            raise ConfigError(f"Re must be a positive number, got {self.re}")
        sizes = {
            "cells_per_d": self.cells_per_d,
            "y_half": self.y_half,
            "span": 1.0 if self.span is None else self.span,
        }
        for name, value in sizes.items():
            if not (value > 0 and math.isfinite(value)):
                raise ConfigError(f"{name} (--{name.replace('_', '-')}) must be a positive number, got {value}")
        if not (0 <= self.sponge < self.x_range[1] - self.x_range[0]):
            raise ConfigError(f"sponge must be >= 0 and shorter than the domain {self.x_range}, got {self.sponge}")
        if not 0 < self.u_lattice <= MAX_U_LATTICE:
            raise ConfigError(
                f"u_lattice = {self.u_lattice} is outside (0, {MAX_U_LATTICE}]: the lattice Mach "
                "number would make the flow compressible; use u_lattice around 0.05-0.1"
            )
        if self.re / self.cells_per_d > MAX_GRID_RE:
            raise ConfigError(
                f"resolution too coarse to be stable: Re / cells_per_d = "
                f"{self.re / self.cells_per_d:.1f} "
                f"> {MAX_GRID_RE}; use cells_per_d >= {math.ceil(self.re / MAX_GRID_RE)}"
            )
        if self.cells_per_d < 4:
            raise ConfigError(f"cells_per_d = {self.cells_per_d} cannot resolve the cylinder; use >= 4")
        if self.tau - 0.5 < 1e-4:
            raise ConfigError(f"tau = {self.tau:.6f} too close to 1/2; raise cells_per_d or u_lattice")
        if not (self.x_range[0] <= -2 and self.x_range[1] >= 4 and self.y_half >= 2):
            raise ConfigError(f"domain x {self.x_range}, |y| <= {self.y_half} too small around the cylinder")

    @property
    def dx(self) -> float:
        return 1.0 / self.cells_per_d

    @property
    def nu(self) -> float:
        return self.u_lattice * self.cells_per_d / self.re

    @property
    def tau(self) -> float:
        return 3.0 * self.nu + 0.5

    @property
    def dt(self) -> float:
        """Physical time (D/U) per lattice step."""
        return self.dx * self.u_lattice

    @property
    def shape(self) -> tuple[int, int, int]:
        nx = round((self.x_range[1] - self.x_range[0]) / self.dx) + 1
        ny = round(2 * self.y_half / self.dx)
        nz = 1 if self.span is None else round(self.span / self.dx)
        return nx, ny, nz

    def coords(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Physical coordinates of the interior nodes along x, y, z."""
        nx, ny, nz = self.shape
        return (
            self.x_range[0] + self.dx * np.arange(nx),
            -self.y_half + self.dx * np.arange(ny),
            self.dx * np.arange(nz),
        )

    def to_dict(self) -> dict:
        d = asdict(self)
        d["x_range"] = list(self.x_range)
        return d


@dataclass
class Grid:
    """Flat, ghosted memory layout shared by both backends (see :mod:`flownav.cfd.ckernel`)."""

    nx: int
    ny: int
    nz: int
    nyg: int = field(init=False)
    nzg: int = field(init=False)
    pad: int = field(init=False)

    def __post_init__(self):
        self.nyg, self.nzg = self.ny + 2, self.nz + 2
        self.pad = self.nyg * self.nzg + self.nzg + 1

    @property
    def m(self) -> int:
        return self.nx * self.nyg * self.nzg

    @property
    def length(self) -> int:
        return self.m + 2 * self.pad

    def flat(self, ix, iy, iz):
        return self.pad + ix * self.nyg * self.nzg + (iy + 1) * self.nzg + (iz + 1)

    def shift(self, c) -> int:
        return c[0] * self.nyg * self.nzg + c[1] * self.nzg + c[2]

    def planes(self, f: Tensor) -> Tensor:
        """View ``[Q, Nx, Nyg*Nzg]`` of the non-pad part of ``f[Q, L]``."""
        return f[:, self.pad : self.pad + self.m].view(f.shape[0], self.nx, self.nyg * self.nzg)

    def interior(self, a: Tensor) -> Tensor:
        """View ``[..., Nx, Ny, Nz]`` of the interior nodes of ``a[..., L]``."""
        v = a[..., self.pad : self.pad + self.m].reshape(*a.shape[:-1], self.nx, self.nyg, self.nzg)
        return v[..., 1:-1, 1:-1]


class CylinderLBM:
    """D3Q19/D3Q27 KBC lattice Boltzmann for the cylinder wake; ``step(n)`` advances n steps."""

    def __init__(self, cfg: SimConfig, device="cpu", backend: str = "auto", threads: int | None = None):
        self.cfg = cfg
        self.threads = threads or torch.get_num_threads()
        self.device = torch.device(device)
        if backend == "auto":
            backend = "c" if self.device.type == "cpu" and shutil.which("gcc") else "torch"
        if backend == "c" and self.device.type != "cpu":
            raise ConfigError("the C kernel runs on the CPU only; use backend='torch' on a GPU")
        if backend not in ("c", "torch"):
            raise ConfigError(f"unknown backend {backend!r}; use 'auto', 'c' or 'torch'")
        self.backend = backend
        self.lat: Lattice = get_lattice(cfg.lattice)
        self.grid = Grid(*cfg.shape)
        g = self.grid
        self.shifts = [g.shift(c) for c in self.lat.c]
        center = (-cfg.x_range[0] / cfg.dx, cfg.y_half / cfg.dx)  # cylinder at (0, 0)
        self.links = boundaries.cylinder_links(self.lat, g, center, 0.5 * cfg.cells_per_d, self.device)
        sponge_cells = round(cfg.sponge / cfg.dx)
        self.beta_x = boundaries.sponge_beta(g.nx, cfg.tau, sponge_cells).to(self.device)
        self.beta_b = self.beta_x[self.links.beta_index].contiguous()
        self.w = self.lat.w_tensor(device=self.device)
        self.c = self.lat.c_tensor(device=self.device)
        self.f = torch.empty(self.lat.q, g.length, device=self.device)
        self.f2 = torch.empty_like(self.f)
        self.steps = 0
        self.force = torch.zeros(3, device=self.device)  # lattice units, last step
        self.reset()

    # ---- state -------------------------------------------------------------------------
    @property
    def time(self) -> float:
        return self.steps * self.cfg.dt

    def reset(self) -> None:
        """Uniform inflow plus a small asymmetric kick (random, span-modulated) behind the body."""
        cfg, g = self.cfg, self.grid
        x, y, z = (torch.as_tensor(a, dtype=torch.float32) for a in cfg.coords())
        X, Y, Z = torch.meshgrid(x, y, z, indexing="ij")
        gen = torch.Generator().manual_seed(cfg.seed)
        u = torch.zeros(3, *X.shape)
        u[0] = 1.0
        bump = torch.exp(-((X - 1.5) ** 2 + Y**2) / 2.0)
        span = 1.0
        if cfg.span is not None:
            # Modes of spanwise wavelength Lz and ~1 D (A and B) plus noise seed 3D structure early.
            lz = cfg.span
            span = 1 + 0.5 * torch.sin(2 * math.pi * Z / lz) + 0.5 * torch.sin(2 * math.pi * Z * round(lz) / lz)
            u[2] = cfg.perturb * bump * torch.sin(2 * math.pi * Z * round(lz) / lz)
        u[1] = cfg.perturb * bump * span
        u += 0.01 * cfg.perturb * torch.randn(u.shape, generator=gen) * (X > 0.5)
        u[:, X**2 + Y**2 < 0.25] = 0.0
        u = u * cfg.u_lattice
        feq = equilibrium(self.lat, torch.ones(X.shape), u)
        self.f.copy_(self.w.view(-1, 1).expand_as(self.f))
        g.interior(self.f).copy_(feq.to(self.device))
        self._fill_ghosts(self.f)
        self.f2.copy_(self.f)
        self.steps = 0

    def state_dict(self) -> dict:
        return {"config": self.cfg.to_dict(), "f": self.f.cpu(), "steps": self.steps}

    def load_state_dict(self, state: dict) -> None:
        if state["config"] != self.cfg.to_dict():
            now, then = self.cfg.to_dict(), state["config"]
            diff = [f"{k} {then.get(k)} there, {now[k]} here" for k in now if then.get(k) != now[k]]
            raise CheckpointError(
                f"checkpoint was written for another set-up ({'; '.join(diff) or state['config']}); use another "
                "--run-dir, delete that run's state.pt, or rerun with the options it was made with"
            )
        self.f.copy_(state["f"].to(self.device))
        self.steps = int(state["steps"])

    # ---- one step ----------------------------------------------------------------------
    def _fill_ghosts(self, f: Tensor) -> None:
        """Periodic y and z ghost layers from the interior (torch path; the C kernel does it)."""
        g = self.grid
        a = f[:, g.pad : g.pad + g.m].view(-1, g.nx, g.nyg, g.nzg)
        a[..., 0] = a[..., -2]
        a[..., -1] = a[..., 1]
        a[:, :, 0, :] = a[:, :, -2, :]
        a[:, :, -1, :] = a[:, :, 1, :]

    def _stream_collide(self, fin: Tensor, fout: Tensor) -> None:
        g = self.grid
        if self.backend == "c":
            ckernel.stream_collide(self.cfg.lattice, fin, fout, self.beta_x, g.nx, g.nyg, g.nzg, g.pad, self.threads)
            return
        p, m = g.pad, g.m
        pulled = [fin[i, p - s : p - s + m].view(g.nx, -1) for i, s in enumerate(self.shifts)]
        post = kbc(self.lat, pulled, self.beta_x.view(-1, 1))
        fout[:, p : p + m] = torch.stack(post).view(self.lat.q, m)

    def _collide_nodes(self, block: Tensor, beta: Tensor) -> Tensor:
        if self.backend == "c":
            block = block.contiguous()
            ckernel.collide(self.cfg.lattice, block, beta)
            return block
        return torch.stack(kbc(self.lat, list(block), beta))

    def _cylinder(self, fin: Tensor, fout: Tensor) -> None:
        """Bouzidi bounce-back on the wall links, collide the boundary nodes, momentum exchange."""
        lk = self.links
        flat = fin.view(-1)
        block = flat[lk.pull]  # [Q, B] pulled populations of the boundary nodes
        fa = flat[lk.src_a]
        bounced = lk.coef[:, 0] * fa + lk.coef[:, 1] * flat[lk.src_b] + lk.coef[:, 2] * flat[lk.src_c]
        block.view(-1)[lk.target] = bounced
        # Each link carries f_i to the wall and returns the bounced value: momentum c_i (f + f~).
        self.force = ((fa + bounced)[:, None] * lk.c_link).sum(0)
        fout[:, lk.nodes] = self._collide_nodes(block, self.beta_b)
        fout[:, lk.solid_nodes] = self.w[:, None]
        fout[:, lk.ghost_dst] = fout[:, lk.ghost_src]  # keep the z ghosts of fixed nodes in sync

    def _inflow_outflow(self, f: Tensor) -> None:
        a = self.grid.planes(f)
        c, w, u_in = self.c, self.w[:, None], self.cfg.u_lattice
        rho1 = a[:, 1].sum(0)
        cu = c[:, 0:1] * u_in
        a[:, 0] = w * rho1 * (1 + 3 * cu + 4.5 * cu * cu - 1.5 * u_in * u_in)
        prev = a[:, -2]
        rho = prev.sum(0)
        u = (c.T @ prev) / rho
        cu = c @ u
        usq = 1.5 * (u * u).sum(0)
        shape = w * (1 + 3 * cu + 4.5 * cu * cu - usq)
        a[:, -1] = prev + shape * (1.0 - rho)  # feq(1, u) + (prev - feq(rho, u))

    @torch.no_grad()
    def step(self, n: int = 1) -> None:
        """Advance n steps; the state (post-collision, ghosts filled) is kept in ``self.f``."""
        # The boundary work is tiny: one thread avoids waiting for a second, busy core.
        saved = torch.get_num_threads()
        if self.backend == "c":
            torch.set_num_threads(1)
        try:
            for _ in range(n):
                self._stream_collide(self.f, self.f2)
                self._cylinder(self.f, self.f2)
                self._inflow_outflow(self.f2)
                if self.backend == "torch":
                    self._fill_ghosts(self.f2)
                self.f, self.f2 = self.f2, self.f
                self.steps += 1
        finally:
            torch.set_num_threads(saved)

    # ---- observables -------------------------------------------------------------------
    @torch.no_grad()
    def macroscopic(self, sl: tuple[slice, slice, slice] | None = None) -> tuple[Tensor, Tensor]:
        """Density and velocity ``[3, ...]`` (units of U, 0 in the body) on interior nodes sl."""
        sl = sl or (slice(None),) * 3
        fi = self.grid.interior(self.f)[(slice(None), *sl)]
        rho = fi.sum(0)
        u = torch.einsum("qd,qxyz->dxyz", self.c, fi) / rho / self.cfg.u_lattice
        solid = self._solid_mask()[sl[0], sl[1]]
        u[:, solid] = 0.0
        return rho, u

    def _solid_mask(self) -> Tensor:
        if not hasattr(self, "_solid"):
            x, y, _ = self.cfg.coords()
            X, Y = np.meshgrid(x, y, indexing="ij")
            self._solid = torch.as_tensor(X**2 + Y**2 < 0.25, device=self.device)
        return self._solid

    def coefficients(self) -> tuple[float, float]:
        """Drag and lift coefficients from the last step's momentum exchange."""
        cfg = self.cfg
        span_cells = self.grid.nz
        scale = 0.5 * cfg.u_lattice**2 * cfg.cells_per_d * span_cells
        fx, fy = (self.force[:2] / scale).tolist()
        return fx, fy

    def mass(self) -> float:
        return float(self.grid.interior(self.f).sum(dtype=torch.float64))
