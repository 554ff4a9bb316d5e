"""The batched navigation environment: kinematics, observations, reward, episodes, resets."""

import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from omegaconf import OmegaConf
from tensordict import TensorDict
from torchrl.envs.utils import check_env_specs

from flownav.builders import build_env, build_flow, build_task
from flownav.envs import (
    REGION_1,
    REGION_2,
    FixedTargetTask,
    ListTask,
    NavigationEnv,
    RegionTask,
    RewardConfig,
    Status,
    SymmetricTask,
)
from flownav.envs.kinematics import body_frame, heading_vector, to_body
from flownav.envs.observations import HISTORY_LEN, HISTORY_STRIDE, State, compute_views
from flownav.errors import ConfigError
from flownav.flows import Box, FunctionFlow, UniformFlow, rotate_z
from flownav.flows.base import WAKE_BOUNDS, Cylinder
from flownav.paths import REPO_ROOT

BIG = Box((-100.0, -100.0, -100.0), (100.0, 100.0, 100.0))


def still_water(bounds=BIG):
    return UniformFlow((0.0, 0.0, 0.0), bounds=bounds)


def set_heading(env, theta, psi):
    env.theta = torch.full_like(env.theta, theta)
    env.psi = torch.full_like(env.psi, psi)


def act(env, td, action):
    td = td.clone()
    td["action"] = torch.as_tensor(action, dtype=torch.float32).expand(env.num_envs, 3).clone()
    return env.step(td)["next"]


def test_check_env_specs_on_a_grid_flow(wake_like_flow):
    env = NavigationEnv(wake_like_flow, num_envs=16, views=("geo", "ego", "geo_flow", "ego_flow"))
    check_env_specs(env)
    td = env.reset()
    assert td["geo"].shape == (16, 8) and td["ego"].shape == (16, 6)
    assert td["geo_flow"].shape == (16, 8) and td["ego_flow"].shape == (16, 6)


def test_one_kinematic_step_by_hand():
    flow = UniformFlow((0.5, 0.0, 0.0), bounds=BIG)
    env = NavigationEnv(flow, ListTask([[1.0, 2.0, 3.0]], [[9.0, 2.0, 3.0]]), num_envs=1, dt=0.2)
    td = env.reset()
    set_heading(env, 0.0, 0.0)
    nxt = act(env, td, [1.0, math.pi / 4, 0.0])
    # theta' = pi/4 * 0.2 = pi/20; v = (cos pi/20 + 0.5, sin pi/20, 0); P' = P + 0.2 v
    assert nxt["heading"][0].tolist() == pytest.approx([math.pi / 20, 0.0], abs=1e-6)
    assert nxt["position"][0].tolist() == pytest.approx([1.2975377, 2.0312869, 3.0], abs=1e-6)
    assert nxt["velocity"][0].tolist() == pytest.approx([1.4876883, 0.1564345, 0.0], abs=1e-6)
    # geo: target - position, total velocity, theta, psi
    assert nxt["geo"][0].tolist() == pytest.approx(
        [7.7024623, -0.0312869, 0.0, 1.4876883, 0.1564345, 0.0, math.pi / 20, 0.0], abs=1e-6
    )
    # Pitch up at the bound: psi' = 0 + pi/2 * 0.2; the swimmer climbs along the new heading.
    nxt2 = act(env, nxt, [0.5, 0.0, math.pi / 2])
    psi = math.pi / 10
    expected = [
        1.2975377 + 0.2 * (0.5 * math.cos(psi) * math.cos(math.pi / 20) + 0.5),
        2.0312869 + 0.2 * 0.5 * math.cos(psi) * math.sin(math.pi / 20),
        3.0 + 0.2 * 0.5 * math.sin(psi),
    ]
    assert nxt2["position"][0].tolist() == pytest.approx(expected, abs=1e-6)


