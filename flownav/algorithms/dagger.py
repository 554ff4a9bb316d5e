"""DAgger: an ego student imitates a geo teacher (paper section 2.3.3, eq. 9).

One iteration, read top to bottom in :func:`train`:

1. **Collect.** A TorchRL ``Collector``, as for PPO: ``num_envs`` swimmers start fresh episodes and run
   ``steps_per_iteration`` steps (finished episodes restart in place). At each step the env emits the
   student's view (``ego``) and the teacher's view (``geo``) of the *same* state; the behaviour policy
   (:class:`~flownav.agents.mixture.TeacherStudentMixture`) labels the state with the teacher's
   deterministic action and executes the student's action, or the teacher's with probability
   ``beta_i = beta.initial * beta.decay ** i`` (per swimmer and step). The paper lets the student act
   alone: ``beta.initial = 0``.
2. **Aggregate.** The (student observation, teacher action) pairs go into a TorchRL replay buffer
   (``LazyTensorStorage``, FIFO beyond ``buffer_capacity``).
3. **Normalise.** The student's observation normaliser is set to the mean and variance of the
   aggregated observations.
4. **Fit.** ``updates_per_iteration`` Adam steps on minibatches sampled uniformly from the buffer,
   minimising eq. 9: ``L = 1/N sum_i sum_j (a_hat_ij - a*_ij)^2`` (actions in their physical units), at
   the rate ``lr`` (or, with ``lr_final``, one falling linearly to it over the iterations).

Logged per iteration (``metrics.csv``, wandb): ``train/loss`` (eq. 9, mean over the iteration's
updates), ``train/loss_onpolicy`` (eq. 9 of the student on the states it just visited, before fitting:
the error DAgger exists to drive down), the success rate of the episodes that ended during collection,
beta, buffer size. A checkpoint (``<run>/checkpoints/last.pt``, one atomic file) carries the optimiser, RNG
states, counters and the filled part of the aggregated data, so ``resume=<run dir>`` continues exactly where
the run stopped. The run's record (final metrics, loss curve) is ``<run>/results.json``.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import torch
from omegaconf import OmegaConf
from tensordict import TensorDict
from torchrl.collectors import Collector
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
from torchrl.data.replay_buffers.samplers import RandomSampler

from flownav.agents.mixture import TeacherStudentMixture
from flownav.agents.networks import DeterministicPolicy
from flownav.agents.scene_router import EXPERT_VIEWS, ROUTED_VIEW, scene_routed
from flownav.algorithms.common import eval_metrics, require_finite_update
from flownav.atomic import atomic_write_text
from flownav.builders import build_env, build_flow, build_task
from flownav.checkpoint import RunCheckpoints, load_policy, load_resume_checkpoint
from flownav.devices import check_on_device, resolve_device
from flownav.envs.observations import GEO_VIEWS, SENSED_VIEWS, observation_size
from flownav.episode_window import EpisodeWindow, with_episode_return
from flownav.errors import CheckpointError, ConfigError
from flownav.evaluation.protocol import EvalSpec, evaluate
from flownav.paths import resolve
from flownav.provenance import sha256
from flownav.runlog import RunLogger, run_summary

STUDENT_VIEWS = (*SENSED_VIEWS, "geo", "geo_flow")  # every on-board (ego) view, and the paper's SI geo views
RESUME_NEEDS = ("buffer", "history")  # DAgger's own entries of last.pt's train_state
NON_FINITE_FIX = "check algo.lr, algo.grad_clip and algo.weight_decay"


def buffer_contents(buffer) -> dict:
    """The filled part of the buffer, in storage order (what a checkpoint keeps of it). Copied: ``buffer[:]`` is a
    view, and torch.save writes a view's whole storage, the buffer's full capacity."""
    return buffer[:].clone().to_dict() if len(buffer) else {}


def refill_buffer(buffer, contents: dict, frames: int) -> None:
    """Rebuild a saved buffer in an empty one: the same pairs at the same storage positions, and the writer's
    cursor where ``frames`` pairs written round robin leave it, so the run samples exactly what it would have."""
    if not contents:
        return
    data = TensorDict(contents, batch_size=[len(next(iter(contents.values())))])
    buffer.extend(data)
    if frames > len(data):  # the FIFO had wrapped: rewrite the first pairs to move the cursor past them
        buffer.extend(data[: frames % len(data)])


def imitation_loss(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Eq. 9: squared error summed over the action's components, averaged over the batch."""
    return ((pred - target) ** 2).sum(-1).mean()


