"""Trajectories over the flow as a self-contained interactive 3D page (plotly, no network needed).

:func:`trajectories_html` writes one HTML file with plotly.js embedded: the recorded episodes of each
policy (one colour per policy as in the static figures; solid: reached the target, dashed: failed),
start (black) and target (gold) markers, the obstacles, and the flow at the first episode's start
time: iso-surfaces of the z-vorticity ``omega_z D / U`` at +-``iso`` of its 99th percentile (red
positive, blue negative) and a horizontal slice of it at the first start's height. Needs the
``[viz]`` extra.

From the command line (Hydra overrides of the project's config pick the flow, task and env)::

    python -m flownav.viz.interactive --checkpoint checkpoints/teacher.pt --checkpoint checkpoints/student.pt \\
        --out results/html/wake.html flow=cylinder
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch
from matplotlib.colors import to_hex

from flownav.envs.navigation import Status
from flownav.flows.base import FlowField
from flownav.viz.colors import policy_color

START_COLOR, TARGET_COLOR = "black", "gold"
VORTICITY_SCALE = "RdBu_r"


@torch.inference_mode()
def vorticity_z_grid(flow: FlowField, t: float, n: tuple[int, int, int] = (72, 40, 28)):
    """(x, y, z, omega_z) on an ``n`` grid over the flow's domain (1D axes, omega_z [nx, ny, nz]).

    Central differences of the sampled velocity, as the static figures' slices (viz.fields)."""
    b = flow.bounds
    axes = [torch.linspace(lo, hi, k) for lo, hi, k in zip(b.lo, b.hi, n, strict=True)]
    X, Y, Z = torch.meshgrid(*axes, indexing="ij")
    pos = torch.stack((X, Y, Z), -1).reshape(-1, 3)
    v = flow.velocity(pos, torch.full((pos.shape[0],), float(t))).reshape(*n, 3)
    dx, dy = (axes[0][1] - axes[0][0]).item(), (axes[1][1] - axes[1][0]).item()
    omega = torch.gradient(v[..., 1], spacing=dx, dim=0)[0] - torch.gradient(v[..., 0], spacing=dy, dim=1)[0]
    return *(a.numpy() for a in axes), omega.numpy()


