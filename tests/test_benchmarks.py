"""The benchmarks' own code paths at tiny size, so that a change of the env's internals cannot break them
unseen (their timings are never asserted)."""

import importlib.util
import math

from flownav.algorithms.ppo import make_actor_critic
from flownav.envs import NavigationEnv
from flownav.flows import UniformFlow
from flownav.flows.base import WAKE_BOUNDS
from flownav.paths import REPO_ROOT


def _load(name):
    spec = importlib.util.spec_from_file_location(name, REPO_ROOT / "benchmarks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_plain_collection_loop_of_the_train_benchmark_runs():
    bench = _load("train_throughput")
    flow = UniformFlow((0.5, 0.0, 0.0), bounds=WAKE_BOUNDS)
    env = NavigationEnv(flow, num_envs=32, views=("geo_sincos",), time_limit=2.0)  # resets within the run
    low, high = env.action_spec.space.low[0], env.action_spec.space.high[0]
    hidden = {"hidden": [8, 8], "activation": "tanh", "init_scale": 0.5, "scale_lb": 1e-3, "output_gain": 0.01}
    policy, *_ = make_actor_critic("geo_sincos", "geo_sincos", low, high, hidden, {"hidden": [8], "activation": "tanh"})
    rate = bench.plain_collect(env, policy, "geo_sincos", 25)
    assert math.isfinite(rate) and rate > 0
