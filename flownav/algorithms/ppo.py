"""PPO for the geo teacher and the ego baseline, built from TorchRL's pieces.

    collector (Collector over the batched NavigationEnv, B swimmers x T steps per batch)
      -> GAE (critic = ValueOperator)
      -> E epochs over a LazyTensorStorage replay buffer sampled without replacement
      -> ClipPPOLoss (actor = TanhNormal ProbabilisticActor), Adam, grad-norm clipping
      -> observation-normaliser update, logging, checkpoints.

The actor is a :class:`~flownav.agents.DeterministicPolicy` whose MLP outputs 6 numbers: the first
3 are the TanhNormal location, the last 3 its scale parameter. Its deterministic action
(tanh of the location, mapped into the action box) is exactly ``DeterministicPolicy.forward``,
so a checkpoint of this actor is a plain deterministic policy for evaluation and DAgger.

Observation normalisation: the actor's ``ObsNormalizer`` (and the critic's own) are updated from
each collected batch *after* the PPO epochs on it, so the batch is scored with the statistics
that collected it (the first-epoch ratio is exactly 1) and the next batch uses the new ones.
"""

from __future__ import annotations

import time
from pathlib import Path

import torch
from omegaconf import OmegaConf
from tensordict.nn import NormalParamExtractor, TensorDictModule
from torch import nn
from torchrl.collectors import Collector
from torchrl.data import LazyTensorStorage, ReplayBuffer, SamplerWithoutReplacement
from torchrl.modules import ProbabilisticActor, TanhNormal, ValueOperator
from torchrl.objectives import ClipPPOLoss
from torchrl.objectives.value import GAE

from flownav.agents.networks import DeterministicPolicy, ObsNormalizer, check_mlp_size, mlp
from flownav.algorithms.common import require_finite_update
from flownav.builders import ConfigError, build_env, build_flow, build_task
from flownav.checkpoint import (
    load_checkpoint,
    load_resume_checkpoint,
    restore_training_state,
    save_policy_checkpoint,
    training_state,
)
from flownav.devices import check_on_device, resolve_device
from flownav.envs.navigation import Status
from flownav.envs.observations import GEO_VIEWS, observation_size
from flownav.episode_window import EpisodeWindow
from flownav.evaluation.rollout import run_episodes
from flownav.runlog import RunLogger, run_summary
from flownav.viz.dashboard import eval_trajectories_figure

LOSS_CRITIC_TYPES = ("l1", "l2", "smooth_l1")
RESUME_NEEDS = ("critic", "window", "sampler")  # PPO's own entries of last.pt's train_state
NON_FINITE_FIX = "check env.reward, algo.lr, algo.max_grad_norm and the flow"
CHECKED_LOSSES = ("loss/objective", "loss/critic", "loss/grad_norm")  # the first columns of each update's losses


# ----------------------------------------------------------------------------- networks
class ActorNet(nn.Module):
    """obs -> DeterministicPolicy's normaliser and MLP (6 outputs) -> (loc, scale) of a TanhNormal."""

    def __init__(self, policy: DeterministicPolicy, init_scale: float = 1.0, scale_lb: float = 1e-3):
        super().__init__()
        self.policy = policy
        self.extract = NormalParamExtractor(scale_mapping=f"biased_softplus_{init_scale}", scale_lb=scale_lb)

    def forward(self, obs):
        return self.extract(self.policy.net(self.policy.normalizer(obs)))


class CriticNet(nn.Module):
    """obs -> own running normaliser -> MLP -> state value."""

    def __init__(self, obs_dim: int, hidden, activation: str):
        super().__init__()
        self.normalizer = ObsNormalizer(obs_dim)
        self.net = mlp(obs_dim, 1, hidden, activation)

    def forward(self, obs):
        return self.net(self.normalizer(obs))

    def load_state_dict(self, state_dict, strict: bool = True, assign: bool = False):
        config = {"obs_dim": self.normalizer.mean.shape[0], "n_outputs": 1}
        config["hidden"] = [m.out_features for m in self.net if isinstance(m, nn.Linear)][:-1]
        check_mlp_size(state_dict, config, "algo.critic.hidden={hidden}")
        return super().load_state_dict(state_dict, strict=strict, assign=assign)


def _init_output_layer(seq: nn.Sequential, gain: float):
    last = [m for m in seq if isinstance(m, nn.Linear)][-1]
    nn.init.orthogonal_(last.weight, gain)
    nn.init.zeros_(last.bias)


