"""DAgger: on a tiny problem the imitation loss falls and the ego student matches its geo teacher; runs resume
exactly; the student's normaliser is the aggregated data's; a teacher of the wrong view is refused."""

from __future__ import annotations

import csv
import json
from collections.abc import Mapping
from pathlib import Path

import pytest
import torch
from hydra import compose, initialize_config_dir
from tiny import DRIFT_TASK

from flownav.algorithms.dagger import beta_at, imitation_loss, lr_at
from flownav.checkpoint import CheckpointError, load_checkpoint, load_policy, save_policy_checkpoint
from flownav.errors import ConfigError
from flownav.evaluation.scripted import HeadToTarget, fit_expert
from flownav.flows.base import WAKE_BOUNDS

ROOT = Path(__file__).resolve().parents[1]
CONF = str(ROOT / "conf")

# A weak uniform stream, targets 2-3 D away: the scripted teacher succeeds, the student can learn it in seconds.
TINY = [
    *DRIFT_TASK,
    "algo.num_envs=64",
    "algo.steps_per_iteration=60",
    "algo.updates_per_iteration=150",
    "algo.batch_size=512",
    "algo.hidden=[64,64]",
    "algo.lr=3e-3",
    "algo.final_eval_episodes=300",
    "logger=csv",
    "logger.progress=false",
    "threads=1",
    "output_checkpoint=null",
    "algo.results_json=null",
]


@pytest.fixture(scope="module")
def teacher_ckpt(tmp_path_factory):
    """The scripted "turn to the target, swim" expert, fitted into a geo DeterministicPolicy checkpoint."""
    policy, mse = fit_expert(HeadToTarget(), hidden=(64, 64), steps=600, batch=1024, seed=0)
    assert mse < 0.3
    path = tmp_path_factory.mktemp("teacher") / "teacher.pt"
    save_policy_checkpoint(path, policy, "geo", "teacher")
    return path


def make_cfg(teacher, *overrides):
    with initialize_config_dir(config_dir=CONF, version_base="1.3"):
        return compose("config", overrides=["+experiment=student", *TINY, f"teacher_checkpoint={teacher}", *overrides])


def rows(run_dir):
    with open(Path(run_dir) / "metrics.csv", newline="") as f:
        return [r for r in csv.DictReader(f) if r.get("train/loss")]


@pytest.fixture(scope="module")
def experiment_cfgs() -> dict:
    """Every experiment of conf/experiment, composed: {name: config}."""
    experiments = sorted(p.stem for p in (ROOT / "conf" / "experiment").glob("*.yaml"))
    with initialize_config_dir(config_dir=CONF, version_base="1.3"):
        return {e: compose("config", overrides=[f"+experiment={e}"]) for e in experiments}


def test_every_student_imitates_a_teacher_trained_on_its_flow_and_task(experiment_cfgs):
    """Each DAgger experiment's teacher checkpoint is made by a PPO experiment on the same flow and task, read
    through another view than the student's, and the student acts alone from the first step (the paper's beta 0)."""
    cfgs = experiment_cfgs
    makers = {c.output_checkpoint: e for e, c in cfgs.items() if c.algo.name == "ppo" and c.output_checkpoint}
    students = {e: c for e, c in cfgs.items() if c.algo.name == "dagger"}
    assert students
    for name, cfg in students.items():
        teacher = makers.get(cfg.teacher_checkpoint, Path(cfg.teacher_checkpoint).stem)  # selection ships by name
        assert teacher in cfgs and cfgs[teacher].algo.name == "ppo", f"{name}: {cfg.teacher_checkpoint}"
        if cfg.algo.get("scene_expert"):  # a routed teacher: the same families, weighted towards the paper's task
            assert unweighted(cfgs[teacher].flow) == unweighted(cfg.flow), f"{name} vs {teacher}"
            assert unweighted(cfgs[teacher].task) == unweighted(cfg.task), f"{name} vs {teacher}"
            if cfg.task.get("posed_wake_any_start_box"):  # a part of the teacher's starts, weighted up
                lo, hi = cfg.task.posed_wake_any_start_box
                m = cfg.task.margin
                assert all(WAKE_BOUNDS.lo[i] + m <= lo[i] < hi[i] <= WAKE_BOUNDS.hi[i] - m for i in range(3)), name
            maker = makers.get(cfg.algo.scene_expert, Path(cfg.algo.scene_expert).stem)
            expert = cfgs[maker]
            if expert.algo.name == "ppo":  # the paper's teacher, made in the paper's scene
                assert (expert.flow.type, expert.task.type, expert.obs.view) == ("grid", "regions", "geo_sincos"), name
            else:  # an oracle imitator whose episodes include the paper's task in the wake as posed
                assert expert.algo.name == "oracle_dagger" and expert.task.posed_wake_regions_share == 1.0, name
                posed = {"angle_deg": [0.0, 0.0], "strength": [1.0, 1.0], "background": [0.0, 0.0]}
                members = expert.flow.members.values()
                assert any(m.type == "wake" and all(m[k] == v for k, v in posed.items()) for m in members), name
        else:
            assert cfgs[teacher].flow == cfg.flow and cfgs[teacher].task == cfg.task, f"{name} vs {teacher}"
        assert cfgs[teacher].obs.view != cfg.obs.view and cfg.algo.beta.initial == 0.0, name


