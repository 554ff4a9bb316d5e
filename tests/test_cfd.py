"""Fast checks of the lattice-Boltzmann generator (flownav.cfd) on small grids."""

from __future__ import annotations

import argparse
import math

import numpy as np
import pytest
import torch

from flownav.cfd import ckernel, diagnostics
from flownav.cfd.collision import kbc
from flownav.cfd.lattice import LATTICES, equilibrium, get_lattice, moments
from flownav.cfd.runner import run
from flownav.cfd.solver import CylinderLBM, Grid, SimConfig


@pytest.fixture(autouse=True)
def _one_thread():
    # Small grids: one thread is faster than waiting for a second, possibly busy core.
    saved = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(saved)


@pytest.mark.parametrize("name", sorted(LATTICES))
def test_lattice_moments_are_isotropic(name):
    lat = get_lattice(name)
    c = lat.c_tensor(torch.float64)
    w = lat.w_tensor(torch.float64)
    assert torch.isclose(w.sum(), torch.tensor(1.0, dtype=torch.float64))
    assert torch.allclose(torch.einsum("q,qa->a", w, c), torch.zeros(3, dtype=torch.float64))
    assert torch.allclose(torch.einsum("q,qa,qb->ab", w, c, c), torch.eye(3, dtype=torch.float64) / 3)
    m4 = torch.einsum("q,qa,qb,qc,qd->abcd", w, c, c, c, c)
    eye = torch.eye(3, dtype=torch.float64)
    iso = (
        torch.einsum("ab,cd->abcd", eye, eye)
        + torch.einsum("ac,bd->abcd", eye, eye)
        + torch.einsum("ad,bc->abcd", eye, eye)
    ) / 9
    assert torch.allclose(m4, iso)
    assert all(lat.c[j] == tuple(-a for a in lat.c[i]) for i, j in enumerate(lat.opposite))


@pytest.mark.parametrize("name", sorted(LATTICES))
def test_kbc_conserves_mass_and_momentum(name):
    lat = get_lattice(name)
    g = torch.Generator().manual_seed(0)
    rho = 1 + 0.05 * torch.rand(50, generator=g)
    u = 0.1 * torch.randn(3, 50, generator=g)
    f = equilibrium(lat, rho, u) * (1 + 0.05 * torch.randn(lat.q, 50, generator=g))
    post = torch.stack(kbc(lat, list(f), 0.9))
    r0, u0 = moments(lat, f)
    r1, u1 = moments(lat, post)
    assert torch.allclose(r0, r1, atol=1e-6)
    assert torch.allclose(u0, u1, atol=1e-6)
    # At equilibrium nothing changes.
    feq = equilibrium(lat, rho, u)
    assert torch.allclose(torch.stack(kbc(lat, list(feq), 0.9)), feq, atol=1e-6)


def _taylor_green(backend: str, lattice="D3Q19", n=24, tau=0.8, steps=120):
    """Shear-wave decay in the periodic (y, z) plane: (measured nu, set nu, mass drift)."""
    lat = get_lattice(lattice)
    grid = Grid(3, n, n)
    k = 2 * math.pi / n
    y, z = torch.meshgrid(torch.arange(n, dtype=torch.float32), torch.arange(n, dtype=torch.float32), indexing="ij")
    u0 = 0.02
    u = torch.zeros(3, 3, n, n)
    u[1] = u0 * torch.sin(k * y) * torch.cos(k * z)
    u[2] = -u0 * torch.cos(k * y) * torch.sin(k * z)
    f = torch.zeros(lat.q, grid.length)
    sim = CylinderLBM.__new__(CylinderLBM)  # only the streaming/collision machinery is needed
    sim.backend, sim.lat, sim.grid, sim.threads = backend, lat, grid, 1
    sim.shifts = [grid.shift(c) for c in lat.c]
    sim.beta_x = torch.full((3,), 1 / (2 * tau))
    sim.cfg = SimConfig(lattice=lattice)
    grid.interior(f).copy_(equilibrium(lat, torch.ones(3, n, n), u))
    sim._fill_ghosts(f)
    f2 = torch.empty_like(f)
    mass0 = grid.interior(f)[:, 1].sum(dtype=torch.float64)

    def energy(ff):
        _, uu = moments(lat, grid.interior(ff)[:, 1])
        return float((uu**2).sum())

    e0 = energy(f)
    for _ in range(steps):
        a = grid.planes(f)
        a[:, 0] = a[:, 1]  # x-invariant flow: copy the middle plane into its x neighbours
        a[:, 2] = a[:, 1]
        sim._stream_collide(f, f2)
        if backend == "torch":
            sim._fill_ghosts(f2)
        f, f2 = f2, f
    nu_measured = -math.log(energy(f) / e0) / (2 * 2 * k * k * steps)
    mass = grid.interior(f)[:, 1].sum(dtype=torch.float64)
    return nu_measured, (tau - 0.5) / 3, float(abs(mass - mass0) / mass0)


