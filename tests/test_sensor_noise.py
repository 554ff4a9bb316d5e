"""Sensor noise on the ego views (env.sensor_noise): what it changes, what it leaves exact, and that a noisy
env resumes exactly."""

import copy

import pytest
import torch
from omegaconf import OmegaConf

from flownav.builders import build_env, build_flow, build_task, compose_config
from flownav.envs import ListTask, NavigationEnv
from flownav.envs.kinematics import to_body
from flownav.envs.observations import HISTORY_LEN, HISTORY_STRIDE
from flownav.flows import Box, FunctionFlow

BIG = Box((-100.0, -100.0, -100.0), (100.0, 100.0, 100.0))
VIEWS = ("geo_priv", "ego_flow", "ego_mem")


def swirl():
    """A steady flow that varies in space, so readings differ from swimmer to swimmer."""
    return FunctionFlow(
        lambda p, t: torch.stack((torch.sin(p[:, 1]), torch.cos(p[:, 0]), 0.3 * torch.sin(p[:, 0] + p[:, 1])), -1),
        bounds=BIG,
        max_speed=1.5,
    )


def make(noise, n=4096, seed=3, bias=(0.0, 0.0, 0.0), views=VIEWS, **kw):
    g = torch.Generator().manual_seed(0)
    start = torch.rand(n, 3, generator=g) * 10
    task = ListTask(start.tolist(), (start + torch.randn(n, 3, generator=g) * 5).tolist())
    return NavigationEnv(
        swirl(), task, num_envs=n, views=views, time_limit=100.0, sensor_noise=noise, sensor_bias=bias, seed=seed, **kw
    )


def run(env, steps, seed=1):
    g = torch.Generator().manual_seed(seed)
    td = env.reset()
    out = [td]
    for _ in range(steps):
        action = torch.rand(env.num_envs, 3, generator=g) * torch.tensor([1.0, 1.0, 1.0]) - torch.tensor([0, 0.5, 0.5])
        td = env.step(td.set("action", action))["next"]
        out.append(td)
    return out


def test_noise_reaches_the_ego_views_only_with_the_configured_spread():
    """Same seed and actions: the dynamics and the privileged view are exactly those of exact sensors; the ego
    views' flow reading errs by sigma_flow per component and the to-target vector by sigma_target times its
    length (body frame: a rotation keeps an isotropic error isotropic)."""
    flow_std, target_std = 0.2, 0.05
    exact, noisy = run(make((0.0, 0.0, 0.0)), 12), run(make((flow_std, target_std, 0.0)), 12)
    for a, b in zip(exact, noisy, strict=True):
        assert torch.equal(a["position"], b["position"]) and torch.equal(a["geo_priv"], b["geo_priv"])
    a, b = exact[-1]["ego_flow"], noisy[-1]["ego_flow"]
    flow_error = b[:, 3:] - a[:, 3:]
    assert flow_error.std().item() == pytest.approx(flow_std, rel=0.05)
    assert flow_error.mean().abs().item() < 0.02
    target_error = (b[:, :3] - a[:, :3]) / a[:, :3].norm(dim=-1, keepdim=True)
    assert target_error.std().item() == pytest.approx(target_std, rel=0.05)
    earlier = noisy[-2]["ego_flow"][:, 3:] - exact[-2]["ego_flow"][:, 3:]
    correlation = torch.corrcoef(torch.stack((flow_error.flatten(), earlier.flatten())))[0, 1]
    assert abs(correlation.item()) < 0.05  # a fresh error each step


def test_the_memory_keeps_each_reading_as_it_was_sensed():
    """The newest memory sample is the current reading (the one ego_flow reports), and a reading stays as sensed
    while it is remembered: four steps later it is the next sample, the same inertial vector seen from the new
    heading."""
    env = make((0.3, 0.0, 0.0), n=64)
    steps = run(env, 8)
    now = steps[-1]["ego_mem"][:, 8:].view(-1, HISTORY_LEN, 3)
    assert torch.allclose(now[:, 0], steps[-1]["ego_flow"][:, 3:], atol=1e-6)
    before = steps[-5]["ego_mem"][:, 8:].view(-1, HISTORY_LEN, 3)[:, 0]
    theta, psi = env.theta, env.psi
    frame_then = _frames(steps[-5]["heading"])
    inertial = torch.einsum("bij,bj->bi", frame_then, before)  # body -> inertial: R b
    seen_now = to_body(_frames(torch.stack((theta, psi), -1)), inertial)
    assert torch.allclose(now[:, 1], seen_now, atol=1e-5)


