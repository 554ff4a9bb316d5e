"""Can a reactive policy do what the oracle does? DAgger with the oracle as the expert, in one test or a family.

    python scripts/oracle_imitation.py --view geo_priv --out /tmp/oracle_imitation_geo_priv.json
    python scripts/oracle_imitation.py --view ego_mem --episodes 256 --iterations 5 --eval-episodes 1000
    python scripts/oracle_imitation.py --test flow=family_mix task=family --oracle oracle --prior short

The question behind item 7's targets (docs/oracle.md): the oracle reaches about 90% of the periodic ABC test by
planning 20 time units ahead with the true flow, where every trained policy stays near head-to-target (1-3%). If a
reactive network trained *in* a test, by imitating the oracle itself, cannot get near it either, the target needs
memory or planning, not another teacher. This script measures it; it ships nothing.

Each iteration runs ``--episodes`` fresh episodes of the test (``--test``: train.py overrides, by default the
well-posed ABC test flow=abc_periodic task=abc env=abc_periodic; a flow family gives a teacher over the
generalist's families) to the end. At every step of every running episode the oracle (``--oracle``: the settings
of that policy in conf/evaluate/config.yaml, by default ``oracle_long``, the ABC oracle) labels the state with its
action, planned from the env's true state; the behaviour is the oracle's own action with probability
beta_i = 0.5 ** i (iteration 0: the oracle alone), else the student's. The (view, oracle action) pairs are
aggregated; the student (an MLP, flownav.agents.networks.DeterministicPolicy; with ``--prior`` a correction of
head-to-target, as the generalist teacher's, turning the way it names) is refitted on all of them (eq. 9, the
normaliser set to their statistics) and evaluated on the protocol's held-out episodes (seed EVAL_SEED, as
``python evaluate.py``). Prints one line per iteration and writes them to ``--out`` as JSON; ``--save`` writes the
student as a policy checkpoint (role ``teacher``: ``python evaluate.py checkpoint=<it>`` runs it, and it can label
states for a DAgger student, alone or as the generalist of a scene-routed teacher).
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from pathlib import Path

import torch
from omegaconf import OmegaConf

from flownav.agents.networks import DeterministicPolicy
from flownav.algorithms.dagger import imitation_loss, set_normalizer_from
from flownav.atomic import atomic_write_text
from flownav.builders import build_env, build_flow, build_task, compose_config
from flownav.checkpoint import save_policy_checkpoint
from flownav.envs.navigation import Status
from flownav.envs.observations import observation_size
from flownav.evaluation.oracle import Oracle
from flownav.evaluation.protocol import EvalSpec, evaluate
from flownav.paths import REPO_ROOT
from flownav.provenance import provenance

TEST = ["flow=abc_periodic", "task=abc", "env=abc_periodic"]
COLLECT_SEED = 7_000  # collection episodes: seeds far from the protocol's EVAL_SEED


def oracle_settings(name: str) -> dict:
    """The settings of the suite's oracle ``name`` (``oracle``: the zoo's; ``oracle_long``: the ABC one)."""
    cfg = OmegaConf.load(REPO_ROOT / "conf" / "evaluate" / "config.yaml")
    return OmegaConf.to_container(cfg.policies[name].settings)


@torch.inference_mode()
def collect(env, oracle: Oracle, student, view: str, beta: float, gen: torch.Generator):
    """Run every slot's episode to its end; return (views, oracle actions) of all visited states, and each
    episode's final status under the behaviour."""
    td = env.reset()
    running = torch.ones(env.num_envs, dtype=torch.bool)
    status = torch.zeros(env.num_envs, dtype=torch.long)
    obs, labels = [], []
    while running.any():
        idx = running.nonzero().squeeze(-1)
        o = td[view][idx]
        label = oracle.act_privileged(env, idx)
        obs.append(o.clone())
        labels.append(label.clone())
        own = torch.rand(idx.numel(), generator=gen) < beta
        action = torch.zeros(env.num_envs, 3)
        action[idx] = torch.where(own[:, None], label, student(o))
        td["action"] = action
        td = env.step(td)["next"]
        done = td["done"].reshape(-1) & running
        status = torch.where(done, td["status"].reshape(-1), status)  # frozen at each episode's end
        running &= ~done
    return torch.cat(obs), torch.cat(labels), status


