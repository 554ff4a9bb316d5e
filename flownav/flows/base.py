"""The one flow interface every part of flownav talks to.

A flow is anything with a batched ``velocity(pos[N,3], t[N]) -> [N,3]``, a domain box, a
list of obstacles (solid regions the swimmer must not enter) and a maximum speed. The
environment only ever calls :meth:`FlowField.velocity`, :meth:`FlowField.in_domain` and
:meth:`FlowField.in_obstacle`, so transforms (rotation, speed scaling) can wrap any flow.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import torch
from torch import Tensor


@dataclass(frozen=True)
class Box:
    """Axis-aligned box ``[lo, hi]`` in the flow's own frame."""

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]

    def __post_init__(self):
        if len(self.lo) != 3 or len(self.hi) != 3:
            raise ValueError(f"Box needs 3 lower and 3 upper bounds, got lo={self.lo}, hi={self.hi}")
        if any(h <= l for l, h in zip(self.lo, self.hi, strict=True)):
            raise ValueError(f"Box upper bounds must exceed lower bounds, got lo={self.lo}, hi={self.hi}")

    def contains(self, pos: Tensor) -> Tensor:
        lo = pos.new_tensor(self.lo)
        hi = pos.new_tensor(self.hi)
        return ((pos >= lo) & (pos <= hi)).all(-1)

    def sample(self, n: int, generator: torch.Generator | None = None, device="cpu") -> Tensor:
        lo = torch.tensor(self.lo, device=device)
        hi = torch.tensor(self.hi, device=device)
        u = torch.rand(n, 3, generator=generator, device=device)
        return lo + u * (hi - lo)

    @property
    def size(self) -> tuple[float, float, float]:
        return tuple(h - l for l, h in zip(self.lo, self.hi, strict=True))


@dataclass(frozen=True)
class Cylinder:
    """Solid circular cylinder with its axis along z (the cylinder of the wake)."""

    center: tuple[float, float] = (0.0, 0.0)
    radius: float = 0.5

    def contains(self, pos: Tensor) -> Tensor:
        dx = pos[..., 0] - self.center[0]
        dy = pos[..., 1] - self.center[1]
        return dx * dx + dy * dy < self.radius**2

    def to_dict(self) -> dict:
        return {"type": "cylinder", "center": list(self.center), "radius": self.radius}


def obstacle_from_dict(d: dict) -> Cylinder:
    if d.get("type") != "cylinder":
        raise ValueError(f"unknown obstacle type {d.get('type')!r}; flownav knows 'cylinder'")
    return Cylinder(center=tuple(d["center"]), radius=float(d["radius"]))


# The navigation domain of the cylinder wake (cylinder of diameter 1 at x = y = 0, axis z).
# It reaches 10 D past the training regions (x in [8, 12]) and 3 D beyond them in y: a swimmer
# swept downstream while it turns into the wake still has room to work back upstream. The span (z)
# is periodic, so z limits are artificial walls: they sit 8 D above and below the regions (z in [3, 7]).
WAKE_BOUNDS = Box((-4.0, -7.0, -5.0), (22.0, 7.0, 15.0))


class FlowField:
    """Base class of all flows. Subclasses implement :meth:`velocity`.

    Attributes:
        bounds: the domain box (positions outside it end an episode).
        obstacles: solid regions (entering one ends an episode).
        max_speed: maximum flow speed, used for the U_max / V_max ratio.
        period: time period of the flow, or ``None`` if it has none.
    """

    bounds: Box
    obstacles: Sequence[Cylinder] = ()
    max_speed: float
    period: float | None = None

    def velocity(self, pos: Tensor, t: Tensor) -> Tensor:  # pragma: no cover - interface
        raise NotImplementedError

    def in_domain(self, pos: Tensor) -> Tensor:
        return self.bounds.contains(pos)

    def in_obstacle(self, pos: Tensor) -> Tensor:
        hit = torch.zeros(pos.shape[:-1], dtype=torch.bool, device=pos.device)
        for obstacle in self.obstacles:
            hit |= obstacle.contains(pos)
        return hit

    def to(self, device) -> FlowField:
        """Flows without tensors are device-free; grid flows override this."""
        return self


class FunctionFlow(FlowField):
    """Wrap a user function ``fn(pos[N,3], t[N]) -> [N,3]`` as a flow."""

    def __init__(
        self,
        fn: Callable[[Tensor, Tensor], Tensor],
        bounds: Box,
        max_speed: float,
        obstacles: Sequence[Cylinder] = (),
        period: float | None = None,
    ):
        self.fn = fn
        self.bounds = bounds
        self.max_speed = float(max_speed)
        self.obstacles = tuple(obstacles)
        self.period = period

    def velocity(self, pos: Tensor, t: Tensor) -> Tensor:
        v = self.fn(pos, t)
        if v.shape != pos.shape:
            raise ValueError(
                f"flow function returned shape {tuple(v.shape)}, expected {tuple(pos.shape)}: "
                "it must map pos[N,3], t[N] to velocity[N,3]"
            )
        return v