def test_every_scene_expert_a_student_reads_is_made_by_an_experiment(experiment_cfgs):
    """Every expert file of a routed teacher (``algo.scene_*_expert``) is the output of an experiment that trains it
    (PPO, or oracle DAgger reading a view the router accepts), so a clean checkout can remake every label."""
    makers = {str(c.output_checkpoint): c for c in experiment_cfgs.values() if c.get("output_checkpoint")}
    routed = {e: c for e, c in experiment_cfgs.items() if c.algo.name == "dagger" and c.algo.get("scene_expert")}
    assert routed
    for name, cfg in routed.items():
        experts = {k: v for k, v in cfg.algo.items() if k.startswith("scene_") and k.endswith("expert") and v}
        assert "scene_expert" in experts, name
        for key, path in experts.items():
            maker = makers.get(path, experiment_cfgs.get(Path(path).stem))  # selection ships by name
            assert maker is not None, f"{name}: algo.{key}={path} is made by no experiment"
            assert maker.algo.name in ("ppo", "oracle_dagger"), f"{name}: {key}"
            if maker.algo.name == "oracle_dagger":
                assert maker.obs.view in ("geo_priv", "geo_priv_wake"), f"{name}: {key} reads {maker.obs.view}"


def unweighted(cfg) -> dict:
    """A flow or task config without what only weights its draws (member weights, shares)."""
    drop = (
        "weight",
        "regions_share",
        "posed_wake_regions_share",
        "posed_wake_any_start_share",
        "posed_wake_any_start_box",  # a box inside the family's domain: it weights where those starts lie
        "posed_wake_reverse_share",
        "full_speed_share",
        "vertical_share",  # exactly vertical currents: directions inside the family's sphere, drawn more often
    )
    if not isinstance(cfg, Mapping):
        return cfg
    return {k: unweighted(v) for k, v in cfg.items() if k not in drop}


def test_beta_schedule_and_loss():
    class A:
        class beta:
            initial, decay = 1.0, 0.5

    assert [beta_at(A, i) for i in range(3)] == [1.0, 0.5, 0.25]
    constant = {"lr": 1e-3, "lr_final": None, "iterations": 5}
    assert [lr_at(constant, i) for i in range(5)] == [1e-3] * 5
    falling = constant | {"lr_final": 2e-4}
    assert [lr_at(falling, i) for i in range(5)] == pytest.approx([1e-3, 8e-4, 6e-4, 4e-4, 2e-4])
    pred, target = torch.zeros(4, 3), torch.ones(4, 3)
    assert float(imitation_loss(pred, target)) == pytest.approx(3.0)  # eq. 9 sums over the 3 action components


@pytest.fixture(scope="module")
def tiny_run(teacher_ckpt, tmp_path_factory):
    """Five DAgger iterations on the tiny problem: (run directory, final metrics)."""
    import train

    run_dir = tmp_path_factory.mktemp("dagger") / "run"
    return run_dir, train.run(make_cfg(teacher_ckpt, "algo.iterations=5"), run_dir)


def test_dagger_learns_the_teacher(tiny_run):
    run_dir, final = tiny_run
    out = run_dir / "checkpoints" / "last.pt"
    assert json.loads((run_dir / "results.json").read_text())["curve"][-1]["iteration"] == 5
    losses = [float(r["train/loss"]) for r in rows(run_dir)]
    onpolicy = [float(r["train/loss_onpolicy"]) for r in rows(run_dir)]
    assert losses[-1] < 0.6 * losses[0] and onpolicy[-1] < 0.7 * max(onpolicy[:2])
    assert final["eval/teacher_success_rate"] > 0.9
    assert final["eval/student_success_rate"] >= final["eval/teacher_success_rate"] - 0.1
    policy, payload = load_policy(out, expect_obs="ego")
    assert payload["role"] == "student" and policy.config["n_outputs"] == 3
    # The normaliser holds the statistics of all aggregated observations.
    obs = payload["train_state"]["buffer"]["obs"]  # the filled part of the buffer, in last.pt
    assert len(obs) == 5 * 64 * 60
    assert obs.untyped_storage().nbytes() == obs.numel() * obs.element_size()  # not the buffer's whole capacity
    assert torch.allclose(policy.normalizer.mean, obs.mean(0), atol=1e-4)
    assert torch.allclose(policy.normalizer.var, obs.var(0, unbiased=False), rtol=1e-3)


