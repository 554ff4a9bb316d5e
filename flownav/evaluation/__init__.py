"""The evaluation protocol (``protocol.evaluate``: one seed rule, one summary), deterministic batched
episodes (``rollout``), statistics (``metrics``) and how they print (``tables``), reference policies
(``scripted``, ``oracle``), seed selection (``selection``), the suite (``experiments``, its kinds in
``kinds/`` registered in ``registry``) and its report (``report``). Entry points: ``evaluate.py``,
``python -m flownav.evaluation.selection``."""

from flownav.evaluation.metrics import subregion_counts, summarize, wilson_interval
from flownav.evaluation.protocol import EVAL_SEED, EvalSpec, Evaluation, env_seed, evaluate
from flownav.evaluation.rollout import Episodes, run_episodes

__all__ = [
    "EVAL_SEED",
    "Episodes",
    "EvalSpec",
    "Evaluation",
    "env_seed",
    "evaluate",
    "run_episodes",
    "subregion_counts",
    "summarize",
    "wilson_interval",
]
