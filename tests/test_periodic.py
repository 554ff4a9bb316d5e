"""Success along the whole step (segment against sphere) and periodic domains (the well-posed ABC test)."""

import math

import pytest
import torch
from omegaconf import OmegaConf

from flownav.builders import build_env, build_flow, build_task
from flownav.envs import ListTask, NavigationEnv, Status
from flownav.envs.kinematics import step_reaches
from flownav.errors import ConfigError
from flownav.flows import ABCFlow, Box, UniformFlow
from flownav.flows.base import make_periodic
from flownav.paths import REPO_ROOT

TWO_PI = 2 * math.pi
CONF = REPO_ROOT / "conf"


def test_a_step_through_the_ball_counts_and_one_beside_it_does_not():
    target = torch.tensor([[0.0, 0.0, 0.0]])
    p0 = torch.tensor([[-0.5, 0.1, 0.0]])
    through = torch.tensor([[1.0, 0.0, 0.0]])  # ends at (0.5, 0.1, 0): both end points 0.51 away
    beside = torch.tensor([[1.0, 0.3, 0.0]])
    assert (target - p0).norm() > 0.3 and (target - p0 - through).norm() > 0.3
    assert step_reaches(target - p0, through, 0.3).item()
    # The line from (-0.5, 0.1) along (1, 0.3) passes the origin at distance |0.1 + 0.15| / sqrt(1.09) = 0.2395.
    assert step_reaches(target - p0, beside, 0.3).item()
    assert not step_reaches(target - p0, beside, 0.23).item()
    # Closest point beyond the segment's end: the end point decides.
    short = torch.tensor([[0.2, 0.0, 0.0]])  # ends at (-0.3, 0.1): distance 0.316
    assert not step_reaches(target - p0, short, 0.3).item()
    assert step_reaches(target - p0, short, 0.32).item()
    # A zero step is the end-point test.
    assert step_reaches(torch.tensor([[0.29, 0.0, 0.0]]), torch.zeros(1, 3), 0.3).item()
    assert not step_reaches(torch.tensor([[0.31, 0.0, 0.0]]), torch.zeros(1, 3), 0.3).item()


def test_the_env_counts_a_fast_step_that_crosses_the_success_ball():
    # Flow 5 along x: one step of 0.2 moves 1.0, the ball is 0.6 wide; start 0.5 before the target.
    big = Box((-50.0, -50.0, -50.0), (50.0, 50.0, 50.0))
    env = NavigationEnv(UniformFlow((5.0, 0.0, 0.0), bounds=big), ListTask([[0, 0, 0]], [[0.5, 0, 0]]), num_envs=1)
    td = env.reset()
    td["action"] = torch.zeros(1, 3)
    out = env.step(td)["next"]
    assert out["position"][0, 0].item() == pytest.approx(1.0)  # ended 0.5 past the target
    assert out["status"].item() == Status.SUCCESS
    # Beside it (0.4 off the line), the same step misses.
    env = NavigationEnv(UniformFlow((5.0, 0.0, 0.0), bounds=big), ListTask([[0, 0, 0]], [[0.5, 0.4, 0]]), num_envs=1)
    td = env.reset()
    td["action"] = torch.zeros(1, 3)
    assert env.step(td)["next"]["status"].item() == Status.RUNNING


def periodic_abc():
    return make_periodic(ABCFlow(), ["y", "z"])


def test_displacement_is_the_minimum_image_on_periodic_axes_only():
    flow = periodic_abc()
    pos = torch.tensor([[0.0, 3.0, -3.0]])
    target = torch.tensor([[5.0, -3.0, 3.0]])
    d = flow.displacement(pos, target)
    assert d[0, 0].item() == pytest.approx(5.0)  # x is bounded: no image
    assert d[0, 1].item() == pytest.approx(TWO_PI - 6.0, abs=1e-5)
    assert d[0, 2].item() == pytest.approx(6.0 - TWO_PI, abs=1e-5)
    # Every periodic image of the target gives the same vector.
    shifted = target + torch.tensor([[0.0, 3 * TWO_PI, -2 * TWO_PI]])
    assert torch.allclose(flow.displacement(pos, shifted), d, atol=1e-4)