def make_actor_critic(obs_key: str, critic_key: str, low, high, actor_cfg, critic_cfg):
    """The TanhNormal ProbabilisticActor (around a DeterministicPolicy) and the ValueOperator."""
    policy = DeterministicPolicy(
        observation_size(obs_key),
        low.tolist(),
        high.tolist(),
        hidden=list(actor_cfg["hidden"]),
        activation=str(actor_cfg["activation"]),
        n_outputs=2 * len(low),
    )
    _init_output_layer(policy.net, float(actor_cfg.get("output_gain", 0.01)))
    net = ActorNet(policy, float(actor_cfg["init_scale"]), float(actor_cfg["scale_lb"]))
    actor = ProbabilisticActor(
        TensorDictModule(net, in_keys=[obs_key], out_keys=["loc", "scale"]),
        in_keys=["loc", "scale"],
        distribution_class=TanhNormal,
        distribution_kwargs={"low": low, "high": high, "tanh_loc": False},
        return_log_prob=True,
    )
    critic_net = CriticNet(observation_size(critic_key), list(critic_cfg["hidden"]), str(critic_cfg["activation"]))
    _init_output_layer(critic_net.net, 1.0)
    critic = ValueOperator(critic_net, in_keys=[critic_key])
    return policy, actor, critic_net, critic


@torch.no_grad()
# ----------------------------------------------------------------------------- config checks
def check_config(cfg) -> None:
    """Checks that tie keys together; each key's type and range is in flownav.schema (train.py checks it)."""
    a = cfg.algo
    if int(a.get("eval_every") or 0) % int(a.log_every):
        raise ConfigError(f"algo.eval_every ({a.eval_every}) must be a multiple of algo.log_every ({a.log_every})")
    frames = int(cfg.env.num_envs) * int(a.rollout_steps)
    if a.minibatch_size > frames:
        raise ConfigError(
            f"algo.minibatch_size ({a.minibatch_size}) exceeds a batch of env.num_envs x algo.rollout_steps = {frames}"
        )


# ----------------------------------------------------------------------------- evaluation
def evaluate_policy(policy, make_env, obs_key: str, episodes: int, chunk: int = 10_000, record: int = 0) -> dict:
    """Deterministic rollouts (:func:`flownav.evaluation.rollout.run_episodes`): exactly ``episodes``
    episodes, one per env slot, no auto-reset. ``make_env(num_envs, chunk_index)`` builds a fresh env.
    With ``record``, the first ``record`` episodes' trajectories are under ``"trajectories"``."""
    ep = run_episodes(policy, obs_key, make_env, episodes, chunk, record=record)
    success = ep.success
    out = {"episodes": len(ep), "success_rate": float(success.float().mean())}
    out["mean_success_time"] = float(ep.time[success].mean()) if success.any() else None
    for s in Status:
        if s not in (Status.RUNNING, Status.SUCCESS):
            out[f"rate_{s.name.lower()}"] = float((ep.status == s).float().mean())
    if record:
        out["trajectories"] = ep.trajectories
    return out


