"""Errors a user can meet, each reported as one line that names the cause and the fix."""

from __future__ import annotations

import torch


class NonFiniteError(FloatingPointError):
    """A NaN or infinity reached an action, a flow velocity, a reward, a loss or a network parameter."""


def require_finite(x: torch.Tensor, what: str, fix: str, positions: torch.Tensor | None = None) -> None:
    """Raise :class:`NonFiniteError` unless every entry of ``x`` (one row per swimmer) is finite.

    One ``isfinite().all()`` on the hot path; the details are only worked out when it fails.
    """
    if torch.isfinite(x).all():
        return
    bad = ~torch.isfinite(x.reshape(x.shape[0], -1)).all(-1) if x.dim() else torch.ones(1, dtype=torch.bool)
    first = int(bad.nonzero()[0, 0])
    value = x.reshape(bad.shape[0], -1)[first].tolist() if x.dim() else float(x)
    at = f" at position {[round(v, 4) for v in positions[first].tolist()]}" if positions is not None else ""
    raise NonFiniteError(
        f"{what} is not finite for {int(bad.sum())} of {bad.shape[0]} swimmers (swimmer {first}{at}: {value}); {fix}"
    )
