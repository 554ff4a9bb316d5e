"""Each row of a batch to its own function: the flow families' members and the routed teacher's experts."""

from __future__ import annotations

from collections.abc import Callable

from torch import Tensor


def route_rows(choice: Tensor, count: int, fn: Callable[[int, Tensor], Tensor], out: Tensor) -> Tensor:
    """``out[rows] = fn(j, rows)`` for the rows whose ``choice`` is j, for every j in range(count)."""
    if count == 1:  # every row: no gather
        return fn(0, slice(None))
    for j in range(count):
        rows = (choice == j).nonzero().squeeze(-1)
        if rows.numel():
            out[rows] = fn(j, rows)
    return out
