"""Faults: non-finite values stop with a named error and never reach a checkpoint; a run interrupted mid-way
resumes bit for bit; quick tries and refused resumes leave shipped files and other directories untouched."""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path
from unittest import mock

import pytest
import torch
from hydra import compose, initialize_config_dir
from tiny import DRIFT_TASK, compose_train

from flownav.checkpoint import load_checkpoint, save_policy_checkpoint
from flownav.envs import NavigationEnv, RegionTask
from flownav.envs.reward import RewardConfig
from flownav.errors import ConfigError, NonFiniteError
from flownav.flows import Box, FunctionFlow, UniformFlow
from flownav.provenance import tree_digest

ROOT = Path(__file__).resolve().parents[1]
CONF = str(ROOT / "conf")
TASK = RegionTask(Box((5.0, 0.0, 5.0), (6.0, 1.0, 6.0)), Box((7.0, 0.0, 5.0), (8.0, 1.0, 6.0)))
QUIET = ["logger=csv", "logger.progress=false", "threads=1"]
# PPO on the analytic wake: episodes (60 steps) span several batches (16 steps), the flow's phase is random.
PPO_TINY = [
    "+experiment=teacher",
    "flow=vortex_street",
    "env.num_envs=128",
    "env.dt=0.5",
    "env.time_limit=30.0",
    "algo.rollout_steps=16",
    "algo.epochs=2",
    "algo.minibatch_size=512",
    "algo.actor.hidden=[32,32]",
    "algo.critic.hidden=[32,32]",
    "algo.final_eval_episodes=0",
    "algo.eval_every=0",
    "checkpoint_every=1",
    *QUIET,
]


SHIPPED = (ROOT / "checkpoints", ROOT / "results", ROOT / "REPORT.md")


@pytest.fixture(scope="module")
def teacher_ckpt(tmp_path_factory):
    from flownav.evaluation.scripted import HeadToTarget, fit_expert

    policy, _ = fit_expert(HeadToTarget(), hidden=(32, 32), steps=300, batch=512, seed=0)
    path = tmp_path_factory.mktemp("teacher") / "teacher.pt"
    save_policy_checkpoint(path, policy, "geo", "teacher")
    return path


def dagger_cfg(teacher, *overrides):
    return compose_train(
        "+experiment=student",
        *DRIFT_TASK,
        "algo.num_envs=32",
        "algo.steps_per_iteration=20",
        "algo.updates_per_iteration=10",
        "algo.batch_size=128",
        "algo.buffer_capacity=1500",  # smaller than the 5 x 640 pairs: the FIFO wraps before the interruption
        "algo.hidden=[32,32]",
        "algo.final_eval_episodes=0",
        "checkpoint_every=1",
        f"teacher_checkpoint={teacher}",
        *QUIET,
        *overrides,
    )


# ----------------------------------------------------------------------------- non-finite values


def bypass_validation(monkeypatch, trainer) -> None:
    """Switch off the up-front config checks (the trainer's and the schema's) so a bad value reaches the run."""
    from flownav import schema

    monkeypatch.setattr(trainer, "check_config", lambda cfg: None)
    for name in ("check_flow", "check_task", "check_env"):
        monkeypatch.setattr(schema, name, lambda *args, **kwargs: None)


def test_nan_action_is_refused_by_name(wake_like_flow):
    env = NavigationEnv(wake_like_flow, num_envs=8, views=("geo",))
    td = env.reset()
    td["action"] = torch.full((8, 3), 0.5)
    td["action"][3, 1] = math.nan
    with pytest.raises(NonFiniteError, match=r"the action is not finite for 1 of 8 swimmers \(swimmer 3"):
        env.step(td)


