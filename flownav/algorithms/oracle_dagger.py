"""DAgger with the oracle as the expert: a reactive network learns to do what the planner does.

The oracle (flownav/evaluation/oracle.py) plans with the true flow, so no teacher checkpoint is needed: it labels
every state from the env's true state. Where PPO's exploration finds nothing (the periodic ABC test) or no expert
reaches the target (the wake's far starts), a network that imitates it can (docs/oracle.md).

One iteration ``i``, read top to bottom in :func:`train`:

1. **Collect.** ``episodes`` fresh episodes of the run's flow, task and env, run side by side to their end (no
   auto-reset). At every step of every running episode the oracle plans its action from the true state; the
   behaviour is that action with probability ``beta_decay ** i`` (iteration 0: the oracle alone), else the
   network's.
2. **Aggregate.** The (network's view, oracle action) pairs of all iterations so far are kept.
3. **Fit.** The observation normaliser set to their mean and variance (with ``init_from``, the saved network's
   kept: its weights read that one); Adam restarted (the data changed) for ``epochs`` passes over all of them in
   shuffled minibatches, minimising eq. 9.
4. **Evaluate.** ``eval_episodes`` held-out episodes of the protocol (``python evaluate.py``'s seed).

Collection episodes use seeds far from the protocol's, and the oracle's sampling its own seed, both per iteration,
so ``resume=<run dir>`` continues exactly: ``last.pt`` (after every iteration) carries the aggregated pairs, the
RNG states and the counters. The run's record (settings, one row per iteration) is ``<run>/results.json``.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import torch
from omegaconf import OmegaConf

from flownav.agents.networks import DeterministicPolicy
from flownav.algorithms.common import eval_metrics, require_finite_update
from flownav.algorithms.dagger import imitation_loss, set_normalizer_from
from flownav.atomic import atomic_write_text
from flownav.builders import build_env, build_flow, build_task
from flownav.checkpoint import RunCheckpoints, load_resume_checkpoint, warm_start
from flownav.devices import resolve_device
from flownav.envs.navigation import Status
from flownav.envs.observations import observation_size
from flownav.evaluation.oracle import Oracle
from flownav.evaluation.protocol import EvalSpec, evaluate
from flownav.paths import REPO_ROOT
from flownav.runlog import RunLogger, run_summary

RESUME_NEEDS = ("pairs", "history")  # this trainer's own entries of last.pt's train_state
COLLECT_SEED = 7_000  # collection episodes: env seeds far from the protocol's EVAL_SEED, 1,000 apart per run seed
NON_FINITE_FIX = "check algo.lr and the oracle's labels (a non-finite flow?)"


def oracle_settings(a) -> dict:
    """The expert's settings: those of the suite's oracle ``algo.oracle`` (conf/evaluate/config.yaml: ``oracle``,
    12 time units ahead; ``oracle_long``, the ABC one), with ``algo.oracle_settings`` replacing any of them."""
    suite = OmegaConf.load(REPO_ROOT / "conf" / "evaluate" / "config.yaml")
    named = OmegaConf.to_container(suite.policies[str(a.oracle)].settings)
    return named | OmegaConf.to_container(a.get("oracle_settings") or OmegaConf.create({}))


@torch.inference_mode()
def collect(env, oracle: Oracle, student, view: str, beta: float, gen: torch.Generator):
    """Run every slot's episode to its end; return the views and oracle actions of all visited states, and each
    episode's final status under the behaviour."""
    td = env.reset()
    running = torch.ones(env.num_envs, dtype=torch.bool, device=env.device)
    status = torch.zeros(env.num_envs, dtype=torch.long, device=env.device)
    obs, labels = [], []
    while running.any():
        idx = running.nonzero().squeeze(-1)
        o = td[view][idx]
        label = oracle.act_privileged(env, idx)
        obs.append(o.clone())
        labels.append(label.clone())
        own = (torch.rand(idx.numel(), generator=gen) < beta).to(env.device)
        action = torch.zeros(env.num_envs, 3, device=env.device)
        action[idx] = torch.where(own[:, None], label, student(o))
        td["action"] = action
        td = env.step(td)["next"]
        done = td["done"].reshape(-1) & running
        status = torch.where(done, td["status"].reshape(-1), status)  # frozen at each episode's end
        running &= ~done
    return torch.cat(obs), torch.cat(labels), status


def fit(student, optim, obs, labels, epochs: int, batch: int, gen: torch.Generator, refit_norm: bool = True) -> float:
    """Refit on all pairs: normaliser to their statistics (if ``refit_norm``), Adam from a fresh state, ``epochs``
    shuffled passes."""
    if refit_norm:
        set_normalizer_from(student, obs)
    optim.state.clear()
    student.train()
    loss = torch.tensor(0.0)
    for _ in range(epochs):
        order = torch.randperm(len(obs), generator=gen).to(obs.device)
        for start in range(0, len(obs), batch):
            b = order[start : start + batch]
            loss = imitation_loss(student(obs[b]), labels[b])
            optim.zero_grad()
            loss.backward()
            optim.step()
    student.eval()
    return float(loss.detach())


