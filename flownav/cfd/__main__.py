"""Command line: ``python -m flownav.cfd {generate,validate,plot}``.

generate  run the 3D Re = 300 wake (resumes from runs/cfd/...) and write data/cylinder_re300
validate  2D Re = 100 check against the literature + the shipped 3D dataset's diagnostics
plot      z-vorticity slice and Q-criterion view of the shipped wake -> docs/figures/
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import torch

from flownav.cfd.dataset import DEFAULT_OUT, DEFAULT_RUN_DIR, GenerateConfig
from flownav.cfd.solver import SimConfig


def _sim_args(p: argparse.ArgumentParser, defaults: SimConfig) -> None:
    p.add_argument("--re", type=float, default=defaults.re)
    p.add_argument("--cells-per-d", type=int, default=defaults.cells_per_d)
    p.add_argument("--u-lattice", type=float, default=defaults.u_lattice)
    p.add_argument("--x-range", type=float, nargs=2, default=list(defaults.x_range))
    p.add_argument("--y-half", type=float, default=defaults.y_half)
    p.add_argument("--sponge", type=float, default=defaults.sponge)
    p.add_argument("--lattice", default=defaults.lattice, choices=["D3Q19", "D3Q27"])
    p.add_argument("--seed", type=int, default=defaults.seed)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m flownav.cfd",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--threads", type=int, default=2, help="torch / OpenMP threads")
    parser.add_argument("--device", default="cpu")
    sub = parser.add_subparsers(dest="cmd", required=True)

    gen = sub.add_parser("generate", help="simulate and write the default dataset")
    g_def = GenerateConfig()
    _sim_args(gen, g_def.sim)
    gen.add_argument("--span", type=float, default=g_def.sim.span)
    gen.add_argument("--warmup", type=float, default=g_def.warmup)
    gen.add_argument("--record", type=float, default=g_def.record)
    gen.add_argument("--frame-dt", type=float, default=g_def.frame_dt)
    gen.add_argument("--out-spacing", type=float, default=g_def.out_spacing)
    gen.add_argument("--out", type=Path, default=DEFAULT_OUT)
    gen.add_argument("--run-dir", type=Path, default=DEFAULT_RUN_DIR)

    val = sub.add_parser("validate", help="2D Re=100 run + 3D dataset check -> results/cfd_validation.json")
    val.add_argument("--dataset", type=Path, default=DEFAULT_OUT)
    val.add_argument("--out", type=Path, default=Path("results/cfd_validation.json"))
    val.add_argument("--run-dir", type=Path, default=Path("runs/cfd/validate_2d_re100"))
    val.add_argument("--cells-per-d", type=int, default=None, help="2D resolution (default in validate.py)")

    plot = sub.add_parser("plot", help="wake figures -> docs/figures/wake_*.png")
    plot.add_argument("--dataset", type=Path, default=DEFAULT_OUT)
    plot.add_argument("--out-dir", type=Path, default=Path("docs/figures"))
    plot.add_argument("--frame", type=int, default=0)

    args = parser.parse_args(argv)
    try:
        _run(args)
    except (ValueError, FloatingPointError) as e:  # bad input or a diverged run: say how to fix it
        raise SystemExit(f"error: {e}") from None


def _run(args: argparse.Namespace) -> None:
    torch.set_num_threads(args.threads)
    t0 = time.time()
    if args.cmd == "generate":
        from flownav.cfd.dataset import generate

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
        diag = generate(cfg, args.out, args.run_dir, args.device)
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
        print(f"wrote {args.out} in {time.time() - t0:.0f} s")
    elif args.cmd == "validate":
        from flownav.cfd.validate import validate

        result = validate(args.dataset, args.out, args.run_dir, args.cells_per_d, args.device)
        print(json.dumps(result["summary"], indent=2))
        if not result["summary"]["all_passed"]:
            raise SystemExit(1)
    elif args.cmd == "plot":
        from flownav.cfd.plot import plot_wake

        for path in plot_wake(args.dataset, args.out_dir, args.frame):
            print(f"wrote {path}")


if __name__ == "__main__":
    main()