def test_actions_are_clipped_angles_wrap_and_pitch_saturates():
    env = NavigationEnv(still_water(), ListTask([[0.0, 0.0, 0.0]], [[50.0, 0.0, 0.0]]), num_envs=1, dt=1.0)
    td = env.reset()
    set_heading(env, 3.0, 1.5)
    nxt = act(env, td, [5.0, 10.0, 10.0])  # U clipped to 1, dtheta to pi/4, dpsi to pi/2
    theta, psi = nxt["heading"][0].tolist()
    assert theta == pytest.approx(3.0 + math.pi / 4 - 2 * math.pi, abs=1e-6)
    assert psi == pytest.approx(math.pi / 2, abs=1e-6)
    assert nxt["position"][0].tolist() == pytest.approx([0.0, 0.0, 1.0], abs=1e-6)  # straight up at U = 1


def test_swim_speed_scale_scales_only_the_swimmer():
    env = NavigationEnv(
        UniformFlow((0.2, 0, 0), bounds=BIG),
        ListTask([[0.0, 0, 0]], [[50.0, 0, 0]]),
        num_envs=1,
        dt=1.0,
        swim_speed_scale=0.1,
    )
    td = env.reset()
    set_heading(env, 0.0, 0.0)
    assert act(env, td, [1.0, 0.0, 0.0])["position"][0, 0].item() == pytest.approx(0.3, abs=1e-6)


def test_ego_view_is_the_body_frame_projection():
    theta, psi = torch.tensor([0.7]), torch.tensor([-0.4])
    frame = body_frame(theta, psi)
    assert torch.allclose(frame[0].T @ frame[0], torch.eye(3), atol=1e-6)
    assert torch.allclose(frame[0, :, 0], heading_vector(theta, psi)[0])
    assert torch.det(frame[0]).item() == pytest.approx(1.0, abs=1e-6)
    ahead = 2.5 * heading_vector(theta, psi)
    state = State(to_target=ahead, velocity=ahead, flow=torch.zeros(1, 3), theta=theta, psi=psi, frame=frame)
    views = compute_views(state, ("ego", "ego_flow"))
    assert views["ego"][0].tolist() == pytest.approx([2.5, 0, 0, 2.5, 0, 0], abs=1e-6)
    assert views["ego_flow"][0, 3:].tolist() == pytest.approx([0, 0, 0], abs=1e-6)


@settings(max_examples=25, deadline=None)
@given(phi=st.floats(-2 * math.pi, 2 * math.pi), seed=st.integers(0, 2**31 - 1))
def test_ego_views_are_invariant_under_rotation_of_the_scene(phi, seed):
    g = torch.Generator().manual_seed(seed)
    n = 64
    to_target, vel, flow = (torch.randn(n, 3, generator=g, dtype=torch.float64) for _ in range(3))
    theta = (torch.rand(n, generator=g, dtype=torch.float64) * 2 - 1) * math.pi
    psi = (torch.rand(n, generator=g, dtype=torch.float64) * 2 - 1) * math.pi / 2
    history = torch.randn(n, HISTORY_LEN, 3, generator=g, dtype=torch.float64)
    speed = torch.rand(n, generator=g, dtype=torch.float64)
    views = ("geo", "ego", "ego_flow", "ego_up", "ego_mem", "ego_mem_speed")
    frame = body_frame(theta, psi)
    before = compute_views(State(to_target, vel, flow, theta, psi, frame, history, swim_speed=speed), views)
    r = lambda v: rotate_z(v, phi)  # noqa: E731
    turned = body_frame(theta + phi, psi)
    rotated = State(
        r(to_target),
        r(vel),
        r(flow),
        theta + phi,
        psi,
        turned,
        r(history),
        swim_speed=speed,
    )
    after = compute_views(rotated, views)
    for view in ("ego", "ego_flow", "ego_up", "ego_mem", "ego_mem_speed"):
        assert torch.allclose(before[view], after[view], atol=1e-12), view
    if abs(math.sin(phi / 2)) > 1e-3:  # any rotation but the identity moves the geo view
        assert not torch.allclose(before["geo"], after["geo"], atol=1e-6)


