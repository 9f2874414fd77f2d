"""two_robot_explore_v0: the versioned entry point (manual: :mod:`envs.explore.env`).

``parallel_env(**kw)`` is the native PettingZoo ``ParallelEnv``, ``env(**kw)`` its AEC version
(PettingZoo's ``parallel_to_aec``), ``raw_env`` the unwrapped class. Any change of observations,
rewards, dynamics or sensing makes a ``two_robot_explore_v1`` module.
"""

from envs.explore.env import env, parallel_env, raw_env

__all__ = ["env", "parallel_env", "raw_env"]
