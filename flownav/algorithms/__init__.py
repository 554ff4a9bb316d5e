"""Training algorithms: ``ppo`` (geo teacher, ego baseline), ``dagger`` (ego student) and ``oracle_dagger`` (a
network that imitates the oracle).

Each module exposes ``train(cfg, run_dir) -> dict`` of final metrics; ``train.py`` dispatches on
``cfg.algo.name`` and imports the module lazily.
"""

ALGORITHMS = {
    "ppo": "flownav.algorithms.ppo",
    "dagger": "flownav.algorithms.dagger",
    "oracle_dagger": "flownav.algorithms.oracle_dagger",
}

__all__ = ["ALGORITHMS"]