def test_wrap_keeps_bounded_axes_and_in_domain_ignores_periodic_ones():
    flow = periodic_abc()
    pos = torch.tensor([[7.0, math.pi + 0.5, -math.pi - 0.25]])
    w = flow.wrap(pos)
    assert w[0, 0].item() == 7.0
    assert w[0, 1].item() == pytest.approx(-math.pi + 0.5, abs=1e-5)
    assert w[0, 2].item() == pytest.approx(math.pi - 0.25, abs=1e-5)
    assert not flow.in_domain(w).item()  # x = 7 > 2 pi: out through the bounded axis
    assert flow.in_domain(torch.tensor([[1.0, 40.0, -40.0]])).item()


def test_a_swimmer_carried_across_a_periodic_face_re_enters_and_reaches_the_image_target():
    # Uniform stream along +y on a box periodic in y (any period is a period of a uniform flow).
    box = Box((-5.0, -2.0, -5.0), (5.0, 2.0, 5.0))
    flow = make_periodic(UniformFlow((0.0, 2.0, 0.0), bounds=box), ["y"])
    # Start near the top face, target just above the bottom face: 3.6 apart in the box, 0.4 across the face.
    env = NavigationEnv(flow, ListTask([[0, 1.8, 0]], [[0, -1.8, 0]]), num_envs=1, views=("geo",))
    td = env.reset()
    assert td["geo"][0, :3].tolist() == pytest.approx([0.0, 0.4, 0.0], abs=1e-5)
    td["action"] = torch.zeros(1, 3)
    out = env.step(td)["next"]  # moves 0.4 along y: crosses y = 2 and lands on the target's image
    assert out["position"][0, 1].item() == pytest.approx(-1.8, abs=1e-5)
    assert out["status"].item() == Status.SUCCESS
    assert out["reward"].item() > 10.0  # 0.4 gained plus the bonus: the reward uses the same distance


def test_a_bounded_axis_still_ends_the_episode():
    box = Box((-5.0, -2.0, -5.0), (5.0, 2.0, 5.0))
    flow = make_periodic(UniformFlow((0.0, 0.0, 30.0), bounds=box), ["y"])
    env = NavigationEnv(flow, ListTask([[0, 0, 0]], [[3, 0, 0]]), num_envs=1)
    td = env.reset()
    td["action"] = torch.zeros(1, 3)
    assert env.step(td)["next"]["status"].item() == Status.LEFT_DOMAIN


def test_a_box_that_is_not_a_period_is_refused():
    assert make_periodic(ABCFlow(), ["x"]).periodic_axes == (0,)  # x spans [-2 pi, 2 pi]: two whole periods
    short = Box((-2 * math.pi, -math.pi, -math.pi), (2 * math.pi, 2.0, math.pi))
    with pytest.raises(ValueError, match="not periodic over its box on axis y"):
        make_periodic(ABCFlow(bounds=short), ["y"])


def test_periodic_axes_refuse_bad_names_and_rotation():
    with pytest.raises(ValueError, match="periodic_axes must be distinct names"):
        make_periodic(ABCFlow(), ["w"])
    with pytest.raises(ValueError, match="cannot be rotated about z"):
        NavigationEnv(periodic_abc(), ListTask([[0, 0, 0]], [[3, 0, 0]]), num_envs=1, misalignment_deg=30)


def test_the_abc_periodic_configs_build_the_well_posed_test():
    flow_cfg = OmegaConf.load(CONF / "flow" / "abc.yaml")
    flow_cfg = OmegaConf.merge(flow_cfg, OmegaConf.load(CONF / "flow" / "abc_periodic.yaml"))
    flow_cfg.pop("defaults")
    flow = build_flow(flow_cfg)
    assert flow.periodic_axes == (1, 2)
    env_cfg = OmegaConf.merge(*(OmegaConf.load(CONF / "env" / f) for f in ("default.yaml", "abc_periodic.yaml")))
    env_cfg.pop("defaults")
    assert env_cfg.time_limit == 100.0 and env_cfg.swim_speed_scale == 0.1
    env = build_env(env_cfg, flow, build_task(OmegaConf.load(CONF / "task" / "abc.yaml"), flow), ["geo"], num_envs=8)
    td = env.reset()
    assert torch.allclose(td["geo"][:, :3], flow.displacement(td["position"], td["target"]))
    bad = OmegaConf.merge(flow_cfg, {"periodic_axes": ["y", "q"]})
    with pytest.raises(ConfigError, match="periodic_axes"):
        build_flow(bad)
