"""A privileged teacher made of two: the paper's teacher in the paper's scene, the generalist teacher elsewhere.

The generalist PPO teacher (``geo_priv``) learns little of the wake crossing: the paper's task is a small share
of its families. The paper's teacher (``geo_sincos``) crosses that wake in 99% of episodes and fails elsewhere.
:class:`SceneRoutedTeacher` reads ``geo_priv_scene`` (``geo_priv`` plus the simulator's flag "this swimmer is
in the paper's training task as posed", flownav.envs.core.paper_scene) and lets each act where it is good, so
that a DAgger student over the families imitates the better teacher of each scene. Episodes of that scene which
start upstream of the paper's regions (flag 2: the extended domain, ``task.posed_wake_any_start_share``) go to the
flow-compensating expert (flownav/agents/flow_compensating.py), which reaches the target from there where the
paper's teacher mostly does not.
"""

from __future__ import annotations

import torch
from torch import nn

from flownav.agents.flow_compensating import FlowCompensating
from flownav.envs.observations import observation_size
from flownav.errors import CheckpointError

ROUTED_VIEW = "geo_priv_scene"
GENERALIST_VIEW = "geo_priv"
EXPERT_VIEW = "geo_sincos"


class SceneRoutedTeacher(nn.Module):
    """``expert`` where the view's last entry (the paper-scene code) is 1, the flow-compensating expert where it is
    2, ``generalist`` elsewhere. The expert reads the first 9 numbers of the view (``geo_priv`` begins with
    ``geo_sincos``), the other two all but the code."""

    def __init__(self, generalist: nn.Module, expert: nn.Module, u_max: float = 1.0):
        super().__init__()
        self.generalist, self.expert = generalist, expert
        self.upstream = FlowCompensating(u_max)
        self.expert_size = observation_size(EXPERT_VIEW)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        code, view = obs[:, -1:], obs[:, :-1]
        elsewhere = torch.where(code > 1.5, self.upstream(view), self.generalist(view))
        return torch.where((code > 0.5) & (code < 1.5), self.expert(obs[:, : self.expert_size]), elsewhere)


def scene_routed(generalist: nn.Module, generalist_view: str, expert: nn.Module, expert_name) -> SceneRoutedTeacher:
    """The routed teacher of a ``geo_priv`` generalist and a ``geo_sincos`` expert (loaded from ``expert_name``)."""
    if generalist_view != GENERALIST_VIEW:
        raise CheckpointError(
            f"algo.scene_expert routes between a {GENERALIST_VIEW!r} teacher and the paper's; the teacher checkpoint "
            f"reads {generalist_view!r}: pass the generalist teacher (python train.py +experiment=generalist_teacher)"
        )
    box = lambda p: [round(v, 6) for v in p.config["action_low"] + p.config["action_high"]]  # noqa: E731
    if box(expert) != box(generalist):
        raise CheckpointError(f"algo.scene_expert {expert_name} acts in another action box than the teacher")
    return SceneRoutedTeacher(generalist, expert, u_max=float(generalist.config["action_high"][0]))
