"""Dashboards: a tiny PPO run logs entropy, episode length, failure causes, learning rate and KL with finite
values, draws the periodic evaluation's trajectories, ends train.log with the summary; TensorBoard by config."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import pytest
from tiny import TINY_PPO, compose_train

from flownav.runlog import run_summary

# Still water, targets about 2 D away, 3 iterations of 64 swimmers x 16 steps, periodic evaluation every 3.
TINY = [
    *TINY_PPO,
    "env.num_envs=64",
    "algo.rollout_steps=16",
    "algo.minibatch_size=512",
    "algo.total_frames=3072",
    "algo.eval_every=3",
    "algo.eval_episodes=20",
    "algo.final_eval_episodes=50",
    "algo.actor.hidden=[16]",
    "algo.critic.hidden=[16]",
    "logger.figure_episodes=3",
]

NEW_KEYS = [
    "policy/entropy",
    "train/episode_length",
    "train/rate_left_domain",
    "train/rate_hit_obstacle",
    "train/rate_timeout",
    "train/success_rate",
    "lr",
    "loss/kl_approx",
]


def make_cfg(*overrides):
    return compose_train(*TINY, *overrides)


def test_tiny_ppo_run_logs_dashboard_keys_figure_and_summary(tmp_path):
    from train import run

    final = run(make_cfg(), tmp_path)
    rows = list(csv.DictReader(open(tmp_path / "metrics.csv", newline="")))
    train_rows = [r for r in rows if r.get("loss/objective")]
    assert len(train_rows) == 3
    for key in NEW_KEYS:
        values = [float(r[key]) for r in train_rows]
        assert all(math.isfinite(v) for v in values), (key, values)
    for r in train_rows:  # a 4-time-unit limit ends episodes every batch: the causes cover them all
        rates = [float(r[f"train/rate_{c}"]) for c in ("left_domain", "hit_obstacle", "timeout")]
        assert sum(rates) + float(r["train/success_rate"]) == pytest.approx(1.0)
        assert 0 < float(r["train/episode_length"]) <= 4.0
    assert float(train_rows[0]["lr"]) == pytest.approx(1e-3 * (1 - 1024 / 3072))  # annealed after the 1st batch
    assert float(train_rows[-1]["policy/entropy"]) != float(train_rows[0]["policy/entropy"])

    pngs = sorted((tmp_path / "figures").glob("eval_trajectories_*.png"))
    assert [p.name for p in pngs] == ["eval_trajectories_3072.png"]  # the one periodic evaluation (iteration 3)
    assert pngs[0].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    log = (tmp_path / "train.log").read_text().strip().splitlines()
    summary = log[log.index("== run summary ==") :]
    assert summary[1] == "steps: 3,072"
    n = 50
    rate = final["eval/success_rate"]
    assert summary[3].startswith(f"held-out success: {rate:.2%} of {n} held-out episodes (95% CI ")
    assert summary[4] == f"last: {tmp_path / 'checkpoints' / 'last.pt'}"
    assert summary[-1] == f"best: {tmp_path / 'checkpoints' / 'best.pt'}"


def test_tiny_dagger_run_logs_episode_outcomes_loss_buffer_and_summary(tmp_path):
    """DAgger's rows: the collected episodes' outcomes (the causes add up to 1 with the successes), eq. 9's loss,
    beta and the buffer's size; train.log ends with the student's and the teacher's held-out success."""
    from tiny import DRIFT_TASK

    from flownav.checkpoint import save_policy_checkpoint
    from flownav.evaluation.scripted import HeadToTarget, fit_expert
    from train import run

    teacher, _ = fit_expert(HeadToTarget(), hidden=(16,), steps=100, batch=256, seed=0)
    save_policy_checkpoint(tmp_path / "teacher.pt", teacher, "geo", "teacher")
    cfg = compose_train(
        "+experiment=student",
        *DRIFT_TASK,
        "env.time_limit=4.0",  # episodes end within each iteration's 25 steps of 0.2
        f"teacher_checkpoint={tmp_path / 'teacher.pt'}",
        *["algo.iterations=2", "algo.num_envs=16", "algo.steps_per_iteration=25", "algo.updates_per_iteration=2"],
        *["algo.batch_size=32", "algo.hidden=[8]", "algo.final_eval_episodes=20"],
        *["logger=csv", "logger.progress=false", "threads=1"],
    )
    run_dir = tmp_path / "run"
    final = run(cfg, run_dir)
    rows = [r for r in csv.DictReader(open(run_dir / "metrics.csv", newline="")) if r.get("train/loss")]
    assert len(rows) == 2
    for r in rows:
        rates = [float(r[f"train/rate_{c}"]) for c in ("left_domain", "hit_obstacle", "timeout")]
        assert sum(rates) + float(r["train/success_rate"]) == pytest.approx(1.0)
        assert 0 < float(r["train/episode_length"]) <= 4.0 and float(r["train/episodes"]) > 0
        assert all(math.isfinite(float(r[k])) for k in ("train/loss", "train/loss_onpolicy", "train/beta"))
    assert [int(float(r["buffer/size"])) for r in rows] == [400, 800]
    log = (run_dir / "train.log").read_text().strip().splitlines()
    summary = log[log.index("== run summary ==") :]
    assert summary[1] == "steps: 800"
    for line, name in zip(summary[3:5], ("student", "teacher"), strict=True):
        rate = final[f"eval/{name}_success_rate"]
        assert line.startswith(f"held-out {name} success: {rate:.2%} of 20 held-out episodes (95% CI ")
    assert summary[-1] == f"last: {run_dir / 'checkpoints' / 'last.pt'}"