@pytest.mark.parametrize("backend", ["c", "torch"])
def test_shear_wave_decays_with_the_set_viscosity_and_conserves_mass(backend):
    nu, nu_ref, drift = _taylor_green(backend)
    assert abs(nu - nu_ref) / nu_ref < 0.03
    assert drift < 1e-5


def test_c_kernel_matches_torch_reference():
    cfg = SimConfig(re=100, cells_per_d=6, span=1.0, x_range=(-3, 6), y_half=3)
    a = CylinderLBM(cfg, backend="c")
    b = CylinderLBM(cfg, backend="torch")
    a.step(6)
    b.step(6)
    assert torch.allclose(a.grid.interior(a.f), b.grid.interior(b.f), atol=2e-6)
    assert torch.allclose(a.force, b.force, atol=1e-4)


def test_drag_is_positive_and_lift_vanishes_in_steady_symmetric_flow():
    cfg = SimConfig(re=20, cells_per_d=6, u_lattice=0.12, span=None, x_range=(-4, 8), y_half=4, perturb=0.0)
    sim = CylinderLBM(cfg)
    state = run(sim, 15.0, None, desc="Re=20")
    h = state.history()
    # The impulsive start leaves pressure waves bouncing in the short box (Cd swings 1.9-3.0): the second half's mean.
    cd, cl = float(h["cd"][h["t"] > 7.5].mean()), state.cl[-1]
    # Re = 20: Cd 2.05 unbounded (Dennis & Chang 1970); this box blocks 12.5% of the channel, which raises it by
    # about a quarter. Measured 2.59.
    assert 2.3 < cd < 2.9
    assert abs(cl) < 0.05 * cd
    assert np.isfinite(sim.macroscopic()[1].numpy()).all()


@pytest.mark.slow
def test_small_2d_wake_sheds_at_about_the_right_strouhal_number():
    cfg = SimConfig(re=100, cells_per_d=6, u_lattice=0.12, span=None, x_range=(-4, 10), y_half=5)
    sim = CylinderLBM(cfg)
    state = run(sim, 60.0, None, desc="2D Re=100 small")
    h = state.history()
    sel = h["t"] > 30
    st = diagnostics.dominant_frequency(h["cl"][sel], float(np.diff(h["t"][sel]).mean()))
    assert h["cl"][sel].std() > 0.1  # it sheds
    assert abs(st - 0.165) / 0.165 < 0.12  # coarse, confined and short: loose bound


def test_bad_input_is_rejected_with_the_fix():
    with pytest.raises(ValueError, match="Re must be"):
        SimConfig(re=-3)
    with pytest.raises(ValueError, match="cells_per_d >= 6"):
        SimConfig(re=300, cells_per_d=4)
    with pytest.raises(ValueError, match="u_lattice"):
        SimConfig(u_lattice=0.4)
    small = SimConfig(re=50, cells_per_d=6, span=None, x_range=(-3, 6), y_half=3)
    other = SimConfig(re=50, cells_per_d=6, span=None, x_range=(-3, 7), y_half=3)
    state = CylinderLBM(small).state_dict()
    with pytest.raises(ValueError, match="another set-up"):
        CylinderLBM(other).load_state_dict(state)


