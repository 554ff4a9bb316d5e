"""What a policy must pass before it ships (``ship_requires`` of its experiment): the selection rule ships the best
seed among those that pass, refuses when none does, and measures each check on the protocol's episodes."""

from __future__ import annotations

import json
import math

import pytest
import torch
from hydra import compose, initialize_config_dir

from flownav import shipping
from flownav.checkpoint import load_policy, save_policy_checkpoint
from flownav.envs.observations import observation_size
from flownav.evaluation.scripted import HeadToTarget, fit_expert
from flownav.evaluation.selection import main, requirement_checks
from flownav.paths import REPO_ROOT

# The training task of these checkpoints: the paper's task in still water, with a time limit that a swimmer at
# full speed meets and one at a third of it mostly does not.
STILL = ["flow=uniform", "flow.velocity=[0.0,0.0,0.0]", "task=regions", "env.time_limit=12.0"]
HEADWIND = ["flow=uniform", "flow.velocity=[0.0,1.5,0.0]"]  # stronger than any swimmer: no one arrives
CHECKS = {"strict": {"headwind": {"overrides": HEADWIND, "min_success": 0.99}}, "lenient": {}}


def policy_file(path, name: str, speed_fraction: float):
    """A geo network fitted to head-to-target at ``speed_fraction`` of the swim speed, from a run of ``name``."""
    pol, _ = fit_expert(HeadToTarget(speed_fraction=speed_fraction), obs_dim=observation_size("geo"), hidden=(32, 32))
    return save_policy_checkpoint(path, pol, "geo", "teacher", meta={"config": {"name": name}})


@pytest.fixture(scope="module")
def seeds(tmp_path_factory):
    d = tmp_path_factory.mktemp("ship_requires")
    return policy_file(d / "fast.pt", "strict", 0.98), policy_file(d / "slow.pt", "lenient", 0.33)


@pytest.fixture
def experiments(monkeypatch):
    """Two experiments by name: "strict" requires the headwind, "lenient" nothing; runs count as finished."""
    monkeypatch.setattr(shipping, "experiment_requirements", lambda name: CHECKS[name])
    monkeypatch.setattr(shipping, "require_shippable", lambda payload, what: None)


def test_the_best_seed_that_fails_a_check_is_not_shipped(seeds, experiments, tmp_path):
    fast, slow = seeds
    out, shipped = tmp_path / "sel.json", tmp_path / "shipped.pt"
    args = ["--name", "t", "--out", str(out), "--threads", "1", *[a for o in STILL for a in ("--override", o)]]
    main([str(fast), str(slow), *args, "--ship", str(shipped)])
    data = json.loads(out.read_text())
    fast_run, slow_run = data["runs"]
    assert fast_run["success_rate"] > 0.9 > slow_run["success_rate"]  # the fast seed is the better one ...
    assert fast_run["requirements"]["headwind"]["success_rate"] == 0.0  # ... and fails its experiment's check
    assert data["shipped"]["checkpoint"] == str(slow) and torch.equal(
        torch.load(shipped, weights_only=True)["policy"]["state_dict"]["net.0.weight"],
        torch.load(slow, weights_only=True)["policy"]["state_dict"]["net.0.weight"],
    )
    # No seed passes: nothing is shipped, one line names each seed and the check it failed with its rate.
    shipped.unlink()
    with pytest.raises(SystemExit) as stop:
        main([str(fast), *args, "--ship", str(shipped)])
    assert stop.value.code == 2 and not shipped.exists()
    assert json.loads(out.read_text())["runs"][0]["requirements"]["headwind"]["success_rate"] == 0.0


def test_no_seed_passing_is_refused_with_the_failed_check_named(seeds, experiments, tmp_path, capsys):
    fast, _ = seeds
    with pytest.raises(SystemExit):
        main(
            [
                str(fast),
                "--name",
                "t",
                "--out",
                str(tmp_path / "s.json"),
                "--threads",
                "1",
                "--ship",
                str(tmp_path / "x.pt"),
            ]
        )
    printed = capsys.readouterr()
    last_line = printed.err.strip().splitlines()[-1]
    assert last_line.endswith(
        f"shipping refused: no checkpoint passes its experiment's ship_requires ({fast}: headwind (0.0000 < 0.99))"
    )
    # Every seed's numbers stay on screen: a refused ship writes no shipped results file to read them from.
    assert f"{fast}: success " in printed.out and "  headwind: 0.0000 (at least 0.99)" in printed.out


