"""Currents from NetCDF through xarray: exact interpolation, projection, units, grid checks, time modes."""

import math
import re

import numpy as np
import pytest
import torch

xr = pytest.importorskip("xarray")

from flownav.flows import load_grid_flow, save_grid_flow  # noqa: E402
from flownav.flows.grid import GridFlowError  # noqa: E402
from flownav.flows.xarray_data import EARTH_RADIUS, load_xarray_flow  # noqa: E402

X = np.linspace(-2.0, 6.0, 5)  # m
Y = np.linspace(-1.0, 2.0, 4)
Z = np.linspace(0.0, 3.0, 3)
T = np.arange(4) * 0.5  # s
# Each component is linear in x, y, z and t, so trilinear-in-space, linear-in-time interpolation is exact.
COEF = np.array([[0.3, 0.1, -0.2, 0.05, 0.4], [-0.1, 0.02, 0.3, -0.1, -0.2], [0.05, -0.03, 0.01, 0.2, 0.1]])


def linear(x, y, z, t):
    return [c[0] + c[1] * x + c[2] * y + c[3] * z + c[4] * t for c in COEF]


def dataset(length="m", speed="m s-1", time="s", k_len=1.0, k_speed=1.0, k_time=1.0, names="uvw") -> "xr.Dataset":
    """The linear field on the grid, its coordinates written in units that are ``k_*`` times the SI ones."""
    t, x, y, z = np.meshgrid(T, X, Y, Z, indexing="ij")
    data = {
        n: (("time", "x", "y", "z"), (c * k_speed).astype(np.float32), {"units": speed})
        for n, c in zip(names, linear(x, y, z, t), strict=False)
    }
    coords = {
        "time": ("time", T * k_time, {"units": time}),
        "x": ("x", X * k_len, {"units": length}),
        "y": ("y", Y * k_len, {"units": length}),
        "z": ("z", Z * k_len, {"units": length}),
    }
    return xr.Dataset(data, coords=coords)


def points(n=64, t_hi=T[-1], seed=0):
    g = torch.Generator().manual_seed(seed)
    lo, hi = torch.tensor([X[0], Y[0], Z[0]]), torch.tensor([X[-1], Y[-1], Z[-1]])
    pos = (lo + torch.rand(n, 3, generator=g, dtype=torch.float64) * (hi - lo)).float()
    t = (torch.rand(n, generator=g, dtype=torch.float64) * t_hi).float()
    return pos, t


def expected(pos, t):
    p, tt = pos.double().numpy(), t.double().numpy()
    return torch.tensor(np.stack(linear(p[:, 0], p[:, 1], p[:, 2], tt), -1))


@pytest.mark.parametrize("engine", ["netcdf4", "h5netcdf", "scipy", "zarr"])
def test_file_interpolates_a_linear_field_exactly(tmp_path, engine):
    """NetCDF4 (HDF5 underneath, read by netCDF4 or h5netcdf), NetCDF3 (scipy) and a zarr store."""
    pytest.importorskip({"netcdf4": "netCDF4", "h5netcdf": "h5netcdf", "scipy": "scipy", "zarr": "zarr"}[engine])
    if engine == "zarr":
        path = tmp_path / "current.zarr"
        dataset().to_zarr(path)
    else:
        path = tmp_path / "current.nc"
        dataset().to_netcdf(path, engine=engine)
    flow = load_xarray_flow(path, time_mode="clamped", engine=engine)
    assert flow.shape == (len(T), len(X), len(Y), len(Z))
    assert flow.origin == pytest.approx((X[0], Y[0], Z[0])) and flow.dt == pytest.approx(0.5)
    pos, t = points()
    torch.testing.assert_close(flow.velocity(pos, t).double(), expected(pos, t), rtol=0, atol=2e-6)
    assert flow.meta["variables"] == {"u": "u", "v": "v", "w": "w"}


def test_km_cm_per_s_and_hours_convert_to_si():
    si = load_xarray_flow(dataset(), time_mode="clamped")
    other = load_xarray_flow(
        dataset("km", "cm s-1", "hours", k_len=1e-3, k_speed=100.0, k_time=1 / 3600), time_mode="clamped"
    )
    assert other.spacing == pytest.approx(si.spacing) and other.origin == pytest.approx(si.origin)
    assert other.dt == pytest.approx(si.dt)
    pos, t = points()
    torch.testing.assert_close(other.velocity(pos, t), si.velocity(pos, t), rtol=1e-6, atol=1e-6)


