"""Tiny training configs shared by the tests: still water, targets about 2 D away, a few swimmers and steps.

cfg = compose_train(*TINY_PPO, "algo.total_frames=1024")   # later overrides win
"""

from __future__ import annotations

from pathlib import Path

from hydra import compose, initialize_config_dir

CONF = str(Path(__file__).resolve().parents[1] / "conf")

STILL_WATER_TASK = [
    "flow=uniform",
    "flow.velocity=[0.0,0.0,0.0]",
    "task.start=[[5.0,0.0,5.0],[6.0,1.0,6.0]]",
    "task.target=[[7.0,0.0,5.0],[8.0,1.0,6.0]]",
]

# DAgger students: a weak current along x, so passive drift fails and the teacher's steering matters.
DRIFT_TASK = [
    "flow=uniform",
    "flow.velocity=[0.1,0.0,0.0]",
    "task.start=[[5.0,0.0,5.0],[6.0,1.0,6.0]]",
    "task.target=[[7.0,0.0,5.0],[8.0,1.0,6.0]]",
    "env.time_limit=20.0",
]

# 2 iterations of 32 swimmers x 8 steps, networks of 8 units, CSV logging only.
TINY_PPO = [
    "+experiment=teacher",
    *STILL_WATER_TASK,
    "env.num_envs=32",
    "env.dt=0.5",
    "env.time_limit=4.0",
    "algo.rollout_steps=8",
    "algo.epochs=1",
    "algo.minibatch_size=128",
    "algo.total_frames=512",
    "algo.eval_every=0",
    "algo.final_eval_episodes=40",
    "algo.actor.hidden=[8]",
    "algo.critic.hidden=[8]",
    "logger=csv",
    "logger.progress=false",
    "threads=1",
]


def compose_train(*overrides):
    """train.py's config with these overrides, as Hydra composes it."""
    with initialize_config_dir(config_dir=CONF, version_base="1.3"):
        return compose("config", overrides=list(overrides))
