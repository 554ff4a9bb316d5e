"""PPO's actor and critic around the shared networks.

The actor is a :class:`~flownav.agents.networks.DeterministicPolicy` whose MLP outputs 6 numbers: the first 3
are a TanhNormal's location, the last 3 its scale parameter. Its deterministic action (tanh of the location,
mapped into the action box) is exactly ``DeterministicPolicy.forward``, so a checkpoint of this actor is a
plain deterministic policy for evaluation and DAgger. The critic reads its own view through its own running
normaliser.
"""

from __future__ import annotations

from tensordict.nn import NormalParamExtractor, TensorDictModule
from torch import nn
from torchrl.modules import ProbabilisticActor, TanhNormal, ValueOperator

from flownav.agents.networks import DeterministicPolicy, ObsNormalizer, check_mlp_size, mlp
from flownav.envs.observations import observation_size


class ActorNet(nn.Module):
    """obs -> DeterministicPolicy's normaliser and MLP (6 outputs) -> (loc, scale) of a TanhNormal."""

    def __init__(self, policy: DeterministicPolicy, init_scale: float = 1.0, scale_lb: float = 1e-3):
        super().__init__()
        self.policy = policy
        self.extract = NormalParamExtractor(scale_mapping=f"biased_softplus_{init_scale}", scale_lb=scale_lb)

    def forward(self, obs):
        return self.extract(self.policy.outputs(obs))


class CriticNet(nn.Module):
    """obs -> own running normaliser -> MLP -> state value."""

    def __init__(self, obs_dim: int, hidden, activation: str):
        super().__init__()
        self.normalizer = ObsNormalizer(obs_dim)
        self.net = mlp(obs_dim, 1, hidden, activation)

    def forward(self, obs):
        return self.net(self.normalizer(obs))

    def load_state_dict(self, state_dict, strict: bool = True, assign: bool = False):
        config = {"obs_dim": self.normalizer.mean.shape[0], "n_outputs": 1}
        config["hidden"] = [m.out_features for m in self.net if isinstance(m, nn.Linear)][:-1]
        check_mlp_size(state_dict, config, "algo.critic.hidden={hidden}")
        return super().load_state_dict(state_dict, strict=strict, assign=assign)


def init_output_layer(seq: nn.Sequential, gain: float) -> None:
    last = [m for m in seq if isinstance(m, nn.Linear)][-1]
    nn.init.orthogonal_(last.weight, gain)
    nn.init.zeros_(last.bias)


def make_actor_critic(obs_key: str, critic_key: str, low, high, actor_cfg, critic_cfg):
    """The deterministic policy, the TanhNormal ProbabilisticActor around it, the critic net and its ValueOperator."""
    policy = DeterministicPolicy(
        observation_size(obs_key),
        low.tolist(),
        high.tolist(),
        hidden=list(actor_cfg["hidden"]),
        activation=str(actor_cfg["activation"]),
        n_outputs=2 * len(low),
        prior=obs_key if actor_cfg.get("prior") else None,
        prior_turn=actor_cfg.get("prior_turn"),
    )
    init_output_layer(policy.net, float(actor_cfg.get("output_gain", 0.01)))
    net = ActorNet(policy, float(actor_cfg["init_scale"]), float(actor_cfg["scale_lb"]))
    actor = ProbabilisticActor(
        TensorDictModule(net, in_keys=[obs_key], out_keys=["loc", "scale"]),
        in_keys=["loc", "scale"],
        distribution_class=TanhNormal,
        distribution_kwargs={"low": low, "high": high, "tanh_loc": False},
        return_log_prob=True,
    )
    critic_net = CriticNet(observation_size(critic_key), list(critic_cfg["hidden"]), str(critic_cfg["activation"]))
    init_output_layer(critic_net.net, 1.0)
    critic = ValueOperator(critic_net, in_keys=[critic_key])
    return policy, actor, critic_net, critic
