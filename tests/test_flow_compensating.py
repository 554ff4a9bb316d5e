"""The flow-compensating expert: its swim velocity plus the local flow points at the target."""

import math

import pytest
import torch

from flownav.agents.flow_compensating import FlowCompensating
from flownav.agents.prior import head_to_target
from flownav.envs import NavigationEnv
from flownav.envs.core import Status
from flownav.envs.tasks import RegionTask
from flownav.evaluation.rollout import run_episodes
from flownav.evaluation.scripted import HeadToTarget
from flownav.flows import UniformFlow
from flownav.flows.base import WAKE_BOUNDS


def geo_priv(to_target, flow, theta, swim_speed=1.0):
    """A geo_priv row (23) with the heading (theta, psi = 0); the entries the expert does not read are zero."""
    obs = torch.zeros(1, 23)
    obs[0, :3], obs[0, 9:12] = torch.tensor(to_target), torch.tensor(flow)
    obs[0, 6], obs[0, 7], obs[0, 21] = math.cos(theta), math.sin(theta), swim_speed
    return obs


def test_facing_the_compensating_heading_it_holds_it_and_the_total_velocity_points_at_the_target():
    # target along +x, flow 0.6 along +y, swim speed 1: swim along (0.8, -0.6), total velocity (0.8, 0, 0)
    theta = math.atan2(-0.6, 0.8)
    speed, dtheta, dpsi = FlowCompensating()(geo_priv([5.0, 0.0, 0.0], [0.3, 0.6, 0.0], theta))[0]
    assert abs(dtheta) < 1e-5 and abs(dpsi) < 1e-5 and abs(speed - 0.98) < 1e-6
    # the flow's part along the target does not change the heading; a cross flow stronger than the swimmer
    # turns it straight against the cross flow
    speed, dtheta, _ = FlowCompensating()(geo_priv([5.0, 0.0, 0.0], [0.0, 2.0, 0.0], -math.pi / 2))[0]
    assert abs(dtheta) < 1e-5 and abs(speed - 0.98) < 1e-6
    # a slower swimmer compensates at a steeper angle: swim speed 0.75 against 0.6 across -> (0.45, -0.6)
    _, dtheta, _ = FlowCompensating()(geo_priv([5.0, 0.0, 0.0], [0.0, 0.6, 0.0], math.atan2(-0.6, 0.45), 0.75))[0]
    assert abs(dtheta) < 1e-5


def test_across_a_current_its_straight_track_is_faster_than_head_to_target():
    """The paper's task (Region 1 -> Region 2, about 6 apart along -y) across a uniform current of 0.85 along +x:
    head-to-target curves downstream and arrives late; compensating the current, the track is straight."""
    flow = UniformFlow((0.85, 0.0, 0.0), WAKE_BOUNDS)

    def make_env(view):
        return lambda n, chunk: NavigationEnv(flow, RegionTask(), num_envs=n, views=(view,), seed=chunk)

    compensating = run_episodes(FlowCompensating(), "geo_priv", make_env("geo_priv"), 200, 200)
    straight = run_episodes(HeadToTarget(), "geo", make_env("geo"), 200, 200)
    arrived = [ep.status == Status.SUCCESS for ep in (compensating, straight)]
    assert arrived[0].all() and arrived[1].float().mean() >= 0.99
    # measured: 20.4 against 31.7 time units on average
    assert compensating.time[arrived[0]].mean() < 0.75 * straight.time[arrived[1]].mean()


def test_the_cap_keeps_half_the_speed_towards_the_target_and_its_ends_are_the_two_experts():
    # target along +x, cross flow 2.0 along +y, swim speed 1: uncapped it swims straight against the cross flow
    # (-y); with min_progress 0.5 along (0.5, -sqrt(0.75)), 60 degrees off the target
    capped = FlowCompensating(min_progress=0.5)
    _, dtheta, _ = capped(geo_priv([5.0, 0.0, 0.0], [0.0, 2.0, 0.0], -math.pi / 3))[0]
    assert abs(dtheta) < 1e-5
    # below the cap (cross flow 0.6 < sqrt(0.75)) it is the uncapped expert, bit for bit
    obs = geo_priv([5.0, 0.0, 0.0], [0.3, 0.6, 0.0], 0.4)
    assert torch.equal(capped(obs), FlowCompensating()(obs))
    # on random rows: min_progress 0 is the uncapped expert, min_progress 1 is head-to-target
    g = torch.Generator().manual_seed(0)
    rows = torch.randn(256, 23, generator=g)
    rows[:, 6:8] = rows[:, 6:8] / rows[:, 6:8].norm(dim=-1, keepdim=True)  # cos, sin of the heading
    rows[:, 8], rows[:, 21] = 0.0, torch.rand(256, generator=g)  # psi 0; swim speeds in (0, 1)
    assert torch.equal(FlowCompensating(min_progress=0.0)(rows), FlowCompensating()(rows))
    straight = head_to_target(rows[:, :3], torch.atan2(rows[:, 7], rows[:, 6]), rows[:, 8])
    assert torch.allclose(FlowCompensating(min_progress=1.0)(rows), straight, atol=1e-5)
    with pytest.raises(ValueError, match=r"^min_progress is 1.5; choose a fraction of the swim speed in \[0, 1\]$"):
        FlowCompensating(min_progress=1.5)