@settings(max_examples=10, deadline=None)
@given(angle=st.floats(5, 355))
def test_misaligned_scene_gives_the_same_ego_episode(angle, wake_like_flow):
    """Rotating flow, domain, starts, targets and headings together changes no ego observation, the flow's gradient
    of ego_mem_grad included (taken along the body axes: along the inertial axes it would differ by up to 0.03)."""
    views = ("geo", "ego", "ego_mem_grad")
    envs = [NavigationEnv(wake_like_flow, num_envs=32, misalignment_deg=a, seed=7, views=views) for a in (0.0, angle)]
    tds = [env.reset() for env in envs]
    g = torch.Generator().manual_seed(1)
    for _ in range(6):
        action = torch.rand(32, 3, generator=g) * torch.tensor([1, 1.5, 3]) - torch.tensor([0, 0.75, 1.5])
        outs = []
        for env, td in zip(envs, tds, strict=True):
            td = td.clone()
            td["action"] = action
            outs.append(env.step(td)["next"])
        assert torch.allclose(outs[0]["ego"], outs[1]["ego"], atol=2e-4)
        assert torch.allclose(outs[0]["ego_mem_grad"], outs[1]["ego_mem_grad"], atol=1e-4)
        assert torch.equal(outs[0]["status"], outs[1]["status"])
        assert torch.allclose(rotate_z(outs[0]["position"], math.radians(angle)), outs[1]["position"], atol=2e-4)
        assert not torch.allclose(outs[0]["geo"], outs[1]["geo"], atol=1e-2)
        tds = outs


def steer_to_target(geo: torch.Tensor, dt: float) -> torch.Tensor:
    """A scripted geo controller for still water: turn towards the target, swim at full speed."""
    d, theta, psi = geo[:, :3], geo[:, 6], geo[:, 7]
    want_theta = torch.atan2(d[:, 1], d[:, 0])
    want_psi = torch.atan2(d[:, 2], d[:, :2].norm(dim=-1))
    dtheta = torch.remainder(want_theta - theta + math.pi, 2 * math.pi) - math.pi
    return torch.stack((torch.ones_like(theta), dtheta / dt, (want_psi - psi) / dt), -1)


def test_successful_episode_reward_sums_to_eq_7():
    cfg = RewardConfig(alpha=1.3, time_penalty=0.7, success_bonus=10.0, success_radius=0.3)
    env = NavigationEnv(still_water(), ListTask([[0.0, 0.0, 0.0]], [[3.0, 1.0, -0.5]]), num_envs=1, dt=0.1, reward=cfg)
    td = env.reset()
    d0 = td["target"].sub(td["position"]).norm().item()
    rewards, dists = [], []
    for _ in range(200):
        td["action"] = steer_to_target(td["geo"], env.dt)
        nxt = env.step(td)["next"]
        rewards.append(nxt["reward"].item())
        dists.append(nxt["target"].sub(nxt["position"]).norm().item())
        td = nxt
        if nxt["done"].item():
            break
    assert Status(nxt["status"].item()) == Status.SUCCESS and nxt["terminated"].item() and not nxt["truncated"].item()
    gamma = [cfg.time_penalty * min(d / d0, 1.0) for d in dists]
    eq7 = -env.dt * sum(gamma) + cfg.alpha * (d0 - dists[-1]) + cfg.success_bonus
    assert sum(rewards) == pytest.approx(eq7, abs=1e-4)
    assert rewards[-1] > cfg.success_bonus - 1  # the bonus arrives once, at the end
    assert all(r > 0 for r in rewards[:-1])  # approaching the target pays more than the time costs here


