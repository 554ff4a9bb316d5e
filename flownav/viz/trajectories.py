"""Trajectory figures (Figs. 3, 5a-d, 6a) and a movie of one episode.

A trajectory is the ``trajectories`` dict of :func:`flownav.evaluation.rollout.run_episodes`:
``position`` [k, T+1, 3], ``velocity`` [k, T+1, 3], ``heading`` [k, T+1, 2], ``alive`` [k, T+1],
``time`` [T+1], ``target`` [k, 3], ``status`` [k], ``t0`` [k].
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import torch
from matplotlib.ticker import MaxNLocator

from flownav.envs.kinematics import body_frame, to_body
from flownav.envs.navigation import Status
from flownav.flows.transforms import RotatedFlow
from flownav.viz.colors import MARKERS, policy_color
from flownav.viz.fields import (
    AXIS_LABELS,
    VORTICITY_CMAP,
    VORTICITY_LABEL,
    draw_obstacles,
    symmetric_levels,
    xy_slice,
)


def _path(traj, i: int = 0) -> np.ndarray:
    alive = traj["alive"][i].numpy()
    return traj["position"][i].numpy()[alive]


def _cylinder_3d(ax, flow, z0: float, z1: float) -> None:
    for ob in getattr(flow, "obstacles", ()):
        th = np.linspace(0, 2 * np.pi, 40)
        zz = np.linspace(z0, z1, 2)
        T, Z = np.meshgrid(th, zz)
        ax.plot_surface(
            ob.center[0] + ob.radius * np.cos(T),
            ob.center[1] + ob.radius * np.sin(T),
            Z,
            color="0.5",
            alpha=0.5,
            linewidth=0,
        )


# Several policies' paths often overlap: earlier ones are drawn wider and below, and each policy
# carries its own marker every few steps, so none hides another.


def _line_style(i: int, n: int, ok: bool) -> dict:
    return {
        "ls": "-" if ok else "--",
        "lw": 1.2 + 1.0 * (n - 1 - i),
        "zorder": 3 + i,
        "marker": MARKERS[i % len(MARKERS)],
        "markevery": 12,
        "ms": 4,
    }


def _draw_episodes(traj, panels) -> int:
    """Each recorded episode of ``traj`` on every ``(axes, (u, v))`` panel, one colour per episode: its path (solid:
    reached the target, dashed: failed), start and target. Returns how many reached the target."""
    wins = 0
    for i in range(traj["position"].shape[0]):
        p, tg = _path(traj, i), traj["target"][i].numpy()
        ok = int(traj["status"][i]) == Status.SUCCESS
        wins += ok
        for a, (u, v) in panels:
            a.plot(p[:, u], p[:, v], "-" if ok else "--", color=f"C{i}", lw=1.2)
            a.plot(p[0, u], p[0, v], "o", color=f"C{i}", ms=3)
            a.plot(tg[u], tg[v], "*", color=f"C{i}", ms=9, mec="k")
    return wins


def style_legend_handles() -> list:
    """Legend entries for what line styles and markers mean (the policies have their own entries)."""
    from matplotlib.lines import Line2D

    return [
        Line2D([], [], color="k", ls="-", label="reached the target"),
        Line2D([], [], color="k", ls="--", label="failed"),
        Line2D([], [], color="k", marker="o", ls="", label="start"),
        Line2D([], [], color="gold", marker="*", mec="k", ms=12, ls="", label="target"),
    ]


def plot_trajectories_3d(runs: dict, flow, out: Path, title: str = "") -> str:
    """One episode per policy (same start and target): in 3D, and in x-y over the z-vorticity of the
    start plane at the start time (colorbar), in two panels of equal size."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    b = flow.bounds
    fig = plt.figure(figsize=(13, 5.2))
    grid = fig.add_gridspec(1, 3, width_ratios=(1, 1, 0.04), wspace=0.25)
    ax = fig.add_subplot(grid[0], projection="3d")
    ax2 = fig.add_subplot(grid[1])
    cax = fig.add_subplot(grid[2])
    first = next(iter(runs.values()))
    start = first["position"][0, 0].numpy()
    target = first["target"][0].numpy()
    X, Y, _, om = xy_slice(flow, float(start[2]), float(first["t0"][0]), (b.lo[0], b.hi[0], b.lo[1], b.hi[1]))
    om, levels = symmetric_levels(om)
    bg = ax2.contourf(X, Y, om, levels=levels, cmap=VORTICITY_CMAP)
    fig.colorbar(bg, cax=cax, label=VORTICITY_LABEL, ticks=MaxNLocator(5, symmetric=True))
    draw_obstacles(ax2, flow)
    _cylinder_3d(ax, flow, b.lo[2], b.hi[2])
    handles = []
    for i, (name, traj) in enumerate(runs.items()):
        p = _path(traj)
        status = Status(int(traj["status"][0])).name.lower()
        style = _line_style(i, len(runs), status == "success")
        color = policy_color(name, i)
        (h,) = ax.plot(p[:, 0], p[:, 1], p[:, 2], color=color, label=f"{name} ({status})", **style)
        ax2.plot(p[:, 0], p[:, 1], color=color, mec="k", mew=0.3, **style)
        handles.append(h)
    for a in (ax, ax2):
        z = (([start[2]],), ([target[2]],)) if a is ax else ((), ())
        a.plot([start[0]], [start[1]], *z[0], "o", color="k", zorder=10)
        a.plot([target[0]], [target[1]], *z[1], "*", color="gold", ms=14, mec="k", zorder=10)
    ax.set_xlim(b.lo[0], b.hi[0])
    ax.set_ylim(b.lo[1], b.hi[1])
    ax.set_zlim(b.lo[2], b.hi[2])
    ax.set_box_aspect(b.size, zoom=1.1)
    ax.set_xlabel(AXIS_LABELS[0])
    ax.set_ylabel(AXIS_LABELS[1])
    ax.set_zlabel(AXIS_LABELS[2])
    ax2.set_xlabel(AXIS_LABELS[0])
    ax2.set_ylabel(AXIS_LABELS[1])
    ax2.set_aspect("equal")
    t0 = float(first["t0"][0])
    ax2.set_title(f"x-y, over the z-vorticity at z = {start[2]:.1f} D, t = {t0:.1f} D/U", fontsize=9)
    fig.legend(handles=handles + style_legend_handles(), loc="lower center", ncol=4, fontsize=8, frameon=False)
    fig.suptitle(title)
    fig.subplots_adjust(left=0.0, right=0.93, top=0.9, bottom=0.17)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return str(out)


