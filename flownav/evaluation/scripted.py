"""A scripted geo expert ("turn towards the target, swim at full speed") and a way to turn any expert into a
checkpointable :class:`~flownav.agents.DeterministicPolicy` by regression. Used by tests and benchmarks as a
stand-in teacher; it is no navigator for the wake (it ignores the flow).
The flow-compensating expert reads the privileged view: the local flow and its own swim speed."""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn

from flownav.agents.flow_compensating import FlowCompensating
from flownav.agents.networks import DeterministicPolicy
from flownav.agents.prior import head_to_target
from flownav.envs.navigation import DPSI_MAX, DTHETA_MAX
from flownav.evaluation.oracle import Oracle

ACTION_LOW = (0.0, -DTHETA_MAX, -DPSI_MAX)


def action_high(u_max: float = 1.0) -> tuple[float, float, float]:
    return (float(u_max), DTHETA_MAX, DPSI_MAX)


class HeadToTarget(nn.Module):
    """Geo observation (to_target, velocity, theta, psi) -> (speed, turn rates towards the target)
    (:func:`flownav.agents.prior.head_to_target`)."""

    def __init__(self, u_max: float = 1.0, speed_fraction: float = 0.98):
        super().__init__()
        self.u_max, self.speed_fraction = float(u_max), float(speed_fraction)

    def forward(self, obs: Tensor) -> Tensor:
        return head_to_target(obs[..., :3], obs[..., 6], obs[..., 7], self.u_max, self.speed_fraction)


class Passive(nn.Module):
    """No swimming, no turning: a passive tracer of the flow (the floor any navigator must beat)."""

    def forward(self, obs: Tensor) -> Tensor:
        return obs.new_zeros(obs.shape[:-1] + (3,))


# Scripted reference policies the evaluation suite can name (``policies.<name>.scripted``, keyword arguments in
# ``policies.<name>.settings``); each reads the geo view unless it names another (``view``, see scripted_view).
# The oracle (oracle.py) plans from the env's true state.
SCRIPTED = {"head_to_target": HeadToTarget, "passive": Passive, "oracle": Oracle, "flow_compensating": FlowCompensating}


def scripted_view(policy) -> str:
    """The observation view a scripted policy reads (``geo`` unless it names another)."""
    return getattr(policy, "view", "geo")


def load_evaluated(name: str, key: str = "checkpoint", expect_obs: str | None = None, device="cpu"):
    """(policy, payload) of a checkpoint file, or of a scripted reference named ``scripted:<name>``, which reads the
    geo view unless it names another. ``key``: the setting that named it, for the message of an unknown name."""
    from flownav.checkpoint import load_policy  # the checkpoint loader imports the networks; keep this module light
    from flownav.errors import ConfigError
    from flownav.paths import resolve

    if not name.startswith("scripted:"):
        return load_policy(resolve(name), expect_obs=expect_obs, device=device)
    kind = name.split(":", 1)[1]
    if kind not in SCRIPTED:
        raise ConfigError(f"{key}={name} names no scripted policy; choose scripted:<{'|'.join(SCRIPTED)}>")
    policy = SCRIPTED[kind]()
    return policy, {"obs": scripted_view(policy), "role": "reference"}


def random_geo_obs(n: int, generator: torch.Generator | None = None, scale: float = 12.0) -> Tensor:
    """Geo observations with target distances log-uniform in [0.1, scale] (dense near the target)."""
    direction = torch.randn(n, 3, generator=generator)
    direction = direction / direction.norm(dim=-1, keepdim=True).clamp_min(1e-6)
    radius = torch.exp(torch.empty(n, 1).uniform_(math.log(0.1), math.log(scale), generator=generator))
    d = direction * radius
    v = torch.randn(n, 3, generator=generator)
    theta = (torch.rand(n, generator=generator) * 2 - 1) * math.pi
    psi = (torch.rand(n, generator=generator) * 2 - 1) * (math.pi / 2) * 0.9
    return torch.cat((d, v, theta[:, None], psi[:, None]), -1)


def fit_expert(
    expert: nn.Module,
    obs_dim: int = 8,
    hidden=(64, 64),
    steps: int = 1500,
    batch: int = 2048,
    lr: float = 1e-2,
    seed: int = 0,
    u_max: float = 1.0,
    sampler=random_geo_obs,
) -> tuple[DeterministicPolicy, float]:
    """Regress a DeterministicPolicy on ``expert`` over random observations; returns it and its final MSE."""
    g = torch.Generator().manual_seed(seed)
    torch.manual_seed(seed)
    policy = DeterministicPolicy(obs_dim, ACTION_LOW, action_high(u_max), hidden=hidden, activation="tanh")
    policy.normalizer.update(sampler(50_000, g))
    opt = torch.optim.Adam(policy.parameters(), lr=lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, steps)
    loss = torch.tensor(float("nan"))
    for _ in range(steps):
        x = sampler(batch, g)
        with torch.no_grad():
            y = expert(x)
        loss = ((policy(x) - y) ** 2).sum(-1).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
    return policy.eval(), float(loss.detach())