def test_failure_causes_and_truncation_are_distinct():
    small = Box((-2.0, -2.0, -2.0), (2.0, 2.0, 2.0))
    wall = UniformFlow((1.0, 0.0, 0.0), bounds=small)
    env = NavigationEnv(wall, ListTask([[1.5, 0.0, 0.0]], [[-1.5, 0.0, 0.0]]), num_envs=1, dt=0.2)
    td = env.reset()
    for _ in range(5):
        td["action"] = torch.zeros(1, 3)
        td = env.step(td)["next"]
    assert Status(td["status"].item()) == Status.LEFT_DOMAIN and td["terminated"].item() and not td["truncated"].item()

    env = NavigationEnv(still_water(), ListTask([[0.0, 0, 0]], [[5.0, 0, 0]]), num_envs=1, dt=0.2, time_limit=1.0)
    td = env.reset()
    for step in range(5):
        td["action"] = torch.zeros(1, 3)
        td = env.step(td)["next"]
        assert td["done"].item() == (step == 4)
    assert Status(td["status"].item()) == Status.TIMEOUT and td["truncated"].item() and not td["terminated"].item()

    stream = FunctionFlow(
        lambda p, t: torch.tensor([1.0, 0, 0]).expand_as(p).clone(),
        WAKE_BOUNDS,
        1.0,
        obstacles=[Cylinder((0.0, 0.0), 0.5)],
    )
    env = NavigationEnv(stream, ListTask([[-2.0, 0.0, 5.0]], [[-2.0, 5.0, 5.0]]), num_envs=1, dt=0.2)
    td = env.reset()
    for _ in range(10):
        td["action"] = torch.zeros(1, 3)
        td = env.step(td)["next"]
        if td["done"].item():
            break
    assert Status(td["status"].item()) == Status.HIT_OBSTACLE and td["terminated"].item()
    assert td["position"][0, 0].item() == pytest.approx(-0.4, abs=1e-5)


def test_partial_reset_touches_only_masked_swimmers(wake_like_flow):
    env = NavigationEnv(wake_like_flow, num_envs=8, seed=3)
    td = env.reset()
    for _ in range(3):
        td["action"] = torch.full((8, 3), 0.1)
        td = env.step(td)["next"]
    before = td.clone()
    mask = torch.tensor([1, 0, 0, 1, 0, 1, 0, 0], dtype=torch.bool)
    after = env.reset(before.clone().set("_reset", mask[:, None]))
    # The environment's own state: untouched where the mask is off.
    assert torch.equal(env.pos[~mask], before["position"][~mask]) and torch.equal(
        env.time[~mask], before["time"][~mask, 0]
    )
    only_mask = env.reset(TensorDict({"_reset": mask[:, None]}, batch_size=[8]))  # the masked ones again
    assert torch.equal(env.pos[~mask], before["position"][~mask])
    assert not torch.equal(only_mask["position"][mask], after["position"][mask])
    for key in ("position", "target", "heading", "time", "geo", "ego", "velocity"):
        assert torch.equal(after[key][~mask], before[key][~mask]), key
        assert not torch.equal(after[key][mask], before[key][mask]), key
    assert (after["time"][mask] == 0).all() and (after["time"][~mask] > 0).all()


def test_returned_observations_are_not_overwritten_by_later_resets():
    env = NavigationEnv(UniformFlow((1.0, 0, 0)), num_envs=4, seed=0)
    rollout = env.rollout(100, break_when_any_done=False)
    done = rollout["next", "done"].squeeze(-1)
    assert done.any()
    last = rollout["next", "position"][done]
    assert (last[:, 0] > 16).all()  # the recorded final positions are the ones that left the domain


def test_seeding_is_reproducible(wake_like_flow):
    a = NavigationEnv(wake_like_flow, num_envs=16, seed=5).reset()
    b = NavigationEnv(wake_like_flow, num_envs=16, seed=5).reset()
    c = NavigationEnv(wake_like_flow, num_envs=16, seed=6).reset()
    assert torch.equal(a["geo"], b["geo"]) and not torch.equal(a["geo"], c["geo"])
    env = NavigationEnv(wake_like_flow, num_envs=16, seed=0)
    env.set_seed(5)
    assert torch.equal(env.reset()["geo"], a["geo"])


def test_task_samplers():
    g = torch.Generator().manual_seed(0)
    start, target = RegionTask().sample(1000, g)
    assert REGION_1.contains(start).all() and REGION_2.contains(target).all()
    start, target = SymmetricTask().sample(4000, g)
    forward = REGION_1.contains(start) & REGION_2.contains(target)
    backward = REGION_2.contains(start) & REGION_1.contains(target)
    assert (forward | backward).all() and 0.45 < forward.float().mean() < 0.55
    start, target = FixedTargetTask((11.5, -3.5, 4.5), WAKE_BOUNDS).sample(10, g)
    assert (target == torch.tensor([11.5, -3.5, 4.5])).all() and WAKE_BOUNDS.contains(start).all()
    starts = ListTask([[0, 0, 0], [1, 1, 1]], [[2, 2, 2], [3, 3, 3]]).sample(3)[0]
    assert starts.tolist() == [[0, 0, 0], [1, 1, 1], [0, 0, 0]]