def _frames(heading):
    from flownav.envs.kinematics import body_frame

    return body_frame(heading[:, 0], heading[:, 1])


def _to_world(td, v):
    """Body-frame components ``v`` of a step's readings as world vectors, by that step's heading (R v)."""
    return torch.einsum("bij,bj->bi", _frames(td["heading"]), v)


def test_a_noisy_env_resumes_exactly():
    """The last reading's error is part of the saved state: a fresh env that loads it sees and steps identically."""
    env = make((0.2, 0.1, 0.0), n=32)
    run(env, 5)
    saved = env.state_dict()
    twin = make((0.2, 0.1, 0.0), n=32, seed=99)
    twin.reset()
    twin.load_state_dict(saved)
    a, b = env._observe(), twin._observe()
    assert torch.equal(a["ego_mem"], b["ego_mem"])
    action = torch.full((32, 3), 0.5)
    a = env.step(a.set("action", action))["next"]
    b = twin.step(b.set("action", action))["next"]
    assert torch.equal(a["ego_mem"], b["ego_mem"]) and torch.equal(a["ego_flow"], b["ego_flow"])


def test_exact_sensors_draw_nothing_and_noisy_ones_draw_after_the_episode():
    """With exact sensors a step draws nothing from the env's generator (every existing run keeps its random
    streams); noisy sensors draw after a reset's other draws, so the first episodes are the same."""
    exact, noisy = make((0.0, 0.0, 0.0), n=16), make((0.1, 0.0, 0.0), n=16)
    a, b = exact.reset(), noisy.reset()
    assert torch.equal(a["position"], b["position"]) and torch.equal(a["target"], b["target"])
    exact_before, noisy_before = exact.rng.get_state(), noisy.rng.get_state()
    for _ in range(3):
        a = exact.step(a.set("action", torch.full((16, 3), 0.5)))["next"]
        b = noisy.step(b.set("action", torch.full((16, 3), 0.5)))["next"]
    assert torch.equal(exact.rng.get_state(), exact_before) and not exact.state.sensor_error.any()
    assert not torch.equal(noisy.rng.get_state(), noisy_before)
    with pytest.raises(ValueError, match=r"sensor_noise is \(flow, target, gradient\)"):
        NavigationEnv(swirl(), num_envs=2, sensor_noise=(-1.0, 0.0, 0.0))


GRADIENT_VIEWS = ("geo_priv", "ego_mem_grad")


def make_grad(noise, n=4096, seed=3):
    """make() with the view that senses the flow's gradient along the body axes."""
    return make(noise, n, seed, views=GRADIENT_VIEWS)


def test_the_gradient_errs_only_with_its_own_noise_and_with_its_spread():
    """Flow and to-target noise leave ego_mem_grad's gradient exact; a gradient noise gives each of its nine
    components an error of that spread, fresh each step, and leaves the dynamics and the privileged view exactly as
    without it; its errors are drawn after the flow's and the target's, so the first readings of those agree."""
    grad = lambda td: td["ego_mem_grad"][:, -9:]  # noqa: E731
    exact, flow_only, both = (run(make_grad(noise), 6) for noise in ((0, 0, 0), (0.2, 0.05, 0), (0.2, 0.05, 0.03)))
    for a, b, c in zip(exact, flow_only, both, strict=True):
        assert torch.equal(grad(a), grad(b)) and torch.equal(a["geo_priv"], c["geo_priv"])
        assert torch.equal(a["position"], c["position"])
    assert torch.equal(flow_only[0]["ego_mem_grad"][:, :-9], both[0]["ego_mem_grad"][:, :-9])
    error = grad(both[-1]) - grad(exact[-1])
    assert error.std().item() == pytest.approx(0.03, rel=0.05) and error.mean().abs().item() < 0.002
    earlier = grad(both[-2]) - grad(exact[-2])
    assert abs(torch.corrcoef(torch.stack((error.flatten(), earlier.flatten())))[0, 1].item()) < 0.05


def test_a_gradient_noise_no_view_reads_changes_nothing():
    """Views without the gradient draw exactly what they drew before the gradient could err: the same readings step
    by step with and without a gradient noise (the noise suite's other policies keep their numbers)."""
    for a, b in zip(run(make((0.2, 0.05, 0.0)), 6), run(make((0.2, 0.05, 0.05)), 6), strict=True):
        assert torch.equal(a["ego_mem"], b["ego_mem"]) and torch.equal(a["ego_flow"], b["ego_flow"])


