"""PPO for the geo teacher and the ego baseline, built from TorchRL's pieces.

    collector (Collector over the batched NavigationEnv, B swimmers x T steps per batch; RewardSum sums returns)
      -> GAE (critic = ValueOperator)
      -> E epochs over a LazyTensorStorage replay buffer sampled without replacement
      -> ClipPPOLoss (actor = TanhNormal ProbabilisticActor, flownav.agents.actor_critic), Adam, grad-norm clipping
      -> observation-normaliser update, logging, evaluation (flownav.evaluation.protocol), checkpoints.

Observation normalisation: the actor's ``ObsNormalizer`` (and the critic's own) are updated from each collected
batch *after* the PPO epochs on it, so the batch is scored with the statistics that collected it (the first-epoch
ratio is exactly 1) and the next batch uses the new ones.
"""

from __future__ import annotations

import time
from pathlib import Path

import torch
from omegaconf import OmegaConf
from torch import nn
from torchrl.collectors import Collector
from torchrl.data import LazyTensorStorage, ReplayBuffer, SamplerWithoutReplacement
from torchrl.objectives import ClipPPOLoss
from torchrl.objectives.value import GAE

from flownav.agents.actor_critic import make_actor_critic
from flownav.agents.networks import DeterministicPolicy
from flownav.algorithms.common import eval_metrics, require_finite_update
from flownav.builders import build_env, build_flow, build_task
from flownav.checkpoint import RunCheckpoints, load_policy, load_resume_checkpoint, warm_start
from flownav.devices import check_on_device, resolve_device
from flownav.envs.observations import GEO_VIEWS
from flownav.episode_window import EpisodeWindow, resume_episodes, with_episode_return
from flownav.errors import ConfigError
from flownav.evaluation.protocol import EvalSpec, evaluate
from flownav.paths import resolve
from flownav.provenance import sha256
from flownav.runlog import RunLogger, run_summary
from flownav.viz.dashboard import eval_trajectories_figure

RESUME_NEEDS = ("critic", "window", "sampler")  # PPO's own entries of last.pt's train_state
NON_FINITE_FIX = "check env.reward, algo.lr, algo.max_grad_norm and the flow"
# Logged per update, averaged over a log row's updates: name -> entry of ClipPPOLoss's output (+ grad_norm).
LOSSES = {
    "loss/objective": "loss_objective",
    "loss/critic": "loss_critic",
    "loss/grad_norm": "grad_norm",
    "loss/kl_approx": "kl_approx",
    "loss/clip_fraction": "clip_fraction",
    "loss/explained_variance": "explained_variance",
    "policy/entropy": "entropy",
    "loss/anchor": "loss_anchor",
}
CHECKED_LOSSES = list(LOSSES)[:3]  # what must stay finite


def check_config(cfg) -> None:
    """Checks that tie keys together; each key's type and range is in flownav.schema (train.py checks it)."""
    a = cfg.algo
    if int(a.get("eval_every") or 0) % int(a.log_every):
        raise ConfigError(f"algo.eval_every ({a.eval_every}) must be a multiple of algo.log_every ({a.log_every})")
    if float(a.get("anchor_coeff") or 0) and not a.get("init_from"):
        raise ConfigError(
            f"algo.anchor_coeff ({a.anchor_coeff}) pulls the actor towards algo.init_from's policy: set algo.init_from "
            "or algo.anchor_coeff=0"
        )
    frames = int(cfg.env.num_envs) * int(a.rollout_steps)
    if a.minibatch_size > frames:
        raise ConfigError(
            f"algo.minibatch_size ({a.minibatch_size}) exceeds a batch of env.num_envs x algo.rollout_steps = {frames}"
        )


def copy_for_evaluation(policy: DeterministicPolicy) -> DeterministicPolicy:
    """A fresh policy with the current weights, for evaluation. Its construction draws from torch's RNG, so a
    seed's training stream includes every evaluation."""
    copy = DeterministicPolicy(**policy.config).to(policy.normalizer.mean.device)
    copy.load_state_dict(policy.state_dict())
    return copy


