"""DAgger with the oracle as the expert (flownav/algorithms/oracle_dagger.py): every visited state gets the oracle's
label, a network learns the planner on a tiny problem, runs resume exactly, a shipped copy leaves the pairs out."""

from __future__ import annotations

import re

import pytest
import torch
from tiny import DRIFT_TASK, compose_train

from flownav.algorithms.oracle_dagger import collect
from flownav.checkpoint import load_checkpoint, ship_checkpoint
from flownav.envs import NavigationEnv, RegionTask
from flownav.errors import ConfigError
from flownav.evaluation.oracle import Oracle
from flownav.evaluation.rollout import run_episodes
from flownav.flows import Box, UniformFlow

SMALL = dict(candidates=32, horizon=40, iterations=2, elites=4)
TINY = [
    "+experiment=oracle_imitator",
    "env=default",
    "task=regions",
    *DRIFT_TASK,
    "algo.oracle=oracle",
    *(f"+algo.oracle_settings.{k}={v}" for k, v in SMALL.items()),
    "algo.episodes=32",
    "algo.epochs=30",
    "algo.batch_size=256",
    "algo.hidden=[32,32]",
    "algo.eval_episodes=100",
    "logger=csv",
    "logger.progress=false",
    "threads=1",
]


def test_every_state_of_the_oracles_own_episodes_gets_its_label():
    """beta = 1 (the oracle acts): the same episodes as the protocol's rollout of the oracle (each status frozen at
    its end), one label per running slot and step, each the oracle's action."""
    flow = UniformFlow((0.3, 0.0, 0.0), bounds=Box((-4.0, -7.0, 0.0), (22.0, 7.0, 10.0)))
    make_env = lambda n, chunk: NavigationEnv(flow, RegionTask(), num_envs=n, views=("geo",), seed=3, time_limit=8.0)  # noqa: E731
    ep = run_episodes(Oracle(**SMALL), "geo", make_env, 6, chunk_size=6)
    never = lambda obs: torch.full((len(obs), 3), float("nan"))  # noqa: E731  (would poison any step it acted in)
    obs, labels, status = collect(make_env(6, 0), Oracle(**SMALL), never, "geo", 1.0, torch.Generator())
    assert torch.equal(status, ep.status) and set(status.tolist()) >= {1, 4}  # some reach, some time out
    assert len(obs) == len(labels) == int((ep.time / 0.2).round().sum()) and torch.isfinite(labels).all()


def test_a_network_learns_the_oracle_on_a_tiny_problem(tmp_path):
    import train

    final = train.run(compose_train(*TINY, "algo.iterations=4"), tmp_path / "run")
    history = load_checkpoint(tmp_path / "run/checkpoints/last.pt")["train_state"]["history"]
    curve = [h["eval/success_rate"] for h in history]
    assert curve[0] < 0.5 and final["eval/success_rate"] >= 0.9, curve


def test_resume_continues_exactly_and_a_shipped_copy_leaves_the_pairs_out(tmp_path):
    import train

    quick = ["algo.episodes=8", "algo.epochs=2", "algo.eval_episodes=0"]
    train.run(compose_train(*TINY, *quick, "algo.iterations=3"), tmp_path / "straight")
    train.run(compose_train(*TINY, *quick, "algo.iterations=2"), tmp_path / "part")
    train.run(compose_train(*TINY, *quick, "algo.iterations=3", f"resume={tmp_path / 'part'}"), tmp_path / "x")
    a = load_checkpoint(tmp_path / "straight/checkpoints/last.pt")
    b = load_checkpoint(tmp_path / "part/checkpoints/last.pt")
    assert all(torch.equal(a["policy"]["state_dict"][k], v) for k, v in b["policy"]["state_dict"].items())
    assert torch.equal(a["train_state"]["pairs"]["obs"], b["train_state"]["pairs"]["obs"])
    losses = [[h["train/loss"] for h in c["train_state"]["history"]] for c in (a, b)]
    assert losses[0] == losses[1]
    shipped = load_checkpoint(ship_checkpoint(tmp_path / "part/checkpoints/last.pt", tmp_path / "shipped.pt"))
    assert "pairs" not in shipped["train_state"] and shipped["train_state"]["iteration"] == 3


def test_an_unknown_oracle_is_named_with_the_choices(tmp_path):
    import train

    with pytest.raises(ConfigError, match=r"algo.oracle is 'planner'; choose one of \['oracle', 'oracle_long'\]"):
        train.run(compose_train(*TINY, "algo.oracle=planner"), tmp_path / "run")


def test_a_warm_start_begins_from_the_saved_network_and_keeps_its_normaliser(tmp_path):
    """algo.init_from: the run's network starts as the saved one (weights and normaliser), and the normaliser stays
    the saved one through every refit (the weights read it), not the new pairs' statistics."""
    import train

    quick = ["algo.episodes=8", "algo.epochs=1", "algo.eval_episodes=0", "algo.iterations=1"]
    train.run(compose_train(*TINY, *quick), tmp_path / "source")
    source = load_checkpoint(tmp_path / "source/checkpoints/last.pt")["policy"]["state_dict"]
    warm = [f"algo.init_from={tmp_path / 'source/checkpoints/last.pt'}", "algo.lr=1e-12", "seed=5"]
    train.run(compose_train(*TINY, *quick, *warm), tmp_path / "warm")
    started = load_checkpoint(tmp_path / "warm/checkpoints/last.pt")["policy"]["state_dict"]
    assert all(torch.equal(started[k], v) for k, v in source.items() if k.startswith("normalizer."))
    assert all(torch.allclose(started[k], v, atol=1e-6) for k, v in source.items())  # lr 1e-12: no step away
    train.run(compose_train(*TINY, *quick, "seed=5"), tmp_path / "cold")
    cold = load_checkpoint(tmp_path / "cold/checkpoints/last.pt")["policy"]["state_dict"]
    assert not torch.equal(cold["normalizer.mean"], source["normalizer.mean"])  # other pairs, other statistics


def test_a_warm_start_of_another_view_is_refused_in_one_line(tmp_path):
    import train

    quick = ["algo.episodes=8", "algo.epochs=1", "algo.eval_episodes=0", "algo.iterations=1"]
    train.run(compose_train(*TINY, *quick), tmp_path / "source")
    source = tmp_path / "source/checkpoints/last.pt"
    message = (
        f"algo.init_from={source} reads 'geo_priv', this run reads 'geo': start from a checkpoint of the run's view "
        "or set obs=geo_priv"
    )
    with pytest.raises(ConfigError, match=f"^{re.escape(message)}$"):
        train.run(compose_train(*TINY, *quick, "obs=geo", f"algo.init_from={source}"), tmp_path / "warm")