def test_starts_never_inside_the_cylinder_or_at_the_target():
    flow = UniformFlow((1.0, 0, 0))
    flow.obstacles = (Cylinder((0.0, 0.0), 0.5),)
    env = NavigationEnv(flow, FixedTargetTask((0.9, 0.0, 5.0), Box((-1, -1, 4), (1, 1, 6))), num_envs=4000)
    td = env.reset()
    r = td["position"][:, :2].norm(dim=-1)
    assert (r >= 0.5).all()
    assert (td["position"].sub(td["target"]).norm(dim=-1) > 0.3).all()


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"views": ("geo", "sonar")}, "unknown observation view"),
        ({"dt": 0.0}, "dt > 0"),
        ({"num_envs": 0}, "num_envs >= 1"),
        ({"reward": "bad"}, "^reward is a RewardConfig \\(flownav.envs.reward\\) or None; got 'bad'$"),
    ],
)
def test_bad_env_arguments_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        NavigationEnv(still_water(), **kwargs)


def test_a_success_radius_of_zero_is_refused():
    with pytest.raises(ValueError, match="success_radius > 0"):
        RewardConfig(success_radius=0.0)


def conf(group, name):
    return OmegaConf.load(REPO_ROOT / "conf" / group / f"{name}.yaml")


@pytest.mark.parametrize(
    "flow_name, task_name", [("uniform", "regions"), ("uniform", "extended"), ("uniform", "symmetric"), ("abc", "abc")]
)
def test_config_groups_build_working_envs(flow_name, task_name):
    flow = build_flow(conf("flow", flow_name))
    task = build_task(conf("task", task_name), flow)
    env = build_env(conf("env", "default"), flow, task, ("geo", "ego"), num_envs=32)
    td = env.rollout(5, break_when_any_done=False)
    assert td["geo"].shape == (32, 5, 8)
    assert flow.in_domain(td["position"][:, 0]).all()  # every episode starts inside the domain


def test_abc_task_is_in_units_of_pi():
    task = build_task(conf("task", "abc"), build_flow(conf("flow", "abc")))
    start, target = task.sample(500, torch.Generator().manual_seed(0))
    assert (start[:, 0] >= -1.8 * math.pi - 1e-5).all() and (start[:, 0] <= -1.5 * math.pi + 1e-5).all()
    assert (target[:, 0] >= 1.5 * math.pi - 1e-5).all() and (target[:, 2] <= 0.3 * math.pi + 1e-5).all()


def test_bad_config_values_name_the_key():
    with pytest.raises(ConfigError, match="flow.type is 'lbm'"):
        build_flow({"type": "lbm"})
    with pytest.raises(ConfigError, match="flow.speed_scale must be > 0"):
        build_flow({"type": "uniform", "speed_scale": -1})
    with pytest.raises(ConfigError, match="task.start must be"):
        build_task(
            {"type": "regions", "start": [[1, 2, 3], [0, 5, 6]], "target": [[0, 0, 0], [1, 1, 1]]}, still_water()
        )
    with pytest.raises(ConfigError, match="env.reward has an unknown key"):
        build_env(
            {"num_envs": 2, "dt": 0.1, "time_limit": 1, "u_max": 1, "reward": {"beta": 1.0}},
            still_water(),
            RegionTask(),
            ("geo",),
        )


def test_time_limit_is_a_whole_number_of_steps_without_float_drift():
    env = NavigationEnv(still_water(), ListTask([[0.0, 0, 0]], [[50.0, 0, 0]]), num_envs=1, dt=0.2, time_limit=6.0)
    td = env.reset()
    for step in range(1, 31):
        td["action"] = torch.zeros(1, 3)
        td = env.step(td)["next"]
        assert td["truncated"].item() == (step == 30)
    assert td["time"].item() == pytest.approx(6.0, abs=1e-6)


