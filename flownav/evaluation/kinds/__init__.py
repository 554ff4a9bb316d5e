"""The experiment kinds of the suite, one module each; importing this package registers them all
(:mod:`flownav.evaluation.registry`). A new kind is a new module here, listed below."""

from flownav.evaluation.kinds import (  # noqa: F401 - imported for their registration
    extended,
    figures,
    loss_curves,
    misalignment,
    ratio_sweep,
    success,
    time_limit,
    zoo,
)
from flownav.evaluation.registry import KINDS, Kind


def kind(name: str) -> Kind:
    """The registered kind ``name``."""
    if name not in KINDS:
        raise ValueError(f"kind {name!r} is not an experiment kind; choose one of {sorted(KINDS)}")
    return KINDS[name]


__all__ = ["KINDS", "kind"]
