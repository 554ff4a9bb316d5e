"""Errors a user can meet, each reported as one line that names the cause and the fix."""

from __future__ import annotations

import torch


class NonFiniteError(FloatingPointError):
    """A NaN or infinity reached an action, a flow velocity, a reward, a loss or a network parameter."""


def require_finite(x: torch.Tensor, what: str, fix: str, positions: torch.Tensor | None = None) -> None:
    """Raise :class:`NonFiniteError` unless every entry of ``x`` (one row per swimmer) is finite.

    The hot path is one sum (NaN and infinity propagate through it; a bool ``isfinite().all()`` costs about
    five times more on CPU); the details are only worked out when it fails. Values so large that their sum
    overflows are refused too.
    """
    if torch.isfinite(x.sum()):
        return
    rows = x.reshape(x.shape[0], -1) if x.dim() else x.reshape(1, 1)
    bad = ~torch.isfinite(rows).all(-1)
    if not bad.any():  # every entry finite, their sum not: absurdly large values
        bad = rows.abs().amax(-1) == rows.abs().max()
        what = f"{what} is too large ({float(rows.abs().max()):.3g})"
    else:
        what = f"{what} is not finite"
    first = int(bad.nonzero()[0, 0])
    at = f" at position {[round(v, 4) for v in positions[first].tolist()]}" if positions is not None else ""
    raise NonFiniteError(
        f"{what} for {int(bad.sum())} of {bad.shape[0]} swimmers (swimmer {first}{at}: {rows[first].tolist()}); {fix}"
    )