def test_checkpoint_resume_is_exact(tmp_path):
    cfg = SimConfig(re=100, cells_per_d=6, span=None, x_range=(-3, 6), y_half=3)
    ref = CylinderLBM(cfg)
    run(ref, 1.2, None)
    a = CylinderLBM(cfg)
    run(a, 0.6, tmp_path / "state.pt")
    b = CylinderLBM(cfg)
    state = run(b, 1.2, tmp_path / "state.pt")  # resumes at t = 0.6
    assert b.steps == ref.steps
    assert torch.equal(b.f, ref.f)
    assert len(state.t) == len(run(CylinderLBM(cfg), 1.2, None).t)


def test_strouhal_and_loop_window_helpers():
    t = np.arange(0, 60, 0.05)
    assert abs(diagnostics.dominant_frequency(np.sin(2 * np.pi * 0.2 * t), 0.05) - 0.2) < 0.002
    assert abs(diagnostics.zero_crossing_frequency(np.sin(2 * np.pi * 0.2 * t + 0.3), 0.05) - 0.2) < 0.002
    period = 19.6  # frames
    n = np.arange(120)
    frames = np.stack([np.sin(2 * np.pi * n / period + p) for p in (0.0, 1.0, 2.0)], -1)[:, None]
    start, T, info = diagnostics.best_loop_window(frames, period, min_periods=3, max_frames=70)
    assert T in (58, 59) and info["periods"] == 3 and start + T < 120
    assert info["seam_rel"] < 1.0


def test_kernel_source_is_cached_per_lattice():
    assert ckernel.load("D3Q19") is ckernel.load("D3Q19")
    assert "D3Q27" in ckernel.source(get_lattice("D3Q27"))


@pytest.mark.slow
def test_generate_writes_a_loadable_periodic_dataset(tmp_path):
    from flownav.cfd.dataset import GenerateConfig, simulate, write_dataset
    from flownav.flows.grid import load_grid_flow

    sim = SimConfig(re=100, cells_per_d=4, u_lattice=0.15, x_range=(-5, 26), y_half=7.5, span=2.0)
    cfg = GenerateConfig(sim=sim, warmup=12.0, record=14.0, frame_dt=0.45, out_spacing=0.5, min_periods=1)
    _, state = simulate(cfg, tmp_path / "run")
    diag = write_dataset(cfg, state, tmp_path / "data", command="test")
    flow = load_grid_flow(tmp_path / "data")
    T, nx, ny, nz = flow.shape
    assert (nx, ny, nz) == (53, 29, 4) and flow.periodic == (False, False, True)
    assert flow.origin == (-4.0, -7.0, 0.0) and nz * flow.spacing[2] == pytest.approx(2.0)
    assert flow.meta["provenance"]["Re"] == 100 and "sha256" in flow.meta
    for key in ("St", "Cd_mean", "rms_w_near_wake", "loop_seam_jump", "window_periods"):
        assert np.isfinite(diag[key])
    # Inside the cylinder the stored velocity is zero.
    u = flow.velocity(torch.tensor([[0.0, 0.0, 1.0], [5.0, 0.0, 1.0]]), torch.zeros(2))
    assert u[0].abs().max() == 0 and u[1].abs().max() > 0.05


def test_kernel_cache_is_keyed_by_the_cpu():
    ckernel.load("D3Q19")
    here = ckernel.library_file("D3Q19")
    assert here.exists()  # the kernel this process loaded was built for this CPU
    assert ckernel.library_file("D3Q19", cpu="x86_64|other model|sse2") != here
    assert ckernel.cpu_signature() and ckernel.library_file("D3Q19", cpu=ckernel.cpu_signature()) == here


