"""Paths relative to the repository: its root, the default dataset, shipped checkpoints and results, resolving."""

from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
DEFAULT_FLOW_DATASET = REPO_ROOT / "data" / "cylinder_re300"
DATA_DIR = REPO_ROOT / "data"
CHECKPOINT_DIR = REPO_ROOT / "checkpoints"
RESULTS_DIR = REPO_ROOT / "results"


def resolve(path: str | Path, base: Path = REPO_ROOT) -> Path:
    """A path as given if it exists (or is absolute), else relative to the repository root."""
    p = Path(path).expanduser()
    if p.is_absolute() or p.exists():
        return p
    return base / p
