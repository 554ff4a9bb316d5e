"""Train a navigation policy from composable Hydra configs.

    python train.py +experiment=teacher                       # PPO geo teacher on the cylinder wake
    python train.py +experiment=baseline_ego                  # PPO ego baseline
    python train.py -m +experiment=teacher seed=0,1,2,3,4     # five seeds, local joblib launcher
    python train.py -m hydra/launcher=slurm +experiment=teacher seed=0,1,2,3,4   # on a SLURM cluster
    python train.py +experiment=teacher resume=outputs/teacher/<run>             # continue a run
    python train.py +experiment=teacher flow=vortex_street algo.total_frames=2e6 # analytic stand-in flow
    python train.py +experiment=student ship=true     # full budget: also copy to output_checkpoint, results_json

The run directory (Hydra's output dir) holds config.yaml, metrics.csv, checkpoints/ and final_metrics.json;
a run writes nowhere else unless ``ship=true`` (flownav/shipping.py).
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

from flownav.algorithms import ALGORITHMS
from flownav.builders import ConfigError
from flownav.checkpoint import find_resume, load_resume_checkpoint
from flownav.runlog import WANDB_MODES
from flownav.shipping import ship_run, train_targets


def validate(cfg: DictConfig) -> None:
    """Checks every trainer relies on; algorithm-specific ones live in the algorithm module."""
    if cfg.algo.name not in ALGORITHMS:
        raise ConfigError(f"algo.name is {cfg.algo.name!r}; choose one of {sorted(ALGORITHMS)}")
    if cfg.logger.wandb.mode not in WANDB_MODES:
        raise ConfigError(f"logger.wandb.mode is {cfg.logger.wandb.mode!r}; choose one of {list(WANDB_MODES)}")
    if cfg.threads is not None and int(cfg.threads) < 1:
        raise ConfigError(f"threads must be >= 1 or null, got {cfg.threads}")
    try:
        torch.device(cfg.device)
    except RuntimeError as e:
        raise ConfigError(f"device {cfg.device!r} is not a torch device ({e})") from e
    if not isinstance(cfg.seed, int):
        raise ConfigError(f"seed must be an integer, got {cfg.seed!r}")


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
    # Every check before the first write: what ship=true would copy, and the run a resume continues
    # (it writes into that run's directory: its metrics.csv and checkpoints continue).
    targets = train_targets(cfg, multirun=multirun_jobs() is not None)
    if cfg.resume:
        run_dir, _ = find_resume(cfg.resume)
        load_resume_checkpoint(cfg.resume, str(cfg.obs.view), needs=algo.RESUME_NEEDS)
    torch.set_num_threads(pick_threads(cfg))
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    OmegaConf.save(cfg, run_dir / ("config_resumed.yaml" if cfg.resume else "config.yaml"), resolve=True)
    metrics = algo.train(cfg, run_dir)
    clean = {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in metrics.items()}
    if targets:
        clean["shipped"] = ship_run(run_dir, targets)
    (run_dir / "final_metrics.json").write_text(json.dumps(clean, indent=2, default=str))
    return clean


@hydra.main(version_base="1.3", config_path="conf", config_name="config")
def main(cfg: DictConfig):
    return run(cfg, HydraConfig.get().runtime.output_dir)


if __name__ == "__main__":
    main()