def fit_step(policy, optim, obs: torch.Tensor, labels: torch.Tensor, grad_clip: float) -> float:
    """One Adam step on eq. 9 (the global gradient norm clipped to ``grad_clip`` unless 0); the batch's loss."""
    loss = imitation_loss(policy(obs), labels)
    optim.zero_grad(set_to_none=True)
    loss.backward()
    if grad_clip:
        torch.nn.utils.clip_grad_norm_(policy.parameters(), float(grad_clip))
    optim.step()
    return float(loss.detach())


def check_config(cfg) -> None:
    """Checks beyond one key's type and range (those are in flownav.schema; train.py checks them)."""
    if not cfg.get("teacher_checkpoint"):
        raise ConfigError("DAgger needs a teacher: set teacher_checkpoint=<path> (python train.py +experiment=teacher)")
    if str(cfg.obs.view) not in STUDENT_VIEWS:
        raise ConfigError(f"obs.view (the student's view) is {cfg.obs.view!r}; choose one of {STUDENT_VIEWS}")


def require_same_teachers(resume, saved: dict, teachers: dict) -> None:
    """Refuse a resume whose teacher or scene experts are other files than the run's (by content: a moved file
    is the same teacher), so that its aggregated labels all come from one teacher. ``teachers``: the run's meta of
    them, ``{setting: path, <setting without _checkpoint>_sha256: hash}``."""
    for setting, path in teachers.items():
        key = f"{setting.removesuffix('_checkpoint')}_sha256"
        if key in saved and key in teachers and saved[key] != teachers[key]:
            shown = setting if setting == "teacher_checkpoint" else f"algo.{setting}"  # as the user sets it
            raise ConfigError(
                f"resume={resume}: {shown}={path} is not the run's (it was {saved.get(setting)}, sha256 {saved[key]}; "
                f"this file's {teachers[key]}): resume with the run's own {shown}"
            )


def beta_at(a, iteration: int) -> float:
    return float(a.beta.initial) * float(a.beta.decay) ** iteration


def lr_at(a, iteration: int) -> float:
    """The fit's learning rate at ``iteration`` (0-based): ``lr``, or linear from ``lr`` to ``lr_final`` at the
    last one (the final student is then the fit of a small step, not one noisy large step from it)."""
    lr, final = float(a["lr"]), a.get("lr_final")
    if final is None:
        return lr
    return lr + (float(final) - lr) * min(iteration / max(int(a["iterations"]) - 1, 1), 1.0)


def set_normalizer_from(policy: DeterministicPolicy, obs: torch.Tensor) -> None:
    """Normaliser statistics = mean and variance of all aggregated observations."""
    norm = policy.normalizer
    norm.mean.copy_(obs.mean(0))
    norm.var.copy_(obs.var(0, unbiased=False))
    norm.count.fill_(obs.shape[0])


def make_collector(env, mixture: TeacherStudentMixture, steps: int, seed: int) -> Collector:
    """Batches of ``steps`` steps of every swimmer, each from fresh episodes (the env reset at each batch)."""
    collector = Collector(
        with_episode_return(env),
        mixture,
        frames_per_batch=env.num_envs * steps,
        total_frames=-1,
        reset_at_each_iter=True,
        trust_policy=True,
        auto_register_policy_transforms=False,  # feed-forward policies: no InitTracker
    )
    env.set_seed(seed)  # the collector's own first reset drew episodes: the first batch's come from the seed
    return collector


def labelled_pairs(batch, student_view: str) -> TensorDict:
    """A batch [B, T]'s (student observation, teacher action) pairs, step by step."""
    obs, labels = batch[student_view].transpose(0, 1), batch["teacher_action"].transpose(0, 1)
    pairs = {"obs": obs.reshape(-1, obs.shape[-1]), "teacher_action": labels.reshape(-1, labels.shape[-1])}
    return TensorDict(pairs, batch_size=[obs.shape[0] * obs.shape[1]])


