import numpy as np
import pytest
import torch

from flownav.flows import GridFlow
from flownav.flows.base import WAKE_BOUNDS, Cylinder

torch.set_num_threads(1)


def smooth_wake_like_field(shape=(6, 21, 13, 8), seed=0) -> np.ndarray:
    """A smooth, unsteady, non-trivial field on the wake box (for tests that need a 'real' flow)."""
    rng = np.random.default_rng(seed)
    T, nx, ny, nz = shape
    t = np.arange(T)[:, None, None, None] / T * 2 * np.pi
    x = np.linspace(0, 2 * np.pi, nx)[None, :, None, None]
    y = np.linspace(0, 2 * np.pi, ny)[None, None, :, None]
    z = np.arange(nz)[None, None, None, :] / nz * 2 * np.pi  # periodic axis: no endpoint
    a, b, c = rng.uniform(0.2, 0.5, 3)
    u = 0.8 + a * np.sin(y + t) * np.cos(z)
    v = b * np.sin(x - t) + 0.1 * np.cos(z)
    w = c * np.cos(x + y - t)
    return np.stack(np.broadcast_arrays(u, v, w), -1).astype(np.float32)


@pytest.fixture(scope="session")
def wake_like_flow() -> GridFlow:
    T, nx, ny, nz = 6, 21, 13, 8
    lo, hi = WAKE_BOUNDS.lo, WAKE_BOUNDS.hi
    spacing = ((hi[0] - lo[0]) / (nx - 1), (hi[1] - lo[1]) / (ny - 1), 4.0 / nz)
    return GridFlow(
        torch.from_numpy(smooth_wake_like_field((T, nx, ny, nz))),
        origin=lo,
        spacing=spacing,
        dt=0.5,
        periodic=(False, False, True),
        bounds=WAKE_BOUNDS,
        obstacles=[Cylinder((0.0, 0.0), 0.5)],
    )
