"""Build and load small C libraries with gcc, cached per source, flags and CPU.

flownav's C kernels (the lattice-Boltzmann update, flownav/cfd/ckernel.py; the grid-flow look-up,
flownav/flows/gridkernel.py) are generated or fixed C sources compiled on first use with ``-march=native``
into ``$FLOWNAV_CACHE`` (default ``~/.cache/flownav``), under a hash of the source, the flags and the CPU, and
loaded with ctypes. The file is written atomically, so concurrent builders never load a partial one.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import platform
import subprocess
import tempfile
from functools import cache
from pathlib import Path

# Every kernel's flags: these, its own, then SHARED (a loadable library).
OPTIMISE = ("-O3", "-march=native", "-fopenmp", "-fno-math-errno", "-fno-trapping-math")
SHARED = ("-shared", "-fPIC")


def cache_dir(kind: str) -> Path:
    root = os.environ.get("FLOWNAV_CACHE") or os.path.join(os.path.expanduser("~"), ".cache", "flownav")
    path = Path(root) / kind
    path.mkdir(parents=True, exist_ok=True)
    return path


@cache
def cpu_signature() -> str:
    """The CPU a ``-march=native`` build is for: machine, model name and feature flags (Linux), so a
    shared cache on a cluster with mixed nodes never hands one node a kernel built for another."""
    parts = [platform.machine(), platform.processor()]
    try:
        info = Path("/proc/cpuinfo").read_text()
    except OSError:
        info = ""
    for field in ("model name", "flags", "Features", "CPU part"):  # x86 and ARM spellings
        line = next((ln for ln in info.splitlines() if ln.split(":")[0].strip() == field), "")
        parts.append(line.split(":", 1)[-1].strip())
    return "|".join(parts)


def library_file(kind: str, name: str, source: str, flags: tuple[str, ...], cpu: str | None = None) -> Path:
    """Where the library ``name`` built from ``source`` with ``flags`` for ``cpu`` (default: this one) is cached."""
    text = "\n".join((source, " ".join(flags), cpu if cpu is not None else cpu_signature()))
    return cache_dir(kind) / f"{name}_{hashlib.sha256(text.encode()).hexdigest()[:16]}.so"


def build(kind: str, name: str, source: str, flags: tuple[str, ...]) -> ctypes.CDLL:
    """Compile ``source`` (once per source, flags and CPU) and load it. Raises RuntimeError with gcc's message."""
    so = library_file(kind, name, source, flags)
    if not so.exists():
        with tempfile.TemporaryDirectory() as tmp:
            c_file, tmp_so = Path(tmp) / f"{name}.c", Path(tmp) / f"{name}.so"
            c_file.write_text(source)
            try:
                subprocess.run(["gcc", *flags, "-o", str(tmp_so), str(c_file)], check=True, capture_output=True)
            except (OSError, subprocess.CalledProcessError) as e:
                err = getattr(e, "stderr", b"") or b""
                raise RuntimeError(f"building the C library {name} failed ({e}; {err.decode()[-500:]})") from e
            os.replace(tmp_so, so)  # atomic: concurrent builders never load a partial file
    return ctypes.CDLL(str(so))
