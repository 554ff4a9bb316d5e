"""The benchmarks' own code paths at tiny size, so that a change of the env's internals cannot break them
unseen (their timings are never asserted)."""

import pytest
import torch
from load import load_module

from flownav.agents.actor_critic import make_actor_critic
from flownav.envs import NavigationEnv
from flownav.flows import UniformFlow
from flownav.flows.base import WAKE_BOUNDS


def _load(name):
    return load_module(f"benchmarks/{name}.py")


def test_plain_collection_loop_of_the_train_benchmark_is_the_env():
    """The benchmark's plain-tensor loop sees exactly the observations the env gives for the same actions, resets
    included, with the env's swim speed, flow strengths and time limit in steps: its speed ratio compares the same
    work."""
    bench = _load("train_throughput")
    flow = UniformFlow((0.5, 0.0, 0.0), bounds=WAKE_BOUNDS)

    def make_env():
        return NavigationEnv(
            flow,
            num_envs=32,
            views=("geo_sincos",),
            time_limit=2.05,  # 10 steps of 0.2: resets at step 10
            swim_speed_scale=0.5,
            flow_strength=(0.5, 1.5),
            seed=0,
        )

    plain_env = make_env()
    low, high = plain_env.action_spec.space.low[0], plain_env.action_spec.space.high[0]
    hidden = {"hidden": [8, 8], "activation": "tanh", "init_scale": 0.5, "scale_lb": 1e-3, "output_gain": 0.01}
    policy, *_ = make_actor_critic("geo_sincos", "geo_sincos", low, high, hidden, {"hidden": [8], "activation": "tanh"})
    record = []
    bench.plain_collect(plain_env, policy, 25, record=record)
    assert len(record) == 25
    env = make_env()
    td = env.reset()
    ended_at = []
    for step, (obs, action) in enumerate(record):
        assert torch.equal(td["geo_sincos"], obs), f"step {step}"
        td["action"] = action
        out, td = env.step_and_maybe_reset(td)
        if out["next", "done"].all():
            ended_at.append(step + 1)
    assert ended_at == [10, 20]  # the record runs through two resets of every episode


def test_eval_benchmark_times_the_protocols_episodes():
    """eval_throughput.py times flownav.evaluation.evaluate on the training env: its success is evaluate.py's."""
    from flownav.builders import compose_config
    from flownav.envs import RegionTask
    from flownav.evaluation import EvalSpec, evaluate
    from flownav.evaluation.scripted import HeadToTarget

    bench = _load("eval_throughput")
    flow = UniformFlow((0.9, 0.0, 0.0), bounds=WAKE_BOUNDS)  # nearly the swim speed: about 80% arrive
    policy = HeadToTarget()
    timed = bench.time_eval(policy, "geo", flow, 1, episodes=300, chunk=100)
    spec = EvalSpec(flow, RegionTask(), compose_config().env, 300, chunk_size=100)
    summary = evaluate(policy, "geo", spec).summary
    assert timed["episodes"] == 300 and timed["success_rate"] == summary["success_rate"]
    assert 0 < summary["success_rate"] < 1  # a stream that beats some swimmers: the episodes are told apart


def test_the_pipeline_cost_counts_every_network_the_students_teacher_is_made_of():
    """The generalist student's cost from nothing: its generalist teacher, the paper's teacher and the four trained
    scene experts its config names, then its own run, each with the wall time its shipped checkpoint recorded."""
    from flownav.checkpoint import load_checkpoint
    from flownav.paths import CHECKPOINT_DIR

    pipeline_cost = _load("family_throughput").pipeline_cost
    cost = pipeline_cost("generalist_student")
    roles = [r["roles"] for r in cost["results"]]
    assert roles == [["teacher_checkpoint"], ["scene_expert"], ["scene_reverse_expert"], ["scene_away_expert"],
                     ["scene_wake_expert"], ["scene_wake_regions_expert"], ["student"]]  # fmt: skip
    away = next(r for r in cost["results"] if r["roles"] == ["scene_away_expert"])
    wall = load_checkpoint(CHECKPOINT_DIR / "generalist_away_expert.pt")["train_state"]["wall_time"]
    assert away["wall_time_min"] == wall / 60
    assert cost["total_min"] == sum(r["wall_time_min"] for r in cost["results"])
    # A network that labels two scenes trained once: counted once.
    turned = "algo.scene_reverse_expert=checkpoints/generalist_wake_expert_turned.pt"
    shared = pipeline_cost("generalist_student", [turned])
    assert [r["roles"] for r in shared["results"]][2:5] == [
        ["scene_reverse_expert", "scene_wake_expert"],
        ["scene_away_expert"],
        ["scene_wake_regions_expert"],
    ]
    reverse = next(r for r in cost["results"] if r["roles"] == ["scene_reverse_expert"])
    assert shared["teacher_networks_min"] == pytest.approx(cost["teacher_networks_min"] - reverse["wall_time_min"])
    assert shared["results"][-1]["roles"] == ["student"]
    assert shared["total_min"] == pytest.approx(sum(r["wall_time_min"] for r in shared["results"]))
    # One file however it is spelled; the student is never one of its teacher's networks.
    spelled = pipeline_cost("generalist_student", [turned.replace("=checkpoints/", f"={CHECKPOINT_DIR}/")])
    assert [r["roles"] for r in spelled["results"]] == [r["roles"] for r in shared["results"]]
    with pytest.raises(ValueError, match="output_checkpoint checkpoints/generalist_teacher.pt is a network of the"):
        pipeline_cost("generalist_student", ["output_checkpoint=checkpoints/generalist_teacher.pt"])


def test_oracle_benchmark_compares_the_same_plans():
    """oracle_throughput.py's two look-ups give the oracle the same plans, at a tiny search."""
    bench = _load("oracle_throughput")
    small = ["algo.oracle_settings.candidates=8", "algo.oracle_settings.iterations=1"]
    small.append("+algo.oracle_settings.horizon=6")
    row = bench.replan(2, 1, small)
    assert row["bit_identical"] and row["swimmers"] == 2 and row["settings"]["candidates"] == 8
    from flownav.flows.grid import load_grid_flow

    flow = load_grid_flow(bench.ROOT / "data" / "cylinder_re300")
    look = bench.look_up(flow, swimmers=3, candidates=5, rounds=1, threads=1)
    assert look["bit_identical"] and look["rows"] == 15
    steps = bench.env_step(batch=8, seconds=0.01, rounds=1)
    assert [(r["flow"], r["batch"]) for r in steps] == [(flow, 8) for flow in bench.ENV_CASES]
    with bench.torch_look_up():
        assert flow.velocity.__func__ is type(flow).velocity_torch  # restored after
    assert flow.velocity.__func__ is not type(flow).velocity_torch