def test_ego_up_is_the_vertical_in_the_body_frame():
    """ego_up's last two numbers are the inertial z axis in the body frame (its y component is always 0)."""
    g = torch.Generator().manual_seed(3)
    theta = (torch.rand(32, generator=g, dtype=torch.float64) * 2 - 1) * math.pi
    psi = (torch.rand(32, generator=g, dtype=torch.float64) * 2 - 1) * math.pi / 2
    frame = body_frame(theta, psi)
    up = to_body(frame, torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64).expand(32, 3))
    zeros = torch.zeros(32, 3, dtype=torch.float64)
    view = compute_views(State(zeros, zeros, zeros, theta, psi, frame), ("ego_up",))["ego_up"]
    assert view.shape == (32, 8) and torch.allclose(up[:, 1], torch.zeros(32, dtype=torch.float64), atol=1e-12)
    assert torch.allclose(view[:, 6:], up[:, [0, 2]], atol=1e-12)


def test_ego_mem_grad_reads_a_linear_flows_gradient_in_the_body_frame():
    """In u = A x the gradient is A everywhere: ego_mem_grad is ego_mem followed by F^T A F (row-major), F the body
    axes, for every heading, at the start and after a turn."""
    A = torch.tensor([[0.1, -0.3, 0.0], [0.2, 0.05, 0.4], [-0.1, 0.0, -0.15]])
    flow = FunctionFlow(lambda p, t: p @ A.T, bounds=BIG, max_speed=100.0)
    env = NavigationEnv(flow, num_envs=16, views=("ego_mem", "ego_mem_grad"), seed=3)
    td = env.reset()
    for _ in range(2):
        frame = body_frame(env.theta, env.psi)
        expected = (frame.transpose(-1, -2) @ A @ frame).flatten(1)
        assert torch.equal(td["ego_mem_grad"][:, :-9], td["ego_mem"])
        assert torch.allclose(td["ego_mem_grad"][:, -9:], expected, atol=1e-4)
        td["action"] = torch.tensor([0.5, 0.6, -0.9]).expand(16, 3)
        td = env.step(td)["next"]


def test_the_body_axis_gradient_and_the_privileged_gradient_read_one_flow_side_by_side():
    """A DAgger env computes the student's ego_mem_grad and the teacher's geo_priv in one look-up: in u = A x each
    reads A, the student as F^T A F along its body axes, the teacher as A along the inertial axes."""
    A = torch.tensor([[0.1, -0.3, 0.0], [0.2, 0.05, 0.4], [-0.1, 0.0, -0.15]])
    flow = FunctionFlow(lambda p, t: p @ A.T, bounds=BIG, max_speed=100.0)
    env = NavigationEnv(flow, num_envs=16, views=("ego_mem_grad", "geo_priv"), seed=5)
    td = env.reset()
    td["action"] = torch.tensor([0.5, 0.6, -0.9]).expand(16, 3)
    td = env.step(td)["next"]
    frame = body_frame(env.theta, env.psi)
    assert torch.allclose(td["ego_mem_grad"][:, -9:], (frame.transpose(-1, -2) @ A @ frame).flatten(1), atol=1e-4)
    assert torch.allclose(td["geo_priv"][:, 12:21], A.flatten().expand(16, 9), atol=1e-4)


