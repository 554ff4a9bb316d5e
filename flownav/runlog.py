"""Run logging shared by every trainer: a CSV file always, wandb (offline unless asked) and TensorBoard
through TorchRL's logger classes, a tqdm bar, and the end-of-run summary.

    logger = RunLogger(run_dir, cfg, total=cfg.algo.total_frames, start=step)
    logger.log(step, {"train/success_rate": 0.4, ...})   # one CSV row, one row per backend, bar refresh
    logger.log_figure(step, "eval/trajectories", fig)     # PNG under <run_dir>/figures, wandb.Image, TB image
    logger.log_checkpoint(run_dir / "checkpoints" / "best.pt")   # a wandb model artifact
    logger.close()
    logger.write_summary(run_summary(...))               # printed and appended to <run_dir>/train.log

* ``metrics.csv`` in the run directory: one row per :meth:`log` call, columns ``step``, ``wall_time``
  (seconds since the run first started, carried over on resume), then the metric names. New metric
  names later in a run are added as columns (the file is rewritten once with the wider header).
  Resuming appends to the same file; rows after the resume step are dropped first, so a resumed run's
  file has each step once.
* wandb: ``cfg.logger.wandb.mode`` is ``offline`` (default: files under ``<run_dir>/wandb``, sync later
  with ``wandb sync``), ``online`` (only if an API key is present, else offline with a warning) or
  ``disabled``.
  Through :class:`torchrl.record.loggers.WandbLogger`: each metric group (``train/``, ``eval/``, ``loss/``)
  is plotted against its own step key (``train/step`` = swimmer steps for PPO, iterations for DAgger).
* TensorBoard (``cfg.logger.tensorboard: true``, e.g. ``logger=tensorboard``): events under
  ``<run_dir>/tensorboard`` through :class:`torchrl.record.loggers.TensorboardLogger`
  (``tensorboard --logdir outputs``).
* Figures: always a PNG ``<run_dir>/figures/<name>_<step>.png``, and an image on each backend.
* tqdm: steps of the environment, with the metrics named in ``cfg.logger.progress_keys``.

TorchRL's ``CSVLogger`` writes one file per metric; the single ``metrics.csv`` table (with the resume rule
above) is what the project's plots and tests read, so the CSV stays here.
"""

from __future__ import annotations

import csv
import io
import math
import os
import time
import warnings
from collections.abc import Mapping
from datetime import timedelta
from pathlib import Path

from flownav.atomic import atomic_write_text
from flownav.evaluation.metrics import wilson_interval

WANDB_MODES = ("offline", "online", "disabled")


def _to_container(cfg):
    try:
        from omegaconf import OmegaConf

        if OmegaConf.is_config(cfg):
            return OmegaConf.to_container(cfg, resolve=True)
    except ImportError:  # pragma: no cover
        pass
    return dict(cfg) if isinstance(cfg, Mapping) else {}


def _get(cfg, path: str, default=None):
    node = cfg
    for part in path.split("."):
        if node is None:
            return default
        try:
            node = node.get(part) if hasattr(node, "get") else getattr(node, part, None)
        except Exception:  # noqa: BLE001 - omegaconf struct errors
            return default
    return default if node is None else node


def wandb_has_key() -> bool:
    if os.environ.get("WANDB_API_KEY"):
        return True
    netrc = Path(os.environ.get("NETRC", Path.home() / ".netrc"))
    try:
        return "api.wandb.ai" in netrc.read_text()
    except OSError:
        return False


def resolve_wandb_mode(requested: str) -> str:
    if requested not in WANDB_MODES:
        raise ValueError(f"logger.wandb.mode is {requested!r}; choose one of {list(WANDB_MODES)}")
    if requested == "online" and not wandb_has_key():
        warnings.warn("logger.wandb.mode=online but no WANDB_API_KEY / ~/.netrc entry: logging offline", stacklevel=2)
        return "offline"
    return requested