def test_user_flow_with_nan_in_part_of_the_domain_is_refused():
    def fn(pos, t):  # a user's flow, broken beyond x = 6.5
        v = torch.zeros_like(pos)
        v[:, 0] = torch.where(pos[:, 0] > 6.5, math.nan, 0.2)
        return v

    flow = FunctionFlow(fn, Box((0.0, -5.0, 0.0), (20.0, 5.0, 10.0)), max_speed=1.0)
    env = NavigationEnv(flow, TASK, num_envs=16, views=("geo",), dt=0.5)
    td = env.reset()
    first_bad = r"flow velocity is not finite for \d+ of 16 swimmers \(swimmer \d+ at position \[6\.[5-9]"
    with pytest.raises(NonFiniteError, match=first_bad):
        for _ in range(20):  # swim towards x = 7..8: the first swimmer past x = 6.5 stops the run
            td["action"] = torch.tensor([[1.0, 0.0, 0.0]]).expand(16, 3).clone()
            td = env.step(td)["next"]


def test_non_finite_reward_is_refused():
    env = NavigationEnv(
        UniformFlow((0.0, 0.0, 0.0)), TASK, num_envs=4, views=("geo",), reward=RewardConfig(alpha=math.nan)
    )
    td = env.reset()
    td["action"] = torch.full((4, 3), 0.5)
    with pytest.raises(NonFiniteError, match=r"the reward is not finite for 4 of 4 .*env\.reward"):
        env.step(td)


def test_ppo_stops_on_a_non_finite_reward_and_writes_no_checkpoint(tmp_path, monkeypatch):
    from flownav.algorithms import ppo

    bypass_validation(monkeypatch, ppo)  # as a bug would
    cfg = compose_train(*PPO_TINY, "algo.total_frames=4096", "env.reward.success_bonus=inf")
    with pytest.raises(NonFiniteError, match="reward"):
        ppo.train(cfg, tmp_path)
    assert not (tmp_path / "checkpoints").exists()


def test_ppo_stops_on_a_non_finite_optimiser_setting(tmp_path, monkeypatch):
    from flownav.algorithms import ppo

    bypass_validation(monkeypatch, ppo)
    cfg = compose_train(*PPO_TINY, "algo.total_frames=4096", "algo.lr=inf")
    with pytest.raises(NonFiniteError, match=r"PPO iteration 1: .* became NaN or infinite; training stopped"):
        ppo.train(cfg, tmp_path)
    assert not (tmp_path / "checkpoints" / "last.pt").exists()


def test_ppo_stops_on_a_non_finite_update_and_keeps_the_last_finite_checkpoint(tmp_path, monkeypatch):
    import train
    from flownav.algorithms import ppo

    train.run(compose_train(*PPO_TINY, "algo.total_frames=4096"), tmp_path)  # 2 iterations of 128 x 16
    last = tmp_path / "checkpoints" / "last.pt"
    before = last.read_bytes()
    bypass_validation(monkeypatch, ppo)
    cfg = compose_train(*PPO_TINY, "algo.total_frames=8192", "algo.lr=inf", f"resume={tmp_path}")
    with pytest.raises(
        NonFiniteError, match=rf"PPO iteration 3: .*\(the last finite checkpoint is {re.escape(str(last))}\)"
    ):
        ppo.train(cfg, tmp_path)
    assert last.read_bytes() == before  # iteration 2, finite
    assert load_checkpoint(last)["train_state"]["iteration"] == 2


def test_dagger_stops_on_grad_clip_nan_and_keeps_the_last_finite_checkpoint(teacher_ckpt, tmp_path, monkeypatch):
    import train
    from flownav.algorithms import dagger

    train.run(dagger_cfg(teacher_ckpt, "algo.iterations=2"), tmp_path)
    bypass_validation(monkeypatch, dagger)
    last = tmp_path / "checkpoints" / "last.pt"
    before = last.read_bytes()
    cfg = dagger_cfg(teacher_ckpt, "algo.iterations=4", "algo.grad_clip=nan", f"resume={tmp_path}")
    with pytest.raises(
        NonFiniteError, match=rf"DAgger iteration 3: .*\(the last finite checkpoint is {re.escape(str(last))}\)"
    ):
        dagger.train(cfg, tmp_path)
    assert last.read_bytes() == before  # iteration 2, finite
    assert load_checkpoint(last)["train_state"]["iteration"] == 2


