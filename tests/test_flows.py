"""Flow fields: exact interpolation, time looping, the on-disk format and its errors, ABC, transforms."""

import json
import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from flownav.flows import (
    ABCFlow,
    Box,
    FunctionFlow,
    GridFlow,
    GridFlowError,
    RotatedFlow,
    ScaledFlow,
    UniformFlow,
    gridkernel,
    load_grid_flow,
    rotate_z,
    save_grid_flow,
)
from flownav.flows.base import Cylinder
from flownav.flows.grid import loop_seam_jump

ORIGIN, SPACING, DT = (1.0, -1.0, 0.5), (0.2, 0.3, 0.1), 0.5
COEF = [[2.0, 3.0, -1.0, 1.0], [1.0, -1.0, 0.5, 0.0], [0.0, 0.0, 1.0, -2.0]]


def linear_field(x, y, z, t):
    """u = A [x, y, z, t]: every component linear in space and time."""
    return [COEF[i][0] * x + COEF[i][1] * y + COEF[i][2] * z + COEF[i][3] * t for i in range(3)]


def linear_grid(T=4, n=(5, 6, 7)) -> np.ndarray:
    t = np.arange(T)[:, None, None, None] * DT
    x = ORIGIN[0] + np.arange(n[0])[None, :, None, None] * SPACING[0]
    y = ORIGIN[1] + np.arange(n[1])[None, None, :, None] * SPACING[1]
    z = ORIGIN[2] + np.arange(n[2])[None, None, None, :] * SPACING[2]
    return np.stack(
        np.broadcast_arrays(*[c.numpy() if torch.is_tensor(c) else c for c in linear_field(x, y, z, t)]), -1
    )


def test_grid_flow_is_exact_on_linear_fields():
    flow = GridFlow(torch.from_numpy(linear_grid()), ORIGIN, SPACING, DT, dtype=torch.float64)
    g = torch.Generator().manual_seed(0)
    lo, size = torch.tensor(ORIGIN, dtype=torch.float64), torch.tensor([0.8, 1.5, 0.6], dtype=torch.float64)
    pos = lo + torch.rand(2000, 3, generator=g, dtype=torch.float64) * size
    pos[:10] = lo + size  # the upper corner of the grid, where the last cell is used
    pos[10:20] = lo
    t = torch.rand(2000, generator=g, dtype=torch.float64) * 1.5  # within [0, (T-1) dt]: no loop
    expected = torch.stack(linear_field(pos[:, 0], pos[:, 1], pos[:, 2], t), -1)
    assert torch.allclose(flow.velocity(pos, t), expected, atol=1e-12)


def test_grid_flow_float32_storage_is_close_on_linear_fields():
    flow = GridFlow(torch.from_numpy(linear_grid()), ORIGIN, SPACING, DT)
    pos = torch.tensor([[1.33, -0.21, 0.87]])
    t = torch.tensor([0.8])
    expected = torch.stack(linear_field(pos[:, 0], pos[:, 1], pos[:, 2], t), -1)
    assert torch.allclose(flow.velocity(pos, t), expected, atol=1e-5)


def test_time_loop_is_continuous_and_periodic():
    field = linear_grid()
    flow = GridFlow(torch.from_numpy(field), ORIGIN, SPACING, DT, dtype=torch.float64)
    period = 4 * DT
    pos = torch.tensor([[1.3, -0.5, 0.75]] * 3, dtype=torch.float64)
    eps = 1e-9
    just_before, at, after = flow.velocity(pos, torch.tensor([period - eps, period, period + eps], dtype=torch.float64))
    at_zero = flow.velocity(pos[:1], torch.tensor([0.0], dtype=torch.float64))[0]
    assert torch.allclose(at, at_zero) and torch.allclose(just_before, at_zero, atol=1e-7)
    assert torch.allclose(after, at_zero, atol=1e-7)
    # In the last interval the flow blends frame T-1 into frame 0, linearly.
    mid = flow.velocity(pos[:1], torch.tensor([3.5 * DT], dtype=torch.float64))[0]
    f_last = flow.velocity(pos[:1], torch.tensor([3 * DT], dtype=torch.float64))[0]
    assert torch.allclose(mid, (f_last + at_zero) / 2, atol=1e-12)
    # Negative times loop the same way.
    assert torch.allclose(
        flow.velocity(pos[:1], torch.tensor([-period + 0.3], dtype=torch.float64)),
        flow.velocity(pos[:1], torch.tensor([0.3], dtype=torch.float64)),
    )


