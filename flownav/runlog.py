"""Run logging shared by every trainer: a CSV file always, wandb (offline unless asked), a tqdm bar.

    logger = RunLogger(run_dir, cfg, total=cfg.algo.total_frames, start=step)
    logger.log(step, {"train/success_rate": 0.4, ...})   # one CSV row, one wandb step, bar refresh
    logger.close()

* ``metrics.csv`` in the run directory: one row per :meth:`log` call, columns ``step``, ``wall_time``
  (seconds since the run first started, carried over on resume), then the metric names. New metric
  names later in a run are added as columns (the file is rewritten once with the wider header).
  Resuming appends to the same file; rows after the resume step are dropped first, so a resumed run's
  file has each step once.
* wandb: ``cfg.logger.wandb.mode`` is ``offline`` (default: files under ``<run_dir>/wandb``, sync later
  with ``wandb sync``), ``online`` (only if an API key is present, else offline with a warning) or
  ``disabled``.
* tqdm: steps of the environment, with the metrics named in ``cfg.logger.progress_keys``.
"""

from __future__ import annotations

import csv
import io
import math
import os
import time
import warnings
from collections.abc import Mapping
from pathlib import Path

from flownav.atomic import atomic_write_text

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

        self.wandb_run = None
        mode = resolve_wandb_mode(str(_get(cfg, "logger.wandb.mode", "disabled")))
        if mode != "disabled":
            os.environ.setdefault("WANDB_SILENT", "true")
            if mode == "offline":
                os.environ["WANDB_MODE"] = "offline"
            import wandb

            self.wandb_run = wandb.init(
                project=str(_get(cfg, "logger.wandb.project", "flownav")),
                entity=_get(cfg, "logger.wandb.entity"),
                group=_get(cfg, "logger.wandb.group"),
                name=f"{_get(cfg, 'name', 'run')}-seed{_get(cfg, 'seed', 0)}",
                dir=str(self.run_dir),
                config=_to_container(cfg),
                mode=mode,
                resume="allow",
                id=self._wandb_id(),
            )

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
        if self.wandb_run is not None:
            self.wandb_run.log(dict(metrics), step=int(step))
        if self.bar is not None:
            self.bar.update(max(0, int(step) - self._last_step))
            shown = {k.split("/")[-1]: f"{row[k]:.3g}" for k in self.progress_keys if k in row}
            if shown:
                self.bar.set_postfix(shown, refresh=False)
        self._last_step = int(step)

    @property
    def elapsed(self) -> float:
        return time.time() - self.t0

    def summary(self, metrics: Mapping[str, float]) -> None:
        if self.wandb_run is not None:
            for k, v in metrics.items():
                self.wandb_run.summary[k] = v

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None
        if self.wandb_run is not None:
            self.wandb_run.finish()
            self.wandb_run = None
