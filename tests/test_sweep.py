"""Many seeds, many machines: a multirun ends with a per-seed summary in its sweep directory; a run restarted in
its own directory continues from its last checkpoint; a submitit job that is preempted and requeued finishes
with exactly the result of an uninterrupted run."""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

import pytest
import torch
import yaml
from hydra import compose, initialize_config_dir
from tiny import DRIFT_TASK, TINY_PPO

from flownav.resume import resolve_resume
from flownav.sweep import summarize_sweep, write_sweep_summary

ROOT = Path(__file__).resolve().parents[1]
CONF = str(ROOT / "conf")


def _fake_job(sweep, name, overrides, final):
    job = sweep / name
    (job / ".hydra").mkdir(parents=True)
    (job / ".hydra" / "overrides.yaml").write_text(yaml.safe_dump(overrides))
    if final is not None:
        (job / "final_metrics.json").write_text(json.dumps(final))


def test_summary_groups_configs_and_picks_the_best_seed(tmp_path):
    common = ["+experiment=teacher"]
    _fake_job(tmp_path, "seed0_0", [*common, "seed=0", "algo.lr=1e-3"], {"eval/success_rate": 0.80, "frames": 100})
    _fake_job(tmp_path, "seed1_1", [*common, "seed=1", "algo.lr=1e-3"], {"eval/success_rate": 0.90, "frames": 100})
    _fake_job(tmp_path, "seed2_2", [*common, "seed=2", "algo.lr=1e-3"], {"eval/success_rate": 0.70, "frames": 100})
    _fake_job(tmp_path, "seed0_3", [*common, "seed=0", "algo.lr=3e-4"], {"eval/student_success_rate": 0.5})
    _fake_job(tmp_path, "seed1_4", [*common, "seed=1", "algo.lr=3e-4"], None)  # failed job
    s = write_sweep_summary(tmp_path)
    fast, slow = s["configs"]["algo.lr=1e-3"], s["configs"]["algo.lr=3e-4"]
    assert fast["n"] == 3 and fast["mean"] == pytest.approx(0.8) and fast["std"] == pytest.approx(0.1)
    assert (fast["best_seed"], fast["best_job"], fast["best_score"]) == (1, "seed1_1", 0.9)
    assert slow == {"n": 1, "mean": 0.5, "std": None, "best_seed": 0, "best_job": "seed0_3", "best_score": 0.5}
    assert [r["status"] for r in s["runs"]].count("done") == 4 and s["common"] == common
    assert json.loads((tmp_path / "sweep_summary.json").read_text()) == s
    md = (tmp_path / "sweep_summary.md").read_text()
    assert "| algo.lr=1e-3 | 3 | 80.00% | 10.00% | 1 | 90.00% |" in md
    assert summarize_sweep([], None)["configs"] == {}


def test_multirun_writes_sweep_summary(tmp_path):
    """Through the default launcher (joblib, two jobs side by side), as a user's -m runs."""
    sweep = tmp_path / "sweep"
    cmd = [sys.executable, "train.py", "-m", *TINY_PPO, "seed=0,1", f"hydra.sweep.dir={sweep}"]
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    s = json.loads((sweep / "sweep_summary.json").read_text())
    finals = [json.loads((sweep / r["job"] / "final_metrics.json").read_text()) for r in s["runs"]]
    scores = [f["eval/success_rate"] for f in finals]
    assert [r["seed"] for r in s["runs"]] == [0, 1] and [r["score"] for r in s["runs"]] == scores
    (group,) = s["configs"].values()
    assert group["n"] == 2 and group["mean"] == pytest.approx(statistics.fmean(scores))
    assert group["std"] == pytest.approx(statistics.stdev(scores))
    assert group["best_score"] == max(scores) and group["best_seed"] == scores.index(max(scores))
    assert "| seed0_0 | 0 | (all) |" in (sweep / "sweep_summary.md").read_text()
    for r in s["runs"]:  # each job wrote its whole run directory
        job = sweep / r["job"]
        assert (job / "metrics.csv").is_file() and (job / "checkpoints" / "last.pt").is_file()
        assert (job / "config.yaml").is_file()


