"""Gymnasium / Stable-Baselines3 adapters: registration, checkers, the action map, seeding, the same episodes as
the TorchRL env, same-step autoreset, and PPO learning a still-water task."""

import math
import subprocess
import sys
import warnings

import numpy as np
import pytest
import torch

gymnasium = pytest.importorskip("gymnasium")
sb3 = pytest.importorskip("stable_baselines3")

import flownav  # noqa: E402,F401 - registers the ids
from flownav.builders import (  # noqa: E402
    ConfigError,
    build_env,
    build_flow,
    build_task,
    compose_config,
)
from flownav.checkpoint import load_policy  # noqa: E402
from flownav.envs.navigation import DPSI_MAX, DTHETA_MAX, Status  # noqa: E402
from flownav.gym import ENV_IDS  # noqa: E402
from flownav.gym.env import FlowNavEnv, FlowNavVectorEnv  # noqa: E402
from flownav.paths import CHECKPOINT_DIR, REPO_ROOT  # noqa: E402

STILL = {"type": "uniform", "velocity": [0.0, 0.0, 0.0], "bounds": [[-4, -7, 0], [22, 7, 10]]}
ABC_OVERRIDES = ["flow=abc", "task=abc", "env.swim_speed_scale=0.1"]  # the ABC test as evaluate.py poses it


def quiet(fn, *args, **kwargs):
    """Run a checker without its warning about the observation Box's infinite bounds (positions are unbounded)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*Box observation space (minimum|maximum) value is.*infinity")
        return fn(*args, **kwargs)


def torchrl_env(overrides, num_envs, seed, view="geo_sincos"):
    """The TorchRL env the project's own entry points build (Hydra config -> builders)."""
    cfg = compose_config(overrides)
    flow = build_flow(cfg.flow)
    return build_env(cfg.env, flow, build_task(cfg.task, flow), [view], num_envs=num_envs, seed=seed)


def paper_action(a: np.ndarray) -> torch.Tensor:
    """The documented map of [-1, 1]^3 onto the paper's action box (u_max = 1)."""
    low = torch.tensor([0.0, -DTHETA_MAX, -DPSI_MAX])
    high = torch.tensor([1.0, DTHETA_MAX, DPSI_MAX])
    return low + (high - low) * (torch.as_tensor(a, dtype=torch.float32) + 1) / 2


def test_import_registers_lazily_and_survives_without_gymnasium():
    code = (
        "import sys, flownav, gymnasium; "
        f"assert set({list(ENV_IDS)!r}) <= set(gymnasium.registry), 'not registered'; "
        "assert 'torch' not in sys.modules and 'flownav.gym.env' not in sys.modules, 'import is not lazy'"
    )
    subprocess.run([sys.executable, "-c", code], cwd=REPO_ROOT, check=True)
    without = "import sys; sys.modules['gymnasium'] = None; import flownav; assert 'flownav.gym' not in sys.modules"
    subprocess.run([sys.executable, "-c", without], cwd=REPO_ROOT, check=True)


@pytest.mark.parametrize("env_id", list(ENV_IDS))
def test_registered_envs_pass_gymnasium_and_sb3_checkers(env_id):
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gymnasium.make(env_id)
    quiet(check_env, env.unwrapped, skip_render_check=True)
    quiet(sb3_check_env, env.unwrapped, warn=True)
    assert env.observation_space.shape == (9,) and env.action_space.shape == (3,)
    obs, info = env.reset(seed=0)
    assert obs.dtype == np.float32 and set(info) == {
        "position",
        "target",
        "velocity",
        "heading",
        "time",
        "status",
        "is_success",
    }
    # The observation is the view of the privileged state: geo_sincos starts with target - position.
    np.testing.assert_allclose(obs[:3], info["target"] - info["position"], atol=1e-6)


def test_abc_env_is_the_abc_test():
    env = gymnasium.make("flownav/ABC-v0").unwrapped
    assert env.swimmers.nav.swim_speed_scale == 0.1
    _, info = env.reset(seed=0)
    assert -1.8 * math.pi <= info["position"][0] <= -1.5 * math.pi  # conf/task/abc.yaml's start box, in pi


