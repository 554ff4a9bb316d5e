"""Flows given as velocity snapshots on a regular grid (CFD output), and their on-disk format.

Interpolation is trilinear in space and linear in time; time loops with period
``T * dt`` (frame ``T`` is frame ``0`` again), so a CFD window whose end matches its start
gives a seamless, infinitely long flow. Spatial axes can be periodic (period ``N * spacing``,
the spanwise axis of the cylinder wake); on the other axes positions are clamped to the grid.
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

import hashlib
import json
import math
import os
import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from torch import Tensor

from flownav.flows.base import Box, Cylinder, FlowField, obstacle_from_dict

FORMAT = "flownav-grid-v1"
VELOCITY_FILE = "velocity.npy"
META_FILE = "meta.json"
DEFAULT_UNITS = {"length": "cylinder diameter D", "velocity": "inflow speed U", "time": "D / U"}


class GridFlowError(ValueError):
    """A grid-flow dataset or array is unusable; the message says how to fix it."""


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
    ):
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
        self.period = self.shape[0] * self.dt
        n = self.shape[1:]
        grid_hi = tuple(o + (k - 1) * s for o, k, s in zip(self.origin, n, self.spacing, strict=True))
        self.bounds = bounds if bounds is not None else Box(self.origin, grid_hi)
        self.obstacles = tuple(obstacles)
        self.meta = dict(meta or {})
        self._flat = velocity.to(device=device, dtype=dtype).reshape(-1, 3).contiguous()
        if max_speed is None:
            max_speed = float(self._flat.float().norm(dim=-1).max())
        self.max_speed = float(max_speed)

    @property
    def device(self) -> torch.device:
        return self._flat.device

    def to(self, device) -> GridFlow:
        self._flat = self._flat.to(device)
        return self

    def _axis(self, coord: Tensor, axis: int) -> tuple[Tensor, Tensor, Tensor]:
        """Lower index, upper index and weight of the upper one along one spatial axis."""
        n = self.shape[1 + axis]
        g = (coord - self.origin[axis]) / self.spacing[axis]
        if self.periodic[axis]:
            g = torch.remainder(g, n)
            i0 = g.floor().clamp_(0, n - 1)
            w = g - i0
            i0 = i0.long()
            return i0, torch.remainder(i0 + 1, n), w
        g = g.clamp(0, n - 1)
        i0 = g.floor().clamp_(max=n - 2)
        w = g - i0
        i0 = i0.long()
        return i0, i0 + 1, w

    def velocity(self, pos: Tensor, t: Tensor) -> Tensor:
        T, nx, ny, nz = self.shape
        f = torch.remainder(t.to(pos.dtype) / self.dt, T)
        f0 = f.floor().clamp_(0, T - 1)
        wt = f - f0
        f0 = f0.long()
        f1 = torch.remainder(f0 + 1, T)
        x0, x1, wx = self._axis(pos[:, 0], 0)
        y0, y1, wy = self._axis(pos[:, 1], 1)
        z0, z1, wz = self._axis(pos[:, 2], 2)
        # 16 corners (2 frames x 8 spatial): flat index and weight, gathered in one call.
        fi = torch.stack((f0, f1), -1)[:, :, None, None, None] * nx
        xi = torch.stack((x0, x1), -1)[:, None, :, None, None]
        yi = torch.stack((y0, y1), -1)[:, None, None, :, None]
        zi = torch.stack((z0, z1), -1)[:, None, None, None, :]
        idx = (((fi + xi) * ny + yi) * nz + zi).reshape(-1, 16)
        wf = torch.stack((1 - wt, wt), -1)[:, :, None, None, None]
        wxs = torch.stack((1 - wx, wx), -1)[:, None, :, None, None]
        wys = torch.stack((1 - wy, wy), -1)[:, None, None, :, None]
        wzs = torch.stack((1 - wz, wz), -1)[:, None, None, None, :]
        w = (wf * wxs * wys * wzs).reshape(-1, 16, 1)
        corners = self._flat[idx.reshape(-1)].reshape(-1, 16, 3).to(pos.dtype)
        return (corners * w).sum(1)


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


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 22), b""):
            h.update(chunk)
    return h.hexdigest()


def _atomic_write_bytes(path: Path, write) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name + ".", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


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
    dtype=np.float16,
) -> Path:
    """Write a grid-flow dataset directory (atomically, file by file) and return its path."""
    velocity = np.asarray(velocity)
    check_velocity_array(velocity.shape, bool(np.isfinite(velocity).all()))
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    stored = np.ascontiguousarray(velocity.astype(dtype))
    _atomic_write_bytes(path / VELOCITY_FILE, lambda f: np.save(f, stored))
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
        "sha256": {VELOCITY_FILE: _sha256(path / VELOCITY_FILE)},
    }
    text = json.dumps(meta, indent=2).encode()
    _atomic_write_bytes(path / META_FILE, lambda f: f.write(text))
    return path


_REQUIRED = ("format", "shape", "origin", "spacing", "dt", "periodic", "bounds", "sha256")


def load_grid_flow(path: str | os.PathLike, device="cpu", dtype=torch.float32, verify: bool = True) -> GridFlow:
    """Load and validate a ``flownav-grid-v1`` dataset directory."""
    path = Path(path)
    regen = "regenerate it with `python -m flownav.cfd generate` or point flow.path at a valid dataset"
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
    missing = [k for k in _REQUIRED if k not in meta]
    if missing:
        raise GridFlowError(f"{meta_path} lacks the keys {missing}: {regen}")
    if meta["format"] != FORMAT:
        raise GridFlowError(f"{meta_path} has format {meta['format']!r}, flownav reads {FORMAT!r}")
    if verify:
        digest = _sha256(vel_path)
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
    tensor = torch.from_numpy(np.ascontiguousarray(arr))
    check_velocity_array(tensor.shape, bool(torch.isfinite(tensor).all()))
    b = meta["bounds"]
    return GridFlow(
        tensor,
        origin=meta["origin"],
        spacing=meta["spacing"],
        dt=meta["dt"],
        periodic=meta["periodic"],
        bounds=Box(tuple(b["lo"]), tuple(b["hi"])),
        obstacles=[obstacle_from_dict(o) for o in meta.get("obstacles", [])],
        max_speed=meta.get("max_speed"),
        meta=meta,
        dtype=dtype,
        device=device,
    )


def loop_seam_jump(velocity: np.ndarray) -> float:
    """Relative jump at the time loop: |u[0] - u[T-1]| against the mean frame-to-frame change."""
    v = np.asarray(velocity, dtype=np.float32)
    seam = np.sqrt(np.mean((v[0] - v[-1]) ** 2))
    steps = np.sqrt(np.mean((v[1:] - v[:-1]) ** 2))
    return float(seam / steps) if steps > 0 else math.inf