def train(cfg, run_dir) -> dict:
    run_dir = Path(run_dir)
    check_config(cfg)
    a = cfg.algo
    # ---- config pulled into locals before the hot loop
    seed = int(cfg.seed)
    student_view = str(cfg.obs.view)
    iterations, steps = int(a.iterations), int(a.steps_per_iteration)
    updates, batch_size = int(a.updates_per_iteration), int(a.batch_size)
    checkpoint_every = int(cfg.checkpoint_every) if cfg.get("checkpoint_every") else 0
    role = str(cfg.get("role") or "student")
    device = resolve_device(cfg.device)
    torch.manual_seed(seed)

    # The teacher reads the view its checkpoint records, unless algo.teacher_view pins one (then they must match).
    teacher, teacher_payload = load_policy(
        resolve(str(cfg.teacher_checkpoint)), expect_obs=a.teacher_view, device=device
    )
    teacher_view = str(teacher_payload["obs"])
    if teacher_view not in GEO_VIEWS:
        raise CheckpointError(
            f"teacher checkpoint {cfg.teacher_checkpoint} reads {teacher_view!r}; a DAgger teacher reads a geo view "
            f"({', '.join(GEO_VIEWS)}): pass a teacher's checkpoint "
            "(python train.py +experiment=teacher)"
        )
    teacher_meta = {
        "teacher_checkpoint": str(cfg.teacher_checkpoint),
        "teacher_sha256": sha256(resolve(str(cfg.teacher_checkpoint))),
    }
    if a.get("scene_expert"):  # the paper's teacher acts in the paper's scene (flownav/agents/scene_router.py)
        keys = [k for k in EXPERT_VIEWS if a.get(k)]
        experts = {}
        for k in keys:  # (name, policy, the view its checkpoint records: scene_routed checks it)
            policy, payload = load_policy(resolve(str(a[k])), device=device)
            experts[k] = (str(a[k]), policy, payload["obs"])
        teacher = scene_routed(
            teacher, teacher_view, experts, currents=a.get("scene_currents"), free_flows=a.get("scene_free_flows")
        )
        teacher_view = ROUTED_VIEW
        for k in keys:
            teacher_meta |= {k: str(a[k]), f"{k}_sha256": sha256(resolve(str(a[k])))}
    elif extra := [k for k in (*EXPERT_VIEWS, "scene_currents", "scene_free_flows") if a.get(k)]:
        raise ConfigError(f"algo.{extra[0]} needs algo.scene_expert: it is one expert of the scene-routed teacher")
    flow = build_flow(cfg.flow, device=device)
    task = build_task(cfg.task, flow)
    env = build_env(
        cfg.env, flow, task, [student_view, teacher_view], num_envs=int(a.num_envs), seed=seed, device=device
    )
    low, high = env.action_spec.space.low[0].tolist(), env.action_spec.space.high[0].tolist()
    t_cfg = teacher_payload["policy"]["config"]
    if [round(v, 6) for v in t_cfg["action_high"]] != [round(v, 6) for v in high]:
        raise ConfigError(
            f"the teacher's action box {t_cfg['action_low']}..{t_cfg['action_high']} differs from the env's "
            f"{low}..{high}: train the student with the teacher's env settings (env.u_max)"
        )
    student = DeterministicPolicy(
        observation_size(student_view),
        low,
        high,
        hidden=list(a.hidden),
        activation=str(a.activation),
        prior=student_view if a.get("prior") else None,
        prior_turn=a.get("prior_turn"),
    ).to(device)
    optim = torch.optim.Adam(student.parameters(), lr=float(a.lr), weight_decay=float(a.weight_decay))
    buffer = TensorDictReplayBuffer(
        storage=LazyTensorStorage(int(a.buffer_capacity), device=device),
        sampler=RandomSampler(),
        batch_size=batch_size,
    )
    mixture = TeacherStudentMixture(student, teacher, student_view, teacher_view, seed=seed + 1)
    collector = make_collector(env, mixture, steps, seed)
    config = OmegaConf.to_container(cfg, resolve=True)
    checkpoints = RunCheckpoints(
        run_dir / "checkpoints", student, student_view, role, config, env, optim, {"beta": mixture.generator}
    )

    iteration, frames, wall_offset, history = 0, 0, 0.0, []
    if cfg.get("resume"):
        _, payload = load_resume_checkpoint(cfg.resume, expect_obs=student_view, needs=RESUME_NEEDS)
        require_same_teachers(cfg.resume, payload.get("meta") or {}, teacher_meta)
        st = checkpoints.restore(payload)
        iteration, frames, wall_offset = int(st["iteration"]), int(st["frames"]), float(st["wall_time"])
        refill_buffer(buffer, st["buffer"], frames)
        history = list(st["history"])

    check_on_device(device, student=student, teacher=teacher, env=env)
    logger = RunLogger(run_dir, cfg, total=iterations, start=iteration, wall_offset=wall_offset)

    def save(name: str, metrics: dict) -> Path:
        counters = {"iteration": iteration, "frames": frames, "wall_time": logger.elapsed}
        return checkpoints.save(
            name, counters, metrics, meta=teacher_meta, buffer=buffer_contents(buffer), history=history
        )

    metrics: dict = dict(history[-1]) if history else {}
    batches, window = iter(collector), EpisodeWindow()
    while iteration < iterations:
        t0 = time.time()
        # 1. collect with the current student (mixed with the teacher by beta)
        mixture.beta = beta = beta_at(a, iteration)
        student.eval()
        batch = next(batches)  # [B, T]
        window.add(batch["next"])
        data = labelled_pairs(batch, student_view)
        with torch.no_grad():
            loss_onpolicy = float(imitation_loss(student(data["obs"]), data["teacher_action"]))
        t_collect = time.time() - t0
        # 2. aggregate, 3. normalise
        buffer.extend(data)
        frames += data.shape[0]
        set_normalizer_from(student, buffer[:]["obs"])
        # 4. fit eq. 9
        student.train()
        lr = lr_at(a, iteration)
        for group in optim.param_groups:
            group["lr"] = lr
        total = 0.0
        for _ in range(updates):
            sample = buffer.sample()
            total += fit_step(student, optim, sample["obs"], sample["teacher_action"], a.grad_clip)
        iteration += 1
        last = checkpoints.directory / "last.pt"
        require_finite_update("DAgger", iteration, {"train/loss": total}, student, last, NON_FINITE_FIX)
        # the episodes that ended during collection: train/episodes, train/success_rate, train/mean_success_time, ...
        episodes = {k.replace("success_time", "mean_success_time"): v for k, v in window.pop().items()}
        metrics = {"iteration": iteration, "train/loss": total / updates, "train/loss_onpolicy": loss_onpolicy}
        metrics |= episodes | {"train/beta": beta, "lr": lr, "buffer/size": len(buffer)}
        metrics |= {"perf/collect_s": t_collect, "perf/iteration_s": time.time() - t0}
        history.append(dict(metrics))
        logger.log(iteration, metrics)
        if checkpoint_every and iteration % checkpoint_every == 0:
            save("last.pt", metrics)
    collector.shutdown()
    save("last.pt", metrics)
    final = {"iterations": iteration, "frames": frames, "wall_time_s": logger.elapsed}
    final.update({k: v for k, v in metrics.items() if isinstance(v, int | float)})

    eval_episodes = int(a.get("final_eval_episodes", 0) or 0)
    if eval_episodes > 0:  # the student and its teacher on the same held-out episodes
        spec = EvalSpec(flow, task, cfg.env, eval_episodes, device=str(device))
        student.eval()
        for name, policy, view in (("student", student, student_view), ("teacher", teacher, teacher_view)):
            final |= eval_metrics(evaluate(policy, view, spec).summary, prefix=f"eval/{name}_")
        logger.log(iteration, {k: v for k, v in final.items() if k.startswith("eval/")})
    logger.summary(final)
    logger.log_checkpoint(checkpoints.directory / "last.pt")
    logger.close()
    curve = [
        {k: h[k] for k in ("iteration", "train/loss", "train/loss_onpolicy", "train/success_rate")} for h in history
    ]
    record = {
        "run_dir": str(run_dir),
        "teacher_checkpoint": str(cfg.teacher_checkpoint),
        "seed": seed,
        "final": final,
        "curve": curve,
    }
    atomic_write_text(run_dir / "results.json", json.dumps(record, indent=1, default=str))  # shipped by ship=true
    held_out = {
        f"held-out {name} success": (final.get(f"eval/{name}_success_rate"), eval_episodes)
        for name in ("student", "teacher")
    }
    logger.write_summary(run_summary(frames, logger.elapsed, held_out, {"last": checkpoints.directory / "last.pt"}))
    return final
