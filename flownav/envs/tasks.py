"""Task samplers: where a swimmer starts and where its target is.

A sampler is anything with ``sample(n, generator, device) -> (start[n,3], target[n,3])``.
The environment rejects starts that lie outside the domain, inside an obstacle or already
within the success radius, and samples them again.
"""

from __future__ import annotations

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