def body_velocity(traj, i: int = 0) -> np.ndarray:
    """Velocity in the body frame (the ego view's velocity) along one recorded trajectory."""
    h = traj["heading"][i]
    frame = body_frame(h[:, 0], h[:, 1])
    return to_body(frame, traj["velocity"][i]).numpy()


def plot_velocity_traces(runs: dict, out: Path) -> str:
    """Fig. 3c: velocity of each policy's episode in the inertial frame (top) and the body frame (bottom)."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    names = list(runs)
    fig, axes = plt.subplots(2, len(names), figsize=(4.2 * len(names), 5.2), squeeze=False, sharex="col")
    for j, name in enumerate(names):
        traj = runs[name]
        alive = traj["alive"][0].numpy()
        t = traj["time"].numpy()[alive]
        ve = traj["velocity"][0].numpy()[alive]
        vb = body_velocity(traj)[alive]
        for c, comp in enumerate("xyz"):
            axes[0][j].plot(t, ve[:, c], label=f"v_e,{comp}")
            axes[1][j].plot(t, vb[:, c], label=f"v_b,{comp}")
        axes[0][j].set_title(f"{name} ({Status(int(traj['status'][0])).name.lower()})")
        for r in range(2):
            axes[r][j].axhline(0, color="k", lw=0.5)
            axes[r][j].grid(alpha=0.3)
            axes[r][j].legend(fontsize=7)
        axes[1][j].set_xlabel("t (D / U)")
    axes[0][0].set_ylabel("inertial (geo) velocity / U")
    axes[1][0].set_ylabel("body-frame (ego) velocity / U")
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return str(out)


def _rotated_box(flow):
    b = flow.bounds
    corners = torch.tensor(
        [
            [b.lo[0], b.lo[1], 0],
            [b.hi[0], b.lo[1], 0],
            [b.hi[0], b.hi[1], 0],
            [b.lo[0], b.hi[1], 0],
            [b.lo[0], b.lo[1], 0],
        ],
        dtype=torch.float32,
    )
    return corners


def plot_misaligned(runs: dict, flow, out: Path) -> str:
    """Figs. 5a-d: x-y trajectories of each policy (rows) at each misalignment angle (columns).

    Solid: success; dashed: failure. The rotated domain and cylinder are drawn in the inertial frame."""
    from flownav.flows.transforms import rotate_z

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    pols = list(dict.fromkeys(k[0] for k in runs))
    angles = list(dict.fromkeys(k[1] for k in runs))
    fig, axes = plt.subplots(
        len(pols), len(angles), figsize=(3.2 * len(angles), 3.0 * len(pols) + 0.4), squeeze=False, layout="constrained"
    )
    box = _rotated_box(flow)
    # One extent for every panel (the union of the rotated domains): panels of equal size and scale.
    corners = torch.cat([rotate_z(box, math.radians(a), (0.0, 0.0)) for a in angles]).numpy()
    lo, hi = corners.min(0) - 0.5, corners.max(0) + 0.5
    for r, pol in enumerate(pols):
        for c, angle in enumerate(angles):
            ax = axes[r][c]
            traj = runs[(pol, angle)]
            rb = rotate_z(box, math.radians(angle), (0.0, 0.0)).numpy()
            ax.plot(rb[:, 0], rb[:, 1], color="0.6", lw=0.8)
            for ob in getattr(flow, "obstacles", ()):
                cen = rotate_z(torch.tensor([[*ob.center, 0.0]]), math.radians(angle), (0.0, 0.0))[0]
                ax.add_patch(plt.Circle((float(cen[0]), float(cen[1])), ob.radius, color="0.3"))
            wins = _draw_episodes(traj, [(ax, (0, 1))])
            ax.set_xlim(lo[0], hi[0])
            ax.set_ylim(lo[1], hi[1])
            ax.set_aspect("equal")
            ax.set_title(f"{pol}, {angle:g} deg: {wins}/{traj['position'].shape[0]}", fontsize=9)
            ax.tick_params(labelsize=6)
            if r == len(pols) - 1:
                ax.set_xlabel(AXIS_LABELS[0], fontsize=8)
            if c == 0:
                ax.set_ylabel(AXIS_LABELS[1], fontsize=8)
    _episode_legend(fig)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return str(out)


def plot_abc(runs: dict, flow, out: Path) -> str:
    """Fig. 6a: episodes of each policy in the ABC flow (x-y and x-z projections over the speed)."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    b = flow.bounds
    pols = list(runs)
    fig, axes = plt.subplots(len(pols), 2, figsize=(11, 2.9 * len(pols) + 0.4), squeeze=False, layout="constrained")
    first = next(iter(runs.values()))
    z = float(first["position"][0, 0, 2])
    X, Y, speed, _ = xy_slice(flow, z, float(first["t0"][0]), (b.lo[0], b.hi[0], b.lo[1], b.hi[1]))
    for r, pol in enumerate(pols):
        traj = runs[pol]
        ax, axz = axes[r]
        bg = ax.contourf(X, Y, speed, levels=20, cmap="Greys", alpha=0.6)
        wins = _draw_episodes(traj, [(ax, (0, 1)), (axz, (0, 2))])
        ax.set_title(f"{pol}: {wins}/{traj['position'].shape[0]} reached (x-y, speed at z={z:.2f})", fontsize=9)
        axz.set_title(f"{pol} (x-z)", fontsize=9)
        ax.set_xlim(b.lo[0], b.hi[0])
        ax.set_ylim(b.lo[1], b.hi[1])
        axz.set_xlim(b.lo[0], b.hi[0])
        axz.set_ylim(b.lo[2], b.hi[2])
        for a, (u, v) in ((ax, (0, 1)), (axz, (0, 2))):
            a.set_xlabel("xyz"[u], fontsize=8)  # the ABC flow's own length unit: no cylinder, no D
            a.set_ylabel("xyz"[v], fontsize=8)
            a.set_aspect("equal")
    fig.colorbar(bg, ax=axes, label="flow speed |u|", ticks=MaxNLocator(4), shrink=0.8)
    _episode_legend(fig)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return str(out)


