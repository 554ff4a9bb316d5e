"""The default dataset: the 3D cylinder wake at Re = 300, resampled onto the flownav grid.

The lattice nodes are aligned with the stored grid (``out_spacing`` is a multiple of the
lattice spacing), so resampling is exact subsampling. The span Lz is periodic and stored once
(``Nz * dz = Lz``); the navigation box z in [-5, 15] is covered by tiling it (``periodic`` z).
"""

from __future__ import annotations

import json
import math
import shlex
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from flownav.atomic import atomic_write_text
from flownav.cfd import diagnostics
from flownav.cfd.runner import CHECKPOINT_EVERY_S, RunState, run
from flownav.cfd.solver import CylinderLBM, SimConfig
from flownav.cfd.validate import REF_3D
from flownav.errors import ConfigError
from flownav.flows.base import WAKE_BOUNDS, Cylinder
from flownav.flows.grid import loop_seam_jump, save_grid_flow
from flownav.provenance import provenance as run_provenance

NAV_BOX = WAKE_BOUNDS  # the stored grid covers the navigation box exactly
SHIPPED_DATASET = Path("data/cylinder_re300")  # written only when --out names it
DEFAULT_RUN_DIR = Path("runs/cfd/cylinder_re300")
MAX_BYTES = 50_000_000  # the repository budget for velocity.npy


@dataclass(frozen=True)
class GenerateConfig:
    sim: SimConfig = field(default_factory=SimConfig)
    warmup: float = 80.0  # D/U before recording: shedding and 3D structure saturate by ~40
    record: float = 30.0  # D/U recorded (~6 periods); the looped window is chosen inside it
    frame_dt: float = 0.25  # ~20 frames per shedding period at St ~ 0.2
    out_spacing: float = 0.25  # stored grid spacing (3 lattice cells); divides Lz = 4
    min_periods: int = 3

    def check(self) -> None:
        sizes = {"warmup": (self.warmup, "D/U"), "record": (self.record, "D/U"), "frame_dt": (self.frame_dt, "D/U")}
        sizes["out_spacing"] = (self.out_spacing, "D")
        for name, (value, unit) in sizes.items():
            if not (value > 0 and math.isfinite(value)):
                flag = "--" + name.replace("_", "-")
                raise ConfigError(f"{name} ({flag}) must be a positive number of {unit}, got {value}")
        if self.min_periods < 1:
            raise ConfigError(f"min_periods must be >= 1, got {self.min_periods}")
        for name in ("warmup", "frame_dt"):  # frames are taken at whole lattice steps; anything else drifts
            steps = getattr(self, name) / self.sim.dt
            if abs(steps - round(steps)) > 1e-6 * max(1.0, steps) or round(steps) < 1:
                good = max(1, round(steps)) * self.sim.dt
                raise ConfigError(
                    f"{name} (--{name.replace('_', '-')}) = {getattr(self, name)} D/U is {steps:.6g} lattice steps of "
                    f"{self.sim.dt:.6g} D/U; use a whole number of steps, e.g. {good:.6g}"
                )
        r = self.out_spacing / self.sim.dx
        if abs(r - round(r)) > 1e-6 or round(r) < 1:
            raise ConfigError(
                f"out_spacing {self.out_spacing} is not a multiple of the lattice spacing "
                f"{self.sim.dx}; "
                "pick e.g. 2 / cells_per_d"
            )
        if self.sim.span is None:
            raise ConfigError("the dataset needs a 3D run: set span (>= 4 D)")
        nz = self.sim.span / self.out_spacing
        if abs(nz - round(nz)) > 1e-6:
            raise ConfigError(f"out_spacing {self.out_spacing} must divide the span {self.sim.span}")
        lo, hi = NAV_BOX.lo, NAV_BOX.hi
        x0, x1 = self.sim.x_range
        if not (x0 < lo[0] and x1 - self.sim.sponge > hi[0] and self.sim.y_half > hi[1]):
            raise ConfigError(
                f"the lattice x {self.sim.x_range} (outlet sponge {self.sim.sponge} D), |y| < {self.sim.y_half} "
                f"must contain {NAV_BOX} ahead of the sponge; widen --x-range / --y-half"
            )