def test_a_non_finite_checkpoint_is_never_written(tmp_path):
    from flownav.agents import DeterministicPolicy

    policy = DeterministicPolicy(8, [0.0, -0.7, -1.5], [1.0, 0.7, 1.5], hidden=(8,))
    with torch.no_grad():
        policy.net[0].weight[0, 0] = math.nan
    with pytest.raises(NonFiniteError, match=r"refusing to write .*x\.pt: policy\.state_dict\.net\.0\.weight"):
        save_policy_checkpoint(tmp_path / "x.pt", policy, "geo", "teacher")
    assert not any(tmp_path.iterdir())
    # A non-finite file made some other way is never read: not shipped (copied to checkpoints/), evaluated or taught.
    from flownav.checkpoint import FORMAT, ship_checkpoint

    payload = {"format": FORMAT, "obs": "geo", "role": "teacher", "meta": {}, "train_state": {"frames": 1}}
    torch.save(payload | {"policy": {"config": policy.config, "state_dict": policy.state_dict()}}, tmp_path / "nan.pt")
    with pytest.raises(NonFiniteError, match=r"nan\.pt has NaN or infinity in policy\.state_dict\.net\.0\.weight;"):
        ship_checkpoint(tmp_path / "nan.pt", tmp_path / "shipped.pt")
    assert not (tmp_path / "shipped.pt").exists()


# ----------------------------------------------------------------------------- exact resume
class Interrupt(RuntimeError):
    pass


def interrupt_at(monkeypatch, module, k):
    """Fail the run right after the update of iteration k (before that iteration's checkpoint)."""
    check = module.require_finite_update

    def failing(trainer, iteration, *args, **kwargs):
        check(trainer, iteration, *args, **kwargs)
        if iteration == k:
            raise Interrupt(f"injected failure at iteration {k}")

    monkeypatch.setattr(module, "require_finite_update", failing)


def train_rows(metrics_csv: Path) -> list[dict]:
    """The training episodes' columns (train/...) of every row of a run's metrics.csv."""
    with open(metrics_csv, newline="") as f:
        return [{k: v for k, v in r.items() if k.startswith("train/")} for r in csv.DictReader(f)]


def max_weight_difference(a: Path, b: Path) -> float:
    # weights_only: a run's whole last.pt (env state, buffer, sampler) loads without unpickling code
    sa, sb = (torch.load(p, weights_only=True)["policy"]["state_dict"] for p in (a, b))
    return max(float((sa[k].double() - sb[k].double()).abs().max()) for k in sa)


def test_ppo_resumes_bit_for_bit_after_a_failure(tmp_path, monkeypatch):
    import train
    from flownav.algorithms import ppo

    budget = "algo.total_frames=10240"  # 5 iterations of 128 x 16
    train.run(compose_train(*PPO_TINY, budget), tmp_path / "straight")
    with monkeypatch.context() as m:
        interrupt_at(m, ppo, 3)
        with pytest.raises(Interrupt):
            train.run(compose_train(*PPO_TINY, budget), tmp_path / "part")
    assert load_checkpoint(tmp_path / "part" / "checkpoints" / "last.pt")["train_state"]["iteration"] == 2
    train.run(compose_train(*PPO_TINY, budget, f"resume={tmp_path / 'part'}"), tmp_path / "unused")
    a, b = tmp_path / "straight" / "checkpoints" / "last.pt", tmp_path / "part" / "checkpoints" / "last.pt"
    print(f"\nPPO resume: max |difference| of the final weights = {max_weight_difference(a, b)}")  # pytest -s
    assert max_weight_difference(a, b) == 0.0
    ca, cb = (load_checkpoint(p)["train_state"]["critic"] for p in (a, b))
    assert all(torch.equal(ca[k], cb[k]) for k in ca)
    # Episodes span batches (60 steps, 16 per batch): those in flight at the checkpoint kept their running returns.
    ra, rb = (train_rows(tmp_path / run / "metrics.csv") for run in ("straight", "part"))
    assert len(ra) == 5 and ra == rb and all(r["train/episodes"] != "0.0" for r in ra)
    assert not (tmp_path / "unused").exists()


