"""The oracle: a batched full-knowledge planner run through the same rollout as every policy."""

import pytest
import torch
from load import load_module

from flownav.envs import ListTask, NavigationEnv, RegionTask
from flownav.evaluation.metrics import summarize
from flownav.evaluation.oracle import Oracle, OracleSettings
from flownav.evaluation.rollout import run_episodes
from flownav.evaluation.scripted import SCRIPTED, HeadToTarget
from flownav.flows import Box, FunctionFlow, UniformFlow
from flownav.flows.families import MixtureFamily, UniformFamily

SMALL = dict(candidates=32, horizon=40, iterations=2, elites=4)


def success(policy, flow, task, episodes, **env_kw):
    make_env = lambda n, chunk: NavigationEnv(flow, task, num_envs=n, views=("geo",), seed=chunk, **env_kw)  # noqa: E731
    ep = run_episodes(policy, "geo", make_env, episodes, chunk_size=episodes)
    return summarize(ep.status, ep.time)


@pytest.mark.parametrize("velocity", [(0.0, 0.0, 0.0), (0.5, 0.0, 0.0)])
def test_the_oracle_reaches_every_target_in_still_water_and_a_uniform_current(velocity):
    flow = UniformFlow(velocity, bounds=Box((-4.0, -7.0, 0.0), (22.0, 7.0, 10.0)))
    s = success(Oracle(**SMALL), flow, RegionTask(), 16, time_limit=30.0)
    assert s["success_rate"] == 1.0


def test_the_oracle_plans_in_each_swimmers_own_flow_of_a_family():
    """A mixture of two current families: every swimmer of the batch drifts in its own current, and the oracle's
    simulated candidates (many rows per swimmer) look up their swimmer's flow and obstacles."""
    box = Box((-4.0, -7.0, 0.0), (22.0, 7.0, 10.0))
    members = [UniformFamily((0.3, 0.5), horizontal=True, bounds=box), UniformFamily((0.0, 0.2), bounds=box)]
    family = MixtureFamily(members, [0.5, 0.5], bounds=box)
    s = success(Oracle(**SMALL), family, RegionTask(), 16, time_limit=30.0)
    assert s["success_rate"] == 1.0


def cross_current_band(pos, t):
    """A current of 3 (three times the swimmer) along +x in the band 1.8 < y < 4.2, still water elsewhere."""
    u = 3.0 * torch.exp(-(((pos[:, 1] - 3.0) / 1.2) ** 8))
    zero = torch.zeros_like(u)
    return torch.stack((u, zero, zero), -1)


@pytest.mark.slow
def test_the_oracle_takes_a_detour_where_heading_straight_fails():
    # Crossing the band drifts a swimmer about 6 along x; the box is 5 wide on each side of the start, so
    # only a detour (first upstream, then across) stays inside.
    flow = FunctionFlow(cross_current_band, Box((-5.0, -2.0, -2.0), (5.0, 8.0, 2.0)), max_speed=3.0)
    task = ListTask([[0.0, 0.0, 0.0]], [[0.0, 6.0, 0.0]])
    straight = success(HeadToTarget(), flow, task, 8, time_limit=40.0)
    assert straight["success_rate"] == 0.0 and straight["failures"]["left_domain"]["rate"] == 1.0
    oracle = success(Oracle(candidates=64, horizon=60, iterations=3, blocks=3), flow, task, 8, time_limit=40.0)
    assert oracle["success_rate"] >= 7 / 8


def test_a_planner_that_senses_only_around_the_swimmer_misses_the_detour():
    """With the flow known within 1 of the swimmer (the felt still water beyond), the band is unseen until the
    swimmer is at its edge, too late to go upstream first: every episode is carried out of the box."""
    flow = FunctionFlow(cross_current_band, Box((-5.0, -2.0, -2.0), (5.0, 8.0, 2.0)), max_speed=3.0)
    task = ListTask([[0.0, 0.0, 0.0]], [[0.0, 6.0, 0.0]])
    local = success(
        Oracle(candidates=64, horizon=60, iterations=3, blocks=3, sensing_radius=1.0), flow, task, 8, time_limit=40.0
    )
    assert local["success_rate"] == 0.0 and local["failures"]["left_domain"]["rate"] == 1.0


def test_a_planner_that_does_not_know_the_walls_is_carried_out_of_the_box():
    """The detour of the full oracle exists only because of the box's walls: a planner that judges a plan leaving the
    box as if the domain went on takes the straight crossing and every episode is carried out."""
    flow = FunctionFlow(cross_current_band, Box((-5.0, -2.0, -2.0), (5.0, 8.0, 2.0)), max_speed=3.0)
    task = ListTask([[0.0, 0.0, 0.0]], [[0.0, 6.0, 0.0]])
    blind = success(
        Oracle(candidates=64, horizon=60, iterations=3, blocks=3, knows_walls=False), flow, task, 8, time_limit=40.0
    )
    assert blind["success_rate"] == 0.0 and blind["failures"]["left_domain"]["rate"] == 1.0


