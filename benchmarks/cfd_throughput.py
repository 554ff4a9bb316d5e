"""Throughput of the lattice-Boltzmann solver against this machine's memory-bandwidth bound.

    python benchmarks/cfd_throughput.py [--threads 2] [--steps 40]

Measures, on the lattice of the shipped dataset (D3Q19, 12 cells per D, 433 x 216 x 48):
* MLUPS (million lattice-node updates per second) of the full step (fused C stream+collide,
  Bouzidi cylinder, inflow/outflow) and of the fused kernel alone;
* a STREAM-like copy bandwidth with torch on arrays of the lattice's size, and the bound
  ``bandwidth / bytes_per_update`` with ``bytes_per_update = 2 * Q * 4`` (each population read
  once and written once per step, float32).
Writes benchmarks/results/cfd_throughput.json (``headline``: mlups, bandwidth_bound_mlups).
The machine is shared: the load average at start is recorded next to the numbers.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import torch

from flownav.atomic import atomic_write_text
from flownav.cfd.solver import CylinderLBM, SimConfig
from flownav.provenance import provenance


def _best_time(fn, repeats: int) -> float:
    fn()
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def copy_bandwidth(n_floats: int, repeats: int = 10) -> float:
    """Bytes per second of ``b.copy_(a)`` on float32 arrays (2 bytes moved per byte copied)."""
    a = torch.rand(n_floats)
    b = torch.empty_like(a)
    t = _best_time(lambda: b.copy_(a), repeats)
    return 2 * a.numel() * a.element_size() / t


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--steps", type=int, default=40)
    p.add_argument("--cells-per-d", type=int, default=SimConfig().cells_per_d)
    p.add_argument("--out", type=Path, default=Path("benchmarks/results/cfd_throughput.json"))
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    load0 = os.getloadavg()
    cfg = SimConfig(cells_per_d=args.cells_per_d)
    sim = CylinderLBM(cfg, threads=args.threads)
    nx, ny, nz = cfg.shape
    cells = nx * ny * nz
    sim.step(3)  # build + warm caches
    # Full step: the best of a few blocks (other jobs share the cores).
    block = max(1, args.steps // 4)
    t_step = _best_time(lambda: sim.step(block), 4) / block
    t_kernel = _best_time(lambda: sim._stream_collide(sim.f, sim.f2), args.steps // 2)
    q = sim.lat.q
    bytes_per_update = 2 * q * 4
    bw = copy_bandwidth(q * sim.grid.length)
    result = {
        "headline": {
            "mlups": cells / t_step / 1e6,
            "bandwidth_bound_mlups": bw / bytes_per_update / 1e6,
            "fraction_of_bound": (cells / t_step) / (bw / bytes_per_update),
        },
        "kernel_only_mlups": cells / t_kernel / 1e6,
        "copy_bandwidth_GBps": bw / 1e9,
        "bytes_per_cell_update": bytes_per_update,
        "lattice": cfg.lattice,
        "collision": "KBC",
        "grid": [nx, ny, nz],
        "cells": cells,
        "threads": args.threads,
        "seconds_per_step": t_step,
        "seconds_per_time_unit": t_step / cfg.dt,
        "loadavg_at_start": load0,
        "cpu": platform.processor() or platform.machine(),
        "torch": torch.__version__,
    } | provenance("python benchmarks/cfd_throughput.py")
    atomic_write_text(args.out, json.dumps(result, indent=2))
    print(json.dumps(result["headline"], indent=2))
    print(
        f"kernel only {result['kernel_only_mlups']:.1f} MLUPS, copy bandwidth {bw / 1e9:.1f} GB/s, "
        f"load average at start {load0[0]:.1f} on {os.cpu_count()} cores; wrote {args.out}"
    )


if __name__ == "__main__":
    main()
