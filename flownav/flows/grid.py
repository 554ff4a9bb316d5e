"""Flows given as velocity snapshots on a regular grid (CFD output), and their on-disk format.

Interpolation is trilinear in space and linear in time. ``time_mode`` says what happens past the
data: ``"looped"`` (the default) loops with period ``T * dt`` (frame ``T`` is frame ``0`` again), so a
CFD window whose end matches its start gives a seamless, infinitely long flow; ``"clamped"`` holds the
first and last frames before ``0`` and after ``(T - 1) * dt``; ``"error"`` raises there. Spatial
axes can be periodic (period ``N * spacing``, the spanwise axis of the cylinder wake); on the other
axes positions are clamped to the grid.
Both are exact for fields linear in x, y, z and t (away from a periodic seam).

On-disk format ``flownav-grid-v1``: a directory holding

* ``velocity.npy``: float16 or float32 array ``[T, Nx, Ny, Nz, 3]`` (u, v, w), grid point
  ``(i, j, k)`` at ``origin + (i, j, k) * spacing``, frame ``n`` at time ``n * dt``;
* ``meta.json``: ``format``, ``shape``, ``origin``, ``spacing``, ``dt``, ``periodic`` (3 bools),
  ``bounds`` (the navigation domain, ``{"lo": [...], "hi": [...]}``), ``obstacles``,
  ``max_speed``, ``units``, ``provenance`` (free dict: command, solver, Re, ...),
  ``diagnostics`` (free dict: St, Cd, ...) and ``sha256`` of ``velocity.npy``.

:func:`load_grid_flow` checks all of it and names the fix when something is wrong.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from torch import Tensor

from flownav import schema
from flownav.atomic import atomic_write
from flownav.errors import DataError
from flownav.flows import gridkernel
from flownav.flows.base import Box, Cylinder, FlowField, obstacle_from_dict
from flownav.provenance import sha256

FORMAT = "flownav-grid-v1"
VELOCITY_FILE = "velocity.npy"
META_FILE = "meta.json"
TIME_MODES = ("looped", "clamped", "error")
DEFAULT_UNITS = {"length": "cylinder diameter D", "velocity": "inflow speed U", "time": "D / U"}
# A declared obstacle is solid: the stored speed inside it must stay below this fraction of the maximum.
OBSTACLE_SPEED_TOL = 0.01

GridFlowError = DataError  # the name flownav.flows exports


class GridFlow(FlowField):
    def __init__(
        self,
        velocity: Tensor | np.ndarray,
        origin: Sequence[float],
        spacing: Sequence[float],
        dt: float,
        periodic: Sequence[bool] = (False, False, False),
        bounds: Box | None = None,
        obstacles: Sequence[Cylinder] = (),
        max_speed: float | None = None,
        meta: dict | None = None,
        dtype: torch.dtype = torch.float32,
        device="cpu",
        time_mode: str = "looped",
    ):
        if time_mode not in TIME_MODES:
            raise GridFlowError(f"time_mode is {time_mode!r}; choose one of {list(TIME_MODES)}")
        self.time_mode = time_mode
        velocity = torch.as_tensor(np.asarray(velocity) if isinstance(velocity, np.ndarray) else velocity)
        check_velocity_array(velocity.shape, torch.isfinite(velocity).all().item())
        if len(origin) != 3 or len(spacing) != 3 or len(periodic) != 3:
            raise GridFlowError("origin, spacing and periodic need 3 entries each (x, y, z)")
        if any(s <= 0 for s in spacing) or not dt > 0:
            raise GridFlowError(f"spacing {list(spacing)} and dt {dt} must be positive")
        self.shape = tuple(velocity.shape[:4])  # T, Nx, Ny, Nz
        self.origin = tuple(float(o) for o in origin)
        self.spacing = tuple(float(s) for s in spacing)
        self.dt = float(dt)
        self.periodic = tuple(bool(p) for p in periodic)
        # Only a looped flow has a period (the env starts episodes at random phases of it).
        self.period = self.shape[0] * self.dt if time_mode == "looped" else None
        self.duration = (self.shape[0] - 1) * self.dt  # time of the last frame
        n = self.shape[1:]
        grid_hi = tuple(o + (k - 1) * s for o, k, s in zip(self.origin, n, self.spacing, strict=True))
        self.bounds = bounds if bounds is not None else Box(self.origin, grid_hi)
        for axis, name in enumerate("xyz"):
            lo, hi, tol = self.origin[axis], grid_hi[axis], 1e-6 * self.spacing[axis]
            if not self.periodic[axis] and (self.bounds.lo[axis] < lo - tol or self.bounds.hi[axis] > hi + tol):
                raise GridFlowError(
                    f"bounds in {name} [{self.bounds.lo[axis]:g}, {self.bounds.hi[axis]:g}] reach beyond the grid's "
                    f"[{lo:g}, {hi:g}] on a non-periodic axis (the edge velocity would be held constant there): "
                    f"shrink bounds to the grid, or check origin and spacing"
                )
        self.obstacles = tuple(obstacles)
        self.meta = dict(meta or {})
        if max_speed is None:
            max_speed = float(velocity.float().norm(dim=-1).max())
        self.max_speed = float(max_speed)
        # A float16 field is kept as float16 (the look-up widens each value it reads, exactly): half the memory.
        self._store(velocity.to(device=device, dtype=torch.float16 if velocity.dtype == torch.float16 else dtype))

    def _store(self, velocity: Tensor) -> None:
        """Lay the field out so that a swimmer's 16 interpolation corners are 4 contiguous rows.

        Frame T (= frame 0) closes the time loop and a ghost layer closes each periodic axis, so
        the upper corner index is always lower + 1. Each row of ``_table`` holds the 2 (z) x 2 (t)
        x 3 values of one (x, y, z, t) cell; a look-up gathers the rows of the 4 (x, y) corners.
        Random gathers from a large grid are bound by memory latency, and 4 gathers of 12 numbers
        beat 16 of 3 (about 4x here) at the price of 4x the memory.
        """
        self._source = velocity
        v = torch.cat((velocity, velocity[:1]), 0)
        for axis, periodic in enumerate(self.periodic):
            if periodic:
                v = torch.cat((v, v.narrow(axis + 1, 0, 1)), axis + 1)
        v = v.permute(1, 2, 3, 0, 4)  # [px, py, pz, T + 1, 3]
        pairs = torch.stack((v[:, :, :-1], v[:, :, 1:]), 3)  # [px, py, pz - 1, 2(z), T + 1, 3]
        pairs = torch.stack((pairs[:, :, :, :, :-1], pairs[:, :, :, :, 1:]), 5)  # [.., 2(z), T, 2(t), 3]
        table = pairs.permute(0, 1, 2, 4, 3, 5, 6)  # [px, py, pz - 1, T, 2(z), 2(t), 3]
        px, py, nzp, T = table.shape[:4]
        self._row_strides = (py * nzp * T, nzp * T, T, 1)  # x, y, z, t
        self._table = table.reshape(-1, 12).contiguous()
        long = {"dtype": torch.long}
        self._kernel_args = (  # what flownav/flows/gridkernel.py reads
            torch.tensor(self.shape, **long),
            torch.tensor(self.origin, dtype=torch.float32),
            torch.tensor(self.spacing, dtype=torch.float32),
            torch.tensor(self.periodic, dtype=torch.int32),
            torch.tensor(self._row_strides, **long),
        )

    @property
    def device(self) -> torch.device:
        return self._table.device

    def to(self, device) -> GridFlow:
        self._store(self._source.to(device))
        return self

    def _axis(self, coord: Tensor, axis: int) -> tuple[Tensor, Tensor]:
        """Lower corner index and the weight of the upper one along one spatial axis."""
        n = self.shape[1 + axis]
        g = (coord - self.origin[axis]) / self.spacing[axis]
        if self.periodic[axis]:
            g = torch.remainder(g, n)
            i0 = g.floor().clamp_(0, n - 1)  # remainder can round up to n
        else:
            g = g.clamp(0, n - 1)
            i0 = g.floor().clamp_(max=n - 2)
        return i0, g - i0

    def _frame(self, t: Tensor) -> Tensor:
        """Fractional frame index in [0, T) for ``time_mode`` (frame T is frame 0 again)."""
        f = t / self.dt
        if self.time_mode == "looped":
            return torch.remainder(f, self.shape[0])
        if self.time_mode == "error" and bool(((f < 0) | (f > self.shape[0] - 1)).any()):
            raise GridFlowError(
                f"flow time {float(t.min()):g}..{float(t.max()):g} is outside the data's "
                f"[0, {self.duration:g}]: use time_mode='looped' or 'clamped', or give more frames"
            )
        return f.clamp(0, self.shape[0] - 1)

    def velocity(self, pos: Tensor, t: Tensor) -> Tensor:
        if not gridkernel.usable(self._table, pos):
            return self.velocity_torch(pos, t)
        if self.time_mode == "error":
            self._frame(t.to(pos.dtype))  # raises past the data
        return gridkernel.velocity(self, pos, t)

    def velocity_torch(self, pos: Tensor, t: Tensor) -> Tensor:
        """The look-up in torch (any device and dtype): the reference of the C kernel, which gives the same numbers."""
        f = self._frame(t.to(pos.dtype))
        f0 = f.floor().clamp_(0, self.shape[0] - 1)
        wt = f - f0
        x0, wx = self._axis(pos[:, 0], 0)
        y0, wy = self._axis(pos[:, 1], 1)
        z0, wz = self._axis(pos[:, 2], 2)
        sx, sy, sz, st = self._row_strides
        # Integer arithmetic: float32 is exact only up to 2^24, far below a big table's row count.
        row = x0.long() * sx + y0.long() * sy + z0.long() * sz + f0.long() * st
        rows = torch.stack((row, row + sx, row + sy, row + sx + sy), 1)  # (x0,y0), (x1,y0), (x0,y1), (x1,y1)
        c = self._table.index_select(0, rows.reshape(-1)).view(-1, 2, 2, 2, 2, 3).to(pos.dtype)  # [N, y, x, z, t, 3]
        # Linear in t, then z, x, y; each pass halves the corners (contiguous halves: fastest here).
        n = c.shape[0]
        c = c.view(n, 8, 2, 3)
        c = c[:, :, 0] + wt.view(n, 1, 1) * (c[:, :, 1] - c[:, :, 0])
        c = c.view(n, 4, 2, 3)
        c = c[:, :, 0] + wz.view(n, 1, 1) * (c[:, :, 1] - c[:, :, 0])
        c = c.view(n, 2, 2, 3)
        c = c[:, :, 0] + wx.view(n, 1, 1) * (c[:, :, 1] - c[:, :, 0])
        return c[:, 0] + wy.view(n, 1) * (c[:, 1] - c[:, 0])


def check_velocity_array(shape: Sequence[int], all_finite: bool) -> None:
    if len(shape) != 5 or shape[-1] != 3:
        raise GridFlowError(
            f"velocity array has shape {tuple(shape)}; expected [T, Nx, Ny, Nz, 3] "
            "(frames, grid points along x, y, z, and the components u, v, w)"
        )
    if shape[0] < 1 or min(shape[1:4]) < 2:
        raise GridFlowError(f"velocity array {tuple(shape)} needs >= 1 frame and >= 2 points per axis")
    if not all_finite:
        raise GridFlowError(
            "velocity array holds NaN or infinite values; regenerate the dataset "
            "(a diverged CFD run) or mask those values before saving"
        )


def save_grid_flow(
    path: str | os.PathLike,
    velocity: np.ndarray,
    origin: Sequence[float],
    spacing: Sequence[float],
    dt: float,
    periodic: Sequence[bool] = (False, False, False),
    bounds: Box | None = None,
    obstacles: Sequence[Cylinder] = (),
    provenance: dict | None = None,
    diagnostics: dict | None = None,
    units: dict | None = None,
    dtype=np.float32,
) -> Path:
    """Write a grid-flow dataset directory (atomically, file by file) and return its path.

    ``dtype=np.float16`` halves the file at about 3 significant digits (the shipped wake uses it)."""
    velocity = np.asarray(velocity)
    check_velocity_array(velocity.shape, bool(np.isfinite(velocity).all()))
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    stored = np.ascontiguousarray(velocity.astype(dtype))
    atomic_write(path / VELOCITY_FILE, lambda f: np.save(f, stored))
    n = velocity.shape[1:4]
    if bounds is None:
        bounds = Box(
            tuple(origin),
            tuple(o + (k - 1) * s for o, k, s in zip(origin, n, spacing, strict=True)),
        )
    meta = {
        "format": FORMAT,
        "shape": list(velocity.shape),
        "dtype": str(stored.dtype),
        "origin": [float(o) for o in origin],
        "spacing": [float(s) for s in spacing],
        "dt": float(dt),
        "periodic": [bool(p) for p in periodic],
        "bounds": {"lo": list(bounds.lo), "hi": list(bounds.hi)},
        "obstacles": [o.to_dict() for o in obstacles],
        "max_speed": float(np.linalg.norm(stored.astype(np.float32), axis=-1).max()),
        "units": units or DEFAULT_UNITS,
        "provenance": provenance or {},
        "diagnostics": diagnostics or {},
        "sha256": {VELOCITY_FILE: sha256(path / VELOCITY_FILE, None)},
    }
    text = json.dumps(meta, indent=2).encode()
    atomic_write(path / META_FILE, lambda f: f.write(text))
    return path


_REQUIRED = ("format", "shape", "origin", "spacing", "dt", "periodic", "bounds", "sha256")
_XYZ = schema.Key(schema.FLOATS, size=3, required=True)
META = {
    "format": schema.Str(),
    "shape": schema.Key(schema.INTS, ge=1),
    "dtype": schema.Str(),
    "origin": _XYZ,
    "spacing": schema.Key(schema.FLOATS, size=3, gt=0),
    "dt": schema.Float(gt=0),
    "periodic": schema.Key(schema.BOOLS, size=3),
    "bounds": {"lo": _XYZ, "hi": _XYZ},
    "obstacles": schema.Key(schema.DICTS),
    "max_speed": schema.Float(ge=0, null=True),
    "sha256": {VELOCITY_FILE: schema.Str(required=True)},
}


def check_obstacles_are_solid(flow: GridFlow, where) -> None:
    """The stored velocity at the grid nodes inside each declared obstacle is near zero (all frames)."""
    n = flow.shape[1:]
    x = [flow.origin[a] + flow.spacing[a] * torch.arange(n[a], dtype=torch.float64) for a in range(2)]
    X, Y = torch.meshgrid(x[0], x[1], indexing="ij")
    for ob in flow.obstacles:
        inside = ob.contains(torch.stack((X, Y), -1))
        if not inside.any():
            continue
        speed = float(flow._source[:, inside.to(flow.device)].float().norm(dim=-1).max())
        if speed > OBSTACLE_SPEED_TOL * max(flow.max_speed, 1e-12):
            raise GridFlowError(
                f"{where}: the flow moves at up to {speed:.3g} inside the declared obstacle {ob.to_dict()} "
                f"(max speed {flow.max_speed:.3g}); a shifted origin or wrong obstacles: fix origin/obstacles"
            )


def load_grid_flow(path: str | os.PathLike, device="cpu", dtype=torch.float32, verify: bool = True) -> GridFlow:
    """Load and validate a ``flownav-grid-v1`` dataset directory."""
    path = Path(path)
    regen = "regenerate it with `python -m flownav.cfd generate --out <dir>` or point flow.path at a valid dataset"
    if not path.is_dir():
        raise GridFlowError(f"no grid-flow dataset at {path}: {regen}")
    meta_path, vel_path = path / META_FILE, path / VELOCITY_FILE
    for p in (meta_path, vel_path):
        if not p.is_file():
            raise GridFlowError(f"dataset {path} lacks {p.name}: {regen}")
    try:
        meta = json.loads(meta_path.read_text())
    except json.JSONDecodeError as e:
        raise GridFlowError(f"{meta_path} is not valid JSON ({e}): {regen}") from e
    if not isinstance(meta, dict):
        raise GridFlowError(f"{meta_path} must hold a JSON object of keys {list(META)}: {regen}")
    missing = [k for k in _REQUIRED if k not in meta]
    if missing:
        raise GridFlowError(f"{meta_path} lacks the keys {missing}: {regen}")
    schema.check_group(meta, META, str(meta_path), error=GridFlowError, join=": ")
    if meta["format"] != FORMAT:
        raise GridFlowError(f"{meta_path} has format {meta['format']!r}, flownav reads {FORMAT!r}")
    if verify:
        digest = sha256(vel_path, None)
        if digest != meta["sha256"].get(VELOCITY_FILE):
            raise GridFlowError(
                f"{vel_path} does not match the sha256 in {meta_path} (corrupt or partial file, "
                f"or a git-lfs pointer): {regen}"
            )
    try:
        arr = np.load(vel_path, mmap_mode="r")
    except (ValueError, OSError) as e:
        raise GridFlowError(f"cannot read {vel_path} ({e}): {regen}") from e
    if list(arr.shape) != list(meta["shape"]):
        raise GridFlowError(f"{vel_path} has shape {list(arr.shape)} but meta.json says {meta['shape']}: {regen}")
    tensor = torch.from_numpy(np.array(arr))  # a writable in-memory copy of the memory map
    check_velocity_array(tensor.shape, bool(torch.isfinite(tensor).all()))
    b = meta["bounds"]
    try:
        bounds = Box(tuple(b["lo"]), tuple(b["hi"]))
        obstacles = [obstacle_from_dict(o) for o in meta.get("obstacles", [])]
    except (ValueError, KeyError, TypeError) as e:
        raise GridFlowError(f"{meta_path}: bounds or obstacles are malformed ({e}): {regen}") from e
    try:
        flow = GridFlow(
            tensor,
            origin=meta["origin"],
            spacing=meta["spacing"],
            dt=meta["dt"],
            periodic=meta["periodic"],
            bounds=bounds,
            obstacles=obstacles,
            max_speed=meta.get("max_speed"),
            meta=meta,
            dtype=dtype,
            device=device,
        )
    except GridFlowError as e:
        raise GridFlowError(f"{meta_path}: {e}") from e
    check_obstacles_are_solid(flow, meta_path)
    return flow


def loop_seam_jump(velocity: np.ndarray) -> float:
    """Relative jump at the time loop: |u[0] - u[T-1]| against the mean frame-to-frame change."""
    v = np.asarray(velocity, dtype=np.float32)
    seam = np.sqrt(np.mean((v[0] - v[-1]) ** 2))
    steps = np.sqrt(np.mean((v[1:] - v[:-1]) ** 2))
    return float(seam / steps) if steps > 0 else math.inf
