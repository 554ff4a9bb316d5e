"""The head-to-target prior: a policy whose network outputs nothing is head-to-target, in every view."""

import math

import pytest
import torch

from flownav.agents.networks import DeterministicPolicy
from flownav.agents.prior import TURN_LEFT_BIASED, TURN_SHORT, TURNS, HeadToTargetPrior, head_to_target
from flownav.checkpoint import load_policy
from flownav.envs.core import Status
from flownav.envs.kinematics import body_frame, to_body
from flownav.evaluation.scripted import ACTION_LOW, HeadToTarget, action_high
from flownav.paths import REPO_ROOT


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
        policy = DeterministicPolicy(
            obs.shape[1], ACTION_LOW, action_high(), hidden=[16], prior=view, prior_turn=TURN_SHORT
        )
        policy = _zero_output(policy)
        assert torch.allclose(policy(obs), expected, atol=1e-4), view


def test_prior_with_a_trained_correction_differs_and_is_saved_in_the_config():
    policy = DeterministicPolicy(6, ACTION_LOW, action_high(), hidden=[16], prior="ego", prior_turn=TURN_SHORT)
    assert policy.config["prior"] == "ego"
    assert set(policy.state_dict()) == set(DeterministicPolicy(6, ACTION_LOW, action_high(), hidden=[16]).state_dict())
    copy = DeterministicPolicy(**policy.config)
    copy.load_state_dict(policy.state_dict())
    d, v, theta, psi = _states(64)
    frame = body_frame(theta, psi)
    obs = torch.cat((to_body(frame, d), to_body(frame, v)), -1)
    assert torch.equal(copy(obs), policy(obs))
    # the correction (a freshly initialised last layer, not zero) moves the action off head-to-target ...
    expected = HeadToTarget()(torch.cat((d, v, theta[:, None], psi[:, None]), -1))
    assert (policy(obs) - expected).abs().max() > 0.01
    # ... and without it the same policy is head-to-target again
    assert torch.allclose(_zero_output(copy)(obs), expected, atol=1e-4)
    assert "prior" not in DeterministicPolicy(6, ACTION_LOW, action_high(), hidden=[16]).config  # old checkpoints


def test_head_to_target_turns_towards_the_target_and_stays_in_the_box():
    d = torch.tensor([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [1.0, 0.0, 1.0], [-1.0, 0.0, 0.0]])
    zero = torch.zeros(4)
    a = head_to_target(d, zero, zero)
    assert a[0, 1] > 0 and a[1, 1] < 0  # left target: turn left; right target: turn right
    assert a[2, 2] > 0 and abs(float(a[2, 1])) < 1e-6  # above: pitch up, no yaw
    assert a[3, 0] < 0.06 and abs(float(a[3, 1])) > 0.7  # behind: slow, turn at nearly the full rate
    unit = 2 * (a - torch.tensor(ACTION_LOW)) / (torch.tensor(action_high()) - torch.tensor(ACTION_LOW)) - 1
    assert unit.abs().max() < 0.999  # representable by a tanh-squashed output


def test_prior_refuses_a_view_without_a_target_direction():
    with pytest.raises(ValueError, match="carries no target direction"):
        HeadToTargetPrior("privileged_unknown", ACTION_LOW, action_high())


def test_head_to_target_turns_the_short_way_and_old_policies_keep_their_left_bias():
    """A target 151 degrees to the right: the short rule turns right; the left-biased rule (the yaw of the policies
    saved before ``prior_turn`` existed, e.g. the shipped generalist ones) turns left, the long way round."""
    d, zero = torch.tensor([[math.cos(math.radians(-90)), math.sin(math.radians(-90)), 0.0]]), torch.zeros(1)
    theta = torch.tensor([math.radians(61)])
    assert head_to_target(d, theta, zero)[0, 1] < -0.7
    assert head_to_target(d, theta, zero, turn=TURN_LEFT_BIASED)[0, 1] > 0.3
    with pytest.raises(ValueError, match="head-to-target turn 'long': choose one of"):
        head_to_target(d, theta, zero, turn="long")
    new = DeterministicPolicy(6, ACTION_LOW, action_high(), hidden=[16], prior="ego", prior_turn=TURN_SHORT)
    assert new.config["prior_turn"] == TURN_SHORT and DeterministicPolicy(**new.config).prior.turn == TURN_SHORT
    old = dict(new.config)
    del old["prior_turn"]
    assert DeterministicPolicy(**old).prior.turn == TURN_LEFT_BIASED
    for name in ("generalist_teacher", "generalist_student"):  # each acts by the rule its training run named
        policy, payload = load_policy(REPO_ROOT / "checkpoints" / f"{name}.pt")
        algo = payload["meta"]["config"]["algo"]
        assert policy.prior.turn == (algo.get("actor", algo).get("prior_turn") or TURN_LEFT_BIASED), name


def test_head_to_target_holds_the_headwind_it_used_to_drift_out_of():
    """Against a current of 0.8 across the paper's task (2,000 episodes): turning the short way the swimmer stays in
    the box; the left-biased turn lets about 3% drift out (y > 7) while it turns the long way round."""
    from flownav.builders import compose_config
    from flownav.envs.tasks import RegionTask
    from flownav.evaluation.protocol import EvalSpec, evaluate
    from flownav.flows.analytic import UniformFlow

    class Yaw(torch.nn.Module):
        def __init__(self, turn):
            super().__init__()
            self.turn = turn

        def forward(self, obs):
            return head_to_target(obs[:, :3], obs[:, 6], obs[:, 7], turn=self.turn)

    spec = EvalSpec(UniformFlow((0.0, 0.8, 0.0)), RegionTask(), compose_config().env, 2000)
    left = {turn: int((evaluate(Yaw(turn), "geo", spec).episodes.status == Status.LEFT_DOMAIN).sum()) for turn in TURNS}
    assert left[TURN_SHORT] == 0 and left[TURN_LEFT_BIASED] > 30, left


def test_the_training_config_key_builds_the_prior_it_names():
    """``algo.prior_turn`` (DAgger) and ``algo.actor.prior_turn`` (PPO) accept the rules prior.py has; null is the
    left-biased rule, recorded as absent."""
    from flownav.agents.actor_critic import make_actor_critic
    from flownav.schema import PRIOR_TURN

    assert set(PRIOR_TURN.choices) == set(TURNS)
    low, high = torch.tensor(ACTION_LOW), torch.tensor(action_high())
    critic = {"hidden": [8], "activation": "tanh"}
    for turn in (None, TURN_SHORT):
        actor = {"hidden": [8], "activation": "tanh", "init_scale": 0.5, "scale_lb": 1e-3, "prior": "head_to_target"}
        policy = make_actor_critic("geo_sincos", "geo_sincos", low, high, actor | {"prior_turn": turn}, critic)[0]
        assert policy.prior.turn == (turn or TURN_LEFT_BIASED) and policy.config.get("prior_turn") == turn
