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

    @property
    def center(self) -> tuple[float, float, float]:
        return tuple((l + h) / 2 for l, h in zip(self.lo, self.hi, strict=True))


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
    periodic_axes: tuple[int, ...] = ()  # axes (0, 1, 2 = x, y, z) on which the domain box wraps around

    def velocity(self, pos: Tensor, t: Tensor) -> Tensor:  # pragma: no cover - interface
        raise NotImplementedError

    def in_domain(self, pos: Tensor) -> Tensor:
        if not self.periodic_axes:
            return self.bounds.contains(pos)
        bounded = [a for a in range(3) if a not in self.periodic_axes]
        lo, hi = pos.new_tensor(self.bounds.lo)[bounded], pos.new_tensor(self.bounds.hi)[bounded]
        p = pos[..., bounded]
        return ((p >= lo) & (p <= hi)).all(-1)

    def wrap(self, pos: Tensor) -> Tensor:
        """Positions mapped into the box on the periodic axes (unchanged on the others)."""
        if not self.periodic_axes:
            return pos
        lo, size = _periodic_lo_size(self, pos)
        return torch.where(size > 0, lo + torch.remainder(pos - lo, size.clamp_min(1e-30)), pos)

    def displacement(self, pos: Tensor, target: Tensor) -> Tensor:
        """target - pos, the minimum image across the periodic axes: the one to-target vector of reward,
        success and every observation."""
        d = target - pos
        if not self.periodic_axes:
            return d
        _, size = _periodic_lo_size(self, pos)
        return torch.where(size > 0, d - size * torch.round(d / size.clamp_min(1e-30)), d)

    def in_obstacle(self, pos: Tensor) -> Tensor:
        hit = torch.zeros(pos.shape[:-1], dtype=torch.bool, device=pos.device)
        for obstacle in self.obstacles:
            hit |= obstacle.contains(pos)
        return hit

    def to(self, device) -> FlowField:
        """Flows without tensors are device-free; grid flows override this."""
        return self

    def probe(self, samples: int, generator: torch.Generator) -> FlowField:
        """What a check of the flow's properties evaluates, ``samples`` rows at a time: the flow itself (a family
        returns a copy of itself with one draw per row)."""
        return self


AXES = "xyz"


def _periodic_lo_size(flow: FlowField, like: Tensor) -> tuple[Tensor, Tensor]:
    """Box corner and period per axis (period 0 on bounded axes)."""
    lo = like.new_tensor(flow.bounds.lo)
    size = like.new_tensor([flow.bounds.size[a] if a in flow.periodic_axes else 0.0 for a in range(3)])
    return lo, size


def axis_indices(axes) -> tuple[int, ...]:
    """The sorted indices (0, 1, 2) of ``flow.periodic_axes``' names ("x", "y", "z")."""
    names = [str(a) for a in axes]
    if any(a not in AXES for a in names) or len(set(names)) != len(names):
        raise ValueError(f"flow.periodic_axes must be distinct names among x, y, z; got {names}")
    return tuple(sorted(AXES.index(a) for a in names))


def make_periodic(flow: FlowField, axes, samples: int = 256, tol: float = 1e-4, device="cpu") -> FlowField:
    """Let ``flow``'s domain wrap around on ``axes`` (names "x", "y", "z"); returns the flow.

    Refuses a flow whose velocity differs between the two opposite faces of its box on an axis (its box is
    not a whole number of spatial periods there), checked at random points and times on ``device`` (the flow's);
    a family is checked on its draws, every member of a mixture on an equal share of them.
    """
    idx = axis_indices(axes)
    g = torch.Generator(device=device).manual_seed(0)
    probe = flow.probe(samples, g)
    lo = torch.tensor(flow.bounds.lo, dtype=torch.float64, device=device)
    hi = torch.tensor(flow.bounds.hi, dtype=torch.float64, device=device)
    for a in idx:
        p = (lo + torch.rand(samples, 3, generator=g, dtype=torch.float64, device=device) * (hi - lo)).float()
        q = p.clone()
        p[:, a], q[:, a] = float(lo[a]), float(hi[a])
        t = torch.rand(samples, generator=g, device=device) * (flow.period or 10.0)
        gap = float((probe.velocity(p, t) - probe.velocity(q, t)).norm(dim=-1).max())
        if gap > tol * max(1.0, flow.max_speed):
            raise ValueError(
                f"flow.periodic_axes: the flow is not periodic over its box on axis {AXES[a]} (velocity differs "
                f"by {gap:.3g} between the faces {AXES[a]} = {float(lo[a]):g} and {float(hi[a]):g}); make the box "
                "span whole periods on that axis or drop it from periodic_axes"
            )
    flow.periodic_axes = idx
    return flow


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