def test_a_gradient_noisy_env_resumes_exactly():
    """The gradient's errors are part of the saved state too."""
    env = make_grad((0.1, 0.05, 0.03), n=32)
    run(env, 5)
    twin = make_grad((0.1, 0.05, 0.03), n=32, seed=99)
    twin.reset()
    twin.load_state_dict(env.state_dict())
    a, b = env._observe(), twin._observe()
    assert torch.equal(a["ego_mem_grad"], b["ego_mem_grad"])
    action = torch.full((32, 3), 0.5)
    a, b = (e.step(o.set("action", action))["next"] for e, o in ((env, a), (twin, b)))
    assert torch.equal(a["ego_mem_grad"], b["ego_mem_grad"])


def test_the_config_key_reaches_the_env():
    """env.sensor_noise.{flow,target,gradient} of the configs is the env's (flow, target, gradient)."""
    keys = ["env.sensor_noise.flow=0.15", "env.sensor_noise.target=0.02", "env.sensor_noise.gradient=0.03"]
    cfg = compose_config(["obs=ego_mem", *keys])
    flow = build_flow(cfg.flow)
    env = build_env(cfg.env, flow, build_task(cfg.task, flow), ["ego_mem"], num_envs=4)
    assert env.settings.sensor_noise == (0.15, 0.02, 0.03) and env.settings.noisy
    assert build_env(compose_config([]).env, flow, build_task(cfg.task, flow), ["ego_mem"], 4).settings.noisy is False


def test_the_noise_suite_compares_only_policies_that_sense_and_applies_its_noise():
    """``+experiment=sensor_noise``: every section noisy, and only ego policies in it (scripted references and the
    oracle read the exact state, so a noise table with them would compare exact against sensed)."""
    from hydra import compose, initialize_config_dir

    from flownav.envs.observations import SENSED_VIEWS
    from flownav.paths import REPO_ROOT

    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf" / "evaluate"), version_base="1.3"):
        cfg = compose("config", overrides=["+experiment=sensor_noise"])
    levels = set()
    for name, suite in cfg.suite.items():
        kind = "sensor_bias" if name.startswith("bias") else "sensor_noise"
        noise = suite.env[kind]
        assert noise.flow > 0 and noise.target > 0 and noise.gradient > 0, name
        levels.add((kind, noise.flow, noise.target, noise.gradient))
        sensed = [cfg.policies[p].obs in SENSED_VIEWS and "checkpoint" in cfg.policies[p] for p in suite.policies]
        assert all(sensed), name
    assert levels == {
        ("sensor_noise", 0.1, 0.05, 0.02),
        ("sensor_noise", 0.2, 0.1, 0.04),
        ("sensor_bias", 0.1, 0.05, 0.02),
    }
    assert "generalist_student_noisy" in cfg.suite.noise_020_paper.policies


def test_the_gradient_sense_script_removes_exactly_the_gradient():
    """scripts/gradient_sense.py's ablation feeds the policy its view with the last nine entries (the body-axis
    gradient) zero and the rest as sensed; the shipped student's actions depend on them."""
    from load import load_module

    script = load_module("scripts/gradient_sense.py")
    seen = []
    act = script.without_gradient(lambda obs: seen.append(obs) or obs[:, :3])
    obs = run(make_grad((0.0, 0.0, 0.0), n=64), 3)[-1]["ego_mem_grad"]
    act(obs)
    assert torch.equal(seen[0][:, :-9], obs[:, :-9]) and not seen[0][:, -9:].any() and obs[:, -9:].any(-1).all()
    suite = script.Suite(compose_config(["+experiment=validation"], app="evaluate"))
    policy, view, _ = suite.policy(script.POLICY)
    assert view == "ego_mem_grad"
    assert not torch.allclose(policy(obs), script.without_gradient(policy)(obs), atol=1e-3)


def test_a_gradient_error_no_view_reads_draws_nothing():
    """With only a gradient error set and no view that reads the gradient, a step draws nothing from the env's
    generator: the random streams (the next episodes' draws) are those of exact sensors."""
    exact, unread = make((0.0, 0.0, 0.0), n=16), make((0.0, 0.0, 0.1), n=16)
    assert not unread.settings.noisy and unread.settings.sensor_error_width == 6
    run(exact, 3), run(unread, 3)
    assert torch.equal(exact.rng.get_state(), unread.rng.get_state())


