"""Flow fields sampled on planes, for figure backgrounds."""

from __future__ import annotations

import torch

from flownav.flows.base import FlowField


@torch.inference_mode()
def xy_slice(flow: FlowField, z: float, t: float, extent, n: tuple[int, int] = (200, 120)):
    """Speed and z-vorticity on the plane ``z`` at time ``t``: (X, Y, speed, omega_z) as numpy arrays.

    ``extent`` is (x0, x1, y0, y1). Vorticity by central differences of the sampled field.
    """
    x0, x1, y0, y1 = extent
    xs, ys = torch.linspace(x0, x1, n[0]), torch.linspace(y0, y1, n[1])
    X, Y = torch.meshgrid(xs, ys, indexing="xy")
    pos = torch.stack((X, Y, torch.full_like(X, z)), -1).reshape(-1, 3)
    device = getattr(flow, "device", pos.device)  # a grid flow may live on the GPU
    pos = pos.to(device)
    v = flow.velocity(pos, torch.full((pos.shape[0],), float(t), device=device)).cpu().reshape(n[1], n[0], 3)
    speed = v.norm(dim=-1)
    dvdx = torch.gradient(v[..., 1], spacing=(xs[1] - xs[0]).item(), dim=1)[0]
    dudy = torch.gradient(v[..., 0], spacing=(ys[1] - ys[0]).item(), dim=0)[0]
    omega = dvdx - dudy
    return X.numpy(), Y.numpy(), speed.numpy(), omega.numpy()


def symmetric_levels(field, n: int = 31, pct: float = 99.0):
    """(field clipped to +-lim, n contour levels over [-lim, lim]), lim the ``pct`` percentile of |field|."""
    import numpy as np

    lim = float(np.nanpercentile(np.abs(field), pct)) or 1.0
    return np.clip(field, -lim, lim), np.linspace(-lim, lim, n)


# One look for every figure of the flow: the colour map and labels of z-vorticity, and lengths in D.
VORTICITY_CMAP = "RdBu_r"
VORTICITY_LABEL = r"$\omega_z D / U$"
AXIS_LABELS = ("x / D", "y / D", "z / D")


def draw_obstacles(ax, flow) -> None:
    """The flow's cylinders as grey discs on an x-y axis."""
    import matplotlib.pyplot as plt

    for ob in getattr(flow, "obstacles", ()):
        ax.add_patch(plt.Circle(ob.center, ob.radius, color="0.3", zorder=2))