def test_a_run_outside_the_tolerance_says_so_in_one_warning_block():
    from flownav.cfd.validate import check_wake_3d, tolerance_warning

    good = {"St": 0.205, "Cd_mean": 1.3, "rms_w_near_wake": 0.05}
    assert tolerance_warning(check_wake_3d(good)) == ""
    block = tolerance_warning(check_wake_3d({**good, "St": 0.77}))
    lines = block.splitlines()
    assert lines[0] == lines[-1] == "=" * 78 and lines[1].startswith("WARNING: this wake is OUTSIDE")
    assert "  St = 0.77, reference 0.203 +- 7% (off by 279%)" in lines and not any("Cd =" in ln for ln in lines)


def test_generate_help_gives_every_option_its_default_the_units_and_the_closing_check():
    from flownav.cfd.__main__ import parser

    gen = parser()._subparsers._group_actions[0].choices["generate"]
    text = " ".join(gen.format_help().split())
    for action in gen._actions:
        if action.dest == "help":
            continue
        assert action.help, action.dest
        if action.default is argparse.SUPPRESS:  # the default is stated in the help text itself
            assert "(default: " in action.help, action.dest
            continue
        stated = f"default: {action.default}"
        assert stated.replace("[", "").split(",")[0] in text.replace("[", ""), action.dest
    assert "--out data/cylinder_re300" in text  # the shipped dataset is written only when named
    assert {"--threads", "--device"} <= {s for a in gen._actions for s in a.option_strings}  # not only before it
    assert "lengths in cylinder diameters D, velocities in the inflow speed U, times in D/U" in text
    assert "(St 0.203 +- 7%, Cd 1.27 +- 12%, rms w / U >= 0.02)" in text and "WARNING block on stderr" in text


def test_generate_command_ends_with_the_warning_when_the_wake_is_off(tmp_path, monkeypatch, capsys):
    """python -m flownav.cfd generate: a run whose Strouhal number is off (a too-coarse lattice gave 0.77) says
    so after everything else it prints; a run inside the tolerance prints no warning."""
    from flownav.cfd import dataset
    from flownav.cfd.__main__ import main

    good = {"St": 0.205, "St_probe_spectrum": 0.2, "Cd_mean": 1.3, "Cl_rms": 0.5, "rms_w_near_wake": 0.05}
    good |= {"loop_seam_jump": 2.0, "window_periods": 6, "frames_per_period": 19}
    for diag in (good, {**good, "St": 0.77}):
        monkeypatch.setattr(dataset, "generate", lambda *args, diag=diag: diag)
        main(["generate", "--threads", "1", "--run-dir", str(tmp_path)])
        captured = capsys.readouterr()
        assert "wrote " in captured.out
        if diag is good:
            assert captured.err == ""
            continue
        err = captured.err.splitlines()
        assert err[1] == "WARNING: this wake is OUTSIDE the validation tolerance of a 3D Re = 300 cylinder wake:"
        assert "  St = 0.77, reference 0.203 +- 7% (off by 279%)" in err and err[-1] == "=" * 78


def test_generator_refuses_fractional_lattice_steps_and_non_positive_sizes():
    from flownav.cfd.dataset import GenerateConfig
    from flownav.errors import ConfigError

    with pytest.raises(ConfigError, match=r"frame_dt \(--frame-dt\) = 0.31 D/U is 37.2 lattice steps"):
        GenerateConfig(frame_dt=0.31).check()
    with pytest.raises(ConfigError, match=r"warmup \(--warmup\) = 80.004 D/U is 9600.48 lattice steps"):
        GenerateConfig(warmup=80.004).check()
    with pytest.raises(ConfigError, match="record .* must be a positive number of D/U"):
        GenerateConfig(record=0.0).check()
    with pytest.raises(ConfigError, match=r"span \(--span\) must be a positive number"):
        SimConfig(span=0.0)
    GenerateConfig().check()  # the shipped dataset's settings: 30 and 9600 steps