def test_run_summary_wilson_interval_and_unevaluated():
    text = run_summary(1000, 90.0, {"student": (0.0, 100), "teacher": (None, 0)}, {"last": Path("/r/last.pt")})
    assert text.splitlines() == [
        "== run summary ==",
        "steps: 1,000",
        "wall time: 0:01:30",
        "student: 0.00% of 100 held-out episodes (95% CI 0.00% - 3.70%)",
        "teacher: not evaluated",
        "last: /r/last.pt",
    ]


def test_tensorboard_backend_writes_events(tmp_path):
    pytest.importorskip("tensorboard")
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    from train import run

    run(make_cfg("logger=tensorboard", "logger.progress=false", "algo.final_eval_episodes=0"), tmp_path)
    events = list((tmp_path / "tensorboard").rglob("events.out.tfevents.*"))
    assert len(events) == 1
    acc = EventAccumulator(str(events[0].parent)).Reload()
    assert [e.step for e in acc.Scalars("policy/entropy")] == [1024, 2048, 3072]
    assert [e.step for e in acc.Images("eval/trajectories")] == [3072]


@pytest.mark.slow
def test_wandb_offline_run_holds_rows_figure_and_checkpoint_artifact(tmp_path, monkeypatch):
    """Through TorchRL's WandbLogger, offline: the trajectory figure is a wandb.Image in the run's media and
    best.pt is a model artifact recorded in the run file (synced with `wandb sync`)."""
    import matplotlib.pyplot as plt
    from omegaconf import OmegaConf

    from flownav.runlog import RunLogger

    monkeypatch.delenv("WANDB_API_KEY", raising=False)
    cfg = OmegaConf.create(
        {"name": "dash", "seed": 3, "logger": {"progress": False, "wandb": {"mode": "offline", "group": "dash"}}}
    )
    logger = RunLogger(tmp_path, cfg)
    logger.log(1024, {"train/success_rate": 0.5, "policy/entropy": 1.2})
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    logger.log_figure(1024, "eval/trajectories", fig)
    (tmp_path / "checkpoints").mkdir()
    (tmp_path / "checkpoints" / "best.pt").write_bytes(b"weights")
    logger.log_checkpoint(tmp_path / "checkpoints" / "best.pt")
    logger.close()
    import wandb

    wandb.teardown()  # wandb-core writes the run file asynchronously: wait for it
    (run,) = (tmp_path / "wandb").glob("offline-run-*")
    assert len(list((run / "files" / "media" / "images" / "eval").glob("trajectories_*.png"))) == 1
    record = next(run.glob("run-*.wandb")).read_bytes()
    assert b"dash-seed3-best" in record and b'{"file":"best.pt"}' in record  # the artifact and its metadata


def test_evaluation_progress_bar_counts_finished_episodes(capsys):
    from flownav.envs import NavigationEnv, RegionTask
    from flownav.evaluation.rollout import run_episodes
    from flownav.evaluation.scripted import HeadToTarget
    from flownav.flows import Box, UniformFlow

    task = RegionTask(Box((5.0, 0.0, 5.0), (6.0, 1.0, 6.0)), Box((7.0, 0.0, 5.0), (8.0, 1.0, 6.0)))

    def make_env(n, chunk):
        return NavigationEnv(UniformFlow((0.0, 0.0, 0.0)), task, num_envs=n, views=("geo",), seed=chunk, time_limit=6.0)

    run_episodes(HeadToTarget(), "geo", make_env, episodes=37, chunk_size=10, progress=True)
    err = capsys.readouterr().err
    assert "37/37" in err and "episode" in err
    run_episodes(HeadToTarget(), "geo", make_env, episodes=5, chunk_size=10)  # off by default (inside training)
    assert capsys.readouterr().err == ""