def train(cfg, run_dir) -> dict:
    run_dir = Path(run_dir)
    a = cfg.algo
    seed, view = int(cfg.seed), str(cfg.obs.view)
    iterations, episodes = int(a.iterations), int(a.episodes)
    eval_episodes = int(a.eval_episodes)
    role = str(cfg.get("role") or "teacher")
    device = resolve_device(cfg.device)
    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)

    flow = build_flow(cfg.flow, device=device)
    task = build_task(cfg.task, flow)
    probe = build_env(cfg.env, flow, task, [view], num_envs=1, device=device)  # the action box; the run's env state
    low, high = probe.action_spec.space.low.reshape(-1).tolist(), probe.action_spec.space.high.reshape(-1).tolist()
    prior = {"prior": view, "prior_turn": a.get("prior_turn")} if a.get("prior") else {}
    student = DeterministicPolicy(
        observation_size(view), low, high, hidden=list(a.hidden), activation=str(a.activation), **prior
    ).to(device)
    warm = bool(a.get("init_from"))  # its weights read the saved normaliser: kept through every refit
    if warm and not cfg.get("resume"):  # a resume carries its own weights
        warm_start(student, str(a.init_from), view)
    student.eval()
    optim = torch.optim.Adam(student.net.parameters(), lr=float(a.lr))
    spec = EvalSpec(flow, task, cfg.env, eval_episodes, chunk_size=max(eval_episodes, 1), device=str(device))
    settings = oracle_settings(a)
    config = OmegaConf.to_container(cfg, resolve=True)
    checkpoints = RunCheckpoints(run_dir / "checkpoints", student, view, role, config, probe, optim, {"fit": gen})

    iteration, wall_offset, history = 0, 0.0, []
    all_obs, all_labels = [], []
    if cfg.get("resume"):
        _, payload = load_resume_checkpoint(cfg.resume, expect_obs=view, needs=RESUME_NEEDS)
        st = checkpoints.restore(payload)
        iteration, wall_offset, history = int(st["iteration"]), float(st["wall_time"]), list(st["history"])
        if st["pairs"]:
            all_obs, all_labels = [st["pairs"]["obs"].to(device)], [st["pairs"]["oracle_action"].to(device)]
    logger = RunLogger(run_dir, cfg, total=iterations, start=iteration, wall_offset=wall_offset)
    meta = {"oracle": str(a.oracle), "oracle_settings": settings}

    def save(metrics: dict) -> Path:
        pairs = {"obs": torch.cat(all_obs), "oracle_action": torch.cat(all_labels)} if all_obs else {}
        counters = {"iteration": iteration, "frames": sum(len(o) for o in all_obs), "wall_time": logger.elapsed}
        return checkpoints.save("last.pt", counters, metrics, meta=meta, pairs=pairs, history=history)

    metrics: dict = dict(history[-1]) if history else {}
    while iteration < iterations:
        t0 = time.time()
        beta = float(a.beta_decay) ** iteration
        env = build_env(cfg.env, flow, task, [view], num_envs=episodes, seed=COLLECT_SEED + 1000 * seed + iteration)
        oracle = Oracle(**settings | {"seed": 1000 * seed + iteration})
        obs, labels, status = collect(env, oracle, student, view, beta, gen)
        all_obs.append(obs)
        all_labels.append(labels)
        pairs_obs = torch.cat(all_obs)
        loss = fit(student, optim, pairs_obs, torch.cat(all_labels), int(a.epochs), int(a.batch_size), gen, not warm)
        iteration += 1
        last = checkpoints.directory / "last.pt"
        require_finite_update("oracle DAgger", iteration, {"train/loss": loss}, student, last, NON_FINITE_FIX)
        metrics = {
            "iteration": iteration,
            "train/beta": beta,
            "train/success_rate": float((status == Status.SUCCESS).float().mean()),  # the behaviour's episodes
            "train/pairs": len(pairs_obs),
            "train/loss": loss,
        }
        if eval_episodes:
            metrics |= eval_metrics(evaluate(student, view, spec).summary)
        metrics["perf/iteration_s"] = time.time() - t0
        history.append(dict(metrics))
        logger.log(iteration, metrics)
        save(metrics)

    final = {"iterations": iteration, "frames": sum(len(o) for o in all_obs), "wall_time_s": logger.elapsed}
    final |= {k: v for k, v in metrics.items() if isinstance(v, int | float)}
    logger.summary(final)
    logger.log_checkpoint(checkpoints.directory / "last.pt")
    logger.close()
    record = {"run_dir": str(run_dir), "seed": seed, "oracle": meta, "final": final, "curve": history}
    atomic_write_text(run_dir / "results.json", json.dumps(record, indent=1, default=str))  # shipped by ship=true
    held_out = {"held-out success": (final.get("eval/success_rate"), eval_episodes)}
    logger.write_summary(
        run_summary(final["frames"], logger.elapsed, held_out, {"last": checkpoints.directory / "last.pt"})
    )
    return final