def trajectories_figure(runs: dict, flow: FlowField, title: str = "", iso: float = 0.5, grid=(72, 40, 28)):
    """The plotly Figure of :func:`trajectories_html` (``runs``: policy name -> recorded trajectories)."""
    import plotly.graph_objects as go  # the [viz] extra

    first = next(iter(runs.values()))
    t0 = float(first["t0"][0])
    start_z = float(first["position"][0, 0, 2])
    xs, ys, zs, om = vorticity_z_grid(flow, t0, grid)
    lim = float(np.percentile(np.abs(om), 99)) or 1.0
    X, Y, Z = np.meshgrid(xs, ys, zs, indexing="ij")
    colorbar = {"title": {"text": "omega_z D / U"}, "len": 0.6, "x": 0.0}
    fig = go.Figure()
    fig.add_trace(
        go.Isosurface(
            x=X.ravel(),
            y=Y.ravel(),
            z=Z.ravel(),
            value=om.ravel(),
            isomin=-iso * lim,
            isomax=iso * lim,
            surface_count=2,
            cmin=-lim,
            cmax=lim,
            colorscale=VORTICITY_SCALE,
            opacity=0.25,
            caps={"x_show": False, "y_show": False, "z_show": False},
            colorbar=colorbar,
            name=f"omega_z = +-{iso * lim:.2f}",
            showlegend=True,
        )
    )
    k = int(np.abs(zs - start_z).argmin())
    sx, sy = np.meshgrid(xs, ys, indexing="ij")
    fig.add_trace(
        go.Surface(
            x=sx,
            y=sy,
            z=np.full_like(sx, zs[k]),
            surfacecolor=np.clip(om[:, :, k], -lim, lim),
            cmin=-lim,
            cmax=lim,
            colorscale=VORTICITY_SCALE,
            opacity=0.55,
            showscale=False,
            name=f"omega_z at z = {zs[k]:.1f}",
            showlegend=True,
        )
    )
    for ob in getattr(flow, "obstacles", ()):
        th, zz = np.meshgrid(np.linspace(0, 2 * np.pi, 40), [flow.bounds.lo[2], flow.bounds.hi[2]])
        fig.add_trace(
            go.Surface(
                x=ob.center[0] + ob.radius * np.cos(th),
                y=ob.center[1] + ob.radius * np.sin(th),
                z=zz,
                colorscale=[[0, "gray"], [1, "gray"]],
                showscale=False,
                name="obstacle",
                showlegend=True,
            )
        )
    for i, (name, traj) in enumerate(runs.items()):
        color = to_hex(policy_color(name, i))
        for e in range(traj["position"].shape[0]):
            alive = traj["alive"][e].numpy()
            p = traj["position"][e].numpy()[alive]
            status = Status(int(traj["status"][e])).name.lower()
            ok = status == "success"
            fig.add_trace(
                go.Scatter3d(
                    x=p[:, 0],
                    y=p[:, 1],
                    z=p[:, 2],
                    mode="lines",
                    line={"color": color, "width": 6, "dash": "solid" if ok else "dash"},
                    name=f"{name} ({status})",
                    legendgroup=name,
                    showlegend=e == 0,
                )
            )
    starts = np.concatenate([tr["position"][:, 0].numpy() for tr in runs.values()])
    targets = np.concatenate([tr["target"].numpy() for tr in runs.values()])
    for label, pts, color, symbol in (
        ("start", starts, START_COLOR, "circle"),
        ("target", targets, TARGET_COLOR, "diamond"),
    ):
        pts = np.unique(pts.round(6), axis=0)
        fig.add_trace(
            go.Scatter3d(
                x=pts[:, 0],
                y=pts[:, 1],
                z=pts[:, 2],
                mode="markers",
                marker={"color": color, "size": 7, "symbol": symbol, "line": {"color": "black", "width": 1}},
                name=label,
            )
        )
    b = flow.bounds
    size = np.array(b.size)
    fig.update_layout(
        title={"text": title},
        scene={
            "xaxis": {"title": {"text": "x / D"}, "range": [b.lo[0], b.hi[0]]},
            "yaxis": {"title": {"text": "y / D"}, "range": [b.lo[1], b.hi[1]]},
            "zaxis": {"title": {"text": "z / D"}, "range": [b.lo[2], b.hi[2]]},
            "aspectmode": "manual",
            "aspectratio": dict(zip("xyz", (size / size.max()).tolist(), strict=True)),
            "camera": {"eye": {"x": -0.75, "y": -1.25, "z": 0.65}, "center": {"x": 0.05, "y": 0, "z": -0.1}},
        },
        legend={"x": 0.82, "y": 0.95},
        margin={"l": 0, "r": 0, "t": 40, "b": 0},
    )
    return fig


def trajectories_html(runs: dict, flow: FlowField, out, title: str = "", **kwargs) -> str:
    """Write the self-contained page (plotly.js inline, no CDN) and return its path."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig = trajectories_figure(runs, flow, title, **kwargs)
    fig.write_html(out, include_plotlyjs="inline", full_html=True)
    return str(out)


def main(argv=None) -> str:
    p = argparse.ArgumentParser(
        prog="python -m flownav.viz.interactive",
        description="Roll out policies from the same starts and write the interactive 3D page.",
        epilog="Other arguments are Hydra overrides of conf/config.yaml (flow=..., task=..., env.time_limit=...).",
    )
    p.add_argument("--checkpoint", action="append", required=True, help="a policy checkpoint (repeat for several)")
    p.add_argument(
        "--out", default="outputs/html/trajectories.html", help="the HTML file to write (default: %(default)s)"
    )
    p.add_argument(
        "--episodes", type=int, default=1, help="episodes per policy (same starts and targets; default: %(default)s)"
    )
    p.add_argument(
        "--seed", type=int, default=0, help="evaluation seed: starts, targets, flow phase (default: %(default)s)"
    )
    a, overrides = p.parse_known_args(argv)
    from flownav.builders import build_flow, build_task, compose_config
    from flownav.checkpoint import load_policy
    from flownav.evaluation.protocol import EvalSpec, evaluate
    from flownav.paths import resolve

    torch.set_num_threads(1)
    cfg = compose_config(overrides)
    flow = build_flow(cfg.flow)
    spec = EvalSpec(flow, build_task(cfg.task, flow), cfg.env, a.episodes, seed=a.seed)
    runs = {}
    for path in a.checkpoint:
        policy, payload = load_policy(resolve(path))
        runs[Path(path).stem] = evaluate(policy, payload["obs"], spec, record=a.episodes).episodes.trajectories
    flow_name = cfg.flow.get("path") or cfg.flow.get("type")
    out = trajectories_html(runs, flow, a.out, title=f"{', '.join(runs)} in {flow_name} (seed {a.seed})")
    print(out)
    return out


if __name__ == "__main__":
    main()
