"""What the flow-gradient sense gives the shipped student, and what an error on it costs: ``generalist_student``
(view ``ego_mem_grad``) on the paper's task and on the validation set's cases, with its gradient as sensed, with a
fresh error of each standard deviation on every gradient component at every step (``env.sensor_noise.gradient``),
with an error of each standard deviation drawn once per episode (``env.sensor_bias.gradient``: a steady bias)
(the flow and to-target readings exact), and with the gradient input set to zero (the sense removed; the policy's
other inputs as they are). ``--rms``: the scale the noise suite's errors are set against instead, the RMS per
component of the flow reading and of the gradient in the paper's task (2,000 swimmers of random actions, 100 steps).

    python scripts/gradient_sense.py                       # noise 0.02 0.05 0.1 1.0, bias 0.02 0.05 0.1, 10,000 / 2,000
    python scripts/gradient_sense.py --noise 0.05 --bias 0.05 --episodes 1000 --validation-episodes 500
    python scripts/gradient_sense.py --rms

Episodes are the protocol's (evaluation seed EVAL_SEED), the same for every row of a case. docs/generalist.md quotes it.
"""

from __future__ import annotations

import argparse

import torch
from omegaconf import OmegaConf

from flownav.builders import build_env, build_flow, build_task, compose_config
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


def reading_rms(swimmers: int = 2000, steps: int = 100) -> tuple[float, float]:
    """RMS per component of ego_mem_grad's newest flow reading and of its gradient in the paper's task, over
    ``swimmers`` swimmers of uniformly random actions for ``steps`` steps (env seed 0, action seed 1)."""
    cfg = compose_config(["obs=ego_mem_grad"])
    flow = build_flow(cfg.flow)
    env = build_env(cfg.env, flow, build_task(cfg.task, flow), ["ego_mem_grad"], num_envs=swimmers)
    g = torch.Generator().manual_seed(1)
    low, high = torch.tensor([0.0, -0.5, -0.5]), torch.tensor([1.0, 0.5, 0.5])
    td, flows, gradients = env.reset(), [], []
    for _ in range(steps):
        td = env.step(td.set("action", low + (high - low) * torch.rand(swimmers, 3, generator=g)))["next"]
        view = td["ego_mem_grad"]
        flows.append(view[:, 8:11])  # the newest memory sample: the flow reading in the body frame
        gradients.append(view[:, -GRADIENT:])
    rms = lambda x: torch.cat(x).pow(2).mean().sqrt().item()  # noqa: E731
    return rms(flows), rms(gradients)


def main(noise: list[float], bias: list[float], episodes: int, validation_episodes: int) -> None:
    torch.set_num_threads(1)
    suite = Suite(compose_config(["+experiment=validation"], app="evaluate"))
    policy, view, _ = suite.policy(POLICY)
    if view != "ego_mem_grad":
        raise SystemExit(f"{POLICY} reads {view!r}; this script removes ego_mem_grad's gradient")
    exact = {"sensor_noise": {"gradient": 0.0}, "sensor_bias": {"gradient": 0.0}}
    rows = [("as sensed", policy, exact)]
    rows += [(f"gradient error {s:g}", policy, {**exact, "sensor_noise": {"gradient": s}}) for s in noise]
    rows += [(f"gradient bias {s:g}", policy, {**exact, "sensor_bias": {"gradient": s}}) for s in bias]
    rows.append(("gradient input zero", without_gradient(policy), exact))
    for case, (flow_cfg, task_cfg, kind) in cases(suite).items():
        flow = suite.flow(flow_cfg)
        task = build_task(task_cfg, flow)
        n = validation_episodes if kind else episodes
        for label, act, errors in rows:
            env = OmegaConf.merge(suite.cfg.env, errors)
            r = evaluate(act, view, EvalSpec(flow, task, env, n, seed=suite.seed)).summary
            lo, hi = r["success_ci95"]
            print(f"{case} | {label}: {100 * r['success_rate']:.2f}% [{100 * lo:.2f}, {100 * hi:.2f}] of {n}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--noise", type=float, nargs="*", default=[0.02, 0.05, 0.1, 1.0])
    parser.add_argument("--bias", type=float, nargs="*", default=[0.02, 0.05, 0.1])
    parser.add_argument("--episodes", type=int, default=10_000, help="on the paper's task")
    parser.add_argument("--validation-episodes", type=int, default=2_000, help="per validation case")
    parser.add_argument("--rms", action="store_true", help="print the readings' RMS instead")
    args = parser.parse_args()
    if args.rms:
        torch.set_num_threads(1)
        flow_rms, gradient_rms = reading_rms()
        print(f"RMS per component in the paper's task: flow reading {flow_rms:.3f}, gradient {gradient_rms:.3f}")
    else:
        main(args.noise, args.bias, args.episodes, args.validation_episodes)
