"""A robot team's env as one Gymnasium agent: a centralised controller of all its robots.

``gymnasium.make("topomerge/TwoRobotExplore-v0", **kwargs)`` (after ``import envs``) builds
:class:`CentralisedExploreEnv` around the PettingZoo ``ParallelEnv`` of ``two_robot_explore_v0``,
``gymnasium.make("topomerge/MultiRobotExplore-v0", n_robots=N, **kwargs)``
:class:`CentralisedMultiRobotEnv` around ``multi_robot_explore_v0``'s, a team of ``N`` (2–8)
robots (:mod:`envs.explore.env`'s docstring is the manual: sensors, maps, rewards
and the ``kwargs``, the same :class:`~envs.explore.config.EnvConfig` fields). One
Gymnasium step is one parallel step of every robot, so Gymnasium's wrappers (``RecordVideo``,
``FlattenObservation``, ``TimeLimit``...), vector envs and single-agent RL libraries apply.

| | centralised env | made from the parallel env's |
|---|---|---|
| action | ``Box(-1, 1, (2N,), float32)`` | ``[v, ω]`` of robot 0, then of robot 1... |
| | ``MultiDiscrete([5] * N)`` (discrete) | robot 0's action, robot 1's... |
| observation | ``Dict({"robot_0": ..., "robot_1": ...})`` | each robot's observation ``Dict`` |
| reward | the team reward, a float | ``"shared"``, ``"oracle"``: what all get |
| | | ``"individual"``: the sum over the robots |
| terminated, truncated | bools | the robots' (they end together) |
| info | ``{"robot_0": ..., "robot_1": ...}`` | each robot's info, as is |
| render | an ``"rgb_array"`` frame or a window | ``render()`` |

``N`` is 2 for ``TwoRobotExplore-v0`` (a 4-value action, ``MultiDiscrete([5, 5])``).

The observation is a nested ``Dict`` (the per-robot spaces are the parallel env's own objects),
which ``FlattenObservation`` flattens to one float32 ``Box`` and vector envs batch key by key.
Seeding: ``reset(seed=s)`` seeds the parallel env's one ``numpy.random.Generator`` with ``s``
(and Gymnasium's ``np_random``, which this env does not draw from), so the same seed and actions
give the same episode as the parallel env. ``RecordVideo`` needs moviepy (``pip install
moviepy``; not a topomerge dependency).
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from envs.explore.config import EnvConfig
from envs.explore.env import (
    DISCRETE_ACTIONS,
    MultiRobotExploreEnv,
    TwoRobotExploreEnv,
)

GYMNASIUM_ID = "topomerge/TwoRobotExplore-v0"
"""The id :mod:`envs` registers :class:`CentralisedExploreEnv` under with Gymnasium."""

MULTI_GYMNASIUM_ID = "topomerge/MultiRobotExplore-v0"
"""The id :mod:`envs` registers :class:`CentralisedMultiRobotEnv` under with Gymnasium."""


class CentralisedExploreEnv(gymnasium.Env):
    """Both robots of ``two_robot_explore_v0`` as one Gymnasium agent (module docstring).

    Args:
        config: an :class:`~envs.explore.config.EnvConfig`, or ``None``.
        render_mode: ``None``, ``"rgb_array"`` or ``"human"``.
        **kwargs: ``EnvConfig`` fields (groups as dicts), as for ``parallel_env``.

    Attributes:
        parallel: the wrapped PettingZoo ``ParallelEnv`` (its maps, world and ``state()``).
        agents: the parallel env's ``possible_agents``, in the joint action's order.

    Raises:
        ValueError, TypeError: what ``parallel_env`` raises for the same arguments.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 10}

    parallel_class: type[MultiRobotExploreEnv] = TwoRobotExploreEnv
    """The PettingZoo env class wrapped."""

    def __init__(self, config: EnvConfig | None = None, *, render_mode: str | None = None,
                 **kwargs: Any) -> None:
        self.parallel = self.parallel_class(config, render_mode=render_mode, **kwargs)
        self.render_mode = render_mode
        self.metadata = {**self.metadata,
                         "render_fps": self.parallel.metadata["render_fps"]}
        self.agents = tuple(self.parallel.possible_agents)
        self.observation_space = spaces.Dict(
            {a: self.parallel.observation_space(a) for a in self.agents})
        if self.parallel.config.action_type == "continuous":
            self.action_space = spaces.Box(-1.0, 1.0, (2 * len(self.agents),), np.float32)
        else:
            self.action_space = spaces.MultiDiscrete([len(DISCRETE_ACTIONS)] * len(self.agents))
        self._individual = self.parallel.config.reward_mode == "individual"

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[dict, dict]:
        """Start an episode of every robot (``options`` as for the parallel env)."""
        super().reset(seed=seed)
        observations, infos = self.parallel.reset(seed=seed, options=options)
        return observations, infos

    def step(self, action: Any) -> tuple[dict, float, bool, bool, dict]:
        """One parallel step with each robot's part of ``action`` (robot 0's first)."""
        observations, rewards, terminations, truncations, infos = self.parallel.step(
            self._split(action))
        reward = (sum(rewards.values()) if self._individual else rewards[self.agents[0]])
        return (observations, float(reward), bool(any(terminations.values())),
                bool(any(truncations.values())), infos)

    def _split(self, action: Any) -> dict[str, Any]:
        """``{agent: its action}`` from the joint action; a wrong shape is a ``ValueError``."""
        n = len(self.agents)
        if self.parallel.config.action_type == "continuous":
            layout = ("[v_0, w_0, v_1, w_1]" if n == 2
                      else f"[v_0, w_0, ..., v_{n - 1}, w_{n - 1}]")
            try:
                arr = np.asarray(action, dtype=np.float64)
            except (TypeError, ValueError) as exc:
                raise TypeError(f"action must be numeric {layout}, got {action!r}") from exc
            if arr.shape != self.action_space.shape:
                raise ValueError(f"action must have shape {self.action_space.shape} "
                                 f"({layout}), got shape {arr.shape}")
            return {a: arr[2 * i:2 * i + 2] for i, a in enumerate(self.agents)}
        arr = np.asarray(action)
        if arr.shape != (n,) or not np.issubdtype(arr.dtype, np.integer):
            rest = "robot 1's" if n == 2 else f"..., robot {n - 1}'s"
            raise ValueError(f"action must be {n} integers (robot 0's action, {rest}), got "
                             f"{action!r}")
        return {a: arr[i] for i, a in enumerate(self.agents)}

    def render(self) -> np.ndarray | None:
        """The parallel env's ``render()``: an ``(H, W, 3)`` uint8 frame for ``"rgb_array"``."""
        return self.parallel.render()

    def close(self) -> None:
        """Close the parallel env (its render window)."""
        self.parallel.close()


class CentralisedMultiRobotEnv(CentralisedExploreEnv):
    """All ``n_robots`` robots of ``multi_robot_explore_v0`` as one Gymnasium agent (module
    docstring): a ``2 · n_robots`` joint velocity command (``MultiDiscrete([5] * n_robots)``
    with discrete actions), every robot's observation, the team reward.

    Args:
        config, render_mode, **kwargs: as :class:`CentralisedExploreEnv`'s (``n_robots``,
            ``comm`` among the ``EnvConfig`` fields).

    Raises:
        ValueError, TypeError: what ``multi_robot_explore_v0.parallel_env`` raises for the same
            arguments (``n_robots`` outside 2–8, say).
    """

    parallel_class = MultiRobotExploreEnv
