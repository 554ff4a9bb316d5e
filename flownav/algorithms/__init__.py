"""Training algorithms: ``ppo`` (geo teacher, ego baseline) and ``dagger`` (ego student).

Each module exposes ``train(cfg, run_dir) -> dict`` of final metrics; ``train.py`` dispatches on
``cfg.algo.name`` and imports the module lazily.
"""

ALGORITHMS = {"ppo": "flownav.algorithms.ppo", "dagger": "flownav.algorithms.dagger"}

__all__ = ["ALGORITHMS"]
