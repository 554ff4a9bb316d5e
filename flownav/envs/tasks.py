"""Task samplers: where a swimmer starts and where its target is.

A sampler is anything with ``sample(n, generator, device) -> (start[n,3], target[n,3])``.
The environment rejects starts that lie outside the domain, inside an obstacle or already
within the success radius, and samples them again. A sampler may also have
``swim_speed(n, generator, device) -> factor[n]``: each episode's factor on the swim speed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import Tensor

from flownav.flows.base import Box

# The paper's regions (section 3.1) and the extended-domain target (section 3.3).
REGION_1 = Box((8.0, 2.0, 3.0), (12.0, 4.0, 7.0))
REGION_2 = Box((8.0, -4.0, 3.0), (12.0, -2.0, 7.0))
EXTENDED_TARGET = (11.5, -3.5, 4.5)


class RegionTask:
    """Start uniform in one box, target uniform in another (the paper's training task)."""

    def __init__(self, start: Box = REGION_1, target: Box = REGION_2):
        self.start, self.target = start, target

    def sample(self, n: int, generator: torch.Generator | None = None, device="cpu") -> tuple[Tensor, Tensor]:
        return self.start.sample(n, generator, device), self.target.sample(n, generator, device)


class SymmetricTask:
    """Start in either box with equal probability, target in the other (paper SI 2)."""

    def __init__(self, a: Box = REGION_1, b: Box = REGION_2):
        self.a, self.b = a, b

    def sample(self, n: int, generator: torch.Generator | None = None, device="cpu") -> tuple[Tensor, Tensor]:
        pa, pb = self.a.sample(n, generator, device), self.b.sample(n, generator, device)
        swap = torch.rand(n, 1, generator=generator, device=device) < 0.5
        return torch.where(swap, pb, pa), torch.where(swap, pa, pb)


class FixedTargetTask:
    """One fixed target, starts uniform in a box (the extended-domain test, section 3.3)."""

    def __init__(self, target: Sequence[float] = EXTENDED_TARGET, start: Box | None = None):
        if start is None:
            raise ValueError("FixedTargetTask needs the start box (usually the whole domain)")
        self.target_point, self.start = tuple(float(x) for x in target), start

    def sample(self, n: int, generator: torch.Generator | None = None, device="cpu") -> tuple[Tensor, Tensor]:
        start = self.start.sample(n, generator, device)
        return start, torch.tensor(self.target_point, device=device).expand(n, 3).clone()


class ListTask:
    """User-given pairs, handed out in order and cycled (for exact, repeatable test sets)."""

    def __init__(self, starts, targets):
        self.starts = torch.as_tensor(starts, dtype=torch.float32).reshape(-1, 3)
        self.targets = torch.as_tensor(targets, dtype=torch.float32).reshape(-1, 3)
        if len(self.starts) != len(self.targets) or len(self.starts) == 0:
            raise ValueError("ListTask needs as many starts as targets, at least one of each")
        self._next = 0

    def sample(self, n: int, generator: torch.Generator | None = None, device="cpu") -> tuple[Tensor, Tensor]:
        idx = (torch.arange(n) + self._next) % len(self.starts)
        self._next = int((self._next + n) % len(self.starts))
        return self.starts[idx].to(device), self.targets[idx].to(device)


class DistanceTask:
    """Start uniform in a box, target in the same box at a distance uniform in [low, high] in a uniform
    random direction (redrawn until it lies in the box): point-to-point navigation anywhere in a flow."""

    def __init__(self, box: Box, distance: Sequence[float] = (8.0, 12.0), tries: int = 5000):
        low, high = (float(d) for d in distance)
        if not 0 < low <= high:
            raise ValueError(f"task.distance must be [low, high] with 0 < low <= high, got {list(distance)}")
        diagonal = sum(s * s for s in box.size) ** 0.5
        if low >= diagonal:
            raise ValueError(f"task.distance {low:g} does not fit in the box (its diagonal is {diagonal:.3g})")
        self.box, self.low, self.high, self.tries = box, low, high, tries

    def sample(self, n: int, generator: torch.Generator | None = None, device="cpu") -> tuple[Tensor, Tensor]:
        start, target = torch.zeros(n, 3, device=device), torch.zeros(n, 3, device=device)
        todo = torch.ones(n, dtype=torch.bool, device=device)
        for _ in range(self.tries):
            k = int(todo.sum())
            s = self.box.sample(k, generator, device)
            direction = torch.randn(k, 3, generator=generator, device=device)
            direction = direction / direction.norm(dim=-1, keepdim=True).clamp_min(1e-9)
            d = self.low + (self.high - self.low) * torch.rand(k, 1, generator=generator, device=device)
            t = s + d * direction
            ok = self.box.contains(t)
            idx = todo.nonzero().squeeze(-1)[ok]
            start[idx], target[idx] = s[ok], t[ok]
            todo[idx] = False
            if not todo.any():
                return start, target
        raise ValueError(f"no target {self.low:g}-{self.high:g} away fits in {self.box} after {self.tries} tries")


class FamilyTask:
    """The generalist's training tasks: point-to-point anywhere, the paper's regions, random swim speeds.

    * With probability ``regions_share``: start in ``start_region``, target in ``target_region`` (the paper's).
      For slots whose flow is the wake as posed (``posed``, passed by the env), with probability
      ``posed_wake_regions_share`` instead (when set): the paper's task in the paper's flow, seen more often
      without posing it in every other flow. Of those, with probability ``posed_wake_any_start_share`` the start is
      drawn anywhere in ``posed_wake_any_start_box`` (default: the shrunk domain) instead of in Region 1 (the
      extended domain of the paper's Fig. 4); with probability ``posed_wake_reverse_share`` the crossing goes the other
      way, from Region 2 to Region 1 (the paper's SI 2).
    * Otherwise: start uniform in ``domain`` shrunk by ``margin`` on every side, target at a distance uniform in
      ``distance`` in a direction uniform on the sphere, drawn again until it lies in the shrunk domain too.
    * :meth:`swim_speed`: the swimmer's speed factor (on ``env.swim_speed_scale``), 1 with probability
      ``full_speed_share``, else log-uniform in ``swim_speed``. With flows of characteristic speed 0.2-1.5,
      factors 0.05-1 give swim-speed ratios U_max / V_flow from about 0.03 to 5 (still water: infinite).
    """

    def __init__(
        self,
        domain: Box,
        distance: Sequence[float] = (4.0, 16.0),
        margin: float = 1.0,
        regions_share: float = 0.25,
        start_region: Box = REGION_1,
        target_region: Box = REGION_2,
        swim_speed: Sequence[float] = (0.05, 1.0),
        full_speed_share: float = 0.5,
        posed_wake_regions_share: float | None = None,
        posed_wake_any_start_share: float = 0.0,
        posed_wake_any_start_box: Box | None = None,
        posed_wake_reverse_share: float = 0.0,
    ):
        self.distance = tuple(float(d) for d in distance)
        self.swim_range = tuple(float(s) for s in swim_speed)
        if len(self.distance) != 2 or not 0 < self.distance[0] <= self.distance[1]:
            raise ValueError(f"distance must be [low, high] with 0 < low <= high, got {list(distance)}")
        if len(self.swim_range) != 2 or not 0 < self.swim_range[0] <= self.swim_range[1]:
            raise ValueError(f"swim_speed must be [low, high] with 0 < low <= high, got {list(swim_speed)}")
        shares = {
            "regions_share": regions_share,
            "full_speed_share": full_speed_share,
            "posed_wake_any_start_share": posed_wake_any_start_share,
            "posed_wake_reverse_share": posed_wake_reverse_share,
        }
        if posed_wake_regions_share is not None:
            shares["posed_wake_regions_share"] = posed_wake_regions_share
        for name, share in shares.items():
            if not 0 <= share <= 1:
                raise ValueError(f"{name} is a fraction in [0, 1], got {share}")
        lo = tuple(x + margin for x in domain.lo)
        hi = tuple(x - margin for x in domain.hi)
        self.box = Box(lo, hi)  # raises when the margin leaves no room
        if self.distance[0] > min(self.box.size):
            raise ValueError(f"distance {list(distance)} does not fit the domain {domain} less margin {margin}")
        self.anywhere = DistanceTask(self.box, self.distance)
        self.regions = RegionTask(start_region, target_region)
        self.regions_share, self.full_speed_share = float(regions_share), float(full_speed_share)
        self.posed_wake_regions_share = None if posed_wake_regions_share is None else float(posed_wake_regions_share)
        self.posed_wake_any_start_share = float(posed_wake_any_start_share)
        self.any_start_box = posed_wake_any_start_box
        self.posed_wake_reverse_share = float(posed_wake_reverse_share)

    @property
    def reads_posed(self) -> bool:
        """Whether :meth:`sample` treats the wake as posed apart: the env then passes ``posed``."""
        shares = (self.posed_wake_any_start_share, self.posed_wake_reverse_share)
        return self.posed_wake_regions_share is not None or max(shares) > 0

    def sample(
        self, n: int, generator: torch.Generator | None = None, device="cpu", posed: Tensor | None = None
    ) -> tuple[Tensor, Tensor]:
        start, target = self.anywhere.sample(n, generator, device)
        r_start, r_target = self.regions.sample(n, generator, device)
        region_start = r_start
        share = torch.full((n, 1), self.regions_share, device=device)
        if posed is not None and self.posed_wake_regions_share is not None:
            share = torch.where(posed[:, None], self.posed_wake_regions_share, share)
        paper = torch.rand(n, 1, generator=generator, device=device) < share
        if posed is not None and self.posed_wake_any_start_share > 0:  # drawn only then: other streams unchanged
            anywhere = torch.rand(n, 1, generator=generator, device=device) < self.posed_wake_any_start_share
            far = start if self.any_start_box is None else self.any_start_box.sample(n, generator, device)
            r_start = torch.where(posed[:, None] & anywhere, far, r_start)
        if posed is not None and self.posed_wake_reverse_share > 0:  # drawn only then: other streams unchanged
            back = posed[:, None] & (
                torch.rand(n, 1, generator=generator, device=device) < self.posed_wake_reverse_share
            )
            r_start, r_target = torch.where(back, r_target, r_start), torch.where(back, region_start, r_target)
        return torch.where(paper, r_start, start), torch.where(paper, r_target, target)

    def swim_speed(self, n: int, generator: torch.Generator | None = None, device="cpu") -> Tensor:
        lo, hi = (math.log(s) for s in self.swim_range)
        factor = torch.exp(lo + (hi - lo) * torch.rand(n, generator=generator, device=device))
        full = torch.rand(n, generator=generator, device=device) < self.full_speed_share
        return torch.where(full, torch.ones_like(factor), factor)