@pytest.mark.slow
def test_interrupted_generate_resumes_to_the_identical_dataset(tmp_path, monkeypatch):
    from flownav.cfd.dataset import GenerateConfig, generate
    from flownav.cfd.validate import check_wake_3d, tolerance_warning

    sim = SimConfig(re=100, cells_per_d=4, u_lattice=0.15, x_range=(-5, 26), y_half=7.5, span=2.0)
    cfg = GenerateConfig(sim=sim, warmup=12.0, record=14.0, frame_dt=0.45, out_spacing=0.5, min_periods=1)
    diag = generate(cfg, None, tmp_path / "whole")  # --out not given: the dataset goes into the run directory
    assert (tmp_path / "whole" / "dataset" / "velocity.npy").is_file()

    step = CylinderLBM.step

    def failing_step(self, n=1):
        if self.steps >= 500:  # after the warm-up (320 steps), frames already recorded
            raise RuntimeError("injected failure")
        step(self, n)

    monkeypatch.setattr(CylinderLBM, "step", failing_step)
    with pytest.raises(RuntimeError, match="injected"):
        generate(cfg, tmp_path / "out", tmp_path / "cut", checkpoint_every_s=0.0)
    monkeypatch.setattr(CylinderLBM, "step", step)
    assert not (tmp_path / "out").exists()
    resumed = generate(cfg, tmp_path / "out", tmp_path / "cut", checkpoint_every_s=0.0)

    for name in ("velocity.npy", "history.npz"):
        assert (tmp_path / "out" / name).read_bytes() == (tmp_path / "whole" / "dataset" / name).read_bytes(), name
    assert resumed == diag
    # The final lattice state too: the populations and the step count, bit for bit.
    from flownav.cfd.runner import NUMPY_ARRAY_GLOBALS
    from flownav.checkpoint import safe_torch_load

    whole, cut = (safe_torch_load(tmp_path / d / "state.pt", NUMPY_ARRAY_GLOBALS)["sim"] for d in ("whole", "cut"))
    diff = float((whole["f"].double() - cut["f"].double()).abs().max())
    print(f"\nCFD resume: max |difference| of the final populations = {diff}")  # pytest -s
    assert whole["steps"] == cut["steps"] and diff == 0.0
    # Re = 100 on 4 cells per D is no Re = 300 wake: the generator's closing warning names it.
    assert "WARNING: this wake is OUTSIDE" in tolerance_warning(check_wake_3d(diag), re=100)


def test_a_run_directory_of_another_set_up_is_refused_and_left_as_it_was(tmp_path):
    from flownav.cfd.dataset import GenerateConfig, generate
    from flownav.cfd.runner import run as run_lbm
    from flownav.cfd.runner import save_checkpoint
    from flownav.errors import CheckpointError

    other = CylinderLBM(SimConfig(re=100, cells_per_d=4, u_lattice=0.15, x_range=(-5, 27), y_half=7.5, span=2.0))
    save_checkpoint(tmp_path / "state.pt", other, run_lbm(other, 0.0, None))
    (tmp_path / "config.json").write_text("the other run's settings")
    before = (tmp_path / "state.pt").read_bytes()
    sim = SimConfig(re=100, cells_per_d=4, u_lattice=0.15, x_range=(-5, 26), y_half=7.5, span=2.0)
    cfg = GenerateConfig(sim=sim, warmup=12.0, record=14.0, frame_dt=0.45, out_spacing=0.5, min_periods=1)
    with pytest.raises(CheckpointError, match=r"another set-up \(x_range \[-5, 27\] there, \[-5, 26\] here\)"):
        generate(cfg, None, tmp_path)
    assert (tmp_path / "config.json").read_text() == "the other run's settings"
    assert (tmp_path / "state.pt").read_bytes() == before and not (tmp_path / "dataset").exists()
