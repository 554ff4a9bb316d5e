"""One evaluation path: every entry point that measures a policy runs the protocol's episodes
(flownav.evaluation.protocol), so the same spec gives the same episodes and the same summary everywhere."""

from __future__ import annotations

import pytest
import torch
from hydra import compose, initialize_config_dir
from load import load_module

from flownav.builders import build_flow, build_task, compose_config
from flownav.checkpoint import save_policy_checkpoint
from flownav.envs.observations import observation_size
from flownav.evaluation.metrics import summarize
from flownav.evaluation.protocol import CHUNK_SEED_STRIDE, EVAL_SEED, EvalSpec, env_seed, evaluate
from flownav.evaluation.scripted import HeadToTarget, fit_expert
from flownav.paths import DEFAULT_FLOW_DATASET, REPO_ROOT

pytestmark = pytest.mark.skipif(not DEFAULT_FLOW_DATASET.is_dir(), reason="needs the shipped wake dataset")

EPISODES, LIMIT = 40, 30.0  # a short time limit keeps it fast; the episodes still end in different ways


def core(summary: dict) -> dict:
    """The protocol's summary without what only some entry points add (timing, provenance)."""
    return {k: summary[k] for k in summarize(torch.tensor([1]), torch.tensor([1.0]))}


@pytest.fixture(scope="module")
def teacher(tmp_path_factory):
    """A geo network that swims at the target (fitted to head-to-target): its episodes end in every way."""
    pol, _ = fit_expert(HeadToTarget(), obs_dim=observation_size("geo"), hidden=(32, 32), steps=300)
    return save_policy_checkpoint(tmp_path_factory.mktemp("protocol") / "teacher.pt", pol, "geo", "teacher")


@pytest.fixture(scope="module")
def reference(teacher):
    """The protocol itself on the training flow, task and env, with the short time limit."""
    from flownav.checkpoint import load_policy

    cfg = compose_config([f"env.time_limit={LIMIT}"])
    flow = build_flow(cfg.flow)
    policy, _ = load_policy(teacher)
    return evaluate(policy, "geo", EvalSpec(flow, build_task(cfg.task, flow), cfg.env, EPISODES))


def compose_eval(*overrides):
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf" / "evaluate"), version_base="1.3"):
        return compose("config", overrides=list(overrides))


def test_the_seed_rule():
    assert env_seed(EVAL_SEED, 0) == EVAL_SEED and env_seed(5, 2) == 5 + 2 * CHUNK_SEED_STRIDE


def test_evaluate_py_runs_the_protocol(teacher, reference):
    import evaluate

    cfg = compose_eval(f"checkpoint={teacher}", f"episodes={EPISODES}", f"env.time_limit={LIMIT}", "progress=false")
    assert core(evaluate.run(cfg, log=lambda *_: None)) == reference.summary


def test_the_suite_runs_the_protocol(teacher, reference):
    from flownav.evaluation.experiments import Suite

    cfg = compose_eval(
        "+experiment=paper_training",
        f"env.time_limit={LIMIT}",
        f"max_episodes={EPISODES}",
        f"policies.teacher.checkpoint={teacher}",
        "policies.teacher.obs=geo",
        "suite.training.policies=[teacher]",
    )
    suite = Suite(cfg, log=lambda *_: None)
    assert core(suite.run("training", cfg.suite.training)["results"]["teacher"]) == reference.summary
    flow = suite.flow(cfg.suite.training.flow)
    ep = suite.rollout("teacher", flow, cfg.suite.training.task, suite.env_cfg(cfg.suite.training), EPISODES).episodes
    for key in ("start", "target", "status", "time", "final_position"):
        assert torch.equal(getattr(ep, key), getattr(reference.episodes, key)), key


def test_seed_selection_runs_the_protocol(teacher, reference):
    from flownav.evaluation.selection import evaluate_checkpoint

    assert core(evaluate_checkpoint(teacher, EPISODES, [f"env.time_limit={LIMIT}"])) == reference.summary


def test_teacher_failures_runs_the_protocol(teacher, reference):
    script = load_module("scripts/teacher_failures.py")
    ep, _ = script.episodes(teacher, [f"time_limit={LIMIT}"], EPISODES)
    assert torch.equal(ep.status, reference.episodes.status) and torch.equal(ep.start, reference.episodes.start)


def test_the_reference_tells_episodes_apart(teacher, reference):
    """The summaries compared above hold more than one outcome, and other episodes end in other counts."""
    from flownav.checkpoint import load_policy

    cfg = compose_config([f"env.time_limit={LIMIT}"])
    flow = build_flow(cfg.flow)
    policy, _ = load_policy(teacher)
    other = evaluate(policy, "geo", EvalSpec(flow, build_task(cfg.task, flow), cfg.env, EPISODES, seed=1))
    assert len(reference.episodes.status.unique()) >= 2  # more than one outcome ...
    assert other.summary["failures"] != reference.summary["failures"]  # ... and other episodes end otherwise


def test_the_selection_command_writes_the_protocol_summary_and_refuses_a_short_ship(teacher, reference, tmp_path):
    import json

    from flownav.evaluation.selection import main

    out = tmp_path / "teacher.json"
    args = [str(teacher), "--name", "t", "--out", str(out), "--episodes", str(EPISODES), "--threads", "1"]
    main([*args, "--override", f"env.time_limit={LIMIT}"])
    data = json.loads(out.read_text())
    assert core(data["runs"][0]) == reference.summary and data["eval_seed"] == EVAL_SEED and data["commit"]
    with pytest.raises(SystemExit) as stop:  # a shipped checkpoint needs the full 10,000 episodes
        main([*args, "--ship", str(tmp_path / "shipped.pt")])
    assert stop.value.code == 2 and not (tmp_path / "shipped.pt").exists()


def test_evaluate_py_runs_a_scripted_reference_through_the_protocol():
    import evaluate as evaluate_py

    cfg = compose_eval("checkpoint=scripted:head_to_target", f"episodes={EPISODES}", f"env.time_limit={LIMIT}")
    flow_cfg = compose_config([f"env.time_limit={LIMIT}"])
    flow = build_flow(flow_cfg.flow)
    expected = evaluate(HeadToTarget(), "geo", EvalSpec(flow, build_task(flow_cfg.task, flow), flow_cfg.env, EPISODES))
    assert core(evaluate_py.run(cfg, log=lambda *_: None)) == expected.summary
    with pytest.raises(evaluate_py.ConfigError, match="names no scripted policy"):
        evaluate_py.run(compose_eval("checkpoint=scripted:nope", "episodes=4"), log=lambda *_: None)
