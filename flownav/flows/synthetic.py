"""A synthetic stand-in for the cylinder wake, for tests and benchmarks: built in a second at any grid size,
smooth, unsteady and looped in time like the CFD dataset, on the wake's box with its cylinder.

    flow = synthetic_wake()                                       # a small GridFlow
    save_grid_flow(path, **synthetic_wake_grid(frames=4))         # the same field as a dataset on disk
"""

from __future__ import annotations

import numpy as np

from flownav.flows.base import WAKE_BOUNDS, Cylinder
from flownav.flows.grid import GridFlow


def synthetic_wake_grid(
    frames: int = 6,
    cells: tuple[int, int] = (21, 13),
    span_cells: int = 8,
    span: float = 4.0,
    frame_dt: float = 0.5,
    strength: float = 1.0,
) -> dict:
    """The keyword arguments of ``GridFlow`` and ``save_grid_flow`` for a field on ``WAKE_BOUNDS``.

    ``cells`` points over x and y (box edges included), ``span_cells`` points over a z period of ``span``
    (tiled over the box, like the CFD wake's span), ``frames`` frames ``frame_dt`` apart, looped. The field
    is a free stream of 0.8 along +x with a pattern drifting across it, times ``strength`` (0.002: swimmers
    that do not swim stay in the box until their time limit).
    """
    lo, hi = WAKE_BOUNDS.lo, WAKE_BOUNDS.hi
    nx, ny = cells
    f32 = np.float32
    t = (np.arange(frames, dtype=f32) / frames * 2 * np.pi)[:, None, None, None]  # looped: frame `frames` is 0
    x = np.linspace(0, 2 * np.pi, nx, dtype=f32)[None, :, None, None]
    y = np.linspace(0, 2 * np.pi, ny, dtype=f32)[None, None, :, None]
    z = (np.arange(span_cells, dtype=f32) / span_cells * 2 * np.pi)[None, None, None, :]  # periodic: no end point
    velocity = np.empty((frames, nx, ny, span_cells, 3), dtype=f32)
    velocity[..., 0] = 0.8 + 0.3 * np.sin(y + t) * np.cos(z)
    velocity[..., 1] = 0.3 * np.sin(x - t) + 0.1 * np.cos(z)
    velocity[..., 2] = 0.2 * np.cos(x + y - t)
    velocity *= f32(strength)
    gx = np.linspace(lo[0], hi[0], nx)[:, None]
    gy = np.linspace(lo[1], hi[1], ny)[None, :]
    velocity[:, gx**2 + gy**2 < 0.25] = 0.0  # the declared cylinder is solid, as the loader checks
    return {
        "velocity": velocity,
        "origin": lo,
        "spacing": ((hi[0] - lo[0]) / (nx - 1), (hi[1] - lo[1]) / (ny - 1), span / span_cells),
        "dt": frame_dt,
        "periodic": (False, False, True),
        "bounds": WAKE_BOUNDS,
        "obstacles": [Cylinder((0.0, 0.0), 0.5)],
    }


def synthetic_wake(**kwargs) -> GridFlow:
    """``GridFlow`` of ``synthetic_wake_grid(**kwargs)``."""
    return GridFlow(**synthetic_wake_grid(**kwargs))
