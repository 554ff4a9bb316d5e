"""What the flow-gradient sense gives the shipped student, and what an error on it costs: ``generalist_student``
(view ``ego_mem_grad``) on the paper's task and on the validation set's cases, with its gradient as sensed, with a
fresh error of each standard deviation on every gradient component at every step (``env.sensor_noise.gradient``;
the flow and to-target readings exact), and with the gradient input set to zero (the sense removed; the policy's
other inputs as they are).

    python scripts/gradient_sense.py                       # 0.02 0.05 0.1 1.0, 10,000 / 2,000 episodes
    python scripts/gradient_sense.py --noise 0.05 --episodes 1000 --validation-episodes 500

Episodes are the protocol's (evaluation seed EVAL_SEED), the same for every row of a case. docs/generalist.md quotes it.
"""

from __future__ import annotations

import argparse

import torch
from omegaconf import OmegaConf

from flownav.builders import build_task, compose_config
from flownav.evaluation.experiments import Suite
from flownav.evaluation.protocol import EvalSpec, evaluate

POLICY = "generalist_student"  # a policy of the evaluation config whose view is ego_mem_grad
GRADIENT = 9  # the view's last 9 entries: the body-axis gradient, row-major


def without_gradient(policy):
    """The policy fed zeros where its view holds the gradient."""

    def act(obs: torch.Tensor) -> torch.Tensor:
        return policy(torch.cat((obs[:, :-GRADIENT], torch.zeros_like(obs[:, -GRADIENT:])), -1))

    return act


def cases(suite: Suite) -> dict:
    """(flow config, task config, episodes) by case: the paper's task, then the validation set's cases."""
    paper = compose_config([])
    out = {"the paper's task": (paper.flow, paper.task, None)}
    for name, case in suite.cfg.suite.validation.cases.items():
        out[f"validation/{name}"] = (case.flow, case.task, "validation")
    return out


def main(noise: list[float], episodes: int, validation_episodes: int) -> None:
    torch.set_num_threads(1)
    suite = Suite(compose_config(["+experiment=validation"], app="evaluate"))
    policy, view, _ = suite.policy(POLICY)
    if view != "ego_mem_grad":
        raise SystemExit(f"{POLICY} reads {view!r}; this script removes ego_mem_grad's gradient")
    rows = [("as sensed", policy, 0.0)] + [(f"gradient error {s:g}", policy, s) for s in noise]
    rows.append(("gradient input zero", without_gradient(policy), 0.0))
    for case, (flow_cfg, task_cfg, kind) in cases(suite).items():
        flow = suite.flow(flow_cfg)
        task = build_task(task_cfg, flow)
        n = validation_episodes if kind else episodes
        for label, act, sigma in rows:
            env = OmegaConf.merge(suite.cfg.env, {"sensor_noise": {"gradient": sigma}})
            r = evaluate(act, view, EvalSpec(flow, task, env, n, seed=suite.seed)).summary
            lo, hi = r["success_ci95"]
            print(f"{case} | {label}: {100 * r['success_rate']:.2f}% [{100 * lo:.2f}, {100 * hi:.2f}] of {n}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--noise", type=float, nargs="*", default=[0.02, 0.05, 0.1, 1.0])
    parser.add_argument("--episodes", type=int, default=10_000, help="on the paper's task")
    parser.add_argument("--validation-episodes", type=int, default=2_000, help="per validation case")
    args = parser.parse_args()
    main(args.noise, args.episodes, args.validation_episodes)
