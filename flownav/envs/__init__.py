"""The batched navigation environment, its kinematics, tasks, reward and observation views."""

from flownav.envs.navigation import DPSI_MAX, DTHETA_MAX, NavigationEnv, Status
from flownav.envs.observations import VIEWS, observation_size
from flownav.envs.reward import RewardConfig
from flownav.envs.tasks import (
    EXTENDED_TARGET,
    REGION_1,
    REGION_2,
    FixedTargetTask,
    ListTask,
    RegionTask,
    SymmetricTask,
)

__all__ = [
    "DPSI_MAX",
    "DTHETA_MAX",
    "EXTENDED_TARGET",
    "REGION_1",
    "REGION_2",
    "VIEWS",
    "FixedTargetTask",
    "ListTask",
    "NavigationEnv",
    "RegionTask",
    "RewardConfig",
    "Status",
    "SymmetricTask",
    "observation_size",
]