def load_anchor(path: str, obs_key: str, device, resumed: dict | None) -> tuple[DeterministicPolicy, str]:
    """The policy of ``path`` (a DAgger student or a PPO run), frozen, and the file's sha256: what
    ``algo.anchor_coeff`` pulls towards. A resumed run refuses another file than the one it started with."""
    digest = sha256(resolve(path))
    started = (resumed or {}).get("train_state", {}).get("anchor_sha256")
    if resumed is not None and started != digest:
        raise ConfigError(
            f"algo.init_from={path} is not the file this run was anchored to (sha256 {started} there, {digest} "
            "here): restore that file, or start a new run"
        )
    with torch.random.fork_rng(devices=[]):  # building the network must not move the run's seeded draws
        anchor, _ = load_policy(resolve(path), expect_obs=obs_key, device=device)
    return anchor, digest


def anchor_loss(policy: DeterministicPolicy, anchor: DeterministicPolicy, batch, obs_key: str) -> torch.Tensor:
    """KL(actor || anchor) of the pre-tanh Gaussians at the actor's scale of collection (detached), averaged over the
    batch: sum over the action of (loc - anchor's loc)^2 / (2 scale^2). It keeps what the anchor does where PPO's
    advantages do not say otherwise, and costs nothing where the actor does what the anchor does."""
    obs = batch[obs_key]
    n = policy.action_dim
    shift = (policy.outputs(obs)[..., :n] - anchor.outputs(obs)[..., :n]) / batch["scale"]
    return (shift**2 / 2).sum(-1).mean()


