"""Gridded currents from NetCDF, HDF5 and zarr (ocean models, CFD output) as a :class:`GridFlow`.

:func:`load_xarray_flow` reads anything xarray opens (a path or an ``xarray.Dataset``) and needs the
``[data]`` extra (``pip install -e ".[data]"``).

Coordinates (CF names, one of each row; a strictly decreasing axis is flipped):

* ``x``, ``y``, ``z`` in ``m``, ``km`` or ``cm``; or ``lon``/``longitude`` (``degrees_east``),
  ``lat``/``latitude`` (``degrees_north``) and ``depth`` (``m``, positive down, so ``z = -depth``);
* ``time`` or ``t``: CF dates, or numbers in ``s``, ``min``, ``h`` or ``days`` (optional: no time
  axis is a steady flow).

Longitude and latitude are projected to metres by the equirectangular projection about the domain's
centre ``(lon0, lat0)``: ``x = R cos(lat0) (lon - lon0)``, ``y = R (lat - lat0)`` (angles in
radians, ``R = 6371 km``), so the domain's centre is ``x = y = 0``. Its distortion grows with the
latitude span (x is 1.8% too long 1 degree north of ``lat0 = 45``); project larger domains
yourself and pass ``x``/``y``.

Variables: ``u``, ``v``, ``w`` are found by the ``variables`` mapping (component -> name), by default
the first present of ``u, v, w`` / ``uo, vo, wo`` (CMEMS, CMIP) or the CF standard names
``eastward_/northward_/upward_sea_water_velocity``. A missing ``w`` becomes zero, with a note.
Velocities in ``m s-1`` or ``cm s-1``.

Everything comes out in metres, seconds and m/s; data with ``units = "1"`` on every coordinate and
variable (a nondimensional CFD run, lengths in D) is kept as it is. Each unusable coordinate or variable
raises a one-line :class:`~flownav.flows.grid.GridFlowError` naming it.

``time_mode`` (:class:`GridFlow`) decides what happens past the last frame: ``"looped"`` (periodic;
the seam is reported), ``"clamped"`` or ``"error"``. What was read, converted and noted is in
``flow.meta`` (and logged).
"""

from __future__ import annotations

import logging
import math
import os
from collections.abc import Mapping, Sequence

import numpy as np
import torch

from flownav.flows.base import Box, Cylinder
from flownav.flows.grid import GridFlow, GridFlowError, loop_seam_jump

log = logging.getLogger(__name__)

EARTH_RADIUS = 6_371_000.0  # metres (mean radius)
LENGTH_UNITS = {"m": 1.0, "meter": 1.0, "meters": 1.0, "metre": 1.0, "metres": 1.0, "km": 1000.0, "cm": 0.01}
VELOCITY_UNITS = {"m s-1": 1.0, "m/s": 1.0, "m s^-1": 1.0, "m.s-1": 1.0, "cm s-1": 0.01, "cm/s": 0.01}
TIME_UNITS = {"s": 1.0, "sec": 1.0, "second": 1.0, "seconds": 1.0, "min": 60.0, "minutes": 60.0}
TIME_UNITS |= {"h": 3600.0, "hour": 3600.0, "hours": 3600.0, "day": 86400.0, "days": 86400.0}
DEGREE_UNITS = {
    "lon": ("degrees_east", "degree_east", "degrees_e", "degree_e"),
    "lat": ("degrees_north", "degree_north", "degrees_n", "degree_n"),
}
DIMENSIONLESS = "1"

COORD_NAMES = {
    "x": ("x", "lon", "longitude"),
    "y": ("y", "lat", "latitude"),
    "z": ("z", "depth"),
    "t": ("time", "t"),
}
DEFAULT_VARIABLES = {"u": ("u", "uo"), "v": ("v", "vo"), "w": ("w", "wo")}
STANDARD_NAMES = {
    "u": "eastward_sea_water_velocity",
    "v": "northward_sea_water_velocity",
    "w": "upward_sea_water_velocity",
}
REGULAR_RTOL = 1e-3  # allowed deviation of a grid step from the mean step, relative to it