def test_resume_auto_continues_the_run_directory_it_runs_in(tmp_path, monkeypatch):
    import csv

    from train import run

    monkeypatch.delenv("SUBMITIT_EXECUTOR", raising=False)
    assert resolve_resume("auto", tmp_path) is None  # nothing to continue: a fresh start
    assert resolve_resume(None, tmp_path) is None
    with initialize_config_dir(config_dir=CONF, version_base="1.3"):
        first = compose("config", overrides=[*TINY_PPO, "algo.total_frames=512", "checkpoint_every=1"])
        second = compose("config", overrides=[*TINY_PPO, "algo.total_frames=768", "checkpoint_every=1", "resume=auto"])
    run(first, tmp_path)
    assert resolve_resume("auto", tmp_path) == str(tmp_path)
    monkeypatch.setenv("SUBMITIT_EXECUTOR", "slurm")  # inside a cluster job, resume=null means auto
    assert resolve_resume(None, tmp_path) == str(tmp_path)
    monkeypatch.delenv("SUBMITIT_EXECUTOR")
    run(second, tmp_path)
    steps = [int(r["step"]) for r in csv.DictReader(open(tmp_path / "metrics.csv", newline="")) if r["loss/objective"]]
    assert steps == [256, 512, 768]  # continued at 512, each step once
    assert (tmp_path / "config_resumed.yaml").is_file()


# A Hydra callback that preempts the job once, like Slurm would: SIGUSR2 (submitit's signal) as soon as the run
# has written its first checkpoint. submitit checkpoints the job and requeues it; the marker file stops the
# requeued job from being preempted again.
PREEMPT_ONCE = """
import os, signal, threading, time
from pathlib import Path
from hydra.experimental.callback import Callback


class PreemptOnce(Callback):
    def on_job_start(self, config, **kwargs):
        run_dir = Path(config.hydra.runtime.output_dir)
        marker = run_dir / "preempted_once"
        if marker.exists():
            return

        def watch():
            while not (run_dir / "checkpoints" / "last.pt").exists():
                time.sleep(0.02)
            marker.write_text(str(os.getpid()))
            os.kill(os.getpid(), signal.SIGUSR2)

        threading.Thread(target=watch, daemon=True).start()
"""

TINY_DAGGER = [
    "+experiment=student",
    *DRIFT_TASK,
    "algo.iterations=4",
    "algo.num_envs=32",
    "algo.steps_per_iteration=40",
    "algo.updates_per_iteration=60",
    "algo.batch_size=256",
    "algo.buffer_capacity=6000",
    "algo.hidden=[32]",
    "algo.final_eval_episodes=0",
    "checkpoint_every=1",
    "logger=csv",
    "logger.progress=false",
    "threads=1",
    "output_checkpoint=null",
    "algo.results_json=null",
]


@pytest.mark.slow
def test_preempted_submitit_job_is_requeued_and_finishes_like_an_uninterrupted_run(tmp_path):
    pytest.importorskip("hydra_plugins.hydra_submitit_launcher")
    from flownav.checkpoint import load_checkpoint, save_policy_checkpoint
    from flownav.evaluation.scripted import HeadToTarget, fit_expert
    from train import run

    policy, _ = fit_expert(HeadToTarget(), hidden=(32,), steps=200, batch=512, seed=0)
    teacher = tmp_path / "teacher.pt"
    save_policy_checkpoint(teacher, policy, "geo", "teacher")
    overrides = [*TINY_DAGGER, f"teacher_checkpoint={teacher}"]

    (tmp_path / "preempt_once.py").write_text(PREEMPT_ONCE)
    sweep = tmp_path / "sweep"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), str(ROOT), os.environ.get("PYTHONPATH", "")])}
    cmd = [
        sys.executable,
        "train.py",
        "-m",
        "hydra/launcher=submitit_local",
        "hydra.launcher.timeout_min=60",  # far from the limit: the signal is a preemption, not a time-out
        "+hydra.callbacks.preempt._target_=preempt_once.PreemptOnce",
        *overrides,
        "seed=0",
        f"hydra.sweep.dir={sweep}",
    ]
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    job_dir = sweep / "seed0_0"
    assert (job_dir / "preempted_once").is_file()  # it was preempted ...
    logs = "".join(p.read_text() for p in (sweep / ".submitit").rglob("*_log.*"))
    assert "this job is preempted" in logs and "Requeued job" in logs  # ... requeued by submitit ...
    assert (job_dir / "config_resumed.yaml").is_file()  # ... and continued its own last.pt

    with initialize_config_dir(config_dir=CONF, version_base="1.3"):
        cfg = compose("config", overrides=[*overrides, "seed=0"])
    straight = tmp_path / "straight"
    run(cfg, straight)
    a = load_checkpoint(job_dir / "checkpoints" / "last.pt")
    b = load_checkpoint(straight / "checkpoints" / "last.pt")
    assert a["train_state"]["iteration"] == b["train_state"]["iteration"] == 4
    for k, v in b["policy"]["state_dict"].items():
        torch.testing.assert_close(a["policy"]["state_dict"][k], v, rtol=0, atol=0)
    assert a["meta"]["metrics"]["train/loss"] == b["meta"]["metrics"]["train/loss"]
    s = json.loads((sweep / "sweep_summary.json").read_text())
    assert [r["status"] for r in s["runs"]] == ["done"]
