"""multi_robot_explore_v0: teams of 2–8 robots with range-limited communication, the versioned
entry point (manual: :mod:`envs.explore.env`).

``parallel_env(n_robots=4, comm={"range": 5.0})`` is the native PettingZoo ``ParallelEnv``,
``env(**kw)`` its AEC version, ``raw_env`` the unwrapped class. Any change of observations,
rewards, dynamics or sensing makes a ``multi_robot_explore_v1`` module.
"""

from envs.explore.env import MultiRobotExploreEnv as raw_env
from envs.explore.env import multi_env as env
from envs.explore.env import multi_parallel_env as parallel_env

__all__ = ["env", "parallel_env", "raw_env"]
