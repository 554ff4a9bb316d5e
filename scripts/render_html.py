"""Render an HTML page (e.g. flownav.viz.interactive's) to a PNG in headless Chromium, offline.

    python scripts/render_html.py results/html/trajectories.html docs/figures/trajectories_3d.png

Exits with a message when no Chromium is installed (``apt-get install -y chromium``).
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

BROWSERS = ("chromium", "chromium-browser", "google-chrome", "chrome")
# Headless, sandbox-free (root in containers), and no network traffic of its own.
FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--hide-scrollbars",
)


def find_chromium() -> str | None:
    return next((path for name in BROWSERS if (path := shutil.which(name))), None)


def render(html: Path, png: Path, size=(1400, 900), wait_ms: int = 8000) -> Path:
    """Screenshot ``html`` into ``png`` once the page's scripts had ``wait_ms`` of virtual time."""
    browser = find_chromium()
    if browser is None:
        raise SystemExit("no Chromium found (tried " + ", ".join(BROWSERS) + "): apt-get install -y chromium")
    png = Path(png).resolve()
    png.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as profile:
        cmd = [
            browser,
            *FLAGS,
            f"--user-data-dir={profile}",
            f"--window-size={size[0]},{size[1]}",
            f"--virtual-time-budget={wait_ms}",
            f"--screenshot={png}",
            Path(html).resolve().as_uri(),
        ]
        result = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    if result.returncode != 0 or not png.is_file():
        raise SystemExit(f"Chromium failed ({result.returncode}): {result.stderr.strip()[-2000:]}")
    return png


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("html", type=Path)
    p.add_argument("png", type=Path)
    p.add_argument("--width", type=int, default=1400)
    p.add_argument("--height", type=int, default=900)
    p.add_argument("--wait-ms", type=int, default=8000, help="virtual time for the page's scripts to draw")
    a = p.parse_args(argv)
    print(render(a.html, a.png, (a.width, a.height), a.wait_ms))


if __name__ == "__main__":
    sys.exit(main())