def test_ego_mem_remembers_the_flow_every_stride_steps_in_the_current_body_frame():
    """In a flow u = (t, 0, 0), sample k of the memory is the flow k * HISTORY_STRIDE steps ago (the start
    flow before the episode began), seen from the current heading; a reset swimmer forgets its past."""
    flow = FunctionFlow(lambda p, t: torch.stack((t, 0 * t, 0 * t), -1), bounds=BIG, max_speed=100.0)
    task = ListTask([[0.0, 0, 0]], [[50.0, 0, 0]])
    env = NavigationEnv(flow, task, num_envs=2, views=("ego_up", "ego_mem"), random_flow_phase=False)
    td = env.reset()
    set_heading(env, math.pi / 2, 0.0)  # heading +y: the inertial x axis is the body's -y axis
    steps = 9
    for _ in range(steps):
        td = act(env, td, [0.0, 0.0, 0.0])
    memory = td["ego_mem"][:, 8:].view(2, HISTORY_LEN, 3)
    lag_steps = torch.arange(HISTORY_LEN) * HISTORY_STRIDE
    expected_t = ((steps - lag_steps).clamp_min(0) * env.dt).float()
    assert memory[0, :, 1].tolist() == pytest.approx((-expected_t).tolist(), abs=1e-5)
    assert memory[:, :, [0, 2]].abs().max().item() < 1e-5
    assert torch.allclose(td["ego_mem"][:, :8], td["ego_up"])
    td = env.reset(td.clone().set("_reset", torch.tensor([[True], [False]])))
    set_heading(env, math.pi / 2, 0.0)
    td = act(env, td, [0.0, 0.0, 0.0])  # the reset swimmer restarts at t = 0, the other goes on to step 10
    memory = -td["ego_mem"][:, 8:].view(2, HISTORY_LEN, 3)[:, :, 1]
    assert memory[0].tolist() == pytest.approx([env.dt] + [0.0] * (HISTORY_LEN - 1), abs=1e-5)
    assert memory[1].tolist() == pytest.approx(((steps + 1 - lag_steps).clamp_min(0) * env.dt).tolist(), abs=1e-5)


def test_geo_sincos_is_geo_with_a_continuous_heading():
    """Same numbers as geo, theta as (cos, sin): no jump where theta wraps, heading straight upstream."""
    flow = UniformFlow((0.3, 0.1, 0.0), bounds=BIG)
    env = NavigationEnv(flow, num_envs=2, views=("geo", "geo_sincos"))
    env.reset()
    set_heading(env, 0.0, 0.2)
    env.theta = torch.tensor([math.pi - 1e-3, -math.pi + 1e-3])  # two headings 0.002 rad apart, across the wrap
    td = env._observe()
    geo, sc = td["geo"], td["geo_sincos"]
    assert torch.equal(sc[:, :6], geo[:, :6]) and torch.equal(sc[:, 8], geo[:, 7])
    assert torch.allclose(sc[:, 6], torch.cos(geo[:, 6])) and torch.allclose(sc[:, 7], torch.sin(geo[:, 6]))
    assert (geo[0, 6] - geo[1, 6]).abs() > 6.0 and (sc[0, 6:] - sc[1, 6:]).abs().max() < 3e-3


def test_privileged_view_reports_the_flow_and_its_phase():
    def swirl(x, t):
        return torch.stack((torch.sin(t), torch.cos(t), 0.1 * x[:, 2]), -1)

    period = 2 * math.pi
    flow = FunctionFlow(swirl, bounds=BIG, max_speed=1.5, period=period)
    env = NavigationEnv(flow, num_envs=8, views=("geo_sincos", "privileged"), dt=0.5, seed=3)
    td = env.reset()
    for _ in range(5):
        td = act(env, td, [0.5, 0.1, 0.0])
    priv = td["privileged"]
    assert torch.equal(priv[:, :9], td["geo_sincos"])
    t = env.t0 + env.time  # each swimmer's own flow time (random start phase)
    assert torch.allclose(priv[:, 9:12], swirl(env.pos, t), atol=1e-5)
    angle = 2 * math.pi * torch.remainder(t / period, 1.0)
    assert priv[:, 12].tolist() == pytest.approx(torch.cos(angle).tolist(), abs=1e-5)
    assert priv[:, 13].tolist() == pytest.approx(torch.sin(angle).tolist(), abs=1e-5)
    # A steady flow has no phase: cos = sin = 0.
    steady = NavigationEnv(still_water(), num_envs=4, views=("privileged",)).reset()["privileged"]
    assert torch.equal(steady[:, 12:], torch.zeros(4, 2))


def _roll(env, steps=12):
    torch.manual_seed(0)
    actions = torch.rand(steps, env.num_envs, 3) * torch.tensor([1.0, 0.4, 0.4]) - torch.tensor([0.0, 0.2, 0.2])
    td, out = env.reset(), []
    for a in actions:
        td["action"] = a
        td = env.step(td)["next"].clone()
        out.append(td["position"])
    return torch.stack(out)