def test_ocean_names_lon_lat_depth_are_projected_about_the_centre():
    lon = np.array([10.0, 10.5, 11.0])
    lat = np.array([46.0, 45.5, 45.0, 44.5, 44.0])  # north to south, as many models store it
    depth = np.array([0.0, 10.0, 20.0])
    uo = np.zeros((1, 3, 5, 3), np.float32)
    uo[0, :, :, :] = depth[None, None, :] / 100 + lat[None, :, None] / 1000  # varies with depth and latitude
    ds = xr.Dataset(
        {
            "uo": (("time", "depth", "lat", "lon"), uo.transpose(0, 3, 2, 1), {"units": "m s-1"}),
            "vo": (("time", "depth", "lat", "lon"), np.zeros((1, 3, 5, 3), np.float32), {"units": "m s-1"}),
        },
        coords={
            "time": ("time", np.array(["2024-01-01"], dtype="datetime64[ns]")),
            "lon": ("lon", lon, {"units": "degrees_east"}),
            "lat": ("lat", lat, {"units": "degrees_north"}),
            "depth": ("depth", depth, {"units": "m", "positive": "down"}),
        },
    )
    flow = load_xarray_flow(ds)
    rad = math.pi / 180
    assert flow.spacing[0] == pytest.approx(EARTH_RADIUS * math.cos(45 * rad) * 0.5 * rad)
    assert flow.spacing[1] == pytest.approx(EARTH_RADIUS * 0.5 * rad)
    assert flow.origin[:2] == pytest.approx((-EARTH_RADIUS * math.cos(45 * rad) * 0.5 * rad, -EARTH_RADIUS * rad))
    assert flow.origin[2] == pytest.approx(-20.0) and flow.spacing[2] == pytest.approx(10.0)
    assert flow.meta["projection"]["lat0"] == pytest.approx(45.0)
    assert flow.meta["projection"]["lon0"] == pytest.approx(10.5)
    assert any("w = 0" in n for n in flow.meta["notes"]) and any("depth" in n for n in flow.meta["notes"])
    # The grid point at depth 10 m, 46 N is at z = -10, y = +1 degree north of the centre.
    pos = torch.tensor([[0.0, EARTH_RADIUS * rad, -10.0]])
    v = flow.velocity(pos, torch.zeros(1))
    assert v[0, 0].item() == pytest.approx(10 / 100 + 46 / 1000, abs=1e-6)
    assert v[0, 2].item() == 0.0


def test_a_non_regular_coordinate_is_named():
    ds = dataset().assign_coords(y=("y", np.array([-1.0, 0.0, 1.5, 2.0]), {"units": "m"}))
    with pytest.raises(GridFlowError, match=r"^coordinate 'y' is not evenly spaced .*first off at index 1"):
        load_xarray_flow(ds)


def test_unknown_units_and_missing_variables_are_named():
    with pytest.raises(GridFlowError, match=r"^variable 'u' has units 'knots'"):
        load_xarray_flow(dataset(speed="knots"))
    with pytest.raises(GridFlowError, match=r"^coordinate 'x' has units 'ft'"):
        load_xarray_flow(dataset(length="ft"))
    missing = "no variable for u in ['east', 'north']: pass variables={'u': '<name>'}"
    with pytest.raises(GridFlowError, match=re.escape(missing)):
        load_xarray_flow(dataset(names=["east", "north"]))
    flow = load_xarray_flow(dataset(names=["east", "north"]), variables={"u": "east", "v": "north"})
    assert flow.meta["variables"] == {"u": "east", "v": "north"}
    assert "no vertical velocity (w / wo) found: w = 0" in flow.meta["notes"]


def test_missing_values_are_counted_and_named():
    ds = dataset()
    ds["v"][0, 1, 1, 1] = np.nan
    ds["v"][2, 0, 0, 0] = np.nan
    with pytest.raises(GridFlowError, match=r"^variable 'v' holds 2 NaN or infinite values \(land or missing data\)"):
        load_xarray_flow(ds)


def test_time_modes_past_the_last_frame():
    ds = dataset()
    end = float(T[-1])
    pos, t = points(16)
    looped = load_xarray_flow(ds, time_mode="looped")
    assert looped.period == pytest.approx(len(T) * 0.5)
    torch.testing.assert_close(looped.velocity(pos, t + looped.period), looped.velocity(pos, t), rtol=0, atol=1e-5)
    assert looped.meta["seam_jump"] == pytest.approx(3.0, rel=1e-4)  # linear in t: the seam steps back 3 frames
    assert any("seam" in n for n in looped.meta["notes"])
    clamped = load_xarray_flow(ds, time_mode="clamped")
    assert clamped.period is None
    late = torch.full_like(t, end + 7.0)
    torch.testing.assert_close(clamped.velocity(pos, late), clamped.velocity(pos, torch.full_like(t, end)))
    strict = load_xarray_flow(ds, time_mode="error")
    torch.testing.assert_close(strict.velocity(pos, t), clamped.velocity(pos, t))
    with pytest.raises(GridFlowError, match=r"^flow time .* is outside the data's \[0, 1.5\]"):
        strict.velocity(pos, late)
    with pytest.raises(GridFlowError, match="time_mode is 'periodic'; choose one of"):
        load_xarray_flow(ds, time_mode="periodic")


def test_user_data_stays_float32(tmp_path):
    third = np.full((1, 2, 2, 2, 3), 1 / 3, np.float32)
    ds = xr.Dataset(
        {c: (("x", "y", "z"), third[0, ..., i], {"units": "m s-1"}) for i, c in enumerate("uvw")},
        coords={a: (a, [0.0, 1.0], {"units": "m"}) for a in "xyz"},
    )
    flow = load_xarray_flow(ds)
    assert flow.velocity(torch.full((1, 3), 0.5), torch.zeros(1))[0, 0].item() == np.float32(1 / 3)
    path = save_grid_flow(tmp_path / "g", third, (0, 0, 0), (1, 1, 1), 1.0)
    assert load_grid_flow(path).velocity(torch.full((1, 3), 0.5), torch.zeros(1))[0, 0].item() == np.float32(1 / 3)