def test_the_capacity_probe_refits_a_runs_labels(tiny_run, capsys):
    """scripts/student_capacity.py refits the run's saved pairs from scratch: on the tiny problem a network of the
    run's size, fitted a little longer than the run fitted it (1,200 Adam steps against 5 x 150), imitates the
    teacher on held-out pairs about as well as the run's own student on its pairs."""
    from load import load_module

    probe = load_module("scripts/student_capacity.py")
    run_dir, _ = tiny_run
    args = ["--hidden", "64,64", "--steps", "1200", "--reports", "3", "--threads", "1"]  # the tests' thread count
    probe.main([str(run_dir / "checkpoints" / "last.pt"), *args])
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "19,200 pairs: 17,280 fitted, 1,920 held out; 1200 steps per network"
    held_out = [float(line.split("held out ")[1].split()[0]) for line in lines[1:]]
    assert len(held_out) == 3 and held_out[0] > held_out[1] > held_out[2]
    assert held_out[-1] < 1.1 * float(rows(run_dir)[-1]["train/loss"])


def test_resume_continues_exactly(teacher_ckpt, tmp_path):
    import train

    quick = [
        "algo.updates_per_iteration=10",
        "algo.steps_per_iteration=20",
        "algo.final_eval_episodes=0",
        "checkpoint_every=1",
    ]
    train.run(make_cfg(teacher_ckpt, *quick, "algo.iterations=3"), tmp_path / "straight")
    train.run(make_cfg(teacher_ckpt, *quick, "algo.iterations=2"), tmp_path / "part")
    train.run(make_cfg(teacher_ckpt, *quick, "algo.iterations=3", f"resume={tmp_path / 'part'}"), tmp_path / "x")
    a, b = rows(tmp_path / "straight"), rows(tmp_path / "part")
    assert len(b) == 3
    assert [r["train/loss"] for r in a] == [r["train/loss"] for r in b]  # as written, digit for digit
    pa = load_checkpoint(tmp_path / "straight" / "checkpoints" / "last.pt")["policy"]["state_dict"]
    pb = load_checkpoint(tmp_path / "part" / "checkpoints" / "last.pt")["policy"]["state_dict"]
    assert all(torch.equal(pa[k], pb[k]) for k in pa)


def test_a_resume_with_another_teacher_is_refused(teacher_ckpt, tmp_path):
    """Every label of a run's aggregated data comes from its one teacher: a resume that names another file (same view,
    other weights) is refused; the same teacher moved elsewhere resumes."""
    import shutil

    import train

    quick = ["algo.updates_per_iteration=2", "algo.steps_per_iteration=5", "algo.final_eval_episodes=0"]
    train.run(make_cfg(teacher_ckpt, *quick, "algo.iterations=1"), tmp_path / "run")
    other = tmp_path / "other.pt"
    payload = load_checkpoint(teacher_ckpt)
    policy, _ = load_policy(teacher_ckpt)
    with torch.no_grad():
        policy.net[0].bias.add_(0.1)
    save_policy_checkpoint(other, policy, payload["obs"], "teacher")
    resume = [*quick, "algo.iterations=2", f"resume={tmp_path / 'run'}"]
    with pytest.raises(ConfigError, match=rf"^resume=.*: teacher_checkpoint={other} is not the run's \(it was "):
        train.run(make_cfg(other, *resume), tmp_path / "x")
    moved = shutil.copy(teacher_ckpt, tmp_path / "moved.pt")
    train.run(make_cfg(moved, *resume), tmp_path / "y")
    assert load_checkpoint(tmp_path / "run" / "checkpoints" / "last.pt")["train_state"]["iteration"] == 2


def test_teacher_of_the_wrong_view_is_refused(tmp_path):
    import train
    from flownav.agents import DeterministicPolicy
    from flownav.evaluation.scripted import ACTION_LOW, action_high

    ego = tmp_path / "ego_teacher.pt"
    save_policy_checkpoint(ego, DeterministicPolicy(6, ACTION_LOW, action_high(), hidden=(8,)), "ego", "baseline")
    with pytest.raises(CheckpointError, match=r"reads 'ego'; a DAgger teacher reads a geo view"):
        train.run(make_cfg(ego, "algo.iterations=1"), tmp_path / "run")
    with pytest.raises(CheckpointError, match=r"reading 'ego'.*needs 'geo'"):  # a pinned view must match
        train.run(make_cfg(ego, "algo.iterations=1", "algo.teacher_view=geo"), tmp_path / "run")
    with pytest.raises(CheckpointError, match="no checkpoint"):
        train.run(make_cfg(tmp_path / "nothing.pt", "algo.iterations=1"), tmp_path / "run2")