def test_periodic_axis_wraps():
    field = np.random.default_rng(0).normal(size=(2, 4, 4, 5, 3))
    flow = GridFlow(
        torch.from_numpy(field), (0, 0, 0), (1, 1, 1), 1.0, periodic=(False, False, True), dtype=torch.float64
    )
    pos = torch.tensor([[1.5, 2.25, 0.4], [1.5, 2.25, 5.4], [1.5, 2.25, -4.6]], dtype=torch.float64)
    v = flow.velocity(pos, torch.zeros(3, dtype=torch.float64))
    assert torch.allclose(v[0], v[1]) and torch.allclose(v[0], v[2])
    # Between the last point (k = 4) and the first (k = 5 = 0): linear blend across the seam.
    seam = flow.velocity(torch.tensor([[1.0, 2.0, 4.5]], dtype=torch.float64), torch.zeros(1, dtype=torch.float64))
    assert torch.allclose(seam[0], torch.from_numpy((field[0, 1, 2, 4] + field[0, 1, 2, 0]) / 2))


def test_save_and_load_round_trip(tmp_path):
    field = linear_grid().astype(np.float32)
    save_grid_flow(
        tmp_path / "ds",
        field,
        ORIGIN,
        SPACING,
        DT,
        obstacles=[Cylinder((1.2, 0.0), 0.1)],
        provenance={"command": "test"},
        dtype=np.float32,
    )
    flow = load_grid_flow(tmp_path / "ds")
    assert flow.shape == field.shape[:4] and flow.meta["provenance"]["command"] == "test"
    assert flow.obstacles == (Cylinder((1.2, 0.0), 0.1),)
    pos = torch.tensor([[1.33, -0.21, 0.87]])
    expected = torch.stack(linear_field(pos[:, 0], pos[:, 1], pos[:, 2], torch.tensor([0.8])), -1)
    assert torch.allclose(flow.velocity(pos, torch.tensor([0.8])), expected.float(), atol=1e-5)


@pytest.mark.parametrize(
    "shape, message",
    [
        ((4, 5, 6, 7), "expected \\[T, Nx, Ny, Nz, 3\\]"),
        ((4, 5, 6, 7, 2), "expected"),
        ((1, 1, 6, 7, 3), ">= 2 points"),
    ],
)
def test_wrong_shapes_are_refused(shape, message):
    with pytest.raises(GridFlowError, match=message):
        GridFlow(torch.zeros(shape), ORIGIN, SPACING, DT)


def test_non_finite_values_are_refused(tmp_path):
    field = linear_grid().astype(np.float32)
    field[1, 2, 3, 4, 0] = np.nan
    with pytest.raises(GridFlowError, match="NaN or infinite"):
        GridFlow(torch.from_numpy(field), ORIGIN, SPACING, DT)
    with pytest.raises(GridFlowError, match="NaN or infinite"):
        save_grid_flow(tmp_path / "ds", field, ORIGIN, SPACING, DT)


