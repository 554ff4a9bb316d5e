"""train.py's Hydra configs: every experiment composes, launchers compose, bad input fails at start."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from hydra.errors import ConfigCompositionException
from omegaconf.errors import ConfigKeyError

ROOT = Path(__file__).resolve().parents[1]
CONF = str(ROOT / "conf")
EXPERIMENTS = sorted(p.stem for p in (ROOT / "conf" / "experiment").glob("*.yaml"))


def cfg_of(*overrides, hydra=False):
    with initialize_config_dir(config_dir=CONF, version_base="1.3"):
        return compose("config", overrides=list(overrides), return_hydra_config=hydra)


@pytest.mark.parametrize("experiment", EXPERIMENTS)
def test_every_experiment_composes(experiment):
    cfg = cfg_of(f"+experiment={experiment}")
    for key in ("seed", "device", "threads", "teacher_checkpoint", "resume", "checkpoint_every", "output_checkpoint"):
        assert key in cfg
    assert cfg.algo.name in ("ppo", "dagger")
    assert cfg.name == experiment.split("_")[0] or cfg.name == experiment or cfg.name.startswith("student")


def test_teacher_and_baseline_differ_only_in_view():
    t, b = cfg_of("+experiment=teacher"), cfg_of("+experiment=baseline_ego")
    assert (t.obs.view, b.obs.view) == ("geo_sincos", "ego")
    assert t.algo == b.algo and t.env == b.env and t.flow == b.flow and t.task == b.task
    assert t.flow.type == "grid"  # the default flow is the CFD wake


def test_local_launcher_is_joblib_two_jobs():
    cfg = cfg_of("+experiment=teacher", hydra=True)
    assert "joblib" in cfg.hydra.launcher._target_.lower()
    assert cfg.hydra.launcher.n_jobs == 2


def test_slurm_launcher_composes():
    cfg = cfg_of("+experiment=teacher", "hydra/launcher=slurm", hydra=True)
    launcher = cfg.hydra.launcher
    assert "submitit" in launcher._target_.lower() and "slurm" in launcher._target_.lower()
    assert launcher.cpus_per_task >= 1 and launcher.timeout_min > 0


@pytest.mark.parametrize("override", ["foo=1", "algo.nonexistent=3", "env.reward.bogus=1"])
def test_unknown_key_fails(override):
    with pytest.raises((ConfigCompositionException, ConfigKeyError)):
        cfg_of("+experiment=teacher", override)


def test_unknown_key_fails_on_the_command_line():
    out = subprocess.run(
        [sys.executable, "train.py", "+experiment=teacher", "algo.lrr=1e-3"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode != 0 and "lrr" in out.stderr


@pytest.mark.parametrize(
    "override, match",
    [
        ("algo.gamma=1.5", "algo.gamma"),
        ("algo.clip_epsilon=0", "algo.clip_epsilon"),
        ("algo.loss_critic_type=l3", "loss_critic_type"),
        ("algo.actor.activation=sigmoid", "activation"),
        ("algo.minibatch_size=100000000", "minibatch_size"),
        ("obs.view=sonar", "obs.view"),
        ("logger.wandb.mode=sometimes", "logger.wandb.mode"),
        ("algo.name=sac", "algo.name"),
        ("threads=0", "threads"),
    ],
)
def test_bad_value_fails_at_start(override, match, tmp_path):
    from flownav.builders import ConfigError
    from train import run

    cfg = cfg_of("+experiment=teacher", "flow=uniform", "logger=csv", override)
    with pytest.raises(ConfigError, match=match):
        run(cfg, tmp_path)


def test_resume_of_missing_run_fails(tmp_path):
    from flownav.builders import ConfigError
    from train import run

    cfg = cfg_of("+experiment=teacher", "flow=uniform", "logger=csv", f"resume={tmp_path / 'nope'}")
    with pytest.raises(ConfigError, match="resume"):
        run(cfg, tmp_path)


@pytest.mark.slow
def test_multirun_two_seeds_with_joblib(tmp_path):
    tiny = [
        "flow=uniform",
        "env.num_envs=64",
        "algo.rollout_steps=8",
        "algo.minibatch_size=256",
        "algo.total_frames=1024",
        "algo.final_eval_episodes=0",
        "algo.actor.hidden=[16]",
        "algo.critic.hidden=[16]",
        "logger=csv",
        "logger.progress=false",
    ]
    out = subprocess.run(
        [sys.executable, "train.py", "-m", "+experiment=teacher", "seed=0,1", *tiny, f"hydra.sweep.dir={tmp_path}"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr[-3000:]
    runs = sorted(tmp_path.glob("seed*"))
    assert [r.name.split("_")[0] for r in runs] == ["seed0", "seed1"]
    for r in runs:
        assert (r / "metrics.csv").is_file() and (r / "checkpoints" / "last.pt").is_file()
        assert (r / "config.yaml").is_file() and (r / "final_metrics.json").is_file()
