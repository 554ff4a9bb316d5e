"""Networks shared by every policy: an MLP, a running observation normaliser, and the
deterministic policy that evaluation, DAgger labelling and checkpoints use.

A teacher (PPO) and a student (DAgger) differ only in how their MLP is trained: the PPO
actor's MLP outputs ``2 * action_dim`` numbers (location and scale of a TanhNormal), the
student's outputs ``action_dim``. In both, the deterministic action is the first
``action_dim`` outputs squashed by tanh into the action box.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor, nn

from flownav.agents.prior import TURN_LEFT_BIASED, HeadToTargetPrior

ACTIVATIONS = {"tanh": nn.Tanh, "relu": nn.ReLU, "elu": nn.ELU, "silu": nn.SiLU}


def mlp(in_dim: int, out_dim: int, hidden: Sequence[int] = (256, 256), activation: str = "tanh") -> nn.Sequential:
    if activation not in ACTIVATIONS:
        raise ValueError(f"unknown activation {activation!r}; choose from {sorted(ACTIVATIONS)}")
    layers, last = [], in_dim
    for h in hidden:
        layers += [nn.Linear(last, int(h)), ACTIVATIONS[activation]()]
        last = int(h)
    layers.append(nn.Linear(last, out_dim))
    return nn.Sequential(*layers)


class ObsNormalizer(nn.Module):
    """Running mean and variance (parallel Welford); frozen unless :meth:`update` is called.

    Part of the policy rather than an env transform (TorchRL's VecNorm): checkpoints, exports and the gym
    wrapper carry the statistics with the weights, and DAgger sets them from its aggregated data."""

    def __init__(self, dim: int, clip: float = 10.0, eps: float = 1e-6):
        super().__init__()
        self.clip, self.eps = clip, eps
        self.register_buffer("mean", torch.zeros(dim))
        self.register_buffer("var", torch.ones(dim))
        self.register_buffer("count", torch.zeros(()))

    @torch.no_grad()
    def update(self, x: Tensor) -> None:
        x = x.reshape(-1, self.mean.shape[0]).to(self.mean)
        n = x.shape[0]
        if n == 0:
            return
        batch_mean, batch_var = x.mean(0), x.var(0, unbiased=False)
        total = self.count + n
        delta = batch_mean - self.mean
        # In place: TorchRL losses hold references to these buffers; rebinding them leaves stale copies.
        self.var.copy_((self.var * self.count + batch_var * n + delta**2 * self.count * n / total) / total)
        self.mean.add_(delta * n / total)
        self.count.copy_(total)

    def forward(self, x: Tensor) -> Tensor:
        return ((x - self.mean) / (self.var + self.eps).sqrt()).clamp(-self.clip, self.clip)


class SquashedAction(nn.Module):
    """Map unbounded numbers to the action box with tanh: low + (high - low) (tanh(x) + 1) / 2."""

    def __init__(self, low: Sequence[float], high: Sequence[float]):
        super().__init__()
        self.register_buffer("low", torch.as_tensor(low, dtype=torch.float32))
        self.register_buffer("high", torch.as_tensor(high, dtype=torch.float32))

    def forward(self, x: Tensor) -> Tensor:
        return self.low + (self.high - self.low) * (torch.tanh(x) + 1) / 2


class DeterministicPolicy(nn.Module):
    """observation -> normalise -> MLP -> first ``action_dim`` outputs -> tanh into the action box.

    With ``prior`` (a view name, for :class:`~flownav.agents.prior.HeadToTargetPrior`) the MLP's first
    ``action_dim`` outputs are a correction added to head-to-target's action before the squash; ``prior_turn``
    is how that head-to-target yaws (recorded in the config; a config with a prior and without it is a policy
    trained on the left-biased rule, ``TURN_LEFT_BIASED``)."""

    def __init__(
        self,
        obs_dim: int,
        action_low: Sequence[float],
        action_high: Sequence[float],
        hidden: Sequence[int] = (256, 256),
        activation: str = "tanh",
        n_outputs: int | None = None,
        prior: str | None = None,
        prior_turn: str | None = None,
    ):
        super().__init__()
        self.action_dim = len(action_low)
        self.config = {
            "obs_dim": int(obs_dim),
            "action_low": [float(v) for v in action_low],
            "action_high": [float(v) for v in action_high],
            "hidden": [int(h) for h in hidden],
            "activation": activation,
            "n_outputs": int(n_outputs or self.action_dim),
        }
        if prior is not None:
            self.config["prior"] = prior
            if prior_turn is not None:
                self.config["prior_turn"] = prior_turn
        self.normalizer = ObsNormalizer(obs_dim)
        self.net = mlp(obs_dim, self.config["n_outputs"], hidden, activation)
        self.squash = SquashedAction(action_low, action_high)
        turn = prior_turn or TURN_LEFT_BIASED
        self.prior = None if prior is None else HeadToTargetPrior(prior, action_low, action_high, turn)

    def outputs(self, obs: Tensor) -> Tensor:
        """The MLP's outputs, the prior's action added to the first ``action_dim`` (pre-tanh)."""
        out = self.net(self.normalizer(obs))
        if self.prior is None:
            return out
        a = self.action_dim
        return torch.cat((out[..., :a] + self.prior(obs), out[..., a:]), -1)

    def forward(self, obs: Tensor) -> Tensor:
        return self.squash(self.outputs(obs)[..., : self.action_dim])

    def load_state_dict(self, state_dict, strict: bool = True, assign: bool = False):
        check_mlp_size(state_dict, self.config, "algo.actor.hidden={hidden} (PPO) or algo.hidden={hidden} (DAgger)")
        return super().load_state_dict(state_dict, strict=strict, assign=assign)


def warm_start_state(policy: DeterministicPolicy, saved: dict) -> dict:
    """The state dict that starts ``policy`` from a saved policy (``{"config", "state_dict"}`` of a checkpoint).

    Same shape: the saved weights. A deterministic policy (``action_dim`` outputs, a DAgger student) into a PPO
    actor (``2 * action_dim``): the saved weights give the location outputs and ``policy``'s own last-layer rows the
    scale outputs, so the actor's deterministic action is the saved policy's. The prior must be the same (the same
    weights correct another head-to-target otherwise)."""
    from flownav.errors import ConfigError

    mine, theirs = policy.config, saved["config"]

    def prior(c):
        return (c.get("prior"), (c.get("prior_turn") or TURN_LEFT_BIASED) if c.get("prior") else None)

    if prior(mine) != prior(theirs):
        raise ConfigError(
            f"the checkpoint's policy corrects prior={theirs.get('prior')} turning {prior(theirs)[1]}, this one "
            f"prior={mine.get('prior')} turning {prior(mine)[1]}: set algo.actor.prior and algo.actor.prior_turn "
            "(PPO) or algo.prior and algo.prior_turn (oracle DAgger) to match"
        )
    state = dict(saved["state_dict"])
    a = policy.action_dim
    if theirs.get("n_outputs") == a and mine["n_outputs"] == 2 * a:
        own = policy.state_dict()
        last = max((k for k in state if _layer_index(k) >= 0), key=_layer_index)
        bias = last.replace("weight", "bias")
        check_mlp_size(state, {**mine, "n_outputs": a}, "algo.actor.hidden={hidden} (PPO)")
        state[last] = torch.cat((state[last], own[last][a:]), 0)
        state[bias] = torch.cat((state[bias], own[bias][a:]), 0)
    return state


def check_mlp_size(state_dict, config: dict, fix: str) -> None:
    """Refuse, in one line naming the sizes and the ``fix`` (a key to set, ``{hidden}`` the saved sizes),
    the weights of an MLP (``net.*``) of another shape than ``config`` (``obs_dim``, ``hidden``, ``n_outputs``)."""
    weights = [state_dict[k] for k in sorted(state_dict, key=_layer_index) if _layer_index(k) >= 0]
    if not weights:
        return
    saved = {
        "obs_dim": weights[0].shape[1],
        "hidden": [w.shape[0] for w in weights[:-1]],
        "n_outputs": weights[-1].shape[0],
    }
    mine = {k: config[k] for k in saved}
    if saved != mine:
        from flownav.errors import CheckpointError

        raise CheckpointError(
            f"the checkpoint's network was trained with hidden={saved['hidden']} ({saved['obs_dim']} inputs, "
            f"{saved['n_outputs']} outputs) but this one has hidden={mine['hidden']} ({mine['obs_dim']} inputs, "
            f"{mine['n_outputs']} outputs): set {fix.format(hidden=saved['hidden'])} or use a checkpoint of this size"
        )


def _layer_index(key: str) -> int:
    """Index of an MLP layer's weight (``net.<i>.weight``) in a state dict, -1 for other entries."""
    parts = key.split(".")
    return int(parts[1]) if len(parts) == 3 and parts[0] == "net" and parts[2] == "weight" else -1