def output_axes(cfg: GenerateConfig):
    """Lattice index slices and physical origin of the stored grid."""
    sim, h = cfg.sim, cfg.out_spacing
    r = round(h / sim.dx)
    lo, hi = NAV_BOX.lo, NAV_BOX.hi
    ix0 = round((lo[0] - sim.x_range[0]) / sim.dx)
    iy0 = round((lo[1] + sim.y_half) / sim.dx)
    nx = round((hi[0] - lo[0]) / h) + 1
    ny = round((hi[1] - lo[1]) / h) + 1
    nz = round(sim.span / h)
    sl = (
        slice(ix0, ix0 + r * (nx - 1) + 1, r),
        slice(iy0, iy0 + r * (ny - 1) + 1, r),
        slice(0, r * nz, r),
    )
    return sl, (lo[0], lo[1], 0.0), (h, h, h)


def frame_sampler(cfg: GenerateConfig):
    sl, _, _ = output_axes(cfg)

    def frame(sim: CylinderLBM) -> np.ndarray:
        _, u = sim.macroscopic(sl)
        return u.permute(1, 2, 3, 0).cpu().numpy().astype(np.float16)

    return frame


def simulate(
    cfg: GenerateConfig, run_dir: Path, device="cpu", checkpoint_every_s: float = CHECKPOINT_EVERY_S
) -> tuple[CylinderLBM, RunState]:
    cfg.check()
    sim = CylinderLBM(cfg.sim, device=device)
    run_dir.mkdir(parents=True, exist_ok=True)
    config = json.dumps({"sim": cfg.sim.to_dict(), **_gen_dict(cfg)}, indent=2)
    if not (run_dir / "state.pt").is_file():  # a resume rewrites it only once its state.pt proved to be this set-up
        atomic_write_text(run_dir / "config.json", config)
    state = run(
        sim,
        cfg.warmup + cfg.record,
        run_dir / "state.pt",
        frame_dt=cfg.frame_dt,
        record_from=cfg.warmup,
        frame_fn=frame_sampler(cfg),
        checkpoint_every_s=checkpoint_every_s,
        desc=f"cylinder Re={cfg.sim.re:g}",
    )
    atomic_write_text(run_dir / "config.json", config)
    return sim, state


def _gen_dict(cfg: GenerateConfig) -> dict:
    return {k: getattr(cfg, k) for k in ("warmup", "record", "frame_dt", "out_spacing", "min_periods")}


def wake_diagnostics(cfg: GenerateConfig, state: RunState) -> dict:
    """St, Cd, Cl over the recorded window; St also from a wake probe; rms w in the near wake."""
    h = state.history()
    sel = h["t"] >= cfg.warmup
    if sel.sum() < 16:
        raise ConfigError("too few samples after the warm-up to measure the wake; record longer")
    t = h["t"][sel]
    stats = diagnostics.force_stats(t, h["cd"][sel], h["cl"][sel])
    dts = float(np.median(np.diff(t)))
    probe_v = h["probes"][sel][:, 1, 1]  # v at (5, 0): one oscillation per shedding period
    stats["St_probe_spectrum"] = diagnostics.dominant_frequency(probe_v, dts)
    stats["St"] = stats["St_lift_spectrum"]
    late = h["rmsw_t"] >= cfg.warmup
    stats["rms_w_near_wake_lattice"] = float(np.mean(h["rmsw"][late])) if late.any() else float("nan")
    stats["rms_w_history"] = {
        "t": h["rmsw_t"][::5].round(2).tolist(),
        "rms_w": h["rmsw"][::5].round(4).tolist(),
    }
    return stats


