"""The errors a user can fix, and how the entry points report them.

Each carries one line that names the key (or file) and the fix. ``train.py``, ``evaluate.py`` and
``python -m flownav.cfd`` print that line and exit with status 2, without a traceback; set
``FLOWNAV_DEBUG=1`` to see the traceback. Any other exception is a bug and keeps its traceback.
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
