"""The errors a user can fix, and how the entry points report them.

Each carries one line that names the key (or file) and the fix. ``train.py``, ``evaluate.py``,
``python -m flownav.evaluation.selection``, ``python -m flownav.cfd`` and ``python -m flownav.export`` print that
line and exit with status 2, without a traceback; set ``FLOWNAV_DEBUG=1`` to see the traceback. Any other
exception is a bug and keeps its traceback.
"""

from __future__ import annotations

import os
import sys
from contextlib import contextmanager

DEBUG_ENV = "FLOWNAV_DEBUG"
EXIT_CODE = 2


class FlownavError(ValueError):
    """Bad input the user can fix; the message is one line naming the key or file and the fix."""


class ConfigError(FlownavError):
    """A config value or command-line option is wrong."""


class CheckpointError(FlownavError):
    """A checkpoint is missing, corrupt, unsafe, or does not fit the requested set-up."""


class DataError(FlownavError):
    """A flow dataset (or an array meant to become one) is unusable."""


class NonFiniteError(FlownavError, FloatingPointError):
    """A NaN or infinity reached an action, a flow velocity, a reward, a loss or a network parameter."""


def require_finite(x, what: str, fix: str, positions=None) -> None:
    """Raise :class:`NonFiniteError` unless every entry of the tensor ``x`` (one row per swimmer) is finite.

    The hot path is one sum (NaN and infinity propagate through it; a bool ``isfinite().all()`` costs about
    five times more on CPU); the details are only worked out when it fails. Values so large that their sum
    overflows are refused too.
    """
    import torch

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


def one_line(error: BaseException) -> str:
    return f"error: {' '.join(str(error).split())}"


@contextmanager
def reported_as_one_line():
    """Turn a :class:`FlownavError` into ``error: <message>`` on stderr and exit status 2."""
    try:
        yield
    except FlownavError as e:
        if os.environ.get(DEBUG_ENV, "") not in ("", "0"):
            raise
        print(one_line(e), file=sys.stderr, flush=True)
        raise SystemExit(EXIT_CODE) from None