def test_action_map_exact_bounds():
    env = FlowNavEnv(flow=STILL)
    _, info0 = env.reset(seed=1)
    _, _, _, _, info = env.step(np.array([1.0, 1.0, -1.0], np.float32))  # full speed, turn left, tilt down
    theta0, psi0 = info0["heading"]
    theta, psi = info["heading"]
    assert math.isclose(theta, math.remainder(theta0 + 0.2 * math.pi / 4, 2 * math.pi), abs_tol=1e-6)
    assert math.isclose(psi, max(psi0 - 0.2 * math.pi / 2, -math.pi / 2), abs_tol=1e-6)
    assert math.isclose(np.linalg.norm(info["velocity"]), 1.0, abs_tol=1e-6)  # u_max, still water
    _, _, _, _, stop = env.step(np.array([-1.0, 0.0, 0.0], np.float32))  # no speed, no turn
    np.testing.assert_array_equal(stop["velocity"], 0.0)
    np.testing.assert_array_equal(stop["heading"], info["heading"])
    np.testing.assert_array_equal(stop["position"], info["position"])
    _, _, _, _, clipped = env.step(np.array([-5.0, 0.0, 0.0], np.float32))  # clipped to -1
    np.testing.assert_array_equal(clipped["velocity"], 0.0)


def test_action_map_is_the_deterministic_policy_without_tanh():
    policy, _ = load_policy(CHECKPOINT_DIR / "student.pt")
    obs = torch.randn(64, policy.config["obs_dim"]) * 3
    a = torch.tanh(policy.outputs(obs)[:, :3])
    torch.testing.assert_close(paper_action(a.numpy()), policy(obs), atol=1e-6, rtol=0)


def test_seeding():
    env = FlowNavEnv(flow="abc", task="abc")
    first, _ = env.reset(seed=5)
    np.testing.assert_array_equal(env.reset(seed=5)[0], first)
    assert not np.array_equal(env.reset(seed=6)[0], first)
    unseeded = [FlowNavEnv(flow="abc", task="abc").reset()[0] for _ in range(2)]
    assert not np.array_equal(*unseeded)  # gymnasium: an unseeded first reset draws its seed from entropy


def test_single_env_gives_the_torchrl_episodes():
    seed, rng = 7, np.random.default_rng(0)
    gym_env = FlowNavEnv(flow="abc", task="abc", swim_speed_scale=0.1)
    nav = torchrl_env(ABC_OVERRIDES, 1, seed)
    obs, info = gym_env.reset(seed=seed)
    td = nav.reset()
    episodes = 0
    for _ in range(200):
        np.testing.assert_array_equal(obs, td["geo_sincos"][0].numpy())
        np.testing.assert_array_equal(info["position"], td["position"][0].numpy())
        a = rng.uniform(-1, 1, 3).astype(np.float32)
        obs, reward, terminated, truncated, info = gym_env.step(a)
        td = nav.step(td.set("action", paper_action(a)[None]))["next"]
        assert reward == td["reward"].item()
        assert (terminated, truncated) == (td["terminated"].item(), td["truncated"].item())
        if terminated or truncated:
            np.testing.assert_array_equal(obs, td["geo_sincos"][0].numpy())
            assert info["status"] == td["status"].item() != Status.RUNNING
            episodes += 1
            obs, info = gym_env.reset()
            td = nav.reset()
    assert episodes >= 3  # random turns leave the ABC box within a few dozen steps


def test_vector_env_gives_the_torchrl_episodes_with_same_step_autoreset():
    seed, B, rng = 3, 4, np.random.default_rng(1)
    vec = gymnasium.make_vec(
        "flownav/ABC-v0", num_envs=B, vectorization_mode="vector_entry_point", time_limit=4.0
    ).unwrapped
    assert isinstance(vec, FlowNavVectorEnv)
    nav = torchrl_env([*ABC_OVERRIDES, "env.time_limit=4.0"], B, seed)
    obs, info = vec.reset(seed=seed)
    root = nav.reset()
    finished = 0
    for _ in range(60):
        np.testing.assert_array_equal(obs, root["geo_sincos"].numpy())
        a = rng.uniform(-1, 1, (B, 3)).astype(np.float32)
        obs, reward, terminated, truncated, info = vec.step(a)
        stepped, root = nav.step_and_maybe_reset(root.set("action", paper_action(a)))
        nxt = stepped["next"]
        np.testing.assert_array_equal(reward, nxt["reward"][:, 0].numpy())
        np.testing.assert_array_equal(terminated | truncated, nxt["done"][:, 0].numpy())
        done = terminated | truncated
        if done.any():
            np.testing.assert_array_equal(info["_final_obs"], done)
            for i in np.flatnonzero(done):
                np.testing.assert_array_equal(info["final_obs"][i], nxt["geo_sincos"][i].numpy())
                assert info["final_info"]["status"][i] == nxt["status"][i].item() != Status.RUNNING
                assert info["time"][i] == 0.0  # the returned observation starts the next episode
            finished += int(done.sum())
    assert finished >= B  # the 4-time-unit limit (20 steps) ends every swimmer's episode at least once


