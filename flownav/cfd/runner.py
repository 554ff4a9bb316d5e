"""Run a :class:`CylinderLBM` to a final time with sampled diagnostics, recorded frames,
a tqdm progress bar, and atomic checkpoints so a killed run resumes where it stopped."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from flownav.atomic import atomic_write
from flownav.cfd.solver import CylinderLBM
from flownav.checkpoint import safe_torch_load

# Wall-clock seconds between checkpoints: a kill loses at most this much stepping; one write of the
# shipped run's state (~0.4 GB) takes about a second.
CHECKPOINT_EVERY_S = 60.0


@dataclass
class RunState:
    """Everything a run accumulates besides the populations."""

    t: list = field(default_factory=list)
    cd: list = field(default_factory=list)
    cl: list = field(default_factory=list)
    probes: list = field(default_factory=list)  # [n_probes, 3] velocity samples
    rmsw_t: list = field(default_factory=list)
    rmsw: list = field(default_factory=list)
    frames: list = field(default_factory=list)  # float16 arrays from the frame callback
    frame_t: list = field(default_factory=list)
    wall: float = 0.0  # wall-clock seconds spent stepping, summed over resumes

    def history(self) -> dict[str, np.ndarray]:
        return {
            "t": np.array(self.t),
            "cd": np.array(self.cd),
            "cl": np.array(self.cl),
            "probes": np.array(self.probes).reshape(len(self.t), -1, 3),
            "rmsw_t": np.array(self.rmsw_t),
            "rmsw": np.array(self.rmsw),
        }


def save_checkpoint(path: Path, sim: CylinderLBM, run: RunState) -> None:
    # Atomic: a kill mid-write leaves the previous checkpoint intact.
    atomic_write(path, lambda f: torch.save({"sim": sim.state_dict(), "run": run.__dict__}, f))


# The numpy types a run state holds (its recorded frames); nothing else may be unpickled.
NUMPY_ARRAY_GLOBALS = (
    np.ndarray,
    np.dtype,
    np._core.multiarray._reconstruct,
    np.dtypes.Float16DType,
    np.dtypes.Float32DType,
    np.dtypes.Float64DType,
)


def load_checkpoint(path: Path, sim: CylinderLBM) -> RunState:
    state = safe_torch_load(path, NUMPY_ARRAY_GLOBALS)
    sim.load_state_dict(state["sim"])
    run = RunState()
    run.__dict__.update(state["run"])
    return run


def probe_nodes(sim: CylinderLBM, points) -> torch.Tensor:
    """Flat node indices of the lattice nodes nearest to physical points (x, y, z), clamped
    into the lattice (small test domains)."""
    cfg, g = sim.cfg, sim.grid
    idx = []
    for x, y, z in points:
        ix = min(max(round((x - cfg.x_range[0]) / cfg.dx), 0), g.nx - 1)
        iy = min(max(round((y + cfg.y_half) / cfg.dx), 0), g.ny - 1)
        iz = round(z / cfg.dx) % g.nz
        idx.append(g.flat(ix, iy, iz))
    return torch.tensor(idx, device=sim.device)


def near_wake_rms_w(sim: CylinderLBM, x_lo=1.0, x_hi=6.0, y_abs=1.5) -> float:
    """rms of w/U over the near wake (x in [x_lo, x_hi], |y| <= y_abs, whole span)."""
    x, y, _ = sim.cfg.coords()
    ix = np.nonzero((x >= x_lo) & (x <= x_hi))[0]
    iy = np.nonzero(np.abs(y) <= y_abs)[0]
    fi = sim.grid.interior(sim.f)[:, ix[0] : ix[-1] + 1, iy[0] : iy[-1] + 1]
    w = torch.einsum("q,qxyz->xyz", sim.c[:, 2], fi) / fi.sum(0) / sim.cfg.u_lattice
    return float(w.pow(2).mean().sqrt())


def run(
    sim: CylinderLBM,
    t_end: float,
    checkpoint: Path | None,
    sample_dt: float = 0.05,
    frame_dt: float | None = None,
    record_from: float = math.inf,
    frame_fn: Callable[[CylinderLBM], np.ndarray] | None = None,
    probes=((2.0, 0.6, 0.0), (5.0, 0.0, 0.0), (10.0, 0.0, 0.0)),
    checkpoint_every_s: float = CHECKPOINT_EVERY_S,
    desc: str = "lbm",
) -> RunState:
    """Advance ``sim`` to ``t_end`` (D/U), resuming from ``checkpoint`` if it exists.

    The checkpoint is rewritten at the first sample ``checkpoint_every_s`` wall-clock seconds after the
    last one (0: at every sample) and at the end; a resumed run reproduces the uninterrupted one bit for bit.
    """
    cfg = sim.cfg
    run_state = RunState()
    if checkpoint is not None and checkpoint.exists():
        run_state = load_checkpoint(checkpoint, sim)
        print(f"resumed {checkpoint} at t = {sim.time:.2f} (step {sim.steps})", flush=True)
    k_sample = max(1, round(sample_dt / cfg.dt))
    k_frame = None
    if frame_fn is not None:
        k_frame = max(1, round(frame_dt / cfg.dt))
        k_sample = math.gcd(k_sample, k_frame)
    k_rmsw = max(k_sample, round(1.0 / cfg.dt) // k_sample * k_sample)
    first_frame = math.ceil(record_from / cfg.dt) if k_frame else None
    probe_idx = probe_nodes(sim, probes)
    c = sim.c
    n_end = math.ceil(t_end / cfg.dt)
    last_ckpt = time.time()
    bar = tqdm(total=n_end, initial=sim.steps, desc=desc, unit="step", mininterval=5.0, smoothing=0.05)
    while sim.steps < n_end:
        t0 = time.time()
        sim.step(min(k_sample - sim.steps % k_sample, n_end - sim.steps))
        run_state.wall += time.time() - t0
        bar.update(sim.steps - bar.n)
        if sim.steps % k_sample:
            continue
        cd, cl = sim.coefficients()
        if not (math.isfinite(cd) and math.isfinite(cl)):
            raise FloatingPointError(
                f"the lattice diverged at t = {sim.time:.2f}; raise cells_per_d or lower u_lattice"
            )
        fp = sim.f[:, probe_idx]
        u = (c.T @ fp) / fp.sum(0) / cfg.u_lattice
        run_state.t.append(sim.time)
        run_state.cd.append(cd)
        run_state.cl.append(cl)
        run_state.probes.append(u.T.cpu().numpy().tolist())
        if sim.steps % k_rmsw == 0:
            run_state.rmsw_t.append(sim.time)
            run_state.rmsw.append(near_wake_rms_w(sim))
            bar.set_postfix(
                t=f"{sim.time:.1f}",
                Cd=f"{cd:.3f}",
                Cl=f"{cl:+.3f}",
                rms_w=f"{run_state.rmsw[-1]:.3f}",
            )
        if k_frame and sim.steps >= first_frame and (sim.steps - first_frame) % k_frame == 0:
            run_state.frames.append(frame_fn(sim))
            run_state.frame_t.append(sim.time)
        if checkpoint is not None and time.time() - last_ckpt > checkpoint_every_s:
            save_checkpoint(checkpoint, sim, run_state)
            last_ckpt = time.time()
    bar.close()
    if checkpoint is not None:
        save_checkpoint(checkpoint, sim, run_state)
    return run_state