def test_a_check_is_measured_on_the_protocols_episodes(seeds, experiments):
    """A check's success is evaluate.py's on the same overrides (same episodes, same summary); the check's own
    overrides come last (the headwind wins over the still water of STILL)."""
    import evaluate as evaluate_py

    fast, _ = seeds
    still = requirement_checks(*load_policy(fast), 400, STILL[:-1] + ["env.time_limit=40.0"])["headwind"]
    assert still["overrides"] == HEADWIND and still["success_rate"] == 0.0
    CHECKS["strict"]["backwind"] = {"overrides": ["flow.velocity=[0.0,-0.5,0.0]"], "min_success": 0.99}
    try:
        rate = requirement_checks(*load_policy(fast), 400, STILL)["backwind"]["success_rate"]
    finally:
        del CHECKS["strict"]["backwind"]
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf" / "evaluate"), version_base="1.3"):
        cfg = compose(
            "config",
            overrides=[f"checkpoint={fast}", "episodes=400", "progress=false", *STILL, "flow.velocity=[0.0,-0.5,0.0]"],
        )
    assert 0.0 < rate == evaluate_py.run(cfg, log=lambda *_: None)["success_rate"]


def test_the_generalist_student_ships_only_if_it_holds_still_water_and_every_current():
    reqs = shipping.experiment_requirements("generalist_student")
    velocities = {tuple(json.loads(r["overrides"][1].split("=", 1)[1])) for r in reqs.values()}
    axes = {tuple(s * 0.8 * (i == j) for j in range(3)) for i in range(3) for s in (1, -1)}
    assert velocities == axes | {(0.0, 0.0, 0.0)} and {r["min_success"] for r in reqs.values()} == {0.99}
    assert all(r["overrides"][0] == "flow=uniform" and "task=regions" in r["overrides"] for r in reqs.values())
    assert shipping.experiment_requirements("generalist_student_ego") == reqs  # built on it
    assert shipping.experiment_requirements("teacher") == {} and shipping.experiment_requirements("nope") == {}


def test_the_noisy_student_ships_only_if_it_is_the_more_robust_policy_in_the_paper_wake():
    """Its checks add the paper's wake as posed (the paper's task, and Region 2 from starts anywhere) at its training
    noise (the run's env) and at twice it (the run's env with its noise keys overridden); none is a zoo case."""
    from omegaconf import OmegaConf

    from flownav.builders import compose_config
    from flownav.evaluation.selection import training_spec
    from flownav.flows.grid import GridFlow

    base = shipping.experiment_requirements("generalist_student")
    reqs = shipping.experiment_requirements("generalist_student_noisy")
    added = {k: r for k, r in reqs.items() if k not in base}
    assert {k: reqs[k] for k in base} == base and len(added) == 4
    run_cfg = compose_config(["+experiment=generalist_student_noisy"])
    payload = {"meta": {"config": OmegaConf.to_container(run_cfg, resolve=True)}}
    noise = {}
    for key, req in added.items():
        spec = training_spec(payload, 10, req["overrides"])
        if key.startswith("paper_task"):
            assert isinstance(spec.flow, GridFlow) and type(spec.task).__name__ == "RegionTask", key
        else:  # the wake member alone, unturned, at full strength, on no current: the paper's wake
            wake = OmegaConf.to_container(compose_config(req["overrides"]).flow)
            assert wake["members"].keys() == {"wake"}, key
            assert [wake["members"]["wake"][k] for k in ("angle_deg", "strength", "background")] == [
                [0.0, 0.0],
                [1.0, 1.0],
                [0.0, 0.0],
            ], key
            shares = ("posed_wake_regions_share", "posed_wake_any_start_share", "posed_wake_reverse_share")
            assert [getattr(spec.task, k) for k in shares] == [1.0, 1.0, 0.0], key
        env = OmegaConf.to_container(spec.env_cfg, resolve=True)
        noise[key] = tuple(env["sensor_noise"][k] for k in ("flow", "target", "gradient"))
        assert {k: v for k, v in env.items() if k != "sensor_noise"} == {
            k: v for k, v in OmegaConf.to_container(run_cfg.env, resolve=True).items() if k != "sensor_noise"
        }
    assert noise == {
        "paper_task_noise_0.1": (0.1, 0.05, 0.02),
        "paper_task_noise_0.2": (0.2, 0.1, 0.04),
        "any_start_noise_0.1": (0.1, 0.05, 0.02),
        "any_start_noise_0.2": (0.2, 0.1, 0.04),
    }
    assert run_cfg.obs == compose_config(["+experiment=generalist_student"]).obs  # its recipe's view