def test_an_anchored_ppo_run_resumes_bit_for_bit_and_only_with_its_anchor(tmp_path, monkeypatch):
    """algo.anchor_coeff: the anchor is reloaded from algo.init_from on a resume, so the run continues exactly; a
    different file at that path is refused in one line."""
    import shutil

    import train
    from flownav.algorithms import ppo
    from flownav.provenance import sha256

    train.run(compose_train(*PPO_TINY, "algo.total_frames=2048"), tmp_path / "start")
    anchor = tmp_path / "anchor.pt"
    shutil.copy(tmp_path / "start" / "checkpoints" / "last.pt", anchor)
    anchored = ("algo.total_frames=6144", f"algo.init_from={anchor}", "algo.anchor_coeff=1.0")  # 3 iterations
    train.run(compose_train(*PPO_TINY, *anchored), tmp_path / "straight")
    with monkeypatch.context() as m:
        interrupt_at(m, ppo, 2)
        with pytest.raises(Interrupt):
            train.run(compose_train(*PPO_TINY, *anchored), tmp_path / "part")
    resume = compose_train(*PPO_TINY, *anchored, f"resume={tmp_path / 'part'}")
    started = sha256(anchor)
    shutil.copy(tmp_path / "straight" / "checkpoints" / "last.pt", anchor)
    message = (
        f"algo.init_from={anchor} is not the file this run was anchored to (sha256 {started} there, "
        f"{sha256(anchor)} here): restore that file, or start a new run"
    )
    with pytest.raises(ConfigError, match=f"^{re.escape(message)}$"):
        train.run(resume, tmp_path / "unused")
    shutil.copy(tmp_path / "start" / "checkpoints" / "last.pt", anchor)
    train.run(resume, tmp_path / "unused")
    a, b = tmp_path / "straight" / "checkpoints" / "last.pt", tmp_path / "part" / "checkpoints" / "last.pt"
    assert max_weight_difference(a, b) == 0.0
    assert train_rows(tmp_path / "straight" / "metrics.csv") == train_rows(tmp_path / "part" / "metrics.csv")
    pulls = []
    for run in ("straight", "part"):
        with open(tmp_path / run / "metrics.csv", newline="") as f:
            pulls.append([float(r["loss/anchor"]) for r in csv.DictReader(f)])
    assert len(pulls[0]) == 3 and pulls[0] == pulls[1] and all(p > 0 for p in pulls[0])


def test_dagger_resumes_bit_for_bit_after_a_failure(teacher_ckpt, tmp_path, monkeypatch):
    import train
    from flownav.algorithms import dagger

    budget = ("algo.iterations=5", "algo.lr_final=2e-4")  # the learning rate falls: the resume must continue it
    train.run(dagger_cfg(teacher_ckpt, *budget), tmp_path / "straight")
    with monkeypatch.context() as m:
        interrupt_at(m, dagger, 4)
        with pytest.raises(Interrupt):
            train.run(dagger_cfg(teacher_ckpt, *budget), tmp_path / "part")
    part = load_checkpoint(tmp_path / "part" / "checkpoints" / "last.pt")["train_state"]
    assert part["iteration"] == 3 and len(part["buffer"]["obs"]) == 1500  # one file, the filled part
    train.run(dagger_cfg(teacher_ckpt, *budget, f"resume={tmp_path / 'part'}"), tmp_path / "unused")
    with open(tmp_path / "part" / "metrics.csv") as f:
        lrs = [float(row["lr"]) for row in csv.DictReader(f)]
    assert lrs == pytest.approx([1e-3, 8e-4, 6e-4, 4e-4, 2e-4])
    a, b = tmp_path / "straight" / "checkpoints" / "last.pt", tmp_path / "part" / "checkpoints" / "last.pt"
    print(f"\nDAgger resume: max |difference| of the final weights = {max_weight_difference(a, b)}")  # pytest -s
    assert max_weight_difference(a, b) == 0.0
    assert not list((tmp_path / "part" / "checkpoints").glob("buffer*"))