def load_xarray_flow(
    source,
    variables: Mapping[str, str] | None = None,
    time_mode: str = "looped",
    engine: str | None = None,
    periodic: Sequence[bool] = (False, False, False),
    bounds: Box | None = None,
    obstacles: Sequence[Cylinder] = (),
    dtype: torch.dtype = torch.float32,
    device="cpu",
) -> GridFlow:
    """Read a current from a NetCDF / HDF5 file, a zarr store or an ``xarray.Dataset`` (module docstring).

    Args:
        source: a path (``*.zarr`` or a directory: zarr; otherwise ``xarray.open_dataset``) or a Dataset.
        variables: component -> variable name, e.g. ``{"u": "uo", "v": "vo"}`` (others by default).
        time_mode: ``"looped"``, ``"clamped"`` or ``"error"`` past the data's last frame.
        engine: xarray engine (``"netcdf4"``, ``"h5netcdf"``, ``"scipy"``, ``"zarr"``); default: xarray's pick.
        periodic, bounds, obstacles: as :class:`GridFlow` (bounds default to the grid's box, in metres).
        dtype: storage of the velocity table (float32; ``torch.float16`` halves memory at 3 digits).
    """
    import xarray as xr  # the [data] extra

    ds = source if isinstance(source, xr.Dataset) else _open(xr, source, engine)
    names = {axis: _find_coord(ds, axis) for axis in COORD_NAMES}
    dims = [names[a] for a in ("t", "x", "y", "z") if names[a] is not None]
    missing = [a for a in ("x", "y", "z") if names[a] is None]
    if missing:
        raise GridFlowError(
            f"no coordinate for {missing} in {sorted(ds.coords)}: name them "
            f"{' / '.join('/'.join(COORD_NAMES[a]) for a in missing)} (ds.rename(...))"
        )
    meta: dict = {"source": str(source) if not isinstance(source, xr.Dataset) else "xarray.Dataset", "notes": []}
    dimensionless = _all_dimensionless(ds, names, variables)
    origin, spacing = [], []
    for axis in ("x", "y", "z"):
        o, s = _regular(ds[names[axis]].values, names[axis])
        origin.append(o)
        spacing.append(s)
    if not dimensionless:
        _to_metres(ds, names, origin, spacing, meta)
    if names["z"] == "depth":
        origin[2], spacing[2] = -origin[2], -spacing[2]
        meta["notes"].append("z = -depth (up is +z; w is taken as upward)")
    flip = [s < 0 for s in spacing]  # store every axis increasing
    spacing_abs = [abs(s) for s in spacing]
    origin = [o if s > 0 else o + s * (ds.sizes[names[a]] - 1) for o, s, a in zip(origin, spacing, "xyz", strict=True)]

    velocity = _velocity(ds, names, dims, variables, dimensionless, meta)
    for axis, f in enumerate(flip):
        if f:
            velocity = np.flip(velocity, axis + 1)

    dt = 1.0
    if names["t"] is not None:
        dt = _time_step(ds[names["t"]], names["t"], dimensionless)
    if velocity.shape[0] > 1 and time_mode == "looped":
        meta["seam_jump"] = loop_seam_jump(velocity)
        meta["notes"].append(
            f"looped in time: the seam (last frame -> first) is {meta['seam_jump']:.2f} times the mean "
            "frame-to-frame change (1: as smooth as any other step)"
        )
    meta |= {"time_mode": time_mode, "units": "dimensionless" if dimensionless else "m, s, m/s"}
    for note in meta["notes"]:
        log.info("%s: %s", meta["source"], note)
    return GridFlow(
        torch.from_numpy(np.ascontiguousarray(velocity, dtype=np.float32)),
        origin=origin,
        spacing=spacing_abs,
        dt=dt,
        periodic=periodic,
        bounds=bounds,
        obstacles=obstacles,
        meta=meta,
        dtype=dtype,
        device=device,
        time_mode=time_mode,
    )