def test_a_reverse_expert_without_the_scene_expert_is_refused(teacher_ckpt, tmp_path):
    import train

    cfg = make_cfg(teacher_ckpt, "algo.iterations=1", f"algo.scene_reverse_expert={teacher_ckpt}")
    with pytest.raises(ConfigError, match=r"^algo.scene_reverse_expert needs algo.scene_expert"):
        train.run(cfg, tmp_path / "run")
    cfg = make_cfg(teacher_ckpt, "algo.iterations=1", "algo.scene_currents=all")
    with pytest.raises(ConfigError, match=r"^algo.scene_currents needs algo.scene_expert"):
        train.run(cfg, tmp_path / "run")
    cfg = make_cfg(teacher_ckpt, "algo.iterations=1", "algo.scene_free_flows=compensating")
    with pytest.raises(ConfigError, match=r"^algo.scene_free_flows needs algo.scene_expert"):
        train.run(cfg, tmp_path / "run")


def test_beta_one_executes_the_teacher(teacher_ckpt):
    from flownav.agents import DeterministicPolicy
    from flownav.agents.mixture import TeacherStudentMixture
    from flownav.algorithms.dagger import make_collector
    from flownav.envs import NavigationEnv, RegionTask
    from flownav.episode_window import EpisodeWindow
    from flownav.evaluation.scripted import ACTION_LOW, action_high
    from flownav.flows import Box, UniformFlow

    teacher, _ = load_policy(teacher_ckpt, expect_obs="geo")
    torch.manual_seed(0)
    student = DeterministicPolicy(6, ACTION_LOW, action_high(), hidden=(8,)).eval()
    task = RegionTask(Box((5.0, 0.0, 5.0), (6.0, 1.0, 6.0)), Box((7.0, 0.0, 5.0), (8.0, 1.0, 6.0)))
    stats = {}
    for beta in (0.0, 1.0):
        # A time limit of the collection's 60 steps: every first episode ends inside it, so both betas are scored.
        env = NavigationEnv(
            UniformFlow((0.1, 0.0, 0.0)), task, num_envs=64, views=("ego", "geo"), seed=0, time_limit=12.0
        )
        mixture = TeacherStudentMixture(student, teacher, "ego", "geo", seed=0)
        mixture.beta = beta
        batch = next(iter(make_collector(env, mixture, 60, seed=0)))
        assert batch["ego"].shape == (64, 60, 6) and batch["teacher_action"].shape == (64, 60, 3)
        with torch.no_grad():  # one call on [64, 60, d] instead of 60 on [64, d]: equal up to float rounding
            executed = teacher(batch["geo"]) if beta else student(batch["ego"])
            torch.testing.assert_close(batch["action"], executed, rtol=1e-5, atol=1e-6)
            torch.testing.assert_close(batch["teacher_action"], teacher(batch["geo"]), rtol=1e-5, atol=1e-6)
        window = EpisodeWindow()
        window.add(batch["next"])
        stats[beta] = window.pop()
        assert stats[beta]["train/episodes"] >= 64
    assert stats[1.0]["train/success_rate"] > 0.9 > stats[0.0]["train/success_rate"]


def test_final_evaluation_is_the_protocols(teacher_ckpt, tmp_path):
    """DAgger's final evaluation of the student (last.pt) and of its teacher is protocol.evaluate on one spec."""
    import train
    from flownav.algorithms.common import eval_metrics
    from flownav.builders import build_flow, build_task
    from flownav.evaluation.protocol import EvalSpec, evaluate

    cfg = make_cfg(teacher_ckpt, "algo.iterations=1", "algo.updates_per_iteration=20", "algo.final_eval_episodes=200")
    final = train.run(cfg, tmp_path)
    flow = build_flow(cfg.flow)
    spec = EvalSpec(flow, build_task(cfg.task, flow), cfg.env, 200)
    for name, path, view in (
        ("student", tmp_path / "checkpoints" / "last.pt", "ego"),
        ("teacher", teacher_ckpt, "geo"),
    ):
        summary = evaluate(load_policy(path, expect_obs=view)[0], view, spec).summary
        assert 0 < summary["successes"] <= summary["episodes"] and summary["episodes"] == 200
        assert name == "teacher" or summary["successes"] < 200  # the student after one iteration: not all
        expected = eval_metrics(summary, prefix=f"eval/{name}_")
        assert {k: final[k] for k in expected} == expected
