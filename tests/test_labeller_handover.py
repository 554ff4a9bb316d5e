"""scripts/labeller_handover.py: a student's steps, then a labeller's, on the protocol's episodes."""

from __future__ import annotations

import pytest
import torch
from load import load_module

from flownav.builders import compose_config
from flownav.envs.core import SCENE_AWAY
from flownav.evaluation.protocol import EvalSpec, evaluate
from flownav.evaluation.scripted import HeadToTarget, Passive
from flownav.paths import DEFAULT_FLOW_DATASET

pytestmark = pytest.mark.skipif(not DEFAULT_FLOW_DATASET.is_dir(), reason="needs the shipped wake dataset")

handover = load_module("scripts/labeller_handover.py")
EPISODES, LIMIT = 60, 20.0


@pytest.fixture(scope="module")
def spec():
    cfg = compose_config([*handover.FAR_STARTS, f"env.time_limit={LIMIT}"], app="evaluate")
    return EvalSpec.from_config(cfg, episodes=EPISODES)


def test_hand_over_at_the_start_is_the_labeller_and_never_is_the_student(spec):
    """At step 0 every action is the labeller's, past the time limit none is: the protocol's episodes of each."""
    at_start, _ = handover.run("scripted:passive", "scripted:head_to_target", 0, spec)
    never, scenes = handover.run("scripted:passive", "scripted:head_to_target", 10_000, spec)
    assert torch.equal(at_start.status, evaluate(HeadToTarget(), "geo", spec).episodes.status)
    assert torch.equal(never.status, evaluate(Passive(), "geo", spec).episodes.status)
    assert at_start.success.any() and not never.success.all()
    assert (scenes == SCENE_AWAY).any()  # the far starts are there to count


def test_rows_count_the_scenes_episodes_still_running_at_the_hand_over(spec):
    alone, scenes = handover.run("scripted:head_to_target", None, 0, spec)
    rows = list(handover.handover_rows("scripted:head_to_target", ["scripted:passive"], [0, 10], spec, SCENE_AWAY))
    far = scenes == SCENE_AWAY
    dt = float(spec.env_cfg["dt"])
    assert [r["episodes"] for r in rows] == [int(far.sum()), int((far & (alone.time > 10.5 * dt)).sum())]
    assert rows[0]["success"] == 0.0  # the passive swimmer from the start reaches no far target
    assert rows[0]["student_alone"] == int(alone.success[far].sum()) / int(far.sum()) > 0


def test_a_policy_it_cannot_read_is_one_line_before_any_episode(capsys):
    with pytest.raises(SystemExit) as stop:
        handover.main(["scripted:passive", "scripted:drift"])
    assert stop.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "scripted:drift names no scripted policy; choose scripted:<head_to_target|" in err
