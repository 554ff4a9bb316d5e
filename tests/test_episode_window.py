"""The training episodes' outcomes: RewardSum's returns are the sums of each episode's step rewards, across batches."""

from __future__ import annotations

import torch
from torchrl.collectors import Collector

from flownav.envs import NavigationEnv, RegionTask
from flownav.envs.navigation import Status
from flownav.episode_window import EpisodeWindow, with_episode_return
from flownav.flows import Box, UniformFlow


def test_returns_lengths_and_outcomes_are_those_of_the_steps():
    task = RegionTask(Box((5.0, 0.0, 5.0), (6.0, 1.0, 6.0)), Box((7.0, 0.0, 5.0), (8.0, 1.0, 6.0)))
    env = NavigationEnv(UniformFlow((1.0, 0.0, 0.0)), task, num_envs=8, views=("geo",), seed=3, time_limit=3.0)
    torch.manual_seed(0)
    policy = lambda td: td.set("action", env.action_spec.rand())  # noqa: E731
    collector = Collector(with_episode_return(env), policy, frames_per_batch=8 * 7, total_frames=-1)
    batches, window = iter(collector), EpisodeWindow()
    steps = []
    for _ in range(5):  # episodes of at most 15 steps over batches of 7
        nxt = next(batches)["next"]
        window.add(nxt)
        steps.append(nxt)
    nxt = torch.cat(steps, 1)  # [8, 35]
    returns, status, times = [], [], []
    running = torch.zeros(8)
    for t in range(nxt.shape[1]):  # by hand, step by step
        running += nxt["reward"][:, t, 0]
        done = nxt["done"][:, t, 0]
        returns.append(running[done])
        status.append(nxt["status"][done, t, 0])
        times.append(nxt["time"][done, t, 0])
        running = torch.where(done, 0.0, running)
    returns, status, times = torch.cat(returns), torch.cat(status), torch.cat(times)
    out = window.pop()
    assert out["train/episodes"] == len(returns) > 8  # every slot ended an episode, some more than one
    assert 0 < int((status == Status.SUCCESS).sum()) < len(status)  # successes and failures
    assert out["train/episode_reward"] == returns.mean().item()
    assert out["train/episode_length"] == times.mean().item()
    assert out["train/success_rate"] == (status == Status.SUCCESS).float().mean().item()
    assert torch.equal(window.running, running)  # what a resumed run carries on from
    assert window.pop()["train/episodes"] == 0  # the window empties at each log row