def test_vector_env_partial_reset_and_one_seed():
    vec = FlowNavVectorEnv(3, flow="abc", task="abc")
    obs, _ = vec.reset(seed=0)
    obs, *_ = vec.step(np.zeros((3, 3), np.float32))
    after, info = vec.reset(options={"reset_mask": np.array([True, False, False])})
    assert info["time"][0] == 0.0 and info["time"][1] > 0.0
    np.testing.assert_array_equal(after[1:], obs[1:])
    with pytest.raises(ValueError, match=r"seed=\[1, 2, 3\]: FlowNavVectorEnv takes one integer seed for all 3"):
        vec.reset(seed=[1, 2, 3])
    with pytest.raises(ValueError, match=r"^action has shape \(2, 3\); expected \(3, 3\) \(values in \[-1, 1\]\)$"):
        vec.step(np.zeros((2, 3), np.float32))


def test_sb3_make_vec_env_reports_whole_episodes():
    from stable_baselines3.common.env_util import make_vec_env

    vec = make_vec_env("flownav/ABC-v0", n_envs=2, seed=0)  # asks for render_mode="rgb_array" first
    vec.reset()
    returns, ended = np.zeros(2), []
    for _ in range(300):
        _, reward, done, infos = vec.step(np.ones((2, 3), np.float32))  # full speed, turning: leaves the box
        returns += reward
        for i in np.flatnonzero(done):
            ended.append((infos[i]["episode"]["r"], returns[i]))
            returns[i] = 0.0
    assert len(ended) >= 2
    for monitor_return, summed in ended:
        assert monitor_return == pytest.approx(summed, abs=1e-5)


def test_bad_keywords_name_the_key():
    with pytest.raises(ConfigError, match=r"unknown env keyword\(s\) \['time_limt'\]; keys of conf/env/default"):
        FlowNavEnv(flow="abc", task="abc", time_limt=3)
    with pytest.raises(ConfigError, match=r"flow='abcd': no conf/flow/abcd.yaml; pass one of \['abc', "):
        FlowNavEnv(flow="abcd")
    with pytest.raises(TypeError, match=r"^render_mode='human': flownav envs do not render; use flownav.viz on"):
        FlowNavEnv(flow="abc", task="abc", render_mode="human")


@pytest.mark.slow
def test_sb3_ppo_learns_still_water():
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    env = gymnasium.make("flownav/CylinderWake-v0", flow=STILL, time_limit=20.0)

    def evaluate(act, n=20):
        returns, successes = [], []
        for k in range(n):
            obs, _ = env.reset(seed=100 + k)
            total, done = 0.0, False
            while not done:
                obs, reward, terminated, truncated, info = env.step(act(obs))
                total, done = total + reward, terminated or truncated
            returns.append(total)
            successes.append(info["is_success"])
        return np.mean(returns), np.mean(successes)

    rng = np.random.default_rng(0)
    random_return, random_success = evaluate(lambda o: rng.uniform(-1, 1, 3).astype(np.float32))
    model = PPO(
        "MlpPolicy",
        env,
        n_steps=512,
        batch_size=128,
        n_epochs=5,
        learning_rate=3e-3,
        gamma=0.98,
        policy_kwargs={"net_arch": [32, 32]},
        seed=0,
        device="cpu",
    )
    model.learn(4096)
    # SB3 saw whole episodes and their is_success flags.
    assert len(model.ep_info_buffer) >= 20 and len(model.ep_success_buffer) == len(model.ep_info_buffer)
    trained_return, trained_success = evaluate(lambda o: model.predict(o, deterministic=True)[0])
    assert random_success == 0.0 and random_return < -5  # random turning never reaches the target in 20 time units
    # 4,096 steps of SB3's PPO: return -10.3 -> 1.0 and 4 of 20 episodes (measured; 8,192 steps still reach 4 of 20).
    # The bar is learning through the gymnasium wrapper; flownav's own PPO learns its tiny problem to > 80%.
    assert trained_return > random_return + 8 and trained_success >= 0.15
