"""envs: the topomerge environments.

Importing this package registers ``topomerge/two_robot_explore_v0`` in PettingZoo's registries
(PettingZoo >= 1.27) and ``topomerge/TwoRobotExplore-v0`` in Gymnasium's, so that::

    import envs, gymnasium, pettingzoo
    par = pettingzoo.make("parallel", "topomerge/two_robot_explore_v0")
    aec = pettingzoo.make("aec", "topomerge/two_robot_explore_v0")
    single = gymnasium.make("topomerge/TwoRobotExplore-v0")   # both robots as one agent

The Gymnasium env (:mod:`envs.two_robot_explore.centralised`) is a centralised view of the same
env: joint action, both robots' observations, the team reward. The entry points are import
strings: the env modules (pymunk, scikit-image...) load on the first ``make``.
"""

import gymnasium
import pettingzoo

ENV_IDS = ("topomerge/two_robot_explore_v0",)
"""PettingZoo environment ids this package registers."""

GYMNASIUM_IDS = ("topomerge/TwoRobotExplore-v0",)
"""Gymnasium environment ids this package registers."""


def _register() -> None:
    for env_type, attr in (("parallel", "parallel_env"), ("aec", "env")):
        registry = pettingzoo.parallel_registry if env_type == "parallel" else (
            pettingzoo.aec_registry)
        spec_id = "topomerge/two_robot_explore-v0"
        if spec_id not in registry:
            pettingzoo.register(env_type, ENV_IDS[0],
                                entry_point=f"envs.two_robot_explore_v0:{attr}")
    if GYMNASIUM_IDS[0] not in gymnasium.registry:
        # the env ends its episodes itself (max_cycles): no TimeLimit on top
        gymnasium.register(GYMNASIUM_IDS[0],
                           entry_point="envs.two_robot_explore.centralised:CentralisedExploreEnv")


_register()
