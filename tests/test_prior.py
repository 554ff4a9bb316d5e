"""The head-to-target prior: a policy whose network outputs nothing is head-to-target, in every view."""

import math

import pytest
import torch

from flownav.agents.networks import DeterministicPolicy
from flownav.agents.prior import HeadToTargetPrior, head_to_target
from flownav.envs.kinematics import body_frame, to_body
from flownav.evaluation.scripted import ACTION_LOW, HeadToTarget, action_high


def _zero_output(policy: DeterministicPolicy) -> DeterministicPolicy:
    last = [m for m in policy.net if isinstance(m, torch.nn.Linear)][-1]
    torch.nn.init.zeros_(last.weight)
    torch.nn.init.zeros_(last.bias)
    return policy


def _states(n: int, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    d = torch.randn(n, 3, generator=g) * 5
    v = torch.randn(n, 3, generator=g)
    theta = (torch.rand(n, generator=g) * 2 - 1) * math.pi
    psi = torch.zeros(n)  # level swimmers: there the body-frame turn rates are the inertial ones
    return d, v, theta, psi


def test_zero_network_is_head_to_target_in_geo_and_ego_views():
    d, v, theta, psi = _states(500)
    expected = HeadToTarget()(torch.cat((d, v, theta[:, None], psi[:, None]), -1))
    frame = body_frame(theta, psi)
    views = {
        "geo": torch.cat((d, v, theta[:, None], psi[:, None]), -1),
        "geo_sincos": torch.cat((d, v, torch.cos(theta)[:, None], torch.sin(theta)[:, None], psi[:, None]), -1),
        "ego": torch.cat((to_body(frame, d), to_body(frame, v)), -1),
    }
    for view, obs in views.items():
        policy = _zero_output(DeterministicPolicy(obs.shape[1], ACTION_LOW, action_high(), hidden=[16], prior=view))
        assert torch.allclose(policy(obs), expected, atol=1e-4), view


def test_prior_with_a_trained_correction_differs_and_is_saved_in_the_config():
    policy = DeterministicPolicy(6, ACTION_LOW, action_high(), hidden=[16], prior="ego")
    assert policy.config["prior"] == "ego"
    assert set(policy.state_dict()) == set(DeterministicPolicy(6, ACTION_LOW, action_high(), hidden=[16]).state_dict())
    copy = DeterministicPolicy(**policy.config)
    copy.load_state_dict(policy.state_dict())
    obs = torch.randn(64, 6)
    assert torch.equal(copy(obs), policy(obs))
    assert "prior" not in DeterministicPolicy(6, ACTION_LOW, action_high(), hidden=[16]).config  # old checkpoints


def test_head_to_target_turns_towards_the_target_and_stays_in_the_box():
    d = torch.tensor([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [1.0, 0.0, 1.0], [-1.0, 0.0, 0.0]])
    zero = torch.zeros(4)
    a = head_to_target(d, zero, zero)
    assert a[0, 1] > 0 and a[1, 1] < 0  # left target: turn left; right target: turn right
    assert a[2, 2] > 0 and abs(float(a[2, 1])) < 1e-6  # above: pitch up, no yaw
    assert a[3, 0] < 0.06 and a[3, 1] > 0  # behind: slow, turn (left, by the periodic error function)
    unit = 2 * (a - torch.tensor(ACTION_LOW)) / (torch.tensor(action_high()) - torch.tensor(ACTION_LOW)) - 1
    assert unit.abs().max() < 0.999  # representable by a tanh-squashed output


def test_prior_refuses_a_view_without_a_target_direction():
    with pytest.raises(ValueError, match="carries no target direction"):
        HeadToTargetPrior("privileged_unknown", ACTION_LOW, action_high())
