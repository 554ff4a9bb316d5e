"""Outcomes of the training episodes that ended since the last log row (a batched env that auto-resets).

    window = EpisodeWindow(num_envs, device)
    window.add(data["next"])         # every collected batch [B, T]: rewards, done, status, time
    metrics.update(window.pop())     # at a log row: return, success, failure causes, length; then empty

An episode spans batches, so each slot's running return lives here between batches (on the run's device).
"""

from __future__ import annotations

import math

import torch

from flownav.envs.navigation import Status
from flownav.evaluation.metrics import FAILURES


class EpisodeWindow:
    def __init__(self, num_envs: int, device="cpu"):
        self.num_envs = int(num_envs)
        self.ep_return = torch.zeros(self.num_envs, device=device)
        self._returns, self._status, self._time = [], [], []

    def state_dict(self) -> dict:
        """The running returns and the window's episodes: what an exactly resumed run needs."""
        return {"ep_return": self.ep_return, "episodes": (self._returns, self._status, self._time)}

    def load_state_dict(self, state: dict) -> None:
        self.ep_return = state["ep_return"].to(self.ep_return.device).clone()
        self._returns, self._status, self._time = (list(w) for w in state["episodes"])

    def add(self, nxt) -> None:
        """One batch's ``next`` tensordict, batch shape [B, T] (or [B * T]) with reward, done, status, time."""
        b = self.num_envs
        rew = nxt["reward"].reshape(b, -1)
        done = nxt["done"].reshape(b, -1)
        status = nxt["status"].reshape(b, -1)
        etime = nxt["time"].reshape(b, -1)
        for t in range(rew.shape[1]):
            self.ep_return += rew[:, t]
            d = done[:, t]
            if d.any():
                self._returns.append(self.ep_return[d].clone())
                self._status.append(status[d, t])
                self._time.append(etime[d, t])
                self.ep_return = torch.where(d, 0.0, self.ep_return)

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