# ----------------------------------------------------------------------------- never overwritten
STUDENT_SMOKE = [
    "+experiment=student",
    "flow=vortex_street",
    "algo.iterations=1",
    "algo.num_envs=16",
    "algo.steps_per_iteration=10",
    "algo.updates_per_iteration=2",
    "algo.batch_size=64",
    "algo.final_eval_episodes=0",
    *QUIET,
]


@pytest.mark.slow
def test_smoke_runs_leave_shipped_files_byte_identical(tmp_path):
    """A one-iteration student and a 50-episode paper evaluation, as a user types them: all in their run dirs."""
    before = tree_digest(*SHIPPED)
    env = os.environ | {"OMP_NUM_THREADS": "1"}
    train_run = tmp_path / "train"
    subprocess.run(
        [sys.executable, "train.py", *STUDENT_SMOKE, f"hydra.run.dir={train_run}"], cwd=ROOT, env=env, check=True
    )
    eval_run = tmp_path / "eval"
    subprocess.run(
        [sys.executable, "evaluate.py", "+experiment=paper_training", "max_episodes=50", "flow=vortex_street"]
        + [f"hydra.run.dir={eval_run}"],
        cwd=ROOT,
        env=env,
        check=True,
    )
    assert tree_digest(*SHIPPED) == before
    assert (train_run / "checkpoints" / "last.pt").is_file() and (train_run / "results.json").is_file()
    assert (eval_run / "REPORT.md").is_file() and (eval_run / "paper.json").is_file()


def test_shipping_a_partial_run_is_refused_before_anything_is_written(tmp_path):
    import evaluate
    import train
    from flownav.shipping import train_targets

    cfg = compose_train(*STUDENT_SMOKE, "ship=true", f"output_checkpoint={tmp_path / 's.pt'}")
    with pytest.raises(ConfigError, match=r"^shipping refused: algo\.iterations=1 is below experiment student's 30 "):
        train.run(cfg, tmp_path / "run")
    assert not (tmp_path / "run").exists() and not (tmp_path / "s.pt").exists()
    with pytest.raises(ConfigError, match=r"^ship=true in a -m sweep: the seeds would race for one file"):
        train_targets(compose_train("+experiment=student", "ship=true"), multirun=True)
    # A run stopped (or resumed but not finished) before its budget: its last.pt is never shipped.
    from omegaconf import OmegaConf

    from flownav.agents import DeterministicPolicy
    from flownav.shipping import ship_run

    full = OmegaConf.to_container(compose_train("+experiment=student"), resolve=True)
    stopped = tmp_path / "stopped"
    policy = DeterministicPolicy(6, [0.0, -0.7, -1.5], [1.0, 0.7, 1.5], hidden=(8,))
    save_policy_checkpoint(
        stopped / "checkpoints" / "last.pt", policy, "ego", "student", {"config": full}, {"iteration": 7}
    )
    with pytest.raises(
        ConfigError, match=r"last\.pt stopped at iteration 7 of algo\.iterations=30 \(an unfinished run\)"
    ):
        ship_run(stopped, {"checkpoint": str(tmp_path / "s.pt")})
    assert not (tmp_path / "s.pt").exists()

    before = tree_digest(*SHIPPED)
    with initialize_config_dir(config_dir=str(ROOT / "conf" / "evaluate"), version_base="1.3"):
        ecfg = compose("config", overrides=["+experiment=paper_training", "max_episodes=50", "report=REPORT.md"])
    with pytest.raises(ConfigError, match=r"^max_episodes=50 caps the episode count: a reduced run never writes"):
        evaluate.run(ecfg, log=lambda *_: None)
    assert tree_digest(*SHIPPED) == before