def test_a_saved_state_with_other_sensor_errors_is_refused_with_its_fix():
    """A state saved with a gradient error (15 errors per swimmer) does not load into an env without one (6)."""
    env = make_grad((0.1, 0.05, 0.03), n=8)
    run(env, 2)
    other = make_grad((0.1, 0.05, 0.0), n=8)
    with pytest.raises(ValueError, match=r"holds 15 sensor errors per swimmer, this env 6: build it with"):
        other.load_state_dict(env.state_dict())


def test_runs_saved_before_the_gradient_error_existed_resume():
    """env.sensor_noise.gradient and env.sensor_bias are null by default, so a run whose saved config lacks them
    resumes (the check accepts a key added since at its null default), and null means exact."""
    from flownav.checkpoint import check_resume_settings

    cfg = OmegaConf.to_container(compose_config([]), resolve=True)
    assert cfg["env"]["sensor_noise"]["gradient"] is None
    saved = copy.deepcopy(cfg)
    del saved["env"]["sensor_noise"]["gradient"], saved["env"]["sensor_bias"]
    check_resume_settings("run", {"meta": {"config": saved}}, cfg)
    flow = build_flow(compose_config([]).flow)
    env = build_env(compose_config([]).env, flow, build_task(compose_config([]).task, flow), ["ego_mem_grad"], 4)
    assert env.settings.sensor_noise == (0.0, 0.0, 0.0)


def test_a_bias_is_drawn_once_per_episode_with_its_spread():
    """env.sensor_bias: each swimmer's readings err by the same bias at every step of its episode, in the reading's
    frame: the flow reading and its memory by one world-frame vector, the to-target vector by one world-frame vector
    times its length, the gradient by one matrix of body-axis components; spread sigma across swimmers; a new
    episode draws a new one. With a fresh noise as well, the first readings' fresh errors are those without it."""
    views = GRADIENT_VIEWS + ("ego_flow", "ego_mem")
    exact = run(make((0.0, 0.0, 0.0), views=views), 6)
    biased_env = make((0.0, 0.0, 0.0), bias=(0.2, 0.05, 0.03), views=views)
    biased = run(biased_env, 6)
    steps = list(zip(exact, biased, strict=True))
    for a, b in steps:
        assert torch.equal(a["position"], b["position"]) and torch.equal(a["geo_priv"], b["geo_priv"])
    flow = [_to_world(b, b["ego_flow"][:, 3:]) - _to_world(a, a["ego_flow"][:, 3:]) for a, b in steps]
    memory = [_to_world(b, b["ego_mem"][:, 8:11]) - _to_world(a, a["ego_mem"][:, 8:11]) for a, b in steps]
    target = [
        (_to_world(b, b["ego_flow"][:, :3]) - _to_world(a, a["ego_flow"][:, :3]))
        / a["ego_flow"][:, :3].norm(dim=-1, keepdim=True)
        for a, b in steps
    ]
    gradient = [b["ego_mem_grad"][:, -9:] - a["ego_mem_grad"][:, -9:] for a, b in steps]
    for errors, sigma in ((flow, 0.2), (memory, 0.2), (target, 0.05), (gradient, 0.03)):
        assert torch.allclose(errors[1], errors[5], atol=1e-4)  # the same error all episode long
        assert errors[5].std().item() == pytest.approx(sigma, rel=0.05)
    assert torch.allclose(memory[5], flow[5], atol=1e-5)  # the memory holds the readings as sensed
    before = biased_env.state.sensor_bias.clone()
    biased_env.reset()
    assert not torch.allclose(before, biased_env.state.sensor_bias)
    noisy, both = make((0.1, 0.05, 0.0)).reset(), make((0.1, 0.05, 0.0), bias=(0.1, 0.0, 0.0)).reset()
    assert torch.equal(noisy["ego_flow"][:, :3], both["ego_flow"][:, :3])  # no to-target bias: the same fresh error