def train(cfg, run_dir) -> dict:
    run_dir = Path(run_dir)
    check_config(cfg)
    a = cfg.algo
    obs_key, critic_key = str(cfg.obs.view), str(cfg.obs.critic_view or cfg.obs.view)
    num_envs, total_frames, lr = int(cfg.env.num_envs), int(a.total_frames), float(a.lr)
    frames_per_batch = num_envs * int(a.rollout_steps)
    n_minibatches = frames_per_batch // int(a.minibatch_size)
    eval_every, eval_episodes = int(a.get("eval_every") or 0), int(a.get("eval_episodes") or 0)
    critic_warmup = int(a.get("critic_warmup_frames") or 0)
    anchor_coeff = float(a.get("anchor_coeff") or 0)
    role = str(cfg.get("role") or ("teacher" if obs_key in GEO_VIEWS else "baseline"))
    figure_episodes = int(cfg.logger.get("figure_episodes") or 0)  # trajectories drawn at each periodic evaluation

    # ---- build: env, actor and critic, GAE, loss, optimiser, replay buffer
    device = resolve_device(cfg.device)
    torch.manual_seed(int(cfg.seed))
    flow = build_flow(cfg.flow, device=cfg.device)
    task = build_task(cfg.task, flow)
    views = sorted({obs_key, critic_key})
    env = build_env(cfg.env, flow, task, views, num_envs=num_envs, seed=int(cfg.seed), device=cfg.device)
    low, high = env.action_spec.space.low[0].clone(), env.action_spec.space.high[0].clone()
    policy, actor, critic_net, critic = make_actor_critic(obs_key, critic_key, low, high, a.actor, a.critic)
    actor, critic = actor.to(device), critic.to(device)  # policy and critic_net are inside them
    adv_module = GAE(gamma=float(a.gamma), lmbda=float(a.lmbda), value_network=critic, average_gae=False)
    loss_module = ClipPPOLoss(
        actor,
        critic,
        clip_epsilon=float(a.clip_epsilon),
        entropy_bonus=float(a.entropy_coeff) > 0,
        entropy_coeff=float(a.entropy_coeff),
        critic_coeff=float(a.critic_coeff),
        loss_critic_type=str(a.loss_critic_type),
        normalize_advantage=bool(a.normalize_advantage),
    )
    optim = torch.optim.Adam(loss_module.parameters(), lr=lr, eps=1e-5)
    buffer = ReplayBuffer(
        storage=LazyTensorStorage(frames_per_batch, device=device),
        sampler=SamplerWithoutReplacement(),
        batch_size=int(a.minibatch_size),
    )
    config = OmegaConf.to_container(cfg, resolve=True)
    checkpoints = RunCheckpoints(run_dir / "checkpoints", policy, obs_key, role, config, env, optim)
    eval_spec = EvalSpec(flow, task, cfg.env, eval_episodes, device=str(device))

    # ---- resume, warm start or fresh start
    frames, iteration, wall_offset, best_success, history_best, time_to_target = 0, 0, 0.0, -1.0, {}, None
    window = EpisodeWindow()  # outcomes of the episodes that end between log rows
    resumed = None
    warm_actor = warm_critic = True  # a normaliser that starts from nothing is warmed up on the first observations
    if cfg.resume:
        _, resumed = load_resume_checkpoint(cfg.resume, expect_obs=obs_key, needs=RESUME_NEEDS)
        critic_net.load_state_dict(resumed["train_state"]["critic"])
        warm_actor = warm_critic = False
    elif a.get("init_from"):  # weights and normalisers from another run, counters from zero
        payload = warm_start(policy, str(a.init_from), obs_key)
        warm_actor = False
        if payload.get("train_state") and "critic" in payload["train_state"]:  # else (a DAgger student) a fresh critic
            critic_net.load_state_dict(payload["train_state"]["critic"])
            warm_critic = False
    anchor, anchor_sha256 = load_anchor(str(a.init_from), obs_key, device, resumed) if anchor_coeff else (None, None)
    if warm_actor or warm_critic:  # so the first batch sees sane inputs
        first = env.reset()
        if warm_actor:
            policy.normalizer.update(first[obs_key])  # in place: the loss holds these buffers
        if warm_critic:
            critic_net.normalizer.update(first[critic_key])
    # The actor is feed-forward: it needs no InitTracker, so the collector leaves the env as it is.
    collector = Collector(
        with_episode_return(env),
        actor,
        frames_per_batch=frames_per_batch,
        total_frames=-1,
        trust_policy=True,
        auto_register_policy_transforms=False,
    )
    if collector.policy is not actor:  # a copy would only see weights, not the normaliser buffers
        raise RuntimeError("the collector copied the actor; PPO needs it to step the live policy")
    if resumed is not None:  # after the collector's own reset: the env, its episodes in flight and RNG as saved
        st = checkpoints.restore(resumed)
        window.load_state_dict(st["window"])
        resume_episodes(collector, env, window.running)
        frames, iteration, wall_offset = int(st["frames"]), int(st["iteration"]), float(st["wall_time"])
        best_success, history_best, time_to_target = (
            float(st["best_success"]),
            dict(st["best_metrics"]),
            st["time_to_target"],
        )
        buffer.sampler.load_state_dict(st["sampler"])
    check_on_device(device, actor=actor, critic=critic, env=env)
    logger = RunLogger(run_dir, cfg, total=total_frames, start=frames, wall_offset=wall_offset)

    def save(name: str, metrics: dict) -> Path:
        counters = {"frames": frames, "iteration": iteration, "wall_time": logger.elapsed}
        return checkpoints.save(
            name,
            counters,
            metrics,
            critic=critic_net.state_dict(),
            best_success=best_success,
            best_metrics=history_best,
            window=window.state_dict(),
            time_to_target=time_to_target,
            sampler=buffer.sampler.state_dict(),
            anchor_sha256=anchor_sha256,
        )

    # ---- the loop: collect, update, log, evaluate, checkpoint
    t_start, frames_at_start, metrics = time.time(), frames, {}
    batches = iter(collector)
    try:
        while frames < total_frames:
            t_iter = time.time()
            data = next(batches)  # [B, T]
            t_collect = time.time() - t_iter
            frames += data.numel()
            iteration += 1
            window.add(data["next"])

            if a.anneal_lr:
                for g in optim.param_groups:
                    g["lr"] = lr * max(0.0, 1.0 - frames / total_frames)
            t_train = time.time()
            losses = []
            for epoch in range(int(a.epochs)):
                if epoch == 0 or a.recompute_advantage:
                    with torch.no_grad():
                        adv_module(data)
                buffer.extend(data.reshape(-1))
                for _ in range(n_minibatches):
                    batch = buffer.sample()
                    loss = loss_module(batch)
                    total = loss["loss_critic"]
                    if frames > critic_warmup:  # a warm-started actor waits for the critic's advantages
                        total = total + loss["loss_objective"] + loss.get("loss_entropy", 0.0)
                        if anchor is not None:
                            loss["loss_anchor"] = anchor_coeff * anchor_loss(policy, anchor, batch, obs_key)
                            total = total + loss["loss_anchor"]
                    optim.zero_grad(set_to_none=True)
                    total.backward()
                    loss["grad_norm"] = nn.utils.clip_grad_norm_(loss_module.parameters(), float(a.max_grad_norm))
                    optim.step()
                    nan = torch.full((), float("nan"), device=device)
                    losses.append(torch.stack([loss.get(k, nan).detach().reshape(()) for k in LOSSES.values()]))
            losses = torch.stack(losses)
            if a.update_normalizer:  # after the update: the next batch is collected with the new statistics
                policy.normalizer.update(data[obs_key])
                critic_net.normalizer.update(data[critic_key])
            checked = dict(zip(CHECKED_LOSSES, losses[:, :3].T, strict=True))
            require_finite_update(
                "PPO", iteration, checked, loss_module, checkpoints.directory / "last.pt", NON_FINITE_FIX
            )
            collector.update_policy_weights_()
            t_train = time.time() - t_train

            if iteration % int(a.log_every) == 0 or frames >= total_frames:
                episodes = window.pop()
                metrics = {**episodes, **dict(zip(LOSSES, losses.mean(0).tolist(), strict=True))}
                metrics["policy/scale"] = data["scale"].mean().item()
                metrics["perf/steps_per_s"] = (frames - frames_at_start) / max(time.time() - t_start, 1e-9)
                metrics |= {"perf/collect_s": t_collect, "perf/train_s": t_train, "lr": optim.param_groups[0]["lr"]}
                # The success that counts: the periodic held-out evaluation's when it is on, else the training
                # episodes' (stochastic policy); best.pt and the time to target follow it.
                score = episodes["train/success_rate"] if episodes["train/episodes"] else float("nan")
                if eval_every and eval_episodes and (iteration % eval_every == 0 or frames >= total_frames):
                    t_eval = time.time()
                    held_out = evaluate(copy_for_evaluation(policy), obs_key, eval_spec, record=figure_episodes)
                    if held_out.episodes.trajectories:
                        figure = eval_trajectories_figure(held_out.episodes.trajectories, flow)
                        logger.log_figure(frames, "eval/trajectories", figure)
                    metrics |= eval_metrics(held_out.summary) | {"perf/eval_s": time.time() - t_eval}
                    score = held_out.success_rate
                elif eval_every:
                    score = float("nan")
                if time_to_target is None and score >= float(a.target_success):
                    time_to_target = logger.elapsed
                    metrics["perf/minutes_to_target"] = time_to_target / 60
                logger.log(frames, metrics)
                if score > best_success:
                    best_success, history_best = score, {"frames": frames, **metrics}
                    save("best.pt", metrics)
            if cfg.checkpoint_every and iteration % int(cfg.checkpoint_every) == 0:
                save("last.pt", metrics)
    finally:
        collector.shutdown()

    # ---- the end: last.pt, the final held-out evaluation, the summaries
    save("last.pt", metrics)
    final = {"frames": frames, "iterations": iteration, "wall_time_s": logger.elapsed, "best_success": best_success}
    final["best_success_source"] = "eval" if eval_every and eval_episodes else "train"
    final |= {k: v for k, v in metrics.items() if not isinstance(v, str)}
    if time_to_target is not None:
        final["minutes_to_target"] = time_to_target / 60
    if a.final_eval_episodes > 0:
        spec = EvalSpec(flow, task, cfg.env, int(a.final_eval_episodes), device=str(device))
        final |= eval_metrics(evaluate(copy_for_evaluation(policy), obs_key, spec).summary)
        logger.log(frames, {k: v for k, v in final.items() if k.startswith("eval/")})
    logger.summary(final)
    logger.log_checkpoint(checkpoints.directory / "best.pt")
    logger.close()
    # End-of-run summary: the final evaluation's success, else the last periodic evaluation's.
    n_held_out = final.get("eval/episodes") or 0
    held_out = {"held-out success": (final.get("eval/success_rate"), n_held_out)}
    ckpts = {"last": checkpoints.directory / "last.pt", "best": checkpoints.directory / "best.pt"}
    logger.write_summary(run_summary(frames, logger.elapsed, held_out, ckpts))
    return final