def test_shipping_without_a_checkpoint_the_shipped_results_have_is_refused(tmp_path):
    """An entry is rewritten whole: shipping it without one of its policies would drop that policy's shipped rows."""
    import evaluate

    absent = tmp_path / "absent.pt"
    before = tree_digest(*SHIPPED)
    with initialize_config_dir(config_dir=str(ROOT / "conf" / "evaluate"), version_base="1.3"):
        ecfg = compose(
            "config", overrides=["+experiment=paper_training", "ship=true", f"policies.student.checkpoint={absent}"]
        )
    with pytest.raises(
        ConfigError,
        match=r"^missing checkpoint .*absent\.pt: run `python train.py \+experiment=student`; "
        r".*paper\.json has student's rows of training, which this run would drop: restore it",
    ):
        evaluate.run(ecfg, log=lambda *_: None)
    assert tree_digest(*SHIPPED) == before
    # a policy the shipped entry never had is no loss: nothing refused
    ecfg.results = str(tmp_path / "paper.json")
    (tmp_path / "paper.json").write_text(json.dumps({"experiments": {"training": {"policies": {"teacher": {}}}}}))
    evaluate.refuse_dropping_shipped_rows(ecfg)


@pytest.mark.slow
@pytest.mark.parametrize(
    "args, message",
    [
        (
            ["suite.training.episodes=50"],
            "error: suite.training.episodes=50 changes an experiment's episode count: only the counts in ",
        ),
        (
            ["+suite.training.policy_episodes.passive=5"],
            "error: +suite.training.policy_episodes.passive=5 changes an experiment's episode count: only the counts ",
        ),
        (["seed=0,1"], "error: a -m sweep writing results/paper.json: its jobs would race for one file; "),
    ],
    ids=["episodes_override", "policy_episodes_override", "sweep"],
)
def test_shipping_an_evaluation_is_refused_for_changed_counts_and_in_a_sweep(args, message, tmp_path):
    """ship=true writes REPORT.md and results/ only with the experiments' own episode counts, from one run."""
    before = tree_digest(*SHIPPED)
    sweep = any("," in a for a in args)
    cmd = [sys.executable, "evaluate.py", *(["-m"] if sweep else []), "+experiment=paper_training", "ship=true", *args]
    cmd.append(f"hydra.{'sweep' if sweep else 'run'}.dir={tmp_path}")
    out = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert out.stderr.strip().splitlines()[-1].startswith(message)
    assert tree_digest(*SHIPPED) == before


def test_ship_copies_a_finished_run_without_its_resume_state(tmp_path, monkeypatch):
    """ship=true at the experiment's budget (shrunk here) copies the policy (no env state, no buffer) and record."""
    import train
    from flownav import shipping

    tiny_budget = {"iterations": 1, "num_envs": 16, "steps_per_iteration": 10, "updates_per_iteration": 2}
    monkeypatch.setattr(shipping, "experiment_budget", lambda name, algo: tiny_budget | {"final_eval_episodes": 0})
    out, record = tmp_path / "ship" / "student.pt", tmp_path / "ship" / "student.json"
    final = train.run(
        compose_train(*STUDENT_SMOKE, "ship=true", f"output_checkpoint={out}", f"algo.results_json={record}"),
        tmp_path / "run",
    )
    assert final["shipped"] == {"checkpoint": str(out), "results": str(record)}
    shipped, last = load_checkpoint(out), load_checkpoint(tmp_path / "run" / "checkpoints" / "last.pt")
    assert {"env", "buffer"} <= set(last["train_state"]) and not {"env", "buffer"} & set(shipped["train_state"])
    assert all(torch.equal(shipped["policy"]["state_dict"][k], v) for k, v in last["policy"]["state_dict"].items())
    assert record.read_bytes() == (tmp_path / "run" / "results.json").read_bytes()


