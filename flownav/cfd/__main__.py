"""Command line: ``python -m flownav.cfd {generate,validate,plot}``.

generate  run the 3D Re = 300 wake (resumes from --run-dir) and write the dataset to --out
          (default <run-dir>/dataset; the shipped data/cylinder_re300 only when --out names it)
validate  2D Re = 100 check against the literature + a 3D dataset's diagnostics
plot      z-vorticity slice and Q-criterion view of a wake dataset -> --out-dir
          (default runs/cfd/figures; the README's figures only when --out-dir names docs/figures)

Lengths are in cylinder diameters D, velocities in the inflow speed U, times in D/U.
Set FLOWNAV_DEBUG=1 to see the traceback of an error.
"""

from __future__ import annotations

import argparse
import json
import sys
import textwrap
import time
from pathlib import Path

import torch

from flownav.cfd.dataset import DEFAULT_RUN_DIR, SHIPPED_DATASET, GenerateConfig
from flownav.cfd.runner import CHECKPOINT_EVERY_S
from flownav.cfd.solver import SimConfig
from flownav.errors import ConfigError, reported_as_one_line


class _Help(argparse.RawDescriptionHelpFormatter, argparse.ArgumentDefaultsHelpFormatter):
    """Keep the description's layout and append every option's default."""


class _Parser(argparse.ArgumentParser):
    """argparse with its errors as the other entry points give them: one line ``error: ...``, exit status 2."""

    def error(self, message: str):
        print(f"error: {self.prog}: {message}; see {self.prog} --help", file=sys.stderr, flush=True)
        raise SystemExit(2)


THREADS, DEVICE = 2, "cpu"
DEVICE_HELP = "torch device (cpu runs the C kernel)"


def generate_description() -> str:
    from flownav.cfd.validate import REF_3D

    text = (
        "Simulate the 3D cylinder wake (resuming from --run-dir) and write the dataset. Units: lengths in cylinder "
        "diameters D, velocities in the inflow speed U, times in D/U; options in lattice units say so.\n\n"
        "At the end the run's Strouhal number, mean drag coefficient and near-wake rms w are checked against a "
        f"3D Re = 300 wake (St {REF_3D['St']:g} +- {100 * REF_3D['St_tol']:g}%, Cd {REF_3D['Cd']:g} +- "
        f"{100 * REF_3D['Cd_tol']:g}%, rms w / U >= {REF_3D['rms_w_min']:g}): a run outside them ends with a "
        "WARNING block on stderr."
    )
    return "\n\n".join(textwrap.fill(paragraph, 79) for paragraph in text.split("\n\n"))


def _run_args(p: argparse.ArgumentParser) -> None:
    """--threads and --device after the command too (before it, as the top-level options, works as well)."""
    p.add_argument(
        "--threads", type=int, default=argparse.SUPPRESS, help=f"torch / OpenMP threads (default: {THREADS})"
    )
    p.add_argument("--device", default=argparse.SUPPRESS, help=f"{DEVICE_HELP} (default: {DEVICE})")


def _sim_args(p: argparse.ArgumentParser, defaults: SimConfig) -> None:
    p.add_argument("--re", type=float, default=defaults.re, help="Reynolds number U D / nu")
    p.add_argument("--cells-per-d", type=int, default=defaults.cells_per_d, help="lattice cells per diameter D")
    p.add_argument(
        "--u-lattice",
        type=float,
        default=defaults.u_lattice,
        help="inflow speed in lattice units (lattice Mach number = u_lattice * sqrt(3)); also sets the time step",
    )
    p.add_argument("--x-range", type=float, nargs=2, default=list(defaults.x_range), help="lattice x extent, D")
    p.add_argument("--y-half", type=float, default=defaults.y_half, help="lattice half-width in y (periodic), D")
    p.add_argument("--sponge", type=float, default=defaults.sponge, help="outlet sponge length, D")
    p.add_argument("--lattice", default=defaults.lattice, choices=["D3Q19", "D3Q27"], help="velocity set")
    p.add_argument("--seed", type=int, default=defaults.seed, help="seed of the initial perturbation")


