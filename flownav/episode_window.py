"""Outcomes of the training episodes that ended since the last log row (a batched env that auto-resets).

TorchRL's ``RewardSum`` sums each episode's reward on the env (``episode_reward``); the env's ``time`` and
``status`` say how long an episode ran and how it ended. The window keeps those three at the steps where an
episode ended:

    collector = Collector(with_episode_return(env), policy, ...)
    window = EpisodeWindow()
    window.add(data["next"])         # every collected batch [B, T]
    metrics.update(window.pop())     # at a log row: return, success, failure causes, length; then empty

An episode spans batches: its running sum lives in the collector's carried tensordict, and the window keeps a
copy (``running``) so that a resumed run carries on from it (:func:`resume_episodes`).
"""

from __future__ import annotations

import math

import torch
from torchrl.envs import RewardSum, TransformedEnv

from flownav.envs.navigation import Status
from flownav.evaluation.metrics import FAILURES

RETURN_KEY = "episode_reward"  # RewardSum's entry


def with_episode_return(env) -> TransformedEnv:
    """The env with each episode's running sum of rewards in ``episode_reward``."""
    return TransformedEnv(env, RewardSum())


def resume_episodes(collector, env, running) -> None:
    """Point the collector at a restored env: the carried observation of its swimmers, no new episode, and the
    running sums of the episodes in flight (``running``, from :attr:`EpisodeWindow.running`)."""
    carried = env.reset(keep_state=True)
    carried.set(RETURN_KEY, running.reshape(carried["done"].shape).to(env.device))
    carried.set("_reset", torch.zeros_like(carried["done"]))  # RewardSum keeps the sums of slots not reset
    collector.reset(tensordict=carried, keep_state=True)


class EpisodeWindow:
    def __init__(self):
        self.running = None  # each slot's return so far, after the last batch (0 where an episode just ended)
        self._returns, self._status, self._time = [], [], []

    def state_dict(self) -> dict:
        """The running returns and the window's episodes: what an exactly resumed run needs."""
        return {"ep_return": self.running, "episodes": (self._returns, self._status, self._time)}

    def load_state_dict(self, state: dict) -> None:
        self.running = state["ep_return"].clone()
        self._returns, self._status, self._time = (list(w) for w in state["episodes"])

    def add(self, nxt) -> None:
        """One batch's ``next`` tensordict, batch shape [B, T], with episode_reward, done, status and time."""
        done = nxt["done"].squeeze(-1).T  # [T, B]: episodes in the order they ended
        returns = nxt[RETURN_KEY].squeeze(-1).T
        self._returns.append(returns[done])
        self._status.append(nxt["status"].squeeze(-1).T[done])
        self._time.append(nxt["time"].squeeze(-1).T[done])
        self.running = torch.where(done[-1], 0.0, returns[-1])

    def pop(self) -> dict:
        """Metrics of the episodes that ended since the last call (NaN when none did); empties the window."""
        n = sum(len(r) for r in self._returns)
        out = {"train/episodes": n}
        if n:
            status = torch.cat(self._status)
            times = torch.cat(self._time).float()
            success = status == Status.SUCCESS
            out["train/episode_reward"] = torch.cat(self._returns).mean().item()
            out["train/success_rate"] = success.float().mean().item()
            out["train/success_time"] = times[success].mean().item() if success.any() else math.nan
            out["train/episode_length"] = times.mean().item()
            for name, s in FAILURES.items():
                out[f"train/rate_{name}"] = (status == s).float().mean().item()
        else:
            for key in ("episode_reward", "success_rate", "success_time", "episode_length"):
                out[f"train/{key}"] = math.nan
            for name in FAILURES:
                out[f"train/rate_{name}"] = math.nan
        self._returns, self._status, self._time = [], [], []
        return out