def _velocity(ds, names: dict, dims: list, variables, dimensionless: bool, meta: dict) -> np.ndarray:
    """[T, Nx, Ny, Nz, 3] in m/s (or as stored when dimensionless), each variable checked."""
    comps, frames = [], None
    for comp in ("u", "v", "w"):
        name = _find_variable(ds, comp, variables)
        if name is None:
            if comp == "w":
                meta["notes"].append("no vertical velocity (w / wo) found: w = 0")
                comps.append(None)
                continue
            raise GridFlowError(
                f"no variable for {comp} in {sorted(ds.data_vars)}: pass variables={{'{comp}': '<name>'}} "
                f"(defaults: {' / '.join(DEFAULT_VARIABLES[comp])})"
            )
        da = ds[name]
        if set(da.dims) != set(dims):
            raise GridFlowError(
                f"variable {name!r} has dimensions {da.dims}; it needs exactly {tuple(dims)} "
                "(select or average the others away first, e.g. ds.isel(...))"
            )
        arr = da.transpose(*dims).values.astype(np.float64)
        if names["t"] is None:
            arr = arr[None]
        bad = int((~np.isfinite(arr)).sum())
        if bad:
            raise GridFlowError(
                f"variable {name!r} holds {bad} NaN or infinite values (land or missing data): "
                "fill them first, e.g. ds.fillna(0.0)"
            )
        scale = 1.0 if dimensionless else _scale(_units(da), VELOCITY_UNITS, f"variable {name!r}", "m s-1")
        comps.append(arr * scale)
        frames = arr.shape
        meta.setdefault("variables", {})[comp] = name
    return np.stack([np.zeros(frames) if c is None else c for c in comps], -1)


def _open(xr, source, engine):
    path = os.fspath(source)
    if not os.path.exists(path):
        raise GridFlowError(f"no flow data at {path}: give a NetCDF / HDF5 file or a zarr store")
    if engine == "zarr" or (engine is None and (path.endswith(".zarr") or os.path.isdir(path))):
        return xr.open_zarr(path)
    return xr.open_dataset(path, engine=engine)


def _find_coord(ds, axis: str) -> str | None:
    return next((n for n in COORD_NAMES[axis] if n in ds.coords or n in ds.dims), None)


def _find_variable(ds, comp: str, variables: Mapping[str, str] | None) -> str | None:
    if variables and comp in variables:
        if variables[comp] not in ds.data_vars:
            raise GridFlowError(f"variables[{comp!r}] = {variables[comp]!r} is not in {sorted(ds.data_vars)}")
        return variables[comp]
    found = next((n for n in DEFAULT_VARIABLES[comp] if n in ds.data_vars), None)
    return found or next((n for n in ds.data_vars if ds[n].attrs.get("standard_name") == STANDARD_NAMES[comp]), None)


def _units(da) -> str | None:
    units = da.attrs.get("units", da.encoding.get("units"))
    return None if units is None else str(units).strip()


def _all_dimensionless(ds, names, variables) -> bool:
    """True when every space coordinate and velocity variable says units = "1"."""
    things = [ds[names[a]] for a in "xyz"]
    things += [ds[n] for c in "uvw" if (n := _find_variable(ds, c, variables)) is not None]
    return all(_units(d) == DIMENSIONLESS for d in things)


def _scale(units, table: Mapping[str, float], what: str, example: str) -> float:
    key = None if units is None else " ".join(str(units).split()).lower()
    if key not in table:
        raise GridFlowError(
            f"{what} has units {units!r}; flownav reads {sorted(set(table))} (or '1' everywhere): "
            f"set its 'units' attribute, e.g. '{example}'"
        )
    return table[key]