def test_ship_refuses_a_finished_run_that_fails_its_experiments_checks(tmp_path, monkeypatch):
    """ship=true evaluates the experiment's ship_requires first: a failed check ships nothing, names check and rate."""
    import train
    from flownav import shipping

    tiny_budget = {"iterations": 1, "num_envs": 16, "steps_per_iteration": 10, "updates_per_iteration": 2}
    monkeypatch.setattr(shipping, "experiment_budget", lambda name, algo: tiny_budget | {"final_eval_episodes": 0})
    headwind = ["flow=uniform", "flow.velocity=[0.0,1.5,0.0]", "task=regions", "env.time_limit=10.0"]  # no one arrives
    monkeypatch.setattr(
        shipping, "experiment_requirements", lambda name: {"headwind": {"overrides": headwind, "min_success": 0.5}}
    )
    out = tmp_path / "ship" / "student.pt"
    cfg = compose_train(*STUDENT_SMOKE, "ship=true", f"output_checkpoint={out}")
    with pytest.raises(ConfigError) as refused:
        train.run(cfg, tmp_path / "run")
    last = tmp_path / "run" / "checkpoints" / "last.pt"
    assert str(refused.value) == (
        f"shipping refused: {last} fails experiment student's ship_requires: headwind (0.0000 < 0.5) "
        "(conf/experiment/student.yaml); nothing was shipped"
    )
    assert last.is_file() and not out.exists()


# ----------------------------------------------------------------------------- resume is safe
def test_resume_accepts_only_a_run_directory_and_writes_nothing_before_its_checks(tmp_path):
    import train

    before = tree_digest(*SHIPPED)
    cfg = compose_train(*STUDENT_SMOKE, f"resume={ROOT / 'checkpoints' / 'teacher.pt'}")
    with pytest.raises(ConfigError, match=r"is not a run directory \(no config\.yaml\); pass the directory of the run"):
        train.run(cfg, tmp_path / "run")
    with pytest.raises(ConfigError, match=r"no such run directory"):
        train.run(compose_train(*STUDENT_SMOKE, f"resume={tmp_path / 'nothing'}"), tmp_path / "run")
    # A run directory whose last.pt is a shipped policy (no training state): refused, nothing written into it.
    fake = tmp_path / "fake"
    (fake / "checkpoints").mkdir(parents=True)
    (fake / "config.yaml").write_text("name: student\n")
    policy_file = fake / "checkpoints" / "last.pt"
    policy_file.write_bytes((ROOT / "checkpoints" / "student.pt").read_bytes())
    with pytest.raises(ConfigError, match=r"holds no training state to resume from \(no .*env"):
        train.run(compose_train(*STUDENT_SMOKE, f"resume={policy_file}"), tmp_path / "run")
    assert sorted(p.name for p in fake.rglob("*")) == ["checkpoints", "config.yaml", "last.pt"]
    assert not (tmp_path / "run").exists() and tree_digest(*SHIPPED) == before


