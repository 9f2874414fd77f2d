"""``envs.explore``: a team of 2–8 sonar robots explores a pymunk world and merges its maps.

The implementation behind the versioned entry points :mod:`envs.two_robot_explore_v0` and
:mod:`envs.multi_robot_explore_v0` (``env``, ``parallel_env``, ``raw_env``); the manual is the
docstring of :mod:`envs.explore.env`. Import the versioned modules, not this package, in
user code: a ``_v1`` may change what lives here.
"""

from envs.explore.config import (
    EnvConfig,
    MappingConfig,
    RobotConfig,
    SonarConfig,
    WorldConfig,
)
from envs.explore.env import MultiRobotExploreEnv, TwoRobotExploreEnv

__all__ = [
    "EnvConfig",
    "MappingConfig",
    "MultiRobotExploreEnv",
    "RobotConfig",
    "SonarConfig",
    "TwoRobotExploreEnv",
    "WorldConfig",
]
