"""The explorer interface: one object drives one robot.

An explorer is used like a Gymnasium agent, by hand, by the dataset generator and by
``train.py``'s evaluation::

    env = two_robot_explore_v0.parallel_env()
    team = make_team("frontier", seed=0)            # {"robot_0": Explorer, "robot_1": Explorer}
    observations, infos = env.reset(seed=0)
    while env.agents:
        actions = {a: team[a].act(observations[a], infos[a]) for a in env.agents}
        observations, rewards, terminations, truncations, infos = env.step(actions)

:func:`run_episode` is that loop with per-step callbacks. Explorers see only what their robot
knows: its observation and its own ``info`` entries (own grid and topological map, odometry,
merge state); the true pose in ``info["pose"]`` is for metrics and must not steer them.
"""

from __future__ import annotations

import abc
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from envs.two_robot_explore.env import DISCRETE_ACTIONS

ACTION_TYPES = ("continuous", "discrete")


class Explorer(abc.ABC):
    """Drives one robot: :meth:`reset` at the start of an episode, :meth:`act` every step.

    Args:
        action_type: the env's ``action_type``: ``"continuous"`` (``Box(-1, 1, (2,))``) or
            ``"discrete"`` (``Discrete(5)``).
    """

    name: str = "explorer"

    def __init__(self, action_type: str = "continuous") -> None:
        if action_type not in ACTION_TYPES:
            raise ValueError(f"action_type must be one of {list(ACTION_TYPES)}, "
                             f"got {action_type!r}")
        self.action_type = action_type
        self.rng = np.random.default_rng()

    def reset(self, seed: int | None = None) -> None:
        """Start a new episode; ``seed`` re-creates the explorer's one random generator."""
        self.rng = np.random.default_rng(seed)

    @abc.abstractmethod
    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> np.ndarray | int:
        """The action for this step, in the env's action space."""


class CommandExplorer(Explorer):
    """An explorer that computes a normalised ``(v, ω)`` command in ``[-1, 1]²`` (forward speed
    and CCW turn rate as fractions of the robot's maxima) in :meth:`command`; :meth:`act`
    sends it as is, or as the nearest of the env's discrete actions."""

    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> np.ndarray | int:
        command = np.clip(np.asarray(self.command(observation, info), dtype=np.float64), -1, 1)
        if self.action_type == "discrete":
            return int(np.argmin(np.linalg.norm(DISCRETE_ACTIONS - command, axis=1)))
        return command.astype(np.float32)

    @abc.abstractmethod
    def command(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> np.ndarray:
        """Normalised ``(v, ω)`` command."""


StepCallback = Callable[[int, dict, dict, dict], None]
"""``callback(step, observations, rewards, infos)`` after every env step."""


def run_episode(env: Any, team: Mapping[str, Explorer], seed: int | None = None,
                callback: StepCallback | None = None,
                options: dict[str, Any] | None = None) -> dict[str, Any]:
    """Run one episode of a PettingZoo ``ParallelEnv`` with one explorer per agent.

    Explorers are reset with seeds drawn from ``seed`` (different per robot, reproducible).
    Returns the last ``infos``, the step count and the summed team reward (robot 0's).
    """
    observations, infos = env.reset(seed=seed, options=options)
    seeds = np.random.SeedSequence(seed).spawn(len(team))
    for explorer, s in zip(team.values(), seeds, strict=True):
        explorer.reset(int(s.generate_state(1)[0]))
    steps, total = 0, 0.0
    last_infos = infos
    while env.agents:
        actions = {a: team[a].act(observations[a], infos[a]) for a in env.agents}
        observations, rewards, _terms, _truncs, infos = env.step(actions)
        steps += 1
        if rewards:
            total += float(next(iter(rewards.values())))
        if infos:
            last_infos = infos
        if callback is not None:
            callback(steps, observations, rewards, infos)
    return {"infos": last_infos, "steps": steps, "return": total}
