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