def parser() -> argparse.ArgumentParser:
    top = _Parser(prog="python -m flownav.cfd", description=__doc__, formatter_class=_Help)
    top.add_argument("--threads", type=int, default=THREADS, help="torch / OpenMP threads")
    top.add_argument("--device", default=DEVICE, help=DEVICE_HELP)
    sub = top.add_subparsers(dest="cmd", required=True)

    gen = sub.add_parser(
        "generate",
        help="simulate and write a wake dataset",
        description=generate_description(),
        formatter_class=_Help,
    )
    _run_args(gen)
    g_def = GenerateConfig()
    _sim_args(gen, g_def.sim)
    gen.add_argument("--span", type=float, default=g_def.sim.span, help="periodic span Lz, D")
    gen.add_argument("--warmup", type=float, default=g_def.warmup, help="time before recording, D/U (whole steps)")
    gen.add_argument("--record", type=float, default=g_def.record, help="time recorded after the warm-up, D/U")
    gen.add_argument(
        "--frame-dt", type=float, default=g_def.frame_dt, help="time between stored frames, D/U (whole steps)"
    )
    gen.add_argument("--out-spacing", type=float, default=g_def.out_spacing, help="stored grid spacing, D")
    gen.add_argument(
        "--out",
        type=Path,
        default=argparse.SUPPRESS,
        help=f"dataset directory (default: <run-dir>/dataset); the shipped one only with --out {SHIPPED_DATASET}",
    )
    gen.add_argument("--run-dir", type=Path, default=DEFAULT_RUN_DIR, help="checkpoint and config of the run")
    gen.add_argument(
        "--checkpoint-every",
        type=float,
        default=CHECKPOINT_EVERY_S,
        help="wall-clock seconds between checkpoints (0: every sample); a kill loses at most this much",
    )

    val = sub.add_parser("validate", help="2D Re=100 run + 3D dataset check", formatter_class=_Help)
    _run_args(val)
    val.add_argument("--dataset", type=Path, default=SHIPPED_DATASET, help="3D dataset whose diagnostics to check")
    val.add_argument("--run-dir", type=Path, default=Path("runs/cfd/validate_2d_re100"), help="2D run directory")
    val.add_argument(
        "--out",
        type=Path,
        default=argparse.SUPPRESS,
        help="result JSON (default: <run-dir>/validation.json); the shipped one: --out results/cfd_validation.json",
    )
    val.add_argument(
        "--cells-per-d", type=int, default=argparse.SUPPRESS, help="2D resolution, cells per D (default: 10)"
    )

    plot = sub.add_parser("plot", help="wake figures", formatter_class=_Help)
    _run_args(plot)
    plot.add_argument("--dataset", type=Path, default=SHIPPED_DATASET, help="wake dataset to draw")
    plot.add_argument(
        "--out-dir",
        type=Path,
        default=Path("runs/cfd/figures"),
        help="where wake_*.png go (the README's figures: --out-dir docs/figures)",
    )
    plot.add_argument("--frame", type=int, default=0, help="frame index")
    return top


def main(argv=None) -> None:
    args = parser().parse_args(argv)
    with reported_as_one_line():
        try:
            _run(args)
        except FloatingPointError as e:  # a diverged run: the message says how to fix it
            raise ConfigError(str(e)) from e


def _run(args: argparse.Namespace) -> None:
    if args.threads < 1:
        raise ConfigError(f"--threads must be >= 1, got {args.threads}")
    torch.set_num_threads(args.threads)
    t0 = time.time()
    if args.cmd == "generate":
        from flownav.cfd.dataset import generate
        from flownav.cfd.validate import check_wake_3d, tolerance_warning

        if args.checkpoint_every < 0:
            raise ConfigError(f"--checkpoint-every must be >= 0 seconds, got {args.checkpoint_every}")
        sim = SimConfig(
            re=args.re,
            cells_per_d=args.cells_per_d,
            u_lattice=args.u_lattice,
            x_range=tuple(args.x_range),
            y_half=args.y_half,
            span=args.span,
            sponge=args.sponge,
            lattice=args.lattice,
            seed=args.seed,
        )
        cfg = GenerateConfig(
            sim=sim,
            warmup=args.warmup,
            record=args.record,
            frame_dt=args.frame_dt,
            out_spacing=args.out_spacing,
        )
        cfg.check()
        out = getattr(args, "out", args.run_dir / "dataset")
        diag = generate(cfg, out, args.run_dir, args.device, args.checkpoint_every)
        keys = (
            "St",
            "St_probe_spectrum",
            "Cd_mean",
            "Cl_rms",
            "rms_w_near_wake",
            "loop_seam_jump",
            "window_periods",
            "frames_per_period",
        )
        print(json.dumps({k: diag[k] for k in keys}, indent=2))
        print(f"wrote {out} in {time.time() - t0:.0f} s")
        warning = tolerance_warning(check_wake_3d(diag), sim.re)
        if warning:
            print(warning, file=sys.stderr, flush=True)
    elif args.cmd == "validate":
        from flownav.cfd.validate import validate

        out = getattr(args, "out", args.run_dir / "validation.json")
        result = validate(args.dataset, out, args.run_dir, getattr(args, "cells_per_d", None), args.device)
        print(json.dumps(result["summary"], indent=2))
        print(f"wrote {out}")
        if not result["summary"]["all_passed"]:
            raise SystemExit(1)
    elif args.cmd == "plot":
        from flownav.cfd.plot import plot_wake

        for path in plot_wake(args.dataset, args.out_dir, args.frame):
            print(f"wrote {path}")


if __name__ == "__main__":
    main()