def test_a_bias_no_view_reads_draws_nothing_and_null_is_none():
    """A gradient bias with views that read no gradient changes nothing (readings and streams); a gradient bias alone
    reaches the gradient's view; the default config has no bias."""
    a, b = make((0.1, 0.05, 0.0), n=64), make((0.1, 0.05, 0.0), n=64, bias=(0.0, 0.0, 0.05))
    assert not b.settings.biased
    for x, y in zip(run(a, 4), run(b, 4), strict=True):
        assert torch.equal(x["ego_mem"], y["ego_mem"])
    assert torch.equal(a.rng.get_state(), b.rng.get_state())
    only = make((0.0, 0.0, 0.0), n=64, bias=(0.0, 0.0, 0.05), views=GRADIENT_VIEWS)
    exact = make((0.0, 0.0, 0.0), n=64, views=GRADIENT_VIEWS)
    assert only.settings.biased and not torch.equal(run(only, 2)[-1]["ego_mem_grad"], run(exact, 2)[-1]["ego_mem_grad"])
    cfg = compose_config(["obs=ego_mem_grad"])
    flow = build_flow(cfg.flow)
    env = build_env(cfg.env, flow, build_task(cfg.task, flow), ["ego_mem_grad"], num_envs=4)
    assert env.settings.sensor_bias == (0.0, 0.0, 0.0) and not env.settings.biased and not env.settings.noisy


def test_a_biased_env_resumes_exactly_and_the_key_reaches_it():
    """The episode's bias (and the track views' memory of the to-target readings) is part of the saved state;
    env.sensor_bias.{flow,target,gradient} is the env's."""
    views = (*GRADIENT_VIEWS, "ego_mem_grad_track")
    env = make((0.0, 0.0, 0.0), n=32, bias=(0.1, 0.05, 0.02), views=views)
    run(env, 6)
    twin = make((0.0, 0.0, 0.0), n=32, seed=99, bias=(0.1, 0.05, 0.02), views=views)
    twin.reset()
    twin.load_state_dict(env.state_dict())
    action = torch.full((32, 3), 0.5)
    a, b = (e.step(e._observe().set("action", action))["next"] for e in (env, twin))
    assert torch.equal(a["ego_mem_grad"], b["ego_mem_grad"])
    assert torch.equal(a["ego_mem_grad_track"], b["ego_mem_grad_track"])
    keys = ["env.sensor_bias.flow=0.1", "env.sensor_bias.target=0.02", "env.sensor_bias.gradient=0.01"]
    cfg = compose_config(["obs=ego_mem", *keys])
    flow = build_flow(cfg.flow)
    built = build_env(cfg.env, flow, build_task(cfg.task, flow), ["ego_mem"], num_envs=4)
    assert built.settings.sensor_bias == (0.1, 0.02, 0.01) and built.settings.biased
    with pytest.raises(ValueError, match=r"sensor_bias is \(flow, target, gradient\)"):
        NavigationEnv(swirl(), num_envs=2, sensor_bias=(0.0, -1.0, 0.0))


def test_a_body_frame_bias_turns_with_the_swimmer():
    """env.sensor_bias.frame=body: the flow reading's and the to-target vector's bias are fixed body-frame components
    (a mounting offset) while the swimmer turns, so in the world frame they turn with it; the memory keeps each
    reading as sensed (a sample from a stride back erred by the bias seen from the heading of then). The same draws
    as the world-frame bias: the world-frame one is constant in the world frame instead. The gradient's is per body
    axis in both."""
    views = GRADIENT_VIEWS + ("ego_flow", "ego_mem")
    bias = (0.2, 0.05, 0.03)
    exact = run(make((0.0, 0.0, 0.0), views=views), 6)
    world_env = make((0.0, 0.0, 0.0), bias=bias, views=views)
    body_env = make((0.0, 0.0, 0.0), bias=bias, views=views, sensor_bias_frame="body")
    world_run, body_run = run(world_env, 6), run(body_env, 6)
    assert torch.equal(world_env.state.sensor_bias, body_env.state.sensor_bias)  # the same draws
    for a, w, b in zip(exact, world_run, body_run, strict=True):
        assert torch.equal(a["position"], b["position"]) and torch.equal(a["geo_priv"], b["geo_priv"])
        flow_body = b["ego_flow"][:, 3:] - a["ego_flow"][:, 3:]
        target_body = (b["ego_flow"][:, :3] - a["ego_flow"][:, :3]) / a["ego_flow"][:, :3].norm(dim=-1, keepdim=True)
        assert torch.allclose(flow_body, 0.2 * body_env.state.sensor_bias[:, 0:3], atol=1e-5)
        assert torch.allclose(target_body, 0.05 * body_env.state.sensor_bias[:, 3:6], atol=1e-5)
        flow_world = _to_world(w, w["ego_flow"][:, 3:]) - _to_world(a, a["ego_flow"][:, 3:])
        assert torch.allclose(flow_world, 0.2 * world_env.state.sensor_bias[:, 0:3], atol=1e-5)
        assert torch.allclose(w["ego_mem_grad"][:, -9:], b["ego_mem_grad"][:, -9:])  # the gradient's: body axes
    turned = (exact[5]["heading"] - exact[1]["heading"]).abs().sum(-1) > 0.1  # swimmers whose heading changed
    assert turned.float().mean() > 0.5
    world_then = _to_world(exact[1], 0.2 * body_env.state.sensor_bias[:, 0:3])
    world_now = _to_world(exact[5], 0.2 * body_env.state.sensor_bias[:, 0:3])
    assert not torch.allclose(world_then[turned], world_now[turned], atol=1e-3)  # in the world frame it turned
    samples = lambda td: td["ego_mem"][:, 8:].view(-1, HISTORY_LEN, 3)  # noqa: E731
    memory = samples(body_run[5]) - samples(exact[5])
    frame_now = _frames(exact[5]["heading"])
    for k in range(HISTORY_LEN):  # k * HISTORY_STRIDE steps back (before the start: the reading at the reset)
        then = exact[max(5 - k * HISTORY_STRIDE, 0)]
        expected = to_body(frame_now, _to_world(then, 0.2 * body_env.state.sensor_bias[:, 0:3]))
        assert torch.allclose(memory[:, k], expected, atol=1e-5), k