def test_flow_strength_one_is_the_flow_itself_and_zero_is_still_water(wake_like_flow):
    task = ListTask([[2.0, 3.0, 5.0]], [[10.0, -3.0, 5.0]])
    plain = NavigationEnv(wake_like_flow, task, num_envs=8, random_flow_phase=False)
    one = NavigationEnv(wake_like_flow, task, num_envs=8, random_flow_phase=False, flow_strength=(1.0, 1.0))
    assert torch.equal(_roll(plain), _roll(one))  # and the first reset's starts and headings are the same
    zero = NavigationEnv(wake_like_flow, task, num_envs=8, random_flow_phase=False, flow_strength=(0.0, 0.0))
    still = NavigationEnv(still_water(wake_like_flow.bounds), task, num_envs=8, random_flow_phase=False)
    assert torch.allclose(_roll(zero), _roll(still), atol=1e-6)


def test_flow_strength_scales_each_episode_by_its_own_draw():
    env = NavigationEnv(
        UniformFlow((0.5, 0, 0), bounds=BIG),
        ListTask([[0.0, 0, 0]], [[50.0, 0, 0]]),
        num_envs=256,
        flow_strength=(0.2, 0.6),
    )
    td = env.reset()
    s = env.strength
    assert (s >= 0.2).all() and (s <= 0.6).all() and s.std() > 0.05
    # at rest in the fluid after a reset: the velocity the swimmer reports is its own episode's flow
    assert torch.allclose(td["velocity"][:, 0], 0.5 * s)
    td["action"] = torch.zeros(256, 3)
    nxt = env.step(td)["next"]
    assert torch.allclose(nxt["position"][:, 0], 0.5 * s * env.dt, atol=1e-6)
    half = NavigationEnv(still_water(), num_envs=4000, flow_strength=(0.0, 0.5), flow_strength_full=0.3)
    half.reset()
    assert (half.strength == 1).float().mean().item() == pytest.approx(0.3, abs=0.03)
    assert (half.strength[half.strength < 1] <= 0.5).all()
    with pytest.raises(ValueError, match="flow_strength"):
        NavigationEnv(still_water(), flow_strength=(0.5, 0.2))
    with pytest.raises(ValueError, match="flow_strength_full"):
        NavigationEnv(still_water(), flow_strength=(0.0, 1.0), flow_strength_full=1.5)
    with pytest.raises(ValueError, match="flow_strength_full needs flow_strength"):
        NavigationEnv(still_water(), flow_strength_full=0.5)
    with pytest.raises(ConfigError, match="env.flow_strength"):
        build_env(
            {"num_envs": 2, "dt": 0.1, "time_limit": 1, "u_max": 1, "flow_strength": [1.0]},
            still_water(),
            RegionTask(),
            ("geo",),
        )


def test_a_rejected_start_is_drawn_again_with_its_own_target():
    """A start inside the cylinder is redrawn together with its target: every episode keeps the task's distance."""
    from flownav.envs.tasks import DistanceTask

    still = FunctionFlow(lambda p, t: torch.zeros_like(p), WAKE_BOUNDS, 1.0, obstacles=[Cylinder((0.0, 0.0), 0.5)])
    task = DistanceTask(Box((-1.5, -1.5, 0.0), (1.5, 1.5, 3.0)), (2.0, 2.5))  # about 1 start in 11 in the cylinder
    first_draw, _ = task.sample(4096, torch.Generator().manual_seed(0))
    assert (first_draw[:, :2].norm(dim=-1) < 0.5).sum() > 200
    env = NavigationEnv(still, task, num_envs=4096, views=("geo",), seed=0)
    env.reset()
    start, target = env.state.pos, env.state.target
    assert not (start[:, :2].norm(dim=-1) < 0.5).any()
    distance = (target - start).norm(dim=-1)
    assert distance.min() >= 2.0 - 1e-4 and distance.max() <= 2.5 + 1e-4
