"""Deterministic batched evaluation (``rollout``), statistics (``metrics``), the paper's experiments
(``experiments``) and their report (``report``). Entry point: ``evaluate.py``."""

from flownav.evaluation.metrics import subregion_counts, summarize, wilson_interval
from flownav.evaluation.rollout import Episodes, run_episodes

__all__ = ["Episodes", "run_episodes", "subregion_counts", "summarize", "wilson_interval"]
