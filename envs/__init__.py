"""envs: the topomerge environments.

Importing this package registers ``topomerge/two_robot_explore_v0`` and
``topomerge/multi_robot_explore_v0`` in PettingZoo's registries (PettingZoo >= 1.27) and
``topomerge/TwoRobotExplore-v0`` and ``topomerge/MultiRobotExplore-v0`` in Gymnasium's, so
that::

    import envs, gymnasium, pettingzoo
    par = pettingzoo.make("parallel", "topomerge/two_robot_explore_v0")
    aec = pettingzoo.make("aec", "topomerge/two_robot_explore_v0")
    team = pettingzoo.make("parallel", "topomerge/multi_robot_explore_v0", n_robots=4,
                           comm={"range": 5.0})
    single = gymnasium.make("topomerge/TwoRobotExplore-v0")   # both robots as one agent
    four = gymnasium.make("topomerge/MultiRobotExplore-v0", n_robots=4)  # four as one agent

The Gymnasium envs (:mod:`envs.explore.centralised`) are centralised views of the
same envs: joint action, every robot's observation, the team reward. The entry points are
import strings: the env modules (pymunk, scikit-image...) load on the first ``make``.
:func:`parallel_env_for` picks the PettingZoo env for a config's ``n_robots``.
"""

import re
from collections.abc import Mapping
from typing import Any

import gymnasium
import pettingzoo

ENV_IDS = ("topomerge/two_robot_explore_v0", "topomerge/multi_robot_explore_v0")
"""PettingZoo environment ids this package registers."""

GYMNASIUM_IDS = ("topomerge/TwoRobotExplore-v0", "topomerge/MultiRobotExplore-v0")
"""Gymnasium environment ids this package registers."""

_MODULES = {ENV_IDS[0]: "envs.two_robot_explore_v0", ENV_IDS[1]: "envs.multi_robot_explore_v0"}
_CENTRALISED = {GYMNASIUM_IDS[0]: "CentralisedExploreEnv",
                GYMNASIUM_IDS[1]: "CentralisedMultiRobotEnv"}


def parallel_env_for(config: Mapping[str, Any]) -> Any:
    """The native ``ParallelEnv`` for ``config`` (``EnvConfig`` fields, groups as dicts):
    ``two_robot_explore_v0`` when its ``n_robots`` is 2 or absent — the two-robot layout
    (``teammate`` (5,)) that policies trained on it read — else ``multi_robot_explore_v0``,
    which checks ``n_robots`` (2–8; an error names the field and the value)."""
    if not isinstance(config, Mapping):
        raise TypeError(f"config must be a mapping of EnvConfig fields, got "
                        f"{type(config).__name__}")
    n = config.get("n_robots", 2)
    if n == 2 and not isinstance(n, bool):
        from envs.two_robot_explore_v0 import parallel_env
    else:
        from envs.multi_robot_explore_v0 import parallel_env
    return parallel_env(**config)


def _register() -> None:
    for env_id, module in _MODULES.items():
        for env_type, attr in (("parallel", "parallel_env"), ("aec", "env")):
            registry = (pettingzoo.parallel_registry if env_type == "parallel"
                        else pettingzoo.aec_registry)
            # PettingZoo keys its registry by the id spelt "...-v0"
            if re.sub(r"_v(\d+)$", r"-v\1", env_id) not in registry:
                pettingzoo.register(env_type, env_id, entry_point=f"{module}:{attr}")
    for gym_id, cls in _CENTRALISED.items():
        if gym_id not in gymnasium.registry:
            # the env ends its episodes itself (max_cycles): no TimeLimit on top
            gymnasium.register(gym_id,
                               entry_point=f"envs.explore.centralised:{cls}")


_register()
