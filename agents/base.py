"""The explorer interface: one object drives one robot.

An explorer is used like a Gymnasium agent, by hand, by the dataset generator and by
``train.py``'s evaluation::

    env = two_robot_explore_v0.parallel_env()
    team = make_team("frontier", env=env)           # {"robot_0": Explorer, "robot_1": Explorer}
    observations, infos = env.reset(seed=0)
    while env.agents:
        actions = {a: team[a].act(observations[a], infos[a]) for a in env.agents}
        observations, rewards, terminations, truncations, infos = env.step(actions)

:func:`run_episode` is that loop with per-step callbacks (it binds the team to the env itself).
Explorers see only what their robot knows: its observation, its own ``info`` entries
(odometry; the true pose in ``info["pose"]`` is for metrics and must not steer them) and, for
explorers that plan on maps, what :meth:`Explorer.bind` gives read access to: the robot's own
maps (``env.robot_map(agent)``, a snapshot) and the merge state (``env.merge_state()``); the
coordinated frontier explorer also reads its teammate's map, as robots sharing maps would.
The maps are read through the env rather than handed out in every step's infos because they
are large (a grid is megabytes) and explorers need them only when they plan.
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
        self.env: Any = None
        """The unwrapped env this explorer reads maps from (:meth:`bind`), ``None`` before."""
        self.agent: str | None = None
        """The robot this explorer drives (:meth:`bind`)."""

    def bind(self, env: Any, agent: str) -> None:
        """Drive robot ``agent`` of ``env`` (a ``two_robot_explore`` env, wrapped or not):
        read access to that robot's maps, ``env.unwrapped.robot_map(agent)``, and to
        ``merge_state()``, for explorers that plan on maps (the others ignore it).
        :func:`run_episode` and ``make_team(name, env=env)`` call it."""
        raw = getattr(env, "unwrapped", env)
        if not (hasattr(raw, "robot_map") and hasattr(raw, "merge_state")):
            raise TypeError(f"env must be a two_robot_explore env (with robot_map and "
                            f"merge_state), got {type(env).__name__}")
        if agent not in raw.possible_agents:
            raise ValueError(f"agent must be one of {list(raw.possible_agents)}, got {agent!r}")
        self.env = raw
        self.agent = agent

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

    Explorers are bound to their robots of ``env`` (:meth:`Explorer.bind`) and reset with
    seeds drawn from ``seed`` (different per robot, reproducible). Returns the last ``infos``,
    the step count and the summed team reward (robot 0's).
    """
    for agent, explorer in team.items():
        explorer.bind(env, agent)
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