def fit(student, obs, labels, epochs: int, batch: int, lr: float, gen: torch.Generator) -> float:
    set_normalizer_from(student, obs)
    opt = torch.optim.Adam(student.net.parameters(), lr=lr)
    student.train()
    loss = torch.tensor(0.0)
    for _ in range(epochs):
        order = torch.randperm(len(obs), generator=gen)
        for start in range(0, len(obs), batch):
            b = order[start : start + batch]
            loss = imitation_loss(student(obs[b]), labels[b])
            opt.zero_grad()
            loss.backward()
            opt.step()
    student.eval()
    return float(loss.detach())


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--test", nargs="+", default=TEST, help="train.py overrides that pose the test (default: ABC)")
    p.add_argument("--oracle", default="oracle_long", choices=("oracle", "oracle_long"), help="the expert's settings")
    p.add_argument("--view", default="geo_priv", help="the student's observation view")
    p.add_argument("--prior", default=None, choices=("short", "left_biased"), help="correct head-to-target")
    p.add_argument("--episodes", type=int, default=256, help="collection episodes per iteration")
    p.add_argument("--iterations", type=int, default=5)
    p.add_argument("--eval-episodes", type=int, default=1000)
    p.add_argument("--epochs", type=int, default=20, help="passes over the aggregated pairs per iteration")
    p.add_argument("--hidden", type=int, nargs="+", default=[256, 256])
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--out", type=Path, default=None, help="the rows as JSON")
    p.add_argument("--save", type=Path, default=None, help="the student after each iteration, a policy checkpoint")
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    gen = torch.Generator().manual_seed(0)

    cfg = compose_config(args.test)
    flow = build_flow(cfg.flow)
    task = build_task(cfg.task, flow)
    probe = build_env(cfg.env, flow, task, [args.view], num_envs=1)
    low, high = probe.action_spec.space.low.reshape(-1), probe.action_spec.space.high.reshape(-1)
    prior = {"prior": args.view, "prior_turn": args.prior} if args.prior else {}
    student = DeterministicPolicy(observation_size(args.view), low.tolist(), high.tolist(), hidden=args.hidden, **prior)
    spec = EvalSpec(flow, task, cfg.env, args.eval_episodes, chunk_size=args.eval_episodes)
    settings = oracle_settings(args.oracle)
    record = {  # what every output says about how it was made
        **provenance("python scripts/oracle_imitation.py " + " ".join(shlex.quote(a) for a in sys.argv[1:])),
        "view": args.view,
        "test": args.test,
        "oracle": args.oracle,
        "settings": settings,
        "args": {k: str(v) for k, v in vars(args).items()},
    }

    rows, all_obs, all_labels = [], [], []
    for i in range(args.iterations):
        t0 = time.time()
        env = build_env(cfg.env, flow, task, [args.view], num_envs=args.episodes, seed=COLLECT_SEED + i)
        beta = 0.5**i
        obs, labels, status = collect(env, Oracle(**settings, seed=i), student, args.view, beta, gen)
        all_obs.append(obs)
        all_labels.append(labels)
        loss = fit(student, torch.cat(all_obs), torch.cat(all_labels), args.epochs, 4096, 1e-3, gen)
        s = evaluate(student, args.view, spec).summary
        row = {
            "iteration": i,
            "beta": beta,
            "behaviour_success": float((status == Status.SUCCESS).float().mean()),
            "pairs": sum(len(o) for o in all_obs),
            "fit_loss": loss,
            "student_success": s["success_rate"],
            "student_left_domain": s["failures"]["left_domain"]["rate"],
            "seconds": round(time.time() - t0, 1),
        }
        rows.append(row)
        print(json.dumps(row), flush=True)
        if args.out:
            atomic_write_text(args.out, json.dumps({**record, "rows": rows}, indent=1))
        if args.save:
            save_policy_checkpoint(args.save, student, args.view, "teacher", meta={**record, "row": row})


if __name__ == "__main__":
    main()