def test_missing_and_corrupt_datasets_name_the_fix(tmp_path):
    with pytest.raises(GridFlowError, match="no grid-flow dataset.*python -m flownav.cfd generate"):
        load_grid_flow(tmp_path / "nowhere")
    path = save_grid_flow(tmp_path / "ds", linear_grid(), ORIGIN, SPACING, DT)
    raw = bytearray((path / "velocity.npy").read_bytes())
    raw[-5] ^= 0xFF
    (path / "velocity.npy").write_bytes(bytes(raw))
    with pytest.raises(GridFlowError, match="does not match the sha256"):
        load_grid_flow(path)
    (path / "velocity.npy").unlink()
    with pytest.raises(GridFlowError, match="lacks velocity.npy"):
        load_grid_flow(path)
    path = save_grid_flow(tmp_path / "ds2", linear_grid(), ORIGIN, SPACING, DT)
    (path / "meta.json").write_text("{not json")
    with pytest.raises(GridFlowError, match="not valid JSON"):
        load_grid_flow(path)
    path = save_grid_flow(tmp_path / "ds3", linear_grid(), ORIGIN, SPACING, DT)
    meta = json.loads((path / "meta.json").read_text())
    meta["shape"][0] += 1
    (path / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(GridFlowError, match="meta.json says"):
        load_grid_flow(path)
    del meta["dt"]
    (path / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(GridFlowError, match="lacks the keys \\['dt'\\]"):
        load_grid_flow(path)


def test_loop_seam_jump_is_small_for_a_periodic_window():
    t = np.arange(20) / 20 * 2 * np.pi
    smooth = np.sin(t)[:, None, None, None, None] * np.ones((20, 2, 2, 2, 3))
    assert loop_seam_jump(smooth) < 1.5  # as large as the largest step of a sine
    assert loop_seam_jump(smooth[:15]) > 2  # a window of 3/4 period jumps at the seam


def divergence(flow, pos, t, h=1e-3):
    div = torch.zeros(pos.shape[0], dtype=pos.dtype)
    for k in range(3):
        e = torch.zeros(3, dtype=pos.dtype)
        e[k] = h
        div += (flow.velocity(pos + e, t)[:, k] - flow.velocity(pos - e, t)[:, k]) / (2 * h)
    return div


def test_abc_flow_is_divergence_free_and_bounded():
    flow = ABCFlow()
    g = torch.Generator().manual_seed(1)
    pos = (torch.rand(5000, 3, generator=g, dtype=torch.float64) * 2 - 1) * math.pi * 2
    t = torch.rand(5000, generator=g, dtype=torch.float64) * 10
    assert divergence(flow, pos, t).abs().max() < 1e-9
    assert 1.15 < flow.max_speed < 1.2
    assert flow.velocity(pos, t).norm(dim=-1).max() <= flow.max_speed + 1e-3
    assert ABCFlow(eps=0).max_speed == pytest.approx(2 / math.sqrt(3), rel=1e-3)
    # The documented equations, at one point.
    x, y, z, tt = 0.3, -1.1, 2.0, 1.7
    a = flow.A * (1 + flow.eps * math.sin(flow.omega * tt))
    expected = [
        a * math.sin(z) + flow.C * math.cos(y),
        flow.B * math.sin(x) + a * math.cos(z),
        flow.C * math.sin(y) + flow.B * math.cos(x),
    ]
    got = flow.velocity(torch.tensor([[x, y, z]], dtype=torch.float64), torch.tensor([tt], dtype=torch.float64))
    assert torch.allclose(got[0], torch.tensor(expected, dtype=torch.float64))


@settings(max_examples=30, deadline=None)
@given(angle=st.floats(-360, 360))
def test_rotated_flow_rotates_field_domain_and_obstacles(angle):
    base = FunctionFlow(
        lambda p, t: torch.stack((1 + 0.1 * p[:, 1], 0.2 * p[:, 0], 0 * t + 0.3), -1),
        Box((-4, -6, 0), (16, 6, 10)),
        1.5,
        obstacles=[Cylinder((0, 0), 0.5)],
    )
    rot = RotatedFlow(base, angle)
    g = torch.Generator().manual_seed(0)
    p = base.bounds.sample(256, g).double()
    t = torch.rand(256, generator=g).double()
    a = math.radians(angle)
    assert torch.allclose(rot.velocity(rotate_z(p, a), t), rotate_z(base.velocity(p, t), a), atol=1e-9)
    assert torch.equal(rot.in_domain(rotate_z(p, a)), base.in_domain(p))
    inside = torch.tensor([[0.1, 0.2, 5.0]], dtype=torch.float64)
    assert rot.in_obstacle(rotate_z(inside, a)).item()


def test_scaled_and_uniform_flows():
    base = UniformFlow((1.0, 0.0, 0.0))
    scaled = ScaledFlow(base, 0.25)
    pos, t = torch.zeros(4, 3), torch.zeros(4)
    assert torch.allclose(scaled.velocity(pos, t), torch.tensor([[0.25, 0.0, 0.0]] * 4))
    assert scaled.max_speed == pytest.approx(0.25)
    with pytest.raises(ValueError, match="positive"):
        ScaledFlow(base, 0.0)


def test_function_flow_checks_its_output_shape():
    flow = FunctionFlow(lambda p, t: p[:, :2], Box((0, 0, 0), (1, 1, 1)), 1.0)
    with pytest.raises(ValueError, match="must map pos\\[N,3\\]"):
        flow.velocity(torch.zeros(5, 3), torch.zeros(5))


def test_box_refuses_inverted_bounds():
    with pytest.raises(ValueError, match="must exceed"):
        Box((0, 0, 0), (1, -1, 1))


@pytest.mark.slow
def test_look_up_is_exact_in_tables_beyond_float32_integer_range():
    """Row indices of a table with more than 2^24 rows must be computed in integers."""
    nx = 2**22 + 1000  # nx x 2 x 2 points x 2 frames: about 16.8M table rows
    field = torch.rand(2, nx, 2, 2, 3, generator=torch.Generator().manual_seed(0)).half()
    flow = GridFlow(field, (0, 0, 0), (1, 1, 1), 1.0, dtype=torch.float16)
    k = torch.tensor([nx - 3, nx - 77, nx // 2 + 3])
    pos = torch.stack((k.float(), torch.zeros(3), torch.zeros(3)), -1)
    got = flow.velocity(pos, torch.ones(3))  # float32 positions, as in the environment
    assert torch.equal(got.float(), field[1, k, 0, 0].float())


needs_gcc = pytest.mark.skipif(gridkernel.load() is None, reason="gcc cannot build the C look-up here")


@needs_gcc
@pytest.mark.parametrize("time_mode", ["looped", "clamped"])
@pytest.mark.parametrize("source", [torch.float32, torch.float16])
def test_the_c_look_up_gives_the_torch_paths_numbers_bit_for_bit(time_mode, source):
    """Periodic and bounded axes, positions beyond the grid, times before and after the data, blocks of 64 and a
    remainder, one thread's batch and a parallel one: equal to the last bit."""
    gen = torch.Generator().manual_seed(3)
    field = torch.randn(5, 9, 7, 6, 3, generator=gen).to(source)
    flow = GridFlow(field, ORIGIN, SPACING, DT, periodic=(False, True, True), time_mode=time_mode)
    assert flow._table.dtype == source  # a float16 field is stored as it is
    lo, size = torch.tensor(ORIGIN), torch.tensor(SPACING) * torch.tensor([9.0, 7.0, 6.0])
    for n in (1, 63, 65, 10_001):
        pos = lo - size + 3 * size * torch.rand(n, 3, generator=gen)
        t = (torch.rand(n, generator=gen) - 0.3) * 40 * DT
        assert gridkernel.usable(flow._table, pos)
        assert torch.equal(flow.velocity(pos, t), flow.velocity_torch(pos, t)), n


@needs_gcc
def test_the_c_look_up_names_a_non_finite_position():
    flow = GridFlow(torch.zeros(2, 3, 3, 3, 3), ORIGIN, SPACING, DT, periodic=(False, False, True))
    pos = torch.tensor([[1.0, -1.0, 0.1], [1.0, -1.0, float("nan")]])
    with pytest.raises(ValueError, match="at 1 non-finite positions or times"):
        flow.velocity(pos, torch.zeros(2))
    with pytest.raises(ValueError, match="one time per position: got 1 for 2 positions"):
        flow.velocity(pos, torch.zeros(1))
    inf = torch.tensor([[float("inf"), -1.0, 0.1]])  # a bounded axis clamps, as the torch path does
    assert torch.equal(flow.velocity(inf, torch.zeros(1)), flow.velocity_torch(inf, torch.zeros(1)))