def test_the_bias_frame_key_reaches_the_env_and_a_bad_one_is_refused():
    cfg = compose_config(["obs=ego_mem", "env.sensor_bias.flow=0.1", "env.sensor_bias.frame=body"])
    flow = build_flow(cfg.flow)
    built = build_env(cfg.env, flow, build_task(cfg.task, flow), ["ego_mem"], num_envs=4)
    assert built.settings.sensor_bias_frame == "body" and built.settings.body_bias
    default = compose_config(["obs=ego_mem", "env.sensor_bias.flow=0.1"])
    built = build_env(default.env, flow, build_task(default.task, flow), ["ego_mem"], num_envs=4)
    assert built.settings.sensor_bias_frame == "world" and not built.settings.body_bias
    with pytest.raises(ValueError, match="sensor_bias_frame is 'world' or 'body'; got 'up'"):
        NavigationEnv(swirl(), num_envs=2, sensor_bias_frame="up")


def test_the_track_memory_holds_the_to_target_readings_of_the_flow_memorys_steps():
    """ego_mem_grad_track is ego_mem_grad followed by the to-target readings of the flow memory's steps, newest (the
    one the ego view reports) first, each seen from the current heading; exact sensors remember the true vectors
    (those of geo, inertial), a biased and noisy sensor its readings as sensed."""
    n, steps = 64, 2 * HISTORY_STRIDE + 1
    exact = run(make((0.0, 0.0, 0.0), n=n, views=("geo", "ego_mem_grad", "ego_mem_grad_track")), steps)
    last = exact[-1]
    track = last["ego_mem_grad_track"]
    assert torch.equal(track[:, : -3 * HISTORY_LEN], last["ego_mem_grad"])
    memory = track[:, -3 * HISTORY_LEN :].view(n, HISTORY_LEN, 3)
    frame = _frames(last["heading"])
    for k in range(HISTORY_LEN):  # before the start the swimmer remembers its start reading
        then = exact[max(len(exact) - 1 - k * HISTORY_STRIDE, 0)]["geo"][:, :3]
        assert torch.allclose(memory[:, k], to_body(frame, then), atol=1e-5), k
    errs = make((0.1, 0.05, 0.02), n=n, bias=(0.1, 0.05, 0.02), views=("ego_mem_grad_track",))
    sensed = run(errs, steps)
    now = sensed[-1]["ego_mem_grad_track"]
    assert torch.equal(now[:, -3 * HISTORY_LEN : -3 * (HISTORY_LEN - 1)], now[:, :3])  # the reading the view reports
    before = sensed[-1 - HISTORY_STRIDE]["ego_mem_grad_track"][:, :3]  # seen then, remembered as it was sensed
    remembered = now[:, -3 * (HISTORY_LEN - 1) : -3 * (HISTORY_LEN - 2)]
    assert torch.allclose(_to_world(sensed[-1], remembered), _to_world(sensed[-1 - HISTORY_STRIDE], before), atol=1e-5)
    exact_then = exact[-1 - HISTORY_STRIDE]["geo"][:, :3]
    assert not torch.allclose(_to_world(sensed[-1 - HISTORY_STRIDE], before), exact_then, atol=1e-3)  # it errs