def _regular(values: np.ndarray, name: str) -> tuple[float, float]:
    """(first value, step) of an evenly spaced coordinate; a clear error naming it otherwise."""
    c = np.asarray(values, dtype=np.float64)
    if c.ndim != 1 or c.size < 2:
        raise GridFlowError(f"coordinate {name!r} needs >= 2 values along one dimension, got shape {c.shape}")
    steps = np.diff(c)
    step = (c[-1] - c[0]) / (c.size - 1)
    uneven = np.abs(steps - step) > REGULAR_RTOL * abs(step)
    if step == 0 or np.sign(steps).min() != np.sign(steps).max() or uneven.any():
        i = int(np.argmax(uneven)) if uneven.any() else 0
        raise GridFlowError(
            f"coordinate {name!r} is not evenly spaced (steps {steps.min():g} to {steps.max():g}, "
            f"first off at index {i}): interpolate onto a regular grid first, e.g. ds.interp({name}=np.linspace(...))"
        )
    return float(c[0]), float(step)


def _to_metres(ds, names, origin: list, spacing: list, meta: dict) -> None:
    """Convert the x, y, z origin and spacing to metres in place (projecting lon/lat)."""
    x, y, z = names["x"], names["y"], names["z"]
    geo = x in COORD_NAMES["x"][1:], y in COORD_NAMES["y"][1:]
    if geo[0] != geo[1]:
        raise GridFlowError(f"coordinates {x!r} and {y!r} mix metres and degrees: use x/y or lon/lat")
    if geo[0]:
        for axis, name in ((0, x), (1, y)):
            units = (_units(ds[name]) or "").lower()
            if units not in DEGREE_UNITS[("lon", "lat")[axis]]:
                raise GridFlowError(
                    f"coordinate {name!r} has units {_units(ds[name])!r}; set it to "
                    f"'{DEGREE_UNITS[('lon', 'lat')[axis]][0]}'"
                )
        n = (ds.sizes[x], ds.sizes[y])
        lon0 = origin[0] + spacing[0] * (n[0] - 1) / 2
        lat0 = origin[1] + spacing[1] * (n[1] - 1) / 2
        rad = math.pi / 180
        kx, ky = EARTH_RADIUS * math.cos(lat0 * rad) * rad, EARTH_RADIUS * rad
        origin[0], spacing[0] = (origin[0] - lon0) * kx, spacing[0] * kx
        origin[1], spacing[1] = (origin[1] - lat0) * ky, spacing[1] * ky
        meta["projection"] = {
            "type": "equirectangular",
            "lon0": lon0,
            "lat0": lat0,
            "earth_radius_m": EARTH_RADIUS,
            "x": "R cos(lat0) (lon - lon0)",
            "y": "R (lat - lat0)",
        }
    else:
        for axis, name in ((0, x), (1, y)):
            k = _scale(_units(ds[name]), LENGTH_UNITS, f"coordinate {name!r}", "m")
            origin[axis], spacing[axis] = origin[axis] * k, spacing[axis] * k
    k = _scale(_units(ds[z]), LENGTH_UNITS, f"coordinate {z!r}", "m")
    origin[2], spacing[2] = origin[2] * k, spacing[2] * k


def _time_step(da, name: str, dimensionless: bool) -> float:
    """Seconds between frames (or the data's own unit when dimensionless), checked to be regular."""
    values = da.values
    if np.issubdtype(values.dtype, np.datetime64) or np.issubdtype(values.dtype, np.timedelta64):
        seconds = (values - values[0]) / np.timedelta64(1, "s")
    else:
        units = _units(da)
        k = (
            1.0
            if dimensionless and units in (None, DIMENSIONLESS)
            else _scale(units, TIME_UNITS, f"coordinate {name!r}", "s")
        )
        seconds = np.asarray(values, dtype=np.float64) * k
    if seconds.size == 1:
        return 1.0
    _, dt = _regular(seconds, name)
    if dt <= 0:
        raise GridFlowError(f"coordinate {name!r} must increase")
    return dt
