"""Which checkpoint a run continues (``cfg.resume``), decided once in ``train.run``.

* ``resume=<run dir | checkpoint file>``: continue that run (in its directory).
* ``resume=auto``: continue this run directory's own ``checkpoints/last.pt`` if there is one, else start fresh.
* ``resume=null`` (default): start fresh, except inside a submitit job (``hydra/launcher=slurm`` or
  ``submitit_local``), where it means ``auto``: a job that Slurm preempted (or that timed out) is requeued
  by submitit with the same overrides, in the same run directory, and picks up its own last checkpoint.
"""

from __future__ import annotations

import os
from pathlib import Path

AUTO = "auto"


def in_submitit_job() -> bool:
    """True inside a job started by submitit (it exports SUBMITIT_EXECUTOR=slurm|local to every job)."""
    return bool(os.environ.get("SUBMITIT_EXECUTOR"))


def resolve_resume(resume, run_dir) -> str | None:
    """The ``resume`` value the trainer sees: a run directory or checkpoint to continue, or None (fresh)."""
    if resume is None and in_submitit_job():
        resume = AUTO
    if resume == AUTO:
        return str(run_dir) if (Path(run_dir) / "checkpoints" / "last.pt").is_file() else None
    return resume