def _episode_legend(fig) -> None:
    """Below the panels: what line styles and markers mean when each colour is one episode."""
    from matplotlib.lines import Line2D

    colour = Line2D([], [], color="0.5", lw=0, label="colour: one episode")
    fig.legend(handles=[colour, *style_legend_handles()], loc="outside lower center", ncol=5, fontsize=8, frameon=False)


def make_movie(traj, flow, out: Path, title: str = "", frames: int = 60, fps: int = 10) -> str:
    """An MP4 (H.264, through imageio-ffmpeg) of one episode: the x-y path over the z-vorticity at the
    swimmer's height and flow time, one colour scale for the whole movie (its colorbar alongside)."""
    import imageio.v2 as imageio  # the [viz] extra

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    b = flow.bounds
    p = _path(traj)
    t = traj["time"].numpy()[traj["alive"][0].numpy()]
    t0 = float(traj["t0"][0])
    idx = np.unique(np.linspace(0, len(p) - 1, min(frames, len(p))).round().astype(int))
    extent = (b.lo[0], b.hi[0], b.lo[1], b.hi[1])
    tg = traj["target"][0].numpy()
    _, levels = symmetric_levels(xy_slice(flow, float(p[0, 2]), t0, extent, n=(120, 72))[3], 21)
    norm = plt.Normalize(levels[0], levels[-1])
    # 800 x 480 pixels: H.264 wants sides divisible by 16.
    fig, ax = plt.subplots(figsize=(8, 4.8), dpi=100, layout="constrained")
    fig.colorbar(plt.cm.ScalarMappable(norm, VORTICITY_CMAP), ax=ax, label=VORTICITY_LABEL, shrink=0.8)
    with imageio.get_writer(out, fps=fps, codec="libx264", quality=8, macro_block_size=16) as writer:
        for i in idx:
            ax.clear()
            X, Y, _, om = xy_slice(flow, float(p[i, 2]), t0 + float(t[i]), extent, n=(120, 72))
            ax.contourf(X, Y, np.clip(om, levels[0], levels[-1]), levels=levels, cmap=VORTICITY_CMAP, norm=norm)
            draw_obstacles(ax, flow)
            ax.plot(p[: i + 1, 0], p[: i + 1, 1], color="k", lw=1.5)
            ax.plot(p[i, 0], p[i, 1], "o", color="tab:orange", ms=7, mec="k")
            ax.plot(tg[0], tg[1], "*", color="gold", ms=14, mec="k")
            ax.set_xlim(extent[0], extent[1])
            ax.set_ylim(extent[2], extent[3])
            ax.set_aspect("equal")
            ax.set_xlabel("x / D")
            ax.set_ylabel("y / D")
            ax.set_title(f"{title}  t = {t[i]:.1f} D/U, z = {p[i, 2]:.2f} D", fontsize=9)
            fig.canvas.draw()
            writer.append_data(np.asarray(fig.canvas.buffer_rgba())[..., :3])
    plt.close(fig)
    return str(out)


__all__ = [
    "RotatedFlow",
    "body_velocity",
    "make_movie",
    "plot_abc",
    "plot_misaligned",
    "plot_trajectories_3d",
    "plot_velocity_traces",
]
