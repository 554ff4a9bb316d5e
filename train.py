"""Train a navigation policy from composable Hydra configs.

    python train.py +experiment=teacher                       # PPO geo teacher on the cylinder wake
    python train.py +experiment=baseline_ego                  # PPO ego baseline
    python train.py -m +experiment=teacher seed=0,1,2,3,4     # five seeds, local joblib launcher
    python train.py -m hydra/launcher=slurm +experiment=teacher seed=0,1,2,3,4   # on a SLURM cluster
    python train.py +experiment=teacher resume=outputs/teacher/<run>             # continue a run
    python train.py +experiment=teacher hydra.run.dir=<run> resume=auto          # continue <run> if it has last.pt
    python train.py +experiment=teacher flow=vortex_street algo.total_frames=2e6 # analytic stand-in flow
    python train.py +experiment=student ship=true     # full budget: also copy to output_checkpoint, results_json

The run directory (Hydra's output dir) holds config.yaml, metrics.csv, checkpoints/ and final_metrics.json;
a run writes nowhere else unless ``ship=true`` (flownav/shipping.py). A multirun's sweep directory also gets
sweep_summary.json / .md (flownav/sweep.py, docs/ecosystem.md).
``train.py`` dispatches on ``algo.name`` to ``flownav.algorithms.<name>.train(cfg, run_dir)``.
"""

from __future__ import annotations

import importlib
import json
import math
import os
from pathlib import Path

import hydra
import torch
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf

from flownav import schema
from flownav.algorithms import ALGORITHMS
from flownav.atomic import atomic_write_text
from flownav.checkpoint import check_resume_settings, find_resume, load_resume_checkpoint
from flownav.errors import reported_as_one_line
from flownav.resume import resolve_resume
from flownav.shipping import ship_run, train_targets


def validate(cfg: DictConfig) -> None:
    """Every key against its group's schema (flownav.schema); cross-key checks live in the algorithm module."""
    schema.check_train(cfg)


def multirun_jobs() -> int | None:
    """The number of parallel jobs of a -m sweep, None outside one (or outside Hydra: tests call run())."""
    try:
        hc = HydraConfig.get()
    except ValueError:
        return None
    if hc.mode != RunMode.MULTIRUN:
        return None
    jobs = int(OmegaConf.select(hc, "launcher.n_jobs", default=1) or 1)
    return jobs if jobs > 0 else os.cpu_count() or 1


def pick_threads(cfg: DictConfig) -> int:
    if cfg.threads is not None:
        return int(cfg.threads)
    cores = os.cpu_count() or 1
    return max(1, cores // (multirun_jobs() or 1))


def run(cfg: DictConfig, run_dir: str | Path) -> dict:
    validate(cfg)
    algo = importlib.import_module(ALGORITHMS[cfg.algo.name])
    cfg.resume = resolve_resume(cfg.resume, run_dir)  # resume=auto, and requeued cluster jobs: own last.pt
    # Every check before the first write: what ship=true would copy, and the run a resume continues
    # (it writes into that run's directory: its metrics.csv and checkpoints continue).
    targets = train_targets(cfg, multirun=multirun_jobs() is not None)
    if cfg.resume:
        run_dir, _ = find_resume(cfg.resume)
        _, payload = load_resume_checkpoint(cfg.resume, str(cfg.obs.view), needs=algo.RESUME_NEEDS)
        check_resume_settings(cfg.resume, payload, OmegaConf.to_container(cfg, resolve=True))
    torch.set_num_threads(pick_threads(cfg))
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    OmegaConf.save(cfg, run_dir / ("config_resumed.yaml" if cfg.resume else "config.yaml"), resolve=True)
    metrics = algo.train(cfg, run_dir)
    clean = {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in metrics.items()}
    if targets:
        clean["shipped"] = ship_run(run_dir, targets)
    atomic_write_text(run_dir / "final_metrics.json", json.dumps(clean, indent=2, default=str))
    return clean


@hydra.main(version_base="1.3", config_path="conf", config_name="config")
def main(cfg: DictConfig):
    with reported_as_one_line():  # bad input: one line, exit status 2 (FLOWNAV_DEBUG=1: the traceback)
        return run(cfg, HydraConfig.get().runtime.output_dir)


if __name__ == "__main__":
    main()
