"""``two_robot_explore``: two sonar robots explore a pymunk world and merge their maps.

The manual is the docstring of :mod:`envs.two_robot_explore.env`; the versioned entry point
(``env``, ``parallel_env``, ``raw_env``) is :mod:`envs.two_robot_explore_v0`.
"""

from envs.two_robot_explore.config import (
    EnvConfig,
    MappingConfig,
    RobotConfig,
    SonarConfig,
    WorldConfig,
)
from envs.two_robot_explore.env import TwoRobotExploreEnv

__all__ = [
    "EnvConfig",
    "MappingConfig",
    "RobotConfig",
    "SonarConfig",
    "TwoRobotExploreEnv",
    "WorldConfig",
]
