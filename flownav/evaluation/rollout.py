"""Deterministic batched evaluation: exactly N episodes, one per environment slot.

Each chunk of ``chunk_size`` episodes is one fresh :class:`~flownav.envs.NavigationEnv` with
``chunk_size`` slots. Every slot runs one episode; its outcome (status, duration) is frozen at its
first ``done`` and it is never reset, so short episodes are not over-counted (an auto-resetting
collector counts more short episodes than long ones). The loop ends when every slot is done.

Cost: one env step and one policy call per step for the whole batch; once fewer than half the
slots are still running, the policy only sees the running ones. 10,000 episodes of 300 steps take
seconds on two CPU cores (``benchmarks/eval_throughput.py``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import torch
from torch import Tensor
from tqdm.auto import tqdm

from flownav.envs.navigation import NavigationEnv, Status

MakeEnv = Callable[[int, int], NavigationEnv]  # (num_envs, chunk index) -> env


@dataclass
class Episodes:
    """Outcome of N episodes (all tensors on the CPU, first dimension N)."""

    start: Tensor  # [N, 3] start position (in the env's, possibly rotated, frame)
    target: Tensor  # [N, 3]
    status: Tensor  # [N] final Status
    time: Tensor  # [N] episode duration (time units)
    final_position: Tensor  # [N, 3]
    trajectories: dict[str, Tensor] = field(default_factory=dict)  # recorded slots, see run_episodes

    def __len__(self) -> int:
        return int(self.status.numel())

    @property
    def success(self) -> Tensor:
        return self.status == Status.SUCCESS


def _policy_fn(policy) -> Callable[[Tensor], Tensor]:
    if isinstance(policy, torch.nn.Module):
        policy.eval()
    return policy


@torch.inference_mode()
def run_episodes(
    policy: Callable[[Tensor], Tensor],
    obs_key: str,
    make_env: MakeEnv,
    episodes: int,
    chunk_size: int = 10_000,
    record: int = 0,
    max_steps: int | None = None,
    progress: bool = False,
) -> Episodes:
    """Run exactly ``episodes`` deterministic episodes of ``policy`` (obs -> action).

    Args:
        policy: maps the ``obs_key`` observation ``[B, d]`` to actions ``[B, 3]``; or a privileged policy with
            ``act_privileged(env, slots) -> [len(slots), 3]`` that plans from the env's state (the oracle).
        make_env: builds the env of one chunk: ``make_env(num_envs, chunk_index)``. The env must emit
            ``obs_key`` and must not auto-reset (a plain NavigationEnv never does).
        episodes, chunk_size: N, and how many run side by side.
        record: record the full trajectories of the first ``record`` episodes (in the first chunk):
            ``position`` [k, T+1, 3], ``velocity`` (inertial, [k, T+1, 3]), ``heading`` [k, T+1, 2],
            ``time`` [T+1], ``alive`` [k, T+1] (False after the episode ended; the last True row is the
            final state), and the per-step ``action`` [k, T, 3].
        max_steps: safety bound on steps per chunk (default: time_limit / dt + 2).
        progress: show a tqdm bar of finished episodes (off inside training, where the run's bar is shown).
    """
    if episodes < 1 or chunk_size < 1:
        raise ValueError(f"need episodes >= 1 and chunk_size >= 1, got {episodes}, {chunk_size}")
    # A privileged policy (the oracle) reads the env's true state: act_privileged(env, running slots) -> actions.
    privileged = getattr(policy, "act_privileged", None)
    act = None if privileged else _policy_fn(policy)
    parts: dict[str, list[Tensor]] = {k: [] for k in ("start", "target", "status", "time", "final_position")}
    traj: dict[str, Tensor] = {}
    done_so_far, chunk = 0, 0
    bar = tqdm(total=episodes, unit="episode", disable=not progress, dynamic_ncols=True)
    while done_so_far < episodes:
        n = min(chunk_size, episodes - done_so_far)
        env = make_env(n, chunk)
        if env.batch_size != torch.Size([n]):
            raise ValueError(f"make_env({n}, {chunk}) returned an env of batch size {tuple(env.batch_size)}")
        if obs_key not in env.observation_spec.keys():
            raise ValueError(f"the env does not emit {obs_key!r}; build it with views including {obs_key!r}")
        limit = max_steps or int(math.ceil(env.time_limit / env.dt)) + 2
        td = env.reset()
        parts["start"].append(td["position"].cpu().clone())
        parts["target"].append(td["target"].cpu().clone())
        status = torch.zeros(n, dtype=torch.int64)
        t_end = torch.zeros(n)
        final = td["position"].cpu().clone()
        running = torch.ones(n, dtype=torch.bool)
        k = min(record, n) if chunk == 0 else 0
        if k:
            t0 = getattr(env, "t0", None)  # read now: the env writes it at reset
            t0 = t0[:k].cpu().clone() if isinstance(t0, Tensor) else torch.zeros(k)
        rec = {"position": [], "velocity": [], "heading": [], "time": [], "alive": [], "action": []}
        if k:
            _record(rec, td, running, k)
        action = torch.zeros(n, 3, device=env.device)
        steps = 0
        while running.any():
            if steps >= limit:
                raise RuntimeError(f"episodes still running after {limit} steps: the env does not time out")
            obs = td[obs_key]
            n_run = int(running.sum())
            if privileged:
                idx = running.nonzero().squeeze(-1)
                action = torch.zeros_like(action)
                action[idx.to(action.device)] = privileged(env, idx)
            elif n_run * 2 < n:  # few left: only the running slots need actions
                idx = running.nonzero().squeeze(-1).to(obs.device)
                action = torch.zeros_like(action)
                action[idx] = act(obs[idx])
            else:
                action = act(obs)
            td["action"] = action
            td = env.step(td)["next"]
            steps += 1
            done = td["done"].reshape(-1).cpu()
            new = done & running
            if new.any():
                status = torch.where(new, td["status"].reshape(-1).cpu(), status)
                t_end = torch.where(new, td["time"].reshape(-1).cpu(), t_end)
                final = torch.where(new[:, None], td["position"].cpu(), final)
            alive_before = running
            running = running & ~done
            bar.update(int(new.sum()))
            if k:
                rec["action"].append(action[:k].cpu().clone())
                _record(rec, td, alive_before, k)
        parts["status"].append(status)
        parts["time"].append(t_end)
        parts["final_position"].append(final)
        if k:
            traj = {key: torch.stack(v, 1) for key, v in rec.items() if key != "time"}
            traj["time"] = torch.stack(rec["time"])
            traj["target"] = parts["target"][0][:k]
            traj["t0"] = t0  # flow-time offset of each episode (random flow phase), for plot backgrounds
            traj["status"] = status[:k]
        done_so_far += n
        chunk += 1
    bar.close()
    cat = {key: torch.cat(v) for key, v in parts.items()}
    return Episodes(trajectories=traj, **cat)


def _record(rec: dict, td, alive: Tensor, k: int) -> None:
    rec["position"].append(td["position"][:k].cpu().clone())
    rec["velocity"].append(td["velocity"][:k].cpu().clone())
    rec["heading"].append(td["heading"][:k].cpu().clone())
    rec["time"].append(td["time"][0, 0].cpu().clone())  # every slot started at 0 and none restarts
    rec["alive"].append(alive[:k].clone())