# ----------------------------------------------------------------------------- training
def train(cfg, run_dir) -> dict:
    run_dir = Path(run_dir)
    check_config(cfg)
    a = cfg.algo
    # ---- config pulled into locals before the hot loop
    obs_key = str(cfg.obs.view)
    critic_key = str(cfg.obs.critic_view or obs_key)
    num_envs = int(cfg.env.num_envs)
    rollout_steps = int(a.rollout_steps)
    frames_per_batch = num_envs * rollout_steps
    total_frames = int(a.total_frames)
    epochs, minibatch_size = int(a.epochs), int(a.minibatch_size)
    n_minibatches = frames_per_batch // minibatch_size
    lr, anneal_lr, max_grad_norm = float(a.lr), bool(a.anneal_lr), float(a.max_grad_norm)
    checkpoint_every = int(cfg.checkpoint_every) if cfg.checkpoint_every else 0
    log_every = int(a.log_every)
    recompute_advantage = bool(a.recompute_advantage)
    normalize_online = bool(a.update_normalizer)
    seed = int(cfg.seed)
    role = str(cfg.get("role") or ("teacher" if obs_key in GEO_VIEWS else "baseline"))
    target_success = float(a.target_success)
    eval_episodes = int(a.final_eval_episodes)
    eval_every, periodic_eval_episodes = int(a.get("eval_every") or 0), int(a.get("eval_episodes") or 0)
    figure_episodes = int(cfg.logger.get("figure_episodes") or 0)  # drawn at each periodic evaluation

    device = resolve_device(cfg.device)
    torch.manual_seed(seed)
    flow = build_flow(cfg.flow, device=cfg.device)
    task = build_task(cfg.task, flow)
    views = sorted({obs_key, critic_key})
    env = build_env(cfg.env, flow, task, views, num_envs=num_envs, seed=seed, device=cfg.device)
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
        batch_size=minibatch_size,
    )

    # ---- resume or start
    ckpt_dir = run_dir / "checkpoints"
    frames, iteration, wall_offset, best_success = 0, 0, 0.0, -1.0
    history_best = {}
    window = EpisodeWindow(num_envs, device)  # outcomes of the episodes that end between log rows
    time_to_target = None
    resumed = None
    if cfg.resume:
        _, resumed = load_resume_checkpoint(cfg.resume, expect_obs=obs_key, needs=RESUME_NEEDS)
        critic_net.load_state_dict(resumed["train_state"]["critic"])
    elif a.get("init_from"):
        # Warm start: weights, normalisers (and optimiser moments) from another run; counters from zero.
        payload = load_checkpoint(str(a.init_from))
        if payload["obs"] != obs_key:
            raise ConfigError(f"algo.init_from={a.init_from} reads {payload['obs']!r}, this run reads {obs_key!r}")
        policy.load_state_dict(payload["policy"]["state_dict"])
        if payload.get("train_state") and "critic" in payload["train_state"]:
            critic_net.load_state_dict(payload["train_state"]["critic"])
    else:
        # Warm the normalisers up on the first observations so the first batch sees sane inputs.
        first = env.reset()
        policy.normalizer.update(first[obs_key])  # in place: the loss holds these buffers
        critic_net.normalizer.update(first[critic_key])

    collector = Collector(
        env,
        actor,
        frames_per_batch=frames_per_batch,
        total_frames=-1,
        trust_policy=True,
    )
    if collector.policy is not actor:  # a copy would only see weights, not the normaliser buffers
        raise RuntimeError("the collector copied the actor; PPO needs it to step the live policy")
    if resumed is not None:
        # After the collector is built (it resets the env): the env's swimmers, episodes in flight and RNG as
        # saved, and the collector's carried observation made from them, so the next batch is the one the
        # uninterrupted run collects.
        st = restore_training_state(resumed, policy, optim, env)
        collector.reset(keep_state=True)
        frames, iteration, wall_offset = int(st["frames"]), int(st["iteration"]), float(st["wall_time"])
        best_success, history_best = float(st["best_success"]), dict(st["best_metrics"])
        window.load_state_dict(st["window"])
        time_to_target = st["time_to_target"]
        buffer.sampler.load_state_dict(st["sampler"])
    check_on_device(device, actor=actor, critic=critic, env=env)
    logger = RunLogger(run_dir, cfg, total=total_frames, start=frames, wall_offset=wall_offset)

    def save(name: str, metrics: dict) -> Path:
        counters = {"frames": frames, "iteration": iteration, "wall_time": logger.elapsed}
        train_state = training_state(
            env,
            optim,
            counters,
            critic=critic_net.state_dict(),
            best_success=best_success,
            best_metrics=history_best,
            window=window.state_dict(),
            time_to_target=time_to_target,
            sampler=buffer.sampler.state_dict(),
        )
        meta = {
            "config": OmegaConf.to_container(cfg, resolve=True),
            "frames": frames,
            "iteration": iteration,
            "metrics": metrics,
        }
        return save_policy_checkpoint(ckpt_dir / name, policy, obs_key, role, meta=meta, train_state=train_state)

    def evaluate(episodes: int, seed_base: int, figure_step: int | None = None) -> dict:
        """Deterministic episodes of a copy of the current policy (its mean action), on fresh envs;
        with ``figure_step``, also a figure of a few of its trajectories for the dashboards."""
        eval_policy = DeterministicPolicy(**policy.config).to(device)
        eval_policy.load_state_dict(policy.state_dict())

        def make_env(n, chunk):
            return build_env(
                cfg.env, flow, task, [obs_key], num_envs=n, seed=seed_base + seed + 7919 * chunk, device=device
            )

        record = figure_episodes if figure_step is not None else 0
        res = evaluate_policy(eval_policy.eval(), make_env, obs_key, episodes, record=record)
        if record:
            logger.log_figure(figure_step, "eval/trajectories", eval_trajectories_figure(res.pop("trajectories"), flow))
        return res

    t_start, frames_at_start = time.time(), frames
    metrics: dict = {}
    collector_iter = iter(collector)
    try:
        while frames < total_frames:
            t_iter = time.time()
            data = next(collector_iter)  # [B, T]
            t_collect = time.time() - t_iter
            frames += data.numel()
            iteration += 1

            window.add(data["next"])  # episode statistics from this batch

            # ---- PPO update
            if anneal_lr:
                for g in optim.param_groups:
                    g["lr"] = lr * max(0.0, 1.0 - frames / total_frames)
            t_train = time.time()
            losses = []
            for epoch in range(epochs):
                if epoch == 0 or recompute_advantage:
                    with torch.no_grad():
                        adv_module(data)
                buffer.extend(data.reshape(-1))
                for _ in range(n_minibatches):
                    batch = buffer.sample()
                    loss = loss_module(batch)
                    total = loss["loss_objective"] + loss["loss_critic"] + loss.get("loss_entropy", 0.0)
                    optim.zero_grad(set_to_none=True)
                    total.backward()
                    gn = nn.utils.clip_grad_norm_(loss_module.parameters(), max_grad_norm)
                    optim.step()
                    losses.append(
                        torch.stack(
                            [
                                loss["loss_objective"],
                                loss["loss_critic"],
                                gn,
                                loss["kl_approx"],
                                loss["clip_fraction"],
                                loss["explained_variance"].reshape(()),
                                loss.get("entropy", torch.full((), float("nan"), device=device)),
                            ]
                        ).detach()
                    )
            # Normalisers move after the update: the next batch is collected with the new statistics.
            if normalize_online:
                policy.normalizer.update(data[obs_key])
                critic_net.normalizer.update(data[critic_key])
            checked = dict(zip(CHECKED_LOSSES, torch.stack(losses)[:, :3].T, strict=True))
            require_finite_update("PPO", iteration, checked, loss_module, ckpt_dir / "last.pt", NON_FINITE_FIX)
            collector.update_policy_weights_()
            t_train = time.time() - t_train

            # ---- logging
            if iteration % log_every == 0 or frames >= total_frames:
                episodes = window.pop()
                n_eps, succ = episodes["train/episodes"], episodes["train/success_rate"]
                lm = torch.stack(losses).mean(0)
                metrics = {
                    **episodes,
                    "loss/objective": lm[0].item(),
                    "loss/critic": lm[1].item(),
                    "loss/grad_norm": lm[2].item(),
                    "loss/kl_approx": lm[3].item(),
                    "loss/clip_fraction": lm[4].item(),
                    "loss/explained_variance": lm[5].item(),
                    "policy/scale": data["scale"].mean().item(),
                    "policy/entropy": lm[6].item(),
                    "perf/steps_per_s": (frames - frames_at_start) / max(time.time() - t_start, 1e-9),
                    "perf/collect_s": t_collect,
                    "perf/train_s": t_train,
                    "lr": optim.param_groups[0]["lr"],
                }
                # The success that counts: deterministic held-out episodes when periodic evaluation is on,
                # else the training episodes of the stochastic policy.
                score = succ if n_eps else float("nan")
                if eval_every and periodic_eval_episodes and (iteration % eval_every == 0 or frames >= total_frames):
                    t_eval = time.time()
                    res = evaluate(periodic_eval_episodes, 20_000_003, figure_step=frames)
                    score = res["success_rate"]
                    metrics["eval/success_rate"] = score
                    metrics["eval/mean_success_time"] = res["mean_success_time"] or float("nan")
                    metrics["perf/eval_s"] = time.time() - t_eval
                elif eval_every:
                    score = float("nan")  # best.pt and the time to target follow the periodic evaluation only
                if time_to_target is None and score >= target_success:
                    time_to_target = logger.elapsed
                    metrics["perf/minutes_to_target"] = time_to_target / 60
                logger.log(frames, metrics)
                if score > best_success:
                    best_success = score
                    history_best = {"frames": frames, **metrics}
                    save("best.pt", metrics)
            if checkpoint_every and iteration % checkpoint_every == 0:
                save("last.pt", metrics)
    finally:
        collector.shutdown()

    save("last.pt", metrics)
    final = {
        "frames": frames,
        "iterations": iteration,
        "wall_time_s": logger.elapsed,
        "best_success": best_success,
        "best_success_source": "eval" if eval_every and periodic_eval_episodes else "train",
    }
    final.update({k: v for k, v in metrics.items() if not isinstance(v, str)})
    if time_to_target is not None:
        final["minutes_to_target"] = time_to_target / 60
    if eval_episodes > 0:
        res = evaluate(eval_episodes, 10_000_019)
        final.update({f"eval/{k}": v for k, v in res.items()})
        logger.log(frames, {f"eval/{k}": v for k, v in res.items() if isinstance(v, int | float)})
    logger.summary(final)
    logger.log_checkpoint(ckpt_dir / "best.pt")
    logger.close()
    # End-of-run summary: the final evaluation's success, else the last periodic evaluation's.
    n_held_out = int(final.get("eval/episodes") or (periodic_eval_episodes if "eval/success_rate" in final else 0))
    held_out = {"held-out success": (final.get("eval/success_rate"), n_held_out)}
    ckpts = {"last": ckpt_dir / "last.pt", "best": ckpt_dir / "best.pt"}
    logger.write_summary(run_summary(frames, logger.elapsed, held_out, ckpts))
    return final
