"""What every trainer shares: the check after an update, and the logged keys of an evaluation."""

from __future__ import annotations

from pathlib import Path

import torch
from torch import nn

from flownav.checkpoint import non_finite_entries
from flownav.errors import NonFiniteError


def require_finite_update(trainer: str, iteration: int, losses: dict, model: nn.Module, last: Path, fix: str) -> None:
    """Stop training, naming what went non-finite, when a loss or a parameter (normalisers included) is NaN or
    infinite after an update. Nothing of this update is saved: the last checkpoint on disk stays the last finite one.
    """
    bad = [name for name, v in losses.items() if not torch.isfinite(torch.as_tensor(v)).all()]
    bad += non_finite_entries(model.state_dict())
    if bad:
        kept = f"the last finite checkpoint is {last}" if last.is_file() else "no checkpoint was written before it"
        raise NonFiniteError(
            f"{trainer} iteration {iteration}: {', '.join(bad[:3])}{' ...' if len(bad) > 3 else ''} became NaN or "
            f"infinite; training stopped ({kept}); {fix}"
        )


def eval_metrics(summary: dict, prefix: str = "eval/") -> dict:
    """The logged keys of an evaluation's summary (:func:`flownav.evaluation.protocol.evaluate`): episodes,
    success_rate, mean_success_time (None without a success) and rate_<failure cause>, under ``prefix``."""
    out = {f"{prefix}{k}": summary[k] for k in ("episodes", "success_rate", "mean_success_time")}
    return out | {f"{prefix}rate_{name}": failure["rate"] for name, failure in summary["failures"].items()}