def write_dataset(cfg: GenerateConfig, state: RunState, out: Path, command: str) -> dict:
    stats = wake_diagnostics(cfg, state)
    if not state.frames:
        raise ConfigError(f"no frames were recorded: --record ({cfg.record}) must cover --frame-dt ({cfg.frame_dt})")
    frames = np.stack(state.frames)  # [F, Nx, Ny, Nz, 3]
    period_frames = 1.0 / (stats["St"] * cfg.frame_dt)
    frame_bytes = frames[0].nbytes
    max_frames = MAX_BYTES // frame_bytes
    start, T, seam = diagnostics.best_loop_window(frames, period_frames, cfg.min_periods, max_frames)
    velocity = frames[start : start + T]
    _, origin, spacing = output_axes(cfg)
    x = cfg.out_spacing * np.arange(velocity.shape[1]) + origin[0]
    y = cfg.out_spacing * np.arange(velocity.shape[2]) + origin[1]
    X, Y = np.meshgrid(x, y, indexing="ij")
    near = (X >= 1) & (X <= 6) & (np.abs(Y) <= 1.5)
    between = (X >= 8) & (X <= 12) & (np.abs(Y) <= 2)
    sim = cfg.sim
    lam, modes = diagnostics.spanwise_wavelength(velocity[:, near][..., 2], cfg.out_spacing)
    diag = {
        **{k: v for k, v in stats.items() if k != "rms_w_history"},
        "rms_w_near_wake": diagnostics.rms_w(velocity[:, near]),
        "rms_w_between_regions": diagnostics.rms_w(velocity[:, between]),
        "spanwise_wavelength_dominant": lam,
        "spanwise_energy_by_mode": modes,
        "frames_per_period": period_frames,
        "window_periods": seam["periods"],
        "window_start_time": float(state.frame_t[start]),
        "loop_seam_jump": loop_seam_jump(velocity),
        "seam_rel_to_step": seam["seam_rel"],
        "rms_w_history": stats["rms_w_history"],
        "reference": {
            "St": REF_3D["St"],
            "Cd": REF_3D["Cd"],
            "source": "3D DNS at Re = 300 (DESIGN.md)",
        },
    }
    provenance = run_provenance(command) | {
        "generator": "flownav.cfd (lattice Boltzmann, KBC collision, Bouzidi cylinder)",
        "Re": sim.re,
        "lattice": sim.lattice,
        "collision": "KBC (entropic multi-relaxation, Hermite shear part)",
        "cells_per_d": sim.cells_per_d,
        "u_lattice": sim.u_lattice,
        "tau": sim.tau,
        "lattice_shape": list(sim.shape),
        "lattice_domain": {
            "x": list(sim.x_range),
            "y": [-sim.y_half, sim.y_half],
            "z": [0.0, sim.span],
        },
        "boundaries": "inflow equilibrium u=U, outflow rho=1 + sponge, periodic y and z, Bouzidi cylinder",
        "span_Lz": sim.span,
        "z_periodic_tiling": (
            f"z is periodic with period Lz = {sim.span}; "
            f"z in [{NAV_BOX.lo[2]:g}, {NAV_BOX.hi[2]:g}] is covered by tiling"
        ),
        "warmup": cfg.warmup,
        "record": cfg.record,
        "frame_dt": cfg.frame_dt,
        "St": stats["St"],
        "Cd": stats["Cd_mean"],
        "wall_time_s": state.wall,
        "torch_threads": torch.get_num_threads(),
    }
    save_grid_flow(
        out,
        velocity,
        origin=origin,
        spacing=spacing,
        dt=cfg.frame_dt,
        periodic=(False, False, True),
        bounds=NAV_BOX,
        obstacles=[Cylinder((0.0, 0.0), 0.5)],
        provenance=provenance,
        diagnostics=diag,
        dtype=np.float16,  # the shipped wake's format: 48 MB (float32 would be 96)
    )
    h = state.history()
    np.savez_compressed(out / "history.npz", **h)
    return diag


def generate(
    cfg: GenerateConfig,
    out: Path | None = None,
    run_dir: Path = DEFAULT_RUN_DIR,
    device="cpu",
    checkpoint_every_s: float = CHECKPOINT_EVERY_S,
) -> dict:
    """Simulate (resuming from ``run_dir``) and write the dataset to ``out`` (default: ``run_dir/dataset``)."""
    _, state = simulate(cfg, run_dir, device, checkpoint_every_s)
    out = run_dir / "dataset" if out is None else out
    command = "python -m flownav.cfd " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    return write_dataset(cfg, state, out, command)
