"""Episode statistics: success rate with a Wilson 95% interval, time of the successes, failure causes,
and success maps over subregions of the start position (the paper's Fig. 4)."""

from __future__ import annotations

import math

import torch
from torch import Tensor

from flownav.envs.navigation import Status
from flownav.flows.base import Box

Z95 = 1.959963984540054  # two-sided 95% normal quantile

FAILURES = {
    "left_domain": Status.LEFT_DOMAIN,
    "hit_obstacle": Status.HIT_OBSTACLE,
    "timeout": Status.TIMEOUT,
}


def wilson_interval(successes: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (95% by default).

    Unlike the normal approximation it stays inside [0, 1] and is sensible at 0% and 100%,
    which matters here: the ego baseline succeeds in 0 of 10,000 episodes.
    """
    if n <= 0:
        return (0.0, 1.0)
    if not 0 <= successes <= n:
        raise ValueError(f"need 0 <= successes <= n, got {successes} of {n}")
    p = successes / n
    z2 = z * z
    denom = 1 + z2 / n
    centre = (p + z2 / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n)) / denom
    return (max(0.0, centre - half), min(1.0, centre + half))


def summarize(status: Tensor, time: Tensor) -> dict:
    """Success rate (with its Wilson interval), mean/std time of successful episodes, failure causes.

    ``status`` holds each episode's final :class:`Status`, ``time`` its duration.
    """
    status = status.reshape(-1).cpu()
    time = time.reshape(-1).cpu().double()
    n = int(status.numel())
    success = status == Status.SUCCESS
    k = int(success.sum())
    lo, hi = wilson_interval(k, n)
    t = time[success]
    out = {
        "episodes": n,
        "successes": k,
        "success_rate": k / n if n else float("nan"),
        "success_ci95": [lo, hi],
        "mean_success_time": float(t.mean()) if k else None,
        "std_success_time": float(t.std(unbiased=False)) if k else None,
        "failures": {},
    }
    for name, s in FAILURES.items():
        c = int((status == s).sum())
        out["failures"][name] = {"count": c, "rate": c / n if n else float("nan")}
    unfinished = int((status == Status.RUNNING).sum())
    if unfinished:
        raise ValueError(f"{unfinished} episodes have no outcome (status RUNNING): the rollout stopped early")
    return out


def truncate_at(status: Tensor, time: Tensor, limit: float, dt: float) -> Tensor:
    """The outcomes the same episodes would have had with a shorter time limit: whatever ended after
    ``limit`` (success or failure) is a timeout. ``dt`` only guards the float comparison of step times."""
    late = time > limit + 0.5 * dt
    return torch.where(late & (status != Status.RUNNING), torch.full_like(status, int(Status.TIMEOUT)), status)


def subregion_counts(start: Tensor, success: Tensor, bounds: Box, bins=(10, 10, 10)) -> tuple[Tensor, Tensor]:
    """Episodes and successes per subregion of the start position: two int tensors of shape ``bins``.

    The domain box is cut into ``bins[0] x bins[1] x bins[2]`` equal cells (the paper: 10 x 10 x 10).
    """
    bins = tuple(int(b) for b in bins)
    lo = torch.tensor(bounds.lo, dtype=torch.float64)
    hi = torch.tensor(bounds.hi, dtype=torch.float64)
    nb = torch.tensor(bins)
    cell = ((start.double().cpu() - lo) / (hi - lo) * nb).floor().long()
    cell = torch.minimum(cell.clamp_min(0), nb - 1)
    flat = (cell[:, 0] * bins[1] + cell[:, 1]) * bins[2] + cell[:, 2]
    size = bins[0] * bins[1] * bins[2]
    counts = torch.bincount(flat, minlength=size).reshape(bins)
    wins = torch.bincount(flat, weights=success.cpu().double(), minlength=size).round().long().reshape(bins)
    return counts, wins
