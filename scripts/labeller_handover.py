"""How well a labeller does from the states a student visits: the student acts for the first ``k`` steps of each
episode, the labeller from then on, and the episodes count the labeller's successes from where the student had
brought the swimmer. DAgger labels the states its student visits, so a labeller is judged there, not on its own
rollouts (docs/generalist_variants.md, "One expert of every wake scene": a labeller within 2 points of another on
its own episodes gave students 5-9 points below the other's).

The protocol's episodes (same starts, targets, headings and flow phases for every pair); the student's steps are
the same for every labeller, so the rows are paired. Each row counts the episodes of one scene (by default the far
starts that scene code 4 routes to ``algo.scene_away_expert``) still running at step ``k``: the labeller's success
from there, and the student's own on the same episodes.

    python scripts/labeller_handover.py checkpoints/generalist_student.pt checkpoints/generalist_away_expert.pt \
        checkpoints/generalist_wake_scenes_expert.pt
    python scripts/labeller_handover.py <student.pt> <labeller.pt>... --steps 0 25 50 --episodes 2000
    python scripts/labeller_handover.py <student.pt> scripted:oracle --episodes 200    # the planner's actions

Defaults: the students' far starts in the wake as posed (``flow=family_wake_posed task=posed_wake_any_start``),
10,000 episodes, hand-over at steps 0, 25, 50 and 75 (time 0, 5, 10, 15).
"""

from __future__ import annotations

import argparse
import functools
from collections.abc import Iterator

import torch
from torch import Tensor

from flownav.builders import compose_config
from flownav.envs.core import SCENE_AWAY, observe, paper_scene
from flownav.errors import reported_as_one_line
from flownav.evaluation.metrics import wilson_interval
from flownav.evaluation.protocol import EvalSpec
from flownav.evaluation.rollout import Episodes, run_episodes
from flownav.evaluation.scripted import load_evaluated

FAR_STARTS = ("flow=family_wake_posed", "task=posed_wake_any_start")


@functools.cache
def load(name: str):
    """(policy, view) of a checkpoint file or of ``scripted:<name>``, read once per name."""
    policy, payload = load_evaluated(name, key="policy")
    return policy, payload["obs"]


def _act(policy, view: str, env, views: dict, idx: Tensor) -> Tensor:
    """The actions of ``policy`` for the slots ``idx``: from the env's state (a planner) or from its view."""
    if hasattr(policy, "act_privileged"):
        return policy.act_privileged(env, idx)
    return policy(views[view][idx.to(views[view].device)])


class HandOver:
    """The student acts while a slot is fewer than ``at`` steps into its episode, the labeller from then on.

    It reads the env's state (every view the env emits), so :func:`run_episodes` runs it as a privileged policy;
    ``scenes`` keeps each chunk's scene codes (:func:`paper_scene`), read at the first step (the reset)."""

    def __init__(self, student, student_view: str, labeller, labeller_view: str, at: int):
        self.student, self.student_view = student, student_view
        self.labeller, self.labeller_view = labeller, labeller_view
        self.at, self.scenes, self._env = int(at), [], None

    @torch.inference_mode()
    def act_privileged(self, env, slots: Tensor) -> Tensor:
        if env is not self._env:
            self._env = env
            self.scenes.append(paper_scene(env.state, env.flow, env.settings).cpu())
        views = observe(env.state, env.flow, env.settings)
        slots = slots.to(env.device)
        handed = env.state.steps[slots] >= self.at
        action = torch.zeros(slots.numel(), 3, device=env.device)
        for who, view, mask in (
            (self.student, self.student_view, ~handed),
            (self.labeller, self.labeller_view, handed),
        ):
            if mask.any():
                action[mask] = _act(who, view, env, views, slots[mask])
        return action


def run(student: str, labeller: str | None, at: int, spec: EvalSpec) -> tuple[Episodes, Tensor]:
    """The episodes of ``student`` handing over to ``labeller`` at step ``at`` (None: the student alone) and
    each episode's scene code."""
    s_policy, s_view = load(student)
    l_policy, l_view = load(labeller) if labeller else (s_policy, s_view)
    policy = HandOver(s_policy, s_view, l_policy, l_view, at if labeller else 1 << 30)
    views = list(dict.fromkeys((s_view, l_view)))
    episodes = run_episodes(policy, s_view, spec.make_env(views), spec.episodes, spec.chunk_size)
    return episodes, torch.cat(policy.scenes)


def handover_rows(student: str, labellers: list[str], steps: list[int], spec: EvalSpec, scene: int) -> Iterator[dict]:
    """Per labeller and hand-over step: of the episodes of ``scene`` the student has not ended by that step, how many
    the labeller brings to the target, and how many the student alone does."""
    alone, scenes = run(student, None, 0, spec)
    dt = float(spec.env_cfg["dt"])
    for k in steps:
        # an episode is still running at step k if the student alone has not ended it in its first k steps
        pick = (scenes == scene) & (alone.time > (k + 0.5) * dt)
        for name in labellers:
            handed, _ = run(student, name, k, spec)
            n = int(pick.sum())
            wins, own = int(handed.success[pick].sum()), int(alone.success[pick].sum())
            yield {
                "labeller": name,
                "step": k,
                "episodes": n,
                "success": wins / max(n, 1),
                "success_ci95": wilson_interval(wins, n) if n else (0.0, 0.0),
                "student_alone": own / max(n, 1),
            }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("student", help="the student's checkpoint (it acts first)")
    parser.add_argument("labellers", nargs="+", help="checkpoints or scripted:<name> that take over")
    parser.add_argument("--steps", nargs="+", type=int, default=[0, 25, 50, 75], help="hand-over steps")
    parser.add_argument("--episodes", type=int, default=10_000)
    parser.add_argument("--scene", type=int, default=SCENE_AWAY, help="the scene code counted (default: far starts)")
    parser.add_argument("--set", action="append", default=[], metavar="OVERRIDE", help="evaluate.py overrides")
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    with reported_as_one_line():
        for name in (args.student, *args.labellers):
            load(name)  # every policy read before the first episode (and only once)
        cfg = compose_config([*FAR_STARTS, *args.set], app="evaluate")
        spec = EvalSpec.from_config(cfg, episodes=args.episodes)
        for r in handover_rows(args.student, args.labellers, args.steps, spec, args.scene):
            lo, hi = r["success_ci95"]
            print(
                f"step {r['step']:>3} | {r['labeller']}: {100 * r['success']:.2f}% [{100 * lo:.2f}, {100 * hi:.2f}] "
                f"of {r['episodes']} (the student alone {100 * r['student_alone']:.2f}%)",
                flush=True,
            )


if __name__ == "__main__":
    main()
