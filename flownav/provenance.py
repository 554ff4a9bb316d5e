"""Where a result came from: the sha256 of a file, the git commit of the code, the command and the machine.

Every file flownav writes about a measurement (results/*.json, REPORT.md, a CFD dataset's meta.json, the
benchmarks' results) takes its provenance from :func:`provenance` and its file digests from :func:`sha256`.
"""

from __future__ import annotations

import hashlib
import os
import platform
import subprocess
import time
from pathlib import Path

from flownav.paths import REPO_ROOT


def sha256(path: str | os.PathLike, length: int | None = 12) -> str:
    """The hex sha256 of a file, read in blocks (a 48 MB wake does not sit in memory twice); ``length``
    hex digits (12 name a checkpoint in a report; None: all 64, for integrity checks)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 22), b""):
            h.update(block)
    return h.hexdigest()[:length]


def tree_digest(*paths: str | os.PathLike) -> dict[str, str]:
    """The full sha256 of every file under ``paths`` (files or directories), by path: what must stay byte-identical."""
    out = {}
    for root in map(Path, paths):
        for f in sorted([root] if root.is_file() else root.rglob("*")):
            if f.is_file():
                out[str(f)] = sha256(f, None)
    return out


def git_commit(root: Path = REPO_ROOT) -> str:
    """HEAD, with ``+dirty`` when tracked files differ from it (other engineers edit the same checkout)."""
    try:
        sha = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, check=True)
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=root,
            capture_output=True,
            text=True,
            check=True,
        )
        return sha.stdout.strip()[:12] + ("+dirty" if dirty.stdout.strip() else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def provenance(command: str | None = None) -> dict:
    """The command (when given), the commit, the UTC date and the machine of a measurement."""
    out = {"command": command} if command is not None else {}
    return out | {
        "commit": git_commit(),
        "date_utc": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime()),
        "host": f"{platform.machine()} {os.cpu_count()} cores, {platform.python_version()}",
    }