class RunLogger:
    def __init__(self, run_dir, cfg=None, total: int | None = None, start: int = 0, wall_offset: float = 0.0):
        self.run_dir = Path(run_dir)
        self.run_dir.mkdir(parents=True, exist_ok=True)
        self.csv_path = self.run_dir / "metrics.csv"
        self.t0 = time.time() - float(wall_offset)
        self.progress_keys = list(_get(cfg, "logger.progress_keys", []) or [])
        self._fields: list[str] = []
        self._rows_from_disk(start)

        # TorchRL loggers, each fed the same rows as the CSV.
        self.wandb = None
        self.backends = []
        mode = resolve_wandb_mode(str(_get(cfg, "logger.wandb.mode", "disabled")))
        if mode != "disabled":
            os.environ.setdefault("WANDB_SILENT", "true")
            if mode == "offline":
                os.environ["WANDB_MODE"] = "offline"
            from torchrl.record.loggers import WandbLogger

            self.wandb = WandbLogger(
                f"{_get(cfg, 'name', 'run')}-seed{_get(cfg, 'seed', 0)}",
                offline=mode == "offline",
                save_dir=str(self.run_dir),
                id=self._wandb_id(),
                project=str(_get(cfg, "logger.wandb.project", "flownav")),
                entity=_get(cfg, "logger.wandb.entity"),
                group=_get(cfg, "logger.wandb.group"),
                config=_to_container(cfg),
                mode=mode,
                log_env_packages=False,
            )
            self.backends.append(self.wandb)
        self.tensorboard = None
        if _get(cfg, "logger.tensorboard", False):
            from torchrl.record.loggers import TensorboardLogger

            self.tensorboard = TensorboardLogger("tensorboard", log_dir=str(self.run_dir))
            self.backends.append(self.tensorboard)

        self.bar = None
        if _get(cfg, "logger.progress", True):
            from tqdm.auto import tqdm

            self.bar = tqdm(total=total, initial=start, unit="step", unit_scale=True, dynamic_ncols=True, smoothing=0.1)
        self._last_step = start

    def _wandb_id(self) -> str:
        """One wandb run per run directory, so a resumed run continues its wandb history."""
        path = self.run_dir / "wandb_id.txt"
        if path.exists():
            return path.read_text().strip()
        import uuid

        run_id = uuid.uuid4().hex[:12]
        path.write_text(run_id)
        return run_id

    def _rows_from_disk(self, start: int) -> None:
        """Keep the rows of an earlier part of this run up to ``start`` (resume)."""
        if not self.csv_path.exists():
            return
        with open(self.csv_path, newline="") as f:
            reader = csv.DictReader(f)
            fields = list(reader.fieldnames or [])
            rows = [r for r in reader if float(r.get("step") or 0) <= start]
        if start == 0:
            rows = []
        self._fields = fields
        self._write_all(rows)

    def _write_all(self, rows) -> None:
        buffer = io.StringIO(newline="")
        writer = csv.DictWriter(buffer, fieldnames=self._fields, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
        atomic_write_text(self.csv_path, buffer.getvalue())

    def log(self, step: int, metrics: Mapping[str, float]) -> None:
        row = {"step": int(step), "wall_time": round(time.time() - self.t0, 3)}
        row.update({k: (float(v) if v is not None else math.nan) for k, v in metrics.items()})
        new = [k for k in row if k not in self._fields]
        if new:
            rows = []
            if self.csv_path.exists() and self._fields:
                with open(self.csv_path, newline="") as f:
                    rows = list(csv.DictReader(f))
            self._fields += new
            self._write_all(rows)
        with open(self.csv_path, "a", newline="") as f:
            csv.DictWriter(f, fieldnames=self._fields, extrasaction="ignore").writerow(row)
        for backend in self.backends:
            backend.log_metrics({k: (math.nan if v is None else float(v)) for k, v in metrics.items()}, step=int(step))
        if self.bar is not None:
            self.bar.update(max(0, int(step) - self._last_step))
            shown = {k.split("/")[-1]: f"{row[k]:.3g}" for k in self.progress_keys if k in row}
            if shown:
                self.bar.set_postfix(shown, refresh=False)
        self._last_step = int(step)

    @property
    def elapsed(self) -> float:
        return time.time() - self.t0

    def log_figure(self, step: int, name: str, fig) -> Path:
        """Save a matplotlib figure as ``<run_dir>/figures/<name>_<step>.png`` and log it on every backend."""
        import matplotlib.pyplot as plt

        path = self.run_dir / "figures" / f"{name.replace('/', '_')}_{int(step)}.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=100)
        if self.wandb is not None:
            import wandb

            self.wandb.log_metrics({name: wandb.Image(str(path))}, step=int(step))
        if self.tensorboard is not None:
            self.tensorboard.experiment.add_figure(name, fig, global_step=int(step), close=False)
        plt.close(fig)
        return path

    def log_checkpoint(self, path, name: str | None = None) -> None:
        """Log a checkpoint file as a wandb model artifact (synced with the run; no-op without wandb)."""
        path = Path(path)
        if self.wandb is None or not path.is_file():
            return
        import wandb

        run = self.wandb.experiment
        artifact = wandb.Artifact(name or f"{run.name}-{path.stem}", type="model", metadata={"file": path.name})
        artifact.add_file(str(path))
        run.log_artifact(artifact, aliases=["latest", path.stem])

    def summary(self, metrics: Mapping[str, float]) -> None:
        if self.wandb is not None:
            for k, v in metrics.items():
                self.wandb.experiment.summary[k] = v

    def write_summary(self, text: str) -> None:
        """Print the end-of-run summary and append it to ``<run_dir>/train.log`` (Hydra's job log, if it is there)."""
        print(text, flush=True)
        with open(self.run_dir / "train.log", "a") as f:
            f.write(text + "\n")

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None
        for backend in self.backends:
            backend.shutdown()
        self.backends, self.wandb, self.tensorboard = [], None, None


def run_summary(
    steps: int, wall_time_s: float, held_out: Mapping[str, tuple[float | None, int]], checkpoints: Mapping[str, Path]
) -> str:
    """The lines that end a run: steps, wall time, each held-out success rate with its 95% Wilson interval
    (``held_out``: name -> (rate, episodes)), and where the checkpoints are."""
    lines = ["== run summary ==", f"steps: {int(steps):,}", f"wall time: {timedelta(seconds=round(wall_time_s))}"]
    for name, (rate, n) in held_out.items():
        if rate is None or n <= 0 or (isinstance(rate, float) and math.isnan(rate)):
            lines.append(f"{name}: not evaluated")
            continue
        lo, hi = wilson_interval(round(rate * n), n)
        lines.append(f"{name}: {rate:.2%} of {n} held-out episodes (95% CI {lo:.2%} - {hi:.2%})")
    for name, path in checkpoints.items():
        lines.append(f"{name}: {path}")
    return "\n".join(lines)
