"""The evaluation protocol: the one way flownav measures a policy.

Every number flownav prints about a policy (``evaluate.py``, the experiment suites, seed selection,
PPO's and DAgger's evaluations during and after training, the scripts) comes from :func:`evaluate`:

* the episodes of chunk ``c`` run in a fresh env seeded ``env_seed(spec.seed, c)`` (:data:`EVAL_SEED`
  unless a spec says otherwise), so the same spec gives the same starts, targets, headings and flow
  phases to every policy and every caller;
* exactly ``spec.episodes`` deterministic episodes (the policy's mean action), one per env slot, no
  auto-reset (:func:`flownav.evaluation.rollout.run_episodes`);
* one summary format (:func:`flownav.evaluation.metrics.summarize`): success rate with its Wilson
  interval, times of the successes, failure causes.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

from torch import Tensor

from flownav.evaluation.metrics import summarize
from flownav.evaluation.rollout import Episodes, MakeEnv, run_episodes

EVAL_SEED = 0  # the held-out evaluation seed of every default evaluation
CHUNK_SEED_STRIDE = 1_000_003  # chunk c of a spec with seed s runs in an env seeded s + c * stride


def env_seed(seed: int, chunk: int) -> int:
    """The env seed of chunk ``chunk`` of an evaluation with seed ``seed`` (the one seed rule)."""
    return int(seed) + CHUNK_SEED_STRIDE * int(chunk)


@dataclass(frozen=True)
class EvalSpec:
    """What an evaluation runs on: a built flow and task, the env config, how many episodes, which seed.

    ``flow`` and ``task`` are built objects (:func:`flownav.builders.build_flow` / ``build_task``) so
    that a suite loads a CFD wake once for all its policies.
    """

    flow: object
    task: object
    env_cfg: Mapping
    episodes: int
    seed: int = EVAL_SEED
    chunk_size: int = 10_000
    device: str = "cpu"

    @classmethod
    def from_config(cls, cfg: Mapping, episodes: int | None = None) -> EvalSpec:
        """The spec of evaluate.py's config: ``cfg.flow`` / ``cfg.task`` / ``cfg.env``, ``cfg.episodes`` (or
        ``episodes``), ``cfg.seed``, ``cfg.chunk_size``, ``cfg.device``."""
        from flownav.builders import build_flow, build_task  # builders imports the envs; keep this module light

        flow = build_flow(cfg["flow"], device=cfg["device"])
        n = int(cfg["episodes"] if episodes is None else episodes)
        return cls(
            flow,
            build_task(cfg["task"], flow),
            cfg["env"],
            n,
            int(cfg["seed"]),
            int(cfg["chunk_size"]),
            str(cfg["device"]),
        )

    def make_env(self, views: Sequence[str]) -> MakeEnv:
        """``make_env(num_envs, chunk)`` for :func:`run_episodes`, seeded by :func:`env_seed`."""
        from flownav.builders import build_env  # builders imports the envs; keep this module light

        def make(n: int, chunk: int):
            return build_env(
                self.env_cfg,
                self.flow,
                self.task,
                list(views),
                num_envs=n,
                seed=env_seed(self.seed, chunk),
                device=self.device,
            )

        return make


@dataclass
class Evaluation:
    """The episodes of one evaluation and their summary (``metrics.summarize``'s dict)."""

    episodes: Episodes
    summary: dict = field(default_factory=dict)

    @property
    def success_rate(self) -> float:
        return float(self.summary["success_rate"])


def evaluate(
    policy: Callable[[Tensor], Tensor],
    obs_key: str,
    spec: EvalSpec,
    *,
    record: int = 0,
    progress: bool = False,
    max_steps: int | None = None,
) -> Evaluation:
    """Run ``spec.episodes`` deterministic episodes of ``policy`` reading ``obs_key``; see the module doc.

    ``record``: keep the full trajectories of the first ``record`` episodes (``Episodes.trajectories``).
    """
    ep = run_episodes(
        policy,
        obs_key,
        spec.make_env([obs_key]),
        int(spec.episodes),
        int(spec.chunk_size),
        record=record,
        max_steps=max_steps,
        progress=progress,
    )
    return Evaluation(episodes=ep, summary=summarize(ep.status, ep.time))
