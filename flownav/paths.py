"""Where the repository keeps its data, checkpoints and results."""

from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
DATA_DIR = REPO_ROOT / "data"
DEFAULT_FLOW_DATASET = DATA_DIR / "cylinder_re300"
CHECKPOINT_DIR = REPO_ROOT / "checkpoints"
RESULTS_DIR = REPO_ROOT / "results"


def resolve(path: str | Path, base: Path = REPO_ROOT) -> Path:
    """A path as given if it exists (or is absolute), else relative to the repository root."""
    p = Path(path).expanduser()
    if p.is_absolute() or p.exists():
        return p
    return base / p