def test_an_override_of_a_key_changes_only_that_key_of_the_runs_own_group():
    """The selection's ``--override env.sensor_bias.flow=0.1`` measures a run trained with sensor noise under that
    bias and its own noise, not train.py's noise-free env; a group's choice (``env=default``) takes that config
    whole; a key the run's config lacks (an older run) comes with its group's other defaults; ``~`` deletes."""
    from omegaconf import OmegaConf

    from flownav.builders import compose_config
    from flownav.evaluation.selection import training_spec

    run_cfg = OmegaConf.to_container(compose_config(["+experiment=generalist_student_noisy"]), resolve=True)
    run_env, defaults = run_cfg["env"], OmegaConf.to_container(compose_config([]).env, resolve=True)
    assert run_env != defaults  # its training noise

    def env(overrides, config=run_cfg):
        return OmegaConf.to_container(training_spec({"meta": {"config": config}}, 10, overrides).env_cfg)

    assert env(["env.sensor_bias.flow=0.1"]) == run_env | {"sensor_bias": run_env["sensor_bias"] | {"flow": 0.1}}
    assert env(["env=default"]) == defaults
    assert env(["~env.sensor_noise"]) == {k: v for k, v in run_env.items() if k != "sensor_noise"}
    older = run_cfg | {"env": {k: v for k, v in run_env.items() if k != "sensor_bias"}}
    assert env(["env.sensor_bias.flow=0.1"], older)["sensor_bias"] == defaults["sensor_bias"] | {"flow": 0.1}


def test_a_key_override_needs_only_the_runs_own_group_to_have_it():
    """``--override task.full_speed_share=0.5`` changes a family-trained run's task although train.py's default task
    (the paper's regions) has no such key; a key no group has is refused with one line naming it."""
    from omegaconf import OmegaConf

    from flownav import schema
    from flownav.builders import compose_config
    from flownav.errors import ConfigError
    from flownav.evaluation.selection import training_spec

    run_cfg = OmegaConf.to_container(compose_config(["+experiment=generalist_student_noisy"]), resolve=True)
    payload = {"meta": {"config": run_cfg}}
    assert run_cfg["task"]["full_speed_share"] != 0.5
    assert training_spec(payload, 10, ["task.full_speed_share=0.5"]).task.full_speed_share == 0.5
    with pytest.raises(ConfigError, match=r"^env has an unknown key 'sensor_nois'; keys: \['num_envs'"):
        schema.check_env(training_spec(payload, 10, ["env.sensor_nois.flow=0.1"]).env_cfg)
    with pytest.raises(ConfigError, match=r"^--override flow=cylinder flow.rotate_deg=30: Could not override"):
        training_spec(payload, 10, ["flow=cylinder", "flow.rotate_deg=30"])  # a key the chosen config lacks: +
    assert training_spec(payload, 10, ["flow=cylinder", "+flow.rotate_deg=30"]).flow.angle == pytest.approx(math.pi / 6)
    # as Hydra: a group of keys merges into the run's, + adds a key only where there is none; errors are one line
    noise = training_spec(payload, 10, ["env.sensor_noise={flow: 0.2}"]).env_cfg["sensor_noise"]
    assert dict(noise) == run_cfg["env"]["sensor_noise"] | {"flow": 0.2}
    with pytest.raises(ConfigError, match=r"^--override \+env.dt=0.5: env.dt is already set; use env.dt=\.\.\."):
        training_spec(payload, 10, ["+env.dt=0.5"])
    assert training_spec(payload, 10, ["++env.dt=0.5"]).env_cfg["dt"] == 0.5
    with pytest.raises(ConfigError, match=r"^--override env.dt.x=1: "):
        training_spec(payload, 10, ["env.dt.x=1"])
