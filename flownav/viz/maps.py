"""Success maps over subregions of the start position (the paper's Fig. 4 and SI 2)."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.ticker import MaxNLocator

from flownav.viz.fields import AXIS_LABELS, VORTICITY_CMAP, VORTICITY_LABEL, draw_obstacles, symmetric_levels, xy_slice


def _rate(maps_entry):
    n = np.asarray(maps_entry["episodes"], dtype=float)
    k = np.asarray(maps_entry["successes"], dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        return k / n, n, k


def plot_success_maps(maps: dict, flow, target, out_prefix: Path, title: str = "", cols: int = 3) -> list[str]:
    """Per policy: a z-pooled map (successes / episodes over all z cells of each x-y column) over the
    z-vorticity of the plane through the target, in a grid of ``cols`` columns; and the 10 z-layers of
    the 3D map. Returns the files."""
    out_prefix = Path(out_prefix)
    out_prefix.parent.mkdir(parents=True, exist_ok=True)
    b = flow.bounds
    extent = (b.lo[0], b.hi[0], b.lo[1], b.hi[1])
    X, Y, _, omega = xy_slice(flow, float(target[2]), 0.0, extent)
    om, levels = symmetric_levels(omega)
    files = []
    names = list(maps)
    cols = min(cols, len(names))
    rows = -(-len(names) // cols)
    fig, axes = plt.subplots(
        rows,
        cols,
        figsize=(4.4 * cols + 2.4, 2.6 * rows + 0.6),
        squeeze=False,
        sharex=True,
        sharey=True,
        layout="constrained",
    )
    for j, ax in enumerate(axes.flat):
        if j >= len(names):
            ax.axis("off")
            continue
        name = names[j]
        _, n, k = _rate(maps[name])
        with np.errstate(invalid="ignore", divide="ignore"):
            pooled = k.sum(2) / n.sum(2)
        bg = ax.pcolormesh(X, Y, om, cmap=VORTICITY_CMAP, vmin=levels[0], vmax=levels[-1], alpha=0.45)
        im = ax.imshow(pooled.T, origin="lower", extent=extent, cmap="Greens", vmin=0, vmax=1, alpha=0.75)
        draw_obstacles(ax, flow)
        ax.plot(target[0], target[1], "*", color="gold", ms=14, mec="k")
        overall = k.sum() / max(n.sum(), 1)
        ax.set_title(f"{name}: {100 * overall:.1f}% overall", fontsize=10)
        ax.set_aspect("equal")
        if j + cols >= len(names):  # the lowest panel of its column
            ax.xaxis.set_tick_params(labelbottom=True)
    fig.colorbar(im, ax=axes, label="success rate (pooled over z)", shrink=0.7)
    fig.colorbar(bg, ax=axes, label=VORTICITY_LABEL + " at the target's z", shrink=0.7, ticks=MaxNLocator(5))
    fig.supxlabel(AXIS_LABELS[0])
    fig.supylabel(AXIS_LABELS[1])
    fig.suptitle(title)
    f = out_prefix.with_name(out_prefix.name + "_xy.png")
    fig.savefig(f, dpi=110)
    plt.close(fig)
    files.append(str(f))
    for name in names:
        rate, n, _ = _rate(maps[name])
        nz = rate.shape[2]
        cols = min(nz, 5)
        rows = int(np.ceil(nz / cols))
        fig, axes = plt.subplots(
            rows, cols, figsize=(3.2 * cols + 1, 2.0 * rows + 0.6), squeeze=False, layout="constrained"
        )
        zs = np.linspace(b.lo[2], b.hi[2], nz + 1)
        for iz in range(rows * cols):
            ax = axes[iz // cols][iz % cols]
            if iz >= nz:
                ax.axis("off")
                continue
            im = ax.imshow(rate[:, :, iz].T, origin="lower", extent=extent, cmap="Greens", vmin=0, vmax=1)
            draw_obstacles(ax, flow)
            if zs[iz] <= target[2] <= zs[iz + 1]:
                ax.plot(target[0], target[1], "*", color="gold", ms=10, mec="k")
            ax.set_title(f"z / D in [{zs[iz]:.0f}, {zs[iz + 1]:.0f}]", fontsize=8)
            ax.tick_params(labelsize=6)
            if iz // cols == rows - 1:
                ax.set_xlabel(AXIS_LABELS[0], fontsize=7)
            if iz % cols == 0:
                ax.set_ylabel(AXIS_LABELS[1], fontsize=7)
        fig.colorbar(im, ax=axes, shrink=0.6, label="success rate")
        fig.suptitle(f"{title}: {name}, success per subregion ({'x'.join(str(s) for s in rate.shape)})")
        f = out_prefix.with_name(f"{out_prefix.name}_{name}_layers.png")
        fig.savefig(f, dpi=100)
        plt.close(fig)
        files.append(str(f))
    return files
