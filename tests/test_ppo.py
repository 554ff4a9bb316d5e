"""PPO learns, checkpoints resume exactly where they stopped, the actor is a DeterministicPolicy."""

from __future__ import annotations

import csv
import re
from pathlib import Path

import pytest
import torch
from hydra import compose, initialize_config_dir
from tiny import STILL_WATER_TASK

from flownav.checkpoint import CheckpointError, load_checkpoint, load_policy
from flownav.envs.observations import observation_size

CONF = str(Path(__file__).resolve().parents[1] / "conf")

# Still water, targets about 2 D away, short episodes: learnable in seconds.
TINY = [
    *STILL_WATER_TASK,
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
    from flownav.builders import build_flow, build_task
    from flownav.evaluation.protocol import EvalSpec, evaluate

    flow = build_flow(cfg.flow)
    spec = EvalSpec(flow, build_task(cfg.task, flow), cfg.env, episodes, seed=777)
    return evaluate(policy, str(cfg.obs.view), spec).success_rate


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

    from flownav.agents.actor_critic import make_actor_critic

    cfg = make_cfg()
    low, high = torch.tensor([0.0, -0.785, -1.57]), torch.tensor([1.0, 0.785, 1.57])
    policy, actor, _, _ = make_actor_critic("geo", "geo", low, high, cfg.algo.actor, cfg.algo.critic)
    torch.nn.init.normal_(policy.net[-1].weight)  # non-trivial locations
    obs = torch.randn(64, 8) * 3
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        td = actor(TensorDict({"geo": obs}, batch_size=[64]))
    torch.testing.assert_close(td["action"], policy(obs), rtol=1e-5, atol=1e-5)


def test_final_evaluation_is_the_protocols(tmp_path):
    """PPO's final evaluation is protocol.evaluate of last.pt on the held-out spec: the same summary, and it is
    not a trivial one (a stream that carries some swimmers to the target and most out of the domain)."""
    from tiny import TINY_PPO, compose_train

    from flownav.algorithms.common import eval_metrics
    from flownav.builders import build_flow, build_task
    from flownav.evaluation.protocol import EvalSpec, evaluate
    from train import run

    cfg = compose_train(*TINY_PPO, "flow.velocity=[1.0,0.0,0.0]", "env.time_limit=20.0")
    final = run(cfg, tmp_path)
    policy, _ = load_policy(tmp_path / "checkpoints" / "last.pt", expect_obs=str(cfg.obs.view))
    flow = build_flow(cfg.flow)
    spec = EvalSpec(flow, build_task(cfg.task, flow), cfg.env, int(cfg.algo.final_eval_episodes))
    summary = evaluate(policy, str(cfg.obs.view), spec).summary
    assert 0 < summary["successes"] < summary["episodes"] == 40
    assert len([f for f in summary["failures"].values() if f["count"]]) == 2
    expected = eval_metrics(summary)
    assert {k: final[k] for k in expected} == expected


def test_resume_continues_step_optimizer_and_normalizer(tmp_path):
    from flownav.agents.actor_critic import make_actor_critic
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
    policy, _, critic_net, critic = make_actor_critic(
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
    from flownav.errors import ConfigError
    from train import run

    run(make_cfg("algo.total_frames=4096", "algo.final_eval_episodes=0"), tmp_path)
    with initialize_config_dir(config_dir=CONF, version_base="1.3"):
        cfg = compose(
            "config", overrides=["+experiment=baseline_ego", *TINY, "algo.total_frames=8192", f"resume={tmp_path}"]
        )
    expected = (
        f"resume={tmp_path}: that run trained a teacher on 'geo_sincos' observations but this config asks for 'ego'; "
        "resume with the same obs (obs=geo_sincos)"
    )
    with pytest.raises(ConfigError) as err:
        run(cfg, tmp_path / "x")
    assert str(err.value) == expected


def _student_file(tmp_path, view="geo_sincos", **config):
    """A DAgger-shaped student (3 outputs) with a non-trivial last layer, saved as a checkpoint."""
    from flownav.agents.networks import DeterministicPolicy
    from flownav.checkpoint import save_policy_checkpoint

    torch.manual_seed(3)
    student = DeterministicPolicy(observation_size(view), [0.0, -0.79, -1.57], [1.0, 0.79, 1.57], hidden=[8], **config)
    torch.nn.init.normal_(student.net[-1].weight)
    student.normalizer.update(torch.randn(500, observation_size(view)) * 2 + 1)
    return save_policy_checkpoint(tmp_path / "student.pt", student, view, "student"), student


def test_a_dagger_student_warm_starts_the_ppo_actor_with_its_own_action():
    """algo.init_from=<a DAgger student>: the actor's location outputs are the student's (its deterministic action
    exactly), its scale outputs the actor's own initial ones; another prior is refused in one line."""
    import tempfile

    from tensordict import TensorDict
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    from flownav.agents.actor_critic import make_actor_critic
    from flownav.agents.networks import warm_start_state
    from flownav.errors import ConfigError

    cfg = make_cfg("algo.actor.hidden=[8]")
    low, high = torch.tensor([0.0, -0.79, -1.57]), torch.tensor([1.0, 0.79, 1.57])
    with tempfile.TemporaryDirectory() as d:
        path, student = _student_file(Path(d))
        payload = load_checkpoint(path)
    policy, actor, _, _ = make_actor_critic("geo_sincos", "geo_sincos", low, high, cfg.algo.actor, cfg.algo.critic)
    scale_rows = policy.net[-1].weight[3:].clone()
    policy.load_state_dict(warm_start_state(policy, payload["policy"]))
    obs = torch.randn(64, 9) * 3
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        td = actor(TensorDict({"geo_sincos": obs}, batch_size=[64]))
    torch.testing.assert_close(td["action"], student(obs))
    assert torch.equal(policy.net[-1].weight[3:], scale_rows)
    with_prior = make_cfg("algo.actor.hidden=[8]", "algo.actor.prior=head_to_target").algo.actor
    other, *_ = make_actor_critic("geo_sincos", "geo_sincos", low, high, with_prior, cfg.algo.critic)
    message = (
        "the checkpoint's policy corrects prior=None turning None, this one prior=geo_sincos turning left_biased: "
        "set algo.actor.prior and algo.actor.prior_turn (PPO) or algo.prior and algo.prior_turn (oracle DAgger) "
        "to match"
    )
    with pytest.raises(ConfigError, match=f"^{re.escape(message)}$"):
        warm_start_state(other, payload["policy"])


def test_during_the_critic_warmup_only_the_critic_learns(tmp_path):
    """algo.critic_warmup_frames: a warm-started actor keeps its weights (and so its action) while the critic
    learns; after the warm-up both learn."""
    from tiny import TINY_PPO, compose_train

    from train import run

    path, student = _student_file(tmp_path)
    start = ["algo.init_from=" + str(path), "algo.update_normalizer=false", "algo.final_eval_episodes=0"]
    run(compose_train(*TINY_PPO, *start, "algo.critic_warmup_frames=512"), tmp_path / "warm")
    saved = load_checkpoint(tmp_path / "warm" / "checkpoints" / "last.pt")
    policy, _ = load_policy(tmp_path / "warm" / "checkpoints" / "last.pt")
    obs = torch.randn(64, 9) * 3
    torch.testing.assert_close(policy(obs), student(obs))
    critic0 = load_checkpoint(path).get("train_state") or {}
    assert "critic" not in critic0 and saved["train_state"]["critic"]  # a critic was trained from scratch
    # 3 batches of 256 frames, the last two after the warm-up (the learning rate anneals to 0 only at the end)
    run(compose_train(*TINY_PPO, *start, "algo.critic_warmup_frames=256", "algo.total_frames=768"), tmp_path / "after")
    moved, _ = load_policy(tmp_path / "after" / "checkpoints" / "last.pt")
    assert not torch.allclose(moved(obs), student(obs))


def test_the_anchor_is_the_kl_to_the_warm_start_at_the_collection_scale(tmp_path):
    """algo.anchor_coeff's term: zero for an actor that acts as its warm start, sum (shift / scale)^2 / 2 when its
    location outputs are shifted; the anchor is the checkpoint's policy, frozen."""
    from tensordict import TensorDict

    from flownav.agents.actor_critic import make_actor_critic
    from flownav.agents.networks import warm_start_state
    from flownav.algorithms.ppo import anchor_loss, load_anchor

    cfg = make_cfg("algo.actor.hidden=[8]")
    low, high = torch.tensor([0.0, -0.79, -1.57]), torch.tensor([1.0, 0.79, 1.57])
    path, _ = _student_file(tmp_path)
    policy, *_ = make_actor_critic("geo_sincos", "geo_sincos", low, high, cfg.algo.actor, cfg.algo.critic)
    policy.load_state_dict(warm_start_state(policy, load_checkpoint(path)["policy"]))
    anchor, _ = load_anchor(str(path), "geo_sincos", "cpu", None)
    assert not any(p.requires_grad for p in anchor.parameters())
    scale = torch.tensor([0.5, 0.25, 2.0]).expand(64, 3)
    batch = TensorDict({"geo_sincos": torch.randn(64, 9) * 3, "scale": scale}, batch_size=[64])
    assert anchor_loss(policy, anchor, batch, "geo_sincos").item() == 0.0
    with torch.no_grad():
        policy.net[-1].bias[:3] += torch.tensor([0.1, 0.2, 0.0])
    expected = (0.1 / 0.5) ** 2 / 2 + (0.2 / 0.25) ** 2 / 2
    torch.testing.assert_close(anchor_loss(policy, anchor, batch, "geo_sincos"), torch.tensor(expected))


def test_an_anchored_warm_start_stays_near_its_student_and_needs_one(tmp_path):
    """With a strong anchor the actor moves far less from the student than without one over the same updates; an
    anchor without algo.init_from is refused in one line."""
    from tiny import TINY_PPO, compose_train

    from flownav.errors import ConfigError
    from train import run

    path, student = _student_file(tmp_path)
    start = ["algo.init_from=" + str(path), "algo.update_normalizer=false", "algo.final_eval_episodes=0"]
    obs = torch.randn(256, 9) * 3
    moved = {}
    for coef in (0.0, 100.0):
        cfg = compose_train(*TINY_PPO, *start, "algo.total_frames=768", f"algo.anchor_coeff={coef}")
        run(cfg, tmp_path / str(coef))
        policy, _ = load_policy(tmp_path / str(coef) / "checkpoints" / "last.pt")
        moved[coef] = (policy(obs) - student(obs)).abs().mean().item()
    assert moved[100.0] < 0.5 * moved[0.0]
    message = (
        "algo.anchor_coeff (1.0) pulls the actor towards algo.init_from's policy: set algo.init_from or "
        "algo.anchor_coeff=0"
    )
    with pytest.raises(ConfigError, match=f"^{re.escape(message)}$"):
        run(compose_train(*TINY_PPO, "algo.anchor_coeff=1.0"), tmp_path / "none")