def passing_band(pos, t):
    """The band of cross_current_band until t = 4, still water after."""
    return cross_current_band(pos, t) * (t < 4.0).to(pos.dtype)[:, None]


def test_a_planner_without_a_forecast_detours_round_a_current_about_to_stop():
    """The full oracle knows the band stops at t = 4 and crosses after it; a planner in the flow frozen at planning
    time goes the long way round it and runs out of time."""
    flow = FunctionFlow(passing_band, Box((-5.0, -2.0, -2.0), (5.0, 8.0, 2.0)), max_speed=3.0)
    task = ListTask([[0.0, 0.0, 0.0]], [[0.0, 6.0, 0.0]])
    settings = dict(candidates=64, horizon=60, iterations=3, blocks=3)
    assert success(Oracle(**settings), flow, task, 8, time_limit=9.0)["success_rate"] == 1.0
    frozen = success(Oracle(**settings, forecast=False), flow, task, 8, time_limit=9.0)
    assert frozen["success_rate"] == 0.0 and frozen["failures"]["timeout"]["rate"] == 1.0


def test_the_oracle_is_a_scripted_reference_and_refuses_to_act_without_the_env():
    assert SCRIPTED["oracle"] is Oracle
    with pytest.raises(TypeError, match="act_privileged"):
        Oracle()(torch.zeros(4, 8))


def test_oracle_settings_are_checked():
    with pytest.raises(ValueError, match="elites <= candidates"):
        OracleSettings(candidates=4, elites=8)
    with pytest.raises(ValueError, match="replan_every <= horizon"):
        OracleSettings(horizon=4, replan_every=5, blocks=2)
    with pytest.raises(ValueError, match="sensing_radius > 0"):
        OracleSettings(sensing_radius=0.0)


def test_the_settings_script_runs_the_suites_tests():
    """scripts/oracle_settings.py measures on the suite's ABC and extended-domain tests: the same flow, task and env
    configs."""
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    from flownav.evaluation.experiments import Suite
    from flownav.paths import REPO_ROOT

    script = load_module("scripts/oracle_settings.py")
    for test, experiment in (("as_posed", "paper_abc"), ("periodic", "abc_periodic"), ("extended", "paper_extended")):
        with initialize_config_dir(config_dir=str(REPO_ROOT / "conf" / "evaluate"), version_base="1.3"):
            cfg = compose("config", overrides=[f"+experiment={experiment}"])
        (entry,) = cfg.suite.values()
        mine = script.test_config(test)
        for key in ("flow", "task"):
            assert OmegaConf.to_container(mine[key]) == OmegaConf.to_container(entry[key]), (test, key)
        suite_env = Suite(cfg, log=lambda *_: None).env_cfg(entry)
        assert OmegaConf.to_container(mine.env) == OmegaConf.to_container(suite_env), test


def test_the_gradient_climber_turns_towards_where_the_flow_carries_it_to_the_target():
    """scripts/gradient_climber.py: facing the target along +x, with du_x/dy = +-1 the rule turns towards +-y (where
    the flow towards the target grows); tau = 0 is head-to-target."""
    from load import load_module

    script = load_module("scripts/gradient_climber.py")
    obs = torch.zeros(2, 23)
    obs[:, 0] = 5.0  # the target 5 ahead along +x
    obs[:, 6] = 1.0  # cos theta = 1: facing +x
    obs[:, 21] = 1.0  # swim speed
    obs[0, script.GRADIENT.start + 1], obs[1, script.GRADIENT.start + 1] = 1.0, -1.0  # du_x/dy
    turn = script.GradientClimber(tau=3.0)(obs)[:, 1]
    assert turn[0] > 0.1 and turn[1] < -0.1
    geo = torch.cat((obs[:, :6], torch.zeros(2, 2)), -1)  # the same state in the geo view: theta = psi = 0
    assert torch.allclose(script.GradientClimber(tau=0.0)(obs), HeadToTarget()(geo))


def test_an_evaluation_of_the_oracle_does_not_depend_on_what_it_planned_before():
    """One oracle object serves every suite of a run: its search's random draws restart with each evaluation, so a
    suite's oracle rows are those of the suite run alone."""
    flow = FunctionFlow(cross_current_band, Box((-5.0, -2.0, -2.0), (5.0, 8.0, 2.0)), max_speed=3.0)
    task = ListTask([[0.0, 0.0, 0.0]], [[0.0, 6.0, 0.0]])
    still = UniformFlow((0.0, 0.0, 0.0), bounds=Box((-4.0, -7.0, 0.0), (22.0, 7.0, 10.0)))

    def episodes(oracle, flow, task):
        make_env = lambda n, chunk: NavigationEnv(flow, task, num_envs=n, views=("geo",), seed=chunk, time_limit=40.0)  # noqa: E731
        return run_episodes(oracle, "geo", make_env, 8, chunk_size=8)

    used = Oracle(**SMALL)
    episodes(used, still, RegionTask())
    after, fresh = episodes(used, flow, task), episodes(Oracle(**SMALL), flow, task)
    assert torch.equal(after.status, fresh.status) and torch.equal(after.time, fresh.time)
