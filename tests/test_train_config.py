"""The two Hydra apps' configs: every training experiment passes the start checks and writes its own files,
every policy of the evaluation suite resolves to its checkpoint and experiment, the apps keep separate
namespaces, launchers are installed plugins, bad input fails at start."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from hydra.errors import ConfigCompositionException
from omegaconf import OmegaConf
from omegaconf.errors import ConfigKeyError

ROOT = Path(__file__).resolve().parents[1]
CONF = str(ROOT / "conf")  # train.py's config dir
EVAL_CONF = str(ROOT / "conf" / "evaluate")  # evaluate.py's
EXPERIMENTS = sorted(p.stem for p in (ROOT / "conf" / "experiment").glob("*.yaml"))


def cfg_of(*overrides, hydra=False):
    with initialize_config_dir(config_dir=CONF, version_base="1.3"):
        return compose("config", overrides=list(overrides), return_hydra_config=hydra)


def eval_cfg(*overrides):
    with initialize_config_dir(config_dir=EVAL_CONF, version_base="1.3"):
        return compose("config", overrides=list(overrides))


def test_every_experiment_passes_the_start_checks_and_writes_its_own_files():
    from train import validate

    cfgs = {e: cfg_of(f"+experiment={e}") for e in EXPERIMENTS}
    for cfg in cfgs.values():
        validate(cfg)
    # Two experiments sharing a run name, shipped checkpoint or results file would overwrite each other.
    for key in ("name", "output_checkpoint", "algo.results_json"):
        values = [OmegaConf.select(c, key) for c in cfgs.values()]
        values = [v for v in values if v is not None]
        assert len(values) == len(set(values)), f"{key} repeats across experiments: {sorted(values)}"


def test_every_suite_policy_resolves_to_its_checkpoint_and_experiment():
    """Each policy evaluate.py names is a shipped checkpoint of the stated view, made by the experiment it names."""
    from flownav.checkpoint import load_policy

    for name, pol in eval_cfg().policies.items():
        if pol.get("scripted"):
            continue
        load_policy(ROOT / pol.checkpoint, expect_obs=pol.obs)  # refuses a missing file or another view
        experiment = pol.command.removeprefix("python train.py +experiment=")
        assert experiment in EXPERIMENTS, f"policy {name}: {pol.command!r} names no experiment"
        cfg = cfg_of(f"+experiment={experiment}")
        assert cfg.obs.view == pol.obs, name
        assert cfg.output_checkpoint in (None, pol.checkpoint), name
        if cfg.algo.name == "dagger":  # the teacher it imitates is shipped too
            load_policy(ROOT / cfg.teacher_checkpoint)


@pytest.mark.parametrize("launcher", ["local", "slurm"])
def test_launcher_is_an_installed_hydra_plugin(launcher):
    from hydra.utils import get_class

    cfg = cfg_of("+experiment=teacher", f"hydra/launcher={launcher}", hydra=True)
    get_class(cfg.hydra.launcher._target_)  # raises if the plugin package is missing
    if launcher == "slurm":  # a preempted or timed-out job is requeued, with time to write its last checkpoint
        assert cfg.hydra.launcher.max_num_timeout > 0 and cfg.hydra.launcher.signal_delay_s > 0


def run_app(*args, timeout=120):
    """Run an entry point of the repository as a user would."""
    return subprocess.run([sys.executable, *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout)


def test_each_app_rejects_the_other_apps_experiments():
    with pytest.raises(ConfigCompositionException, match="Could not find 'experiment/teacher'"):
        eval_cfg("+experiment=teacher")
    with pytest.raises(ConfigCompositionException, match="Could not find 'experiment/paper'"):
        cfg_of("+experiment=paper")


def test_evaluate_takes_hydra_flags_after_overrides_and_lists_only_its_groups():
    out = run_app("evaluate.py", "+experiment=paper_abc", "--cfg", "job")
    assert out.returncode == 0, out.stderr[-2000:]
    assert "abc:" in out.stdout
    text = run_app("evaluate.py", "--help").stdout
    assert text.startswith("evaluate.py: ") and "paper_abc" in text
    assert not any(line.startswith(("algo:", "obs:", "logger:")) for line in text.splitlines())


@pytest.mark.parametrize("override", ["foo=1", "algo.nonexistent=3", "env.reward.bogus=1"])
def test_unknown_key_fails(override):
    with pytest.raises((ConfigCompositionException, ConfigKeyError)):
        cfg_of("+experiment=teacher", override)


def test_unknown_key_fails_on_the_command_line():
    out = run_app("train.py", "+experiment=teacher", "algo.lrr=1e-3")
    assert out.returncode != 0 and "lrr" in out.stderr