def test_a_resume_with_other_settings_is_refused_before_anything_is_written(tmp_path):
    """A resume continues its run with the run's settings: another env size (which used to end in a ValueError
    traceback from the env state) or network is one line naming the keys, and the run directory is left as it was;
    the budget may change."""
    import train

    run = tmp_path / "run"
    train.run(compose_train(*PPO_TINY, "algo.total_frames=2048"), run)  # one iteration of 128 x 16
    files = {p: p.read_bytes() for p in run.rglob("*") if p.is_file()}
    for override, message in (
        ("env.num_envs=64", "env.num_envs=128 there, 64 here"),
        ("algo.actor.hidden=[16,16]", "algo.actor.hidden=[32, 32] there, [16, 16] here"),
        ("algo.rollout_steps=8", "algo.rollout_steps=16 there, 8 here"),
    ):
        cfg = compose_train(*PPO_TINY, "algo.total_frames=4096", override, f"resume={run}")
        with pytest.raises(ConfigError, match=re.escape(f"this config differs from the run's ({message})")):
            train.run(cfg, tmp_path / "unused")
        assert {p: p.read_bytes() for p in run.rglob("*") if p.is_file()} == files  # no config_resumed.yaml
    assert not (tmp_path / "unused").exists()


def test_a_resume_accepts_a_setting_added_since_at_its_null_default_only():
    """A run saved before a key existed resumes when that key is null (off) here, and is refused when it is set."""
    from flownav.checkpoint import check_resume_settings

    payload = {"meta": {"config": {"algo": {"lr": 0.001}}}}
    check_resume_settings("run", payload, {"algo": {"lr": 0.001, "scene_reverse_expert": None}})
    message = "algo.scene_reverse_expert=(unset) there, x.pt here"
    with pytest.raises(ConfigError, match=re.escape(message)):
        check_resume_settings("run", payload, {"algo": {"lr": 0.001, "scene_reverse_expert": "x.pt"}})
    with pytest.raises(ConfigError, match=re.escape("algo.gone=None there, (unset) here")):
        check_resume_settings("run", {"meta": {"config": {"algo": {"gone": None}}}}, {"algo": {}})


class _Parsed(Exception):
    """Raised instead of parsing: carries the command line's parser."""

    def __init__(self, parser):
        self.parser = parser


def parser_of(main) -> argparse.ArgumentParser:
    """The argparse parser a command's ``main`` builds (stopped before it parses anything)."""

    def stop(self, *args, **kwargs):
        raise _Parsed(self)

    with mock.patch.object(argparse.ArgumentParser, "parse_known_args", stop), pytest.raises(_Parsed) as e:
        main([])
    return e.value.parser


def path_defaults(parser, prefix=""):
    """(option, default) of every path-like option of a parser and its sub-commands."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from path_defaults(sub, f"{prefix}{name} ")
        elif any(w in action.dest for w in ("out", "json", "dir", "ship")) and isinstance(action.default, str | Path):
            yield f"{prefix}{action.option_strings[0] if action.option_strings else action.dest}", action.default


def test_no_command_line_default_writes_into_a_shipped_place():
    """Every output a command writes by default lies outside checkpoints/, results/, data/ and REPORT.md (and the
    README's figures, docs/figures); the shipped places are written only when an option names them."""
    from flownav.cfd import __main__ as cfd
    from flownav.evaluation import selection
    from flownav.shipping import is_shipped
    from flownav.viz import interactive, plots

    defaults = [
        d for main in (cfd.main, interactive.main, plots.main, selection.main) for d in path_defaults(parser_of(main))
    ]
    assert {"generate --run-dir", "plot --out-dir", "--out"} <= {name for name, _ in defaults}
    shipped = [(name, str(v)) for name, v in defaults if is_shipped(v) or Path(v).parts[:2] == ("docs", "figures")]
    assert shipped == []
    from flownav.export import parse_arguments

    assert parse_arguments(["checkpoint=checkpoints/student.pt"])["out"] is None  # -> exports/<name>.onnx


def test_the_budget_to_ship_includes_the_experiments_an_experiment_builds_on():
    """generalist_student_ego builds on generalist_student (whose DAgger budget differs from student's): shipping
    checks a run against the composed budget, not against the algo group's defaults."""
    from flownav.shipping import experiment_budget

    ego = experiment_budget("generalist_student_ego", "dagger")
    parent = experiment_budget("generalist_student", "dagger")
    assert ego == parent
    assert parent != experiment_budget("student_mem", "dagger")
