"""Device-clean training: cfg.device is checked once with a one-line error, every parameter, buffer and env
of PPO and DAgger lives on it, and a tiny training runs on CUDA when there is one."""

from __future__ import annotations

import pytest
import torch
from tiny import TINY_PPO, compose_train

from flownav.devices import check_on_device, resolve_device
from flownav.errors import ConfigError

TINY = [*TINY_PPO, "algo.eval_every=2", "algo.eval_episodes=8", "algo.final_eval_episodes=16"]
TINY += ["logger.figure_episodes=2"]


def make_cfg(*overrides):
    return compose_train(*TINY, *overrides)


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has CUDA")
def test_resolve_device_keeps_cpu_and_refuses_what_it_cannot_run():
    """The same messages through train.py and evaluate.py: tests/test_bad_input.py (cases cuda, device_typo)."""
    assert resolve_device("cpu") == torch.device("cpu")
    with pytest.raises(ConfigError, match=r"^device=cuda asks for CUDA but torch sees no CUDA device here; use"):
        resolve_device("cuda")
    with pytest.raises(ConfigError, match=r"^device=gpu is not a torch device \(cpu, cuda, cuda:0\)$"):
        resolve_device("gpu")


def test_check_on_device_names_the_stray_tensor():
    net = torch.nn.Sequential(torch.nn.Linear(2, 2))
    net.register_buffer("stats", torch.zeros(2, device="meta"))
    check_on_device("meta", w=torch.zeros(1, device="meta"))
    with pytest.raises(RuntimeError, match=r"^policy\.stats is on meta, the run's device is cpu \(cfg\.device\)$"):
        check_on_device("cpu", policy=net)


def test_ppo_puts_networks_buffer_returns_and_eval_envs_on_cfg_device(monkeypatch, tmp_path):
    """Everything PPO builds (checked by the trainer itself) and every env it builds, evaluation included,
    is on cfg.device."""
    from flownav import builders
    from flownav.algorithms import ppo

    built = []
    real_build_env = builders.build_env

    def recording_build_env(*args, **kwargs):
        env = real_build_env(*args, **kwargs)
        built.append(env)
        return env

    monkeypatch.setattr(ppo, "build_env", recording_build_env)  # the training env
    monkeypatch.setattr(builders, "build_env", recording_build_env)  # the evaluation envs (protocol.EvalSpec)
    checked = []
    monkeypatch.setattr(ppo, "check_on_device", lambda device, **things: checked.append((device, things)))
    from train import run

    run(make_cfg(), tmp_path)
    assert len(built) >= 3  # training env, periodic evaluation (+ figure), final evaluation
    assert {str(env.device) for env in built} == {"cpu"}
    ((device, things),) = checked
    assert set(things) == {"actor", "critic", "env"}
    check_on_device(device, **things)  # the real check passes on what PPO built


def test_dagger_puts_student_teacher_buffer_and_eval_envs_on_cfg_device(monkeypatch, tmp_path):
    """What DAgger builds (checked by the trainer itself), its aggregated buffer and every env it builds, the
    final evaluation's included, is on cfg.device."""
    from tiny import DRIFT_TASK

    from flownav import builders
    from flownav.algorithms import dagger
    from flownav.checkpoint import save_policy_checkpoint
    from flownav.evaluation.scripted import HeadToTarget, fit_expert

    teacher, _ = fit_expert(HeadToTarget(), hidden=(16,), steps=50, batch=256, seed=0)
    save_policy_checkpoint(tmp_path / "teacher.pt", teacher, "geo", "teacher")
    built, checked, storages = [], [], []
    real_build_env, real_storage = builders.build_env, dagger.LazyTensorStorage

    def recording_build_env(*args, **kwargs):
        built.append(real_build_env(*args, **kwargs))
        return built[-1]

    def recording_storage(*args, **kwargs):
        storages.append(kwargs.get("device"))
        return real_storage(*args, **kwargs)

    monkeypatch.setattr(dagger, "build_env", recording_build_env)  # the training env
    monkeypatch.setattr(builders, "build_env", recording_build_env)  # the evaluation envs (protocol.EvalSpec)
    monkeypatch.setattr(dagger, "LazyTensorStorage", recording_storage)
    monkeypatch.setattr(dagger, "check_on_device", lambda device, **things: checked.append((device, things)))
    from train import run

    cfg = compose_train(
        "+experiment=student",
        *DRIFT_TASK,
        f"teacher_checkpoint={tmp_path / 'teacher.pt'}",
        *["algo.iterations=1", "algo.num_envs=8", "algo.steps_per_iteration=5", "algo.updates_per_iteration=2"],
        *["algo.batch_size=16", "algo.hidden=[8]", "algo.final_eval_episodes=8"],
        *["logger=csv", "logger.progress=false", "threads=1"],
    )
    run(cfg, tmp_path / "run")
    assert len(built) >= 2  # training env, final evaluation
    assert {str(env.device) for env in built} == {"cpu"} and [str(d) for d in storages] == ["cpu"]
    ((device, things),) = checked
    assert str(device) == "cpu" and set(things) == {"student", "teacher", "env"}
    check_on_device(device, **things)  # the real check passes on what DAgger built


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_tiny_ppo_trains_on_cuda(tmp_path):
    from flownav.checkpoint import load_checkpoint
    from train import run

    final = run(make_cfg("device=cuda"), tmp_path)
    assert final["frames"] == 512 and final["eval/episodes"] > 0
    payload = load_checkpoint(tmp_path / "checkpoints" / "last.pt")
    assert payload["obs"] == "geo_sincos"
    weights = payload["policy"]["state_dict"].values()  # saved from the GPU, read on the CPU: finite numbers
    assert all(w.device.type == "cpu" and torch.isfinite(w).all() for w in weights)
