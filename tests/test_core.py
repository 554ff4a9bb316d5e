"""The physics core (flownav.envs.core): three steps computed by hand, and NavigationEnv as its exact wrapper."""

import math
from dataclasses import replace

import pytest
import torch
from omegaconf import OmegaConf

from flownav.builders import build_flow, build_task
from flownav.envs import ListTask, NavigationEnv, RewardConfig, Status, core
from flownav.envs.tasks import FamilyTask
from flownav.flows import Box, UniformFlow
from flownav.flows.base import WAKE_BOUNDS
from flownav.flows.vortex_street import VortexStreetFlow


def test_three_steps_in_a_uniform_flow_by_hand():
    """Swim speed scaled by 0.5 in a current of 0.5 along x: straight ahead, a clipped climb, a clipped turn at
    rest, then the time limit of 3 steps."""
    flow = UniformFlow((0.5, 0.0, 0.0), bounds=Box((-10.0, -10.0, -10.0), (10.0, 10.0, 10.0)))
    settings = core.Settings(
        task=ListTask([[0.0, 0.0, 0.0]], [[5.0, 0.0, 0.0]]),
        views=("geo",),
        dt=0.2,
        max_steps=3,
        u_max=1.0,
        swim_speed_scale=0.5,
        reward=RewardConfig(alpha=1.0, time_penalty=0.5, success_bonus=10.0, success_radius=0.3),
    )
    rng = torch.Generator().manual_seed(0)
    state = core.reset(core.initial_state(1, settings, "cpu"), torch.arange(1), flow, settings, rng)
    state = replace(state, theta=torch.zeros(1), psi=torch.zeros(1))  # heading along x
    c, s = math.cos(math.pi / 10), math.sin(math.pi / 10)
    d2 = math.dist((5.0, 0.0, 0.0), (0.3 + 0.1 * c, 0.0, 0.1 * s))
    d3 = math.dist((5.0, 0.0, 0.0), (0.4 + 0.1 * c, 0.0, 0.1 * s))
    expected = [
        # action (U, dtheta, dpsi), position, (theta, psi), reward -0.5 min(d / 5, 1) dt + (d_prev - d), status
        ((1.0, 0.0, 0.0), (0.2, 0.0, 0.0), (0.0, 0.0), -0.1 * 4.8 / 5 + 0.2, Status.RUNNING),
        ((2.0, 0.0, 3.0), (0.3 + 0.1 * c, 0.0, 0.1 * s), (0.0, math.pi / 10), -0.1 * d2 / 5 + 4.8 - d2, Status.RUNNING),
        ((0.0, -5.0, 0.0), (0.4 + 0.1 * c, 0.0, 0.1 * s), (-math.pi / 20, math.pi / 10), -0.1 * d3 / 5 + d2 - d3, 4),
    ]
    for action, position, heading, reward, status in expected:
        state, r = core.step(state, torch.tensor([action]), flow, settings)
        assert state.pos[0].tolist() == pytest.approx(position, abs=1e-6)
        assert (state.theta.item(), state.psi.item()) == pytest.approx(heading, abs=1e-6)
        assert r.item() == pytest.approx(reward, abs=1e-6)
        assert state.status.item() == status
    assert state.time.item() == pytest.approx(0.6)
    assert core.observe(state, flow, settings)["geo"][0, 3:6].tolist() == pytest.approx([0.5, 0.0, 0.0])


def _abc_periodic():
    flow = build_flow(OmegaConf.merge(OmegaConf.load("conf/flow/abc.yaml"), {"periodic_axes": ["y", "z"]}))
    task = build_task(OmegaConf.load("conf/task/abc.yaml"), flow)
    return flow, dict(task=task, views=("geo_sincos", "ego_up"), swim_speed_scale=0.1)


CASES = {
    "swim speed, flow strengths, memory": lambda: (
        VortexStreetFlow(),
        dict(views=("geo", "ego_mem"), swim_speed_scale=0.4, flow_strength=(0.0, 2.0), flow_strength_full=0.25),
    ),
    "family flow, per-slot swim speeds, privileged views": lambda: (
        build_flow(OmegaConf.load("conf/flow/family_fourier.yaml")),
        dict(task=FamilyTask(WAKE_BOUNDS), views=("geo_priv", "geo_priv_critic"), flow_strength=(0.5, 1.0)),
    ),
    "misaligned scene": lambda: (
        VortexStreetFlow(),
        dict(views=("ego", "privileged"), misalignment_deg=40.0, rotation_center=(2.0, -1.0)),
    ),
    "periodic axes": _abc_periodic,
}


@pytest.mark.parametrize("case", CASES)
def test_the_env_is_the_core_functions_step_for_step(case):
    """The same seed and actions give the same trajectories (positions, headings, rewards, statuses, every view)
    through the core functions alone as through NavigationEnv's TorchRL step_and_maybe_reset, with resets of some
    slots while the others run on (ended episodes, and a third of the slots reset by a mask every 7 steps)."""
    flow, kwargs = CASES[case]()
    kwargs |= dict(num_envs=32, time_limit=3.0, seed=3)
    env = NavigationEnv(flow, **kwargs)
    twin = NavigationEnv(flow, **kwargs)  # never stepped: its settings and its own slots of a family flow
    settings, scene = twin.settings, twin.flow
    rng = torch.Generator().manual_seed(3)
    state = core.reset(core.initial_state(32, settings, "cpu"), torch.arange(32), scene, settings, rng)
    td = env.reset()
    actions = torch.Generator().manual_seed(0)
    partial = 0
    for i in range(40):
        views = core.observe(state, scene, settings)
        for name in settings.views:
            assert torch.equal(td[name], views[name]), f"step {i}: {name}"
        action = torch.rand(32, 3, generator=actions) * torch.tensor([1.4, 2.4, 4.0]) - torch.tensor([0.2, 1.2, 2.0])
        state, reward = core.step(state, action, scene, settings)
        td["action"] = action
        out, td = env.step_and_maybe_reset(td)
        after = out["next"]
        assert torch.equal(after["position"], state.pos), f"step {i}"
        assert torch.equal(after["heading"], torch.stack((state.theta, state.psi), -1)), f"step {i}"
        assert torch.equal(after["reward"][:, 0], reward), f"step {i}"
        assert torch.equal(after["status"][:, 0], state.status), f"step {i}"
        ended = (state.status != Status.RUNNING).nonzero().squeeze(-1)
        partial += 0 < ended.numel() < 32
        state = core.reset(state, ended, scene, settings, rng)
        if i % 7 == 6:
            mask = torch.arange(32) % 3 == i % 3
            state = core.reset(state, mask.nonzero().squeeze(-1), scene, settings, rng)
            td = env.reset(td.set("_reset", mask[:, None]))
    assert partial >= 3, "episodes must end while others run on"
