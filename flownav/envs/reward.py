"""Reward of eq. 6, signed so that approaching the target pays:

    r_n = -gamma_n dt + alpha (d_{n-1} - d_n) + r_success [success_n]

where success_n means the step's segment from x_{n-1} to x_n passes within success_radius of the target
(flownav/envs/core.py: a fast step must not jump over the ball; the paper checks d_n only), and
gamma_n = time_penalty * min(d_n / d_0, 1): the time penalty fades as the swimmer closes in, so it weighs
accuracy over speed near the end. Over a whole episode (eq. 7)

    sum_n r_n = -dt sum_n gamma_n + alpha (d_0 - d_N) + r_success [success].
"""

from __future__ import annotations

from dataclasses import dataclass

from torch import Tensor


@dataclass(frozen=True)
class RewardConfig:
    alpha: float = 1.0  # reward per unit of distance gained
    time_penalty: float = 0.5  # gamma at or beyond the start distance, per time unit
    success_bonus: float = 10.0
    success_radius: float = 0.3

    def __post_init__(self):
        if self.success_radius <= 0 or self.alpha < 0 or self.time_penalty < 0:
            raise ValueError(f"reward needs success_radius > 0, alpha >= 0, time_penalty >= 0: {self}")


def attenuation(cfg: RewardConfig, dist: Tensor, start_dist: Tensor) -> Tensor:
    return cfg.time_penalty * (dist / start_dist.clamp_min(1e-6)).clamp(max=1.0)


def step_reward(
    cfg: RewardConfig,
    prev_dist: Tensor,
    dist: Tensor,
    start_dist: Tensor,
    success: Tensor,
    dt: float,
):
    return (
        -attenuation(cfg, dist, start_dist) * dt
        + cfg.alpha * (prev_dist - dist)
        + cfg.success_bonus * success.to(dist.dtype)
    )
