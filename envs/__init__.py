"""envs: the topomerge PettingZoo environments.

Importing this package registers ``topomerge/two_robot_explore_v0`` in PettingZoo's registries
(PettingZoo >= 1.27), so that::

    import envs, pettingzoo
    par = pettingzoo.make("parallel", "topomerge/two_robot_explore_v0")
    aec = pettingzoo.make("aec", "topomerge/two_robot_explore_v0")

The entry points are import strings: the env modules (pymunk, scikit-image...) load on the
first ``make``.
"""

import pettingzoo

ENV_IDS = ("topomerge/two_robot_explore_v0",)
"""Environment ids this package registers."""


def _register() -> None:
    for env_type, attr in (("parallel", "parallel_env"), ("aec", "env")):
        registry = pettingzoo.parallel_registry if env_type == "parallel" else (
            pettingzoo.aec_registry)
        spec_id = "topomerge/two_robot_explore-v0"
        if spec_id not in registry:
            pettingzoo.register(env_type, ENV_IDS[0],
                                entry_point=f"envs.two_robot_explore_v0:{attr}")


_register()
