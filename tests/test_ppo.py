"""PPO learns, checkpoints resume exactly where they stopped, the actor is a DeterministicPolicy."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
import torch
from hydra import compose, initialize_config_dir

from flownav.checkpoint import CheckpointError, load_checkpoint, load_policy
from flownav.envs.observations import observation_size

CONF = str(Path(__file__).resolve().parents[1] / "conf")

# Still water, targets about 2 D away, short episodes: learnable in seconds.
TINY = [
    "flow=uniform",
    "flow.velocity=[0.0,0.0,0.0]",
    "task.start=[[5.0,0.0,5.0],[6.0,1.0,6.0]]",
    "task.target=[[7.0,0.0,5.0],[8.0,1.0,6.0]]",
    "env.num_envs=256",
    "env.dt=0.5",
    "env.time_limit=15.0",
    "env.reward.time_penalty=0.1",
    "env.reward.success_radius=0.5",
    "algo.lr=1e-3",
    "algo.rollout_steps=16",
    "algo.epochs=4",
    "algo.minibatch_size=1024",
    "algo.actor.hidden=[64,64]",
    "algo.critic.hidden=[64,64]",
    "logger=csv",
    "logger.progress=false",
    "threads=1",
]


def make_cfg(*overrides):
    with initialize_config_dir(config_dir=CONF, version_base="1.3"):
        return compose("config", overrides=["+experiment=teacher", *TINY, *overrides])


def rows(run_dir):
    return list(csv.DictReader(open(Path(run_dir) / "metrics.csv", newline="")))


def _success(policy, cfg, episodes=1000):
    from flownav.algorithms.ppo import evaluate_policy
    from flownav.builders import build_env, build_flow, build_task

    flow = build_flow(cfg.flow)
    task = build_task(cfg.task, flow)
    view = str(cfg.obs.view)
    make_env = lambda n, o: build_env(cfg.env, flow, task, [view], num_envs=n, seed=777 + o)  # noqa: E731
    return evaluate_policy(policy, make_env, view, episodes)["success_rate"]


@pytest.mark.slow
def test_ppo_learns_tiny_navigation(tmp_path):
    """Still water, target ~2 D away: held-out success goes from ~0 to > 80% in ~250k swimmer steps.

    The teacher's view (geo_sincos) needs twice the steps of the raw-angle geo here (0.52 at 120k; geo 0.98):
    turning round from straight away, theta = pi, is a sharp function of (cos, sin) but a linear one of theta.
    """
    from flownav.agents.networks import DeterministicPolicy
    from train import run

    cfg = make_cfg("algo.total_frames=245760", "algo.final_eval_episodes=0", "checkpoint_every=100")
    torch.manual_seed(0)
    view = str(cfg.obs.view)  # the teacher's: geo_sincos
    untrained = DeterministicPolicy(
        observation_size(view), [0.0, -0.79, -1.57], [1.0, 0.79, 1.57], hidden=[64, 64], n_outputs=6
    )
    assert _success(untrained, cfg) < 0.1
    run(cfg, tmp_path)
    policy, payload = load_policy(tmp_path / "checkpoints" / "last.pt", expect_obs=view)
    assert payload["role"] == "teacher" and policy.config["n_outputs"] == 6
    success = _success(policy, cfg)
    assert success > 0.8, f"PPO did not learn the tiny task: held-out success {success:.3f}"
    # Periodic deterministic evaluation (every 10 of the 60 iterations) drives best.pt.
    evals = [float(r["eval/success_rate"]) for r in rows(tmp_path) if r.get("eval/success_rate")]
    assert len(evals) == 6 and evals[-1] > 0.7, evals
    best = load_checkpoint(tmp_path / "checkpoints" / "best.pt")
    assert best["meta"]["metrics"]["eval/success_rate"] == max(evals)
    with pytest.raises(CheckpointError, match="ego"):
        load_policy(tmp_path / "checkpoints" / "last.pt", expect_obs="ego")


def test_deterministic_action_is_tanh_of_loc():
    from tensordict import TensorDict
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    from flownav.algorithms.ppo import make_actor_critic

    cfg = make_cfg()
    low, high = torch.tensor([0.0, -0.785, -1.57]), torch.tensor([1.0, 0.785, 1.57])
    policy, actor, _, _ = make_actor_critic("geo", "geo", low, high, cfg.algo.actor, cfg.algo.critic)
    torch.nn.init.normal_(policy.net[-1].weight)  # non-trivial locations
    obs = torch.randn(64, 8) * 3
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        td = actor(TensorDict({"geo": obs}, batch_size=[64]))
    torch.testing.assert_close(td["action"], policy(obs), rtol=1e-5, atol=1e-5)


def test_resume_continues_step_optimizer_and_normalizer(tmp_path):
    from flownav.algorithms import ppo
    from train import run

    batch = 256 * 16
    cfg = make_cfg(f"algo.total_frames={2 * batch}", "checkpoint_every=1", "algo.final_eval_episodes=0")
    run(cfg, tmp_path)
    saved = load_checkpoint(tmp_path / "checkpoints" / "last.pt")
    assert saved["train_state"]["frames"] == 2 * batch and saved["train_state"]["iteration"] == 2

    # restore_training_state puts exactly the saved tensors back (policy, optimiser, env)
    from flownav.builders import build_env, build_flow, build_task
    from flownav.checkpoint import restore_training_state

    flow = build_flow(cfg.flow)
    env = build_env(cfg.env, flow, build_task(cfg.task, flow), [cfg.obs.view], num_envs=256)
    low, high = env.action_spec.space.low[0], env.action_spec.space.high[0]
    policy, _, critic_net, critic = ppo.make_actor_critic(
        cfg.obs.view, cfg.obs.view, low, high, cfg.algo.actor, cfg.algo.critic
    )
    params = list(policy.parameters()) + list(critic_net.parameters())
    optim = torch.optim.Adam(params, lr=1e-3)
    st = restore_training_state(saved, policy, optim, env)
    assert (st["frames"], st["iteration"]) == (2 * batch, 2)
    for k, v in saved["policy"]["state_dict"].items():
        torch.testing.assert_close(policy.state_dict()[k], v, rtol=0, atol=0)
    assert saved["policy"]["state_dict"]["normalizer.count"] > 0
    for k, v in saved["train_state"]["env"].items():
        if torch.is_tensor(v):
            torch.testing.assert_close(getattr(env, k, None) if k != "rng" else env.rng.get_state(), v, rtol=0, atol=0)
    for (_, a), (_, b) in zip(
        sorted(optim.state_dict()["state"].items()),
        sorted(saved["train_state"]["optimizer"]["state"].items()),
        strict=True,
    ):
        for key in ("exp_avg", "exp_avg_sq", "step"):
            torch.testing.assert_close(a[key], b[key], rtol=0, atol=0)

    # the resumed run continues from the saved step and writes into the same directory
    cfg2 = make_cfg(
        f"algo.total_frames={3 * batch}", "checkpoint_every=1", "algo.final_eval_episodes=0", f"resume={tmp_path}"
    )
    run(cfg2, tmp_path / "elsewhere")
    steps = [int(r["step"]) for r in rows(tmp_path)]
    assert steps == [batch, 2 * batch, 3 * batch]
    last = load_checkpoint(tmp_path / "checkpoints" / "last.pt")
    st = last["train_state"]
    assert st["frames"] == 3 * batch and st["iteration"] == 3
    # Adam kept counting from the saved state: 3 iterations x epochs x minibatches steps in total
    n_steps = 3 * cfg.algo.epochs * (batch // cfg.algo.minibatch_size)
    assert all(int(s["step"]) == n_steps for s in st["optimizer"]["state"].values())
    # the normaliser kept its statistics: warm-up reset + 3 batches of observations
    assert float(last["policy"]["state_dict"]["normalizer.count"]) == 256 + 3 * batch


def test_resume_refuses_other_view(tmp_path):
    from flownav.builders import ConfigError
    from train import run

    run(make_cfg("algo.total_frames=4096", "algo.final_eval_episodes=0"), tmp_path)
    with initialize_config_dir(config_dir=CONF, version_base="1.3"):
        cfg = compose(
            "config", overrides=["+experiment=baseline_ego", *TINY, "algo.total_frames=8192", f"resume={tmp_path}"]
        )
    with pytest.raises(ConfigError, match="geo"):
        run(cfg, tmp_path / "x")


def test_report_eval_ships_the_best_checkpoint_by_held_out_success(tmp_path, capsys):
    """`report eval --ship` evaluates every seed on the same held-out episodes and copies the best one; only
    finished runs of the experiment's budget, on the full held-out episode count."""
    from omegaconf import OmegaConf

    from flownav.algorithms import report
    from flownav.checkpoint import save_policy_checkpoint
    from flownav.evaluation.scripted import HeadToTarget, Passive, fit_expert

    overrides = [o for o in TINY if o.startswith(("flow", "task", "env."))]
    config = OmegaConf.to_container(make_cfg(), resolve=True)  # the teacher experiment at its full budget
    paths = []
    for name, expert in (("drifts", Passive()), ("swims", HeadToTarget())):
        policy, _ = fit_expert(expert, hidden=(32, 32), steps=400, batch=512, seed=0)
        finished = {"frames": config["algo"]["total_frames"]}
        meta = {"config": config}
        paths.append(str(save_policy_checkpoint(tmp_path / f"{name}.pt", policy, "geo", "teacher", meta, finished)))
    args = ["eval", "--name", "t", "--out", str(tmp_path / "t.json"), "--threads", "1"]
    args += [a for o in overrides for a in ("--override", o)] + ["--ship", str(tmp_path / "shipped.pt")]

    with pytest.raises(SystemExit, match=r"^error: --episodes 64 is below the 10000 a shipped result needs"):
        report.main([*args, "--episodes", "64", *paths])
    unfinished = dict(config, algo=dict(config["algo"], total_frames=4096))
    policy, _ = fit_expert(Passive(), hidden=(8,), steps=1, batch=8, seed=0)
    short = save_policy_checkpoint(
        tmp_path / "short.pt", policy, "geo", "teacher", {"config": unfinished}, {"frames": 4096}
    )
    with pytest.raises(SystemExit, match=r"algo\.total_frames=4096 is below experiment teacher's 45000000"):
        report.main([*args, *paths, str(short)])
    assert not (tmp_path / "shipped.pt").exists() and not (tmp_path / "t.json").exists()

    report.main([*args, *paths])
    out = json.loads((tmp_path / "t.json").read_text())
    rates = [r["success_rate"] for r in out["runs"]]
    assert rates[0] == 0.0 and rates[1] > 0.5 and out["runs"][0]["episodes"] == 10_000
    assert out["shipped"]["checkpoint"] == paths[1]
    shipped, best = load_checkpoint(tmp_path / "shipped.pt"), load_checkpoint(paths[1])
    assert all(torch.equal(shipped["policy"]["state_dict"][k], v) for k, v in best["policy"]["state_dict"].items())
