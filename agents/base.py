"""The explorer interface: one object drives one robot.

An explorer is used like a Gymnasium agent, by hand, by the dataset generator and by
``train.py``'s evaluation::

    env = two_robot_explore_v0.parallel_env()
    team = make_team("frontier", env=env)           # {"robot_0": Explorer, ...}: one per robot
    observations, infos = env.reset(seed=0)
    while env.agents:
        actions = {a: team[a].act(observations[a], infos[a]) for a in env.agents}
        observations, rewards, terminations, truncations, infos = env.step(actions)

:func:`run_episode` is that loop with per-step callbacks (it binds the team to the env itself).
Explorers see only what their robot knows: its observation, its own ``info`` entries
(odometry; the true pose in ``info["pose"]`` is for metrics and must not steer them) and, for
explorers that plan on maps, what :meth:`Explorer.bind` gives read access to: the robot's own
maps (``env.robot_map(agent)``, a snapshot) and the merge state (``env.merge_state()``); the
coordinated frontier explorer also reads its teammates' maps as it knows them
(``env.teammate_map(agent, teammate)``), as robots sharing maps would.
The maps are read through the env rather than handed out in every step's infos because they
are large (a grid is megabytes) and explorers need them only when they plan.
"""

from __future__ import annotations

import abc
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from envs.explore.env import DISCRETE_ACTIONS

ACTION_TYPES = ("continuous", "discrete")

FRONT_HALF_WIDTH_DEG = 35.0
"""A sonar pointing within this of the heading looks ahead (:attr:`SonarRing.front`)."""
SIDE_LIMIT_DEG = 135.0
"""... and one pointing between :data:`FRONT_HALF_WIDTH_DEG` and this to either side looks to
that side (:attr:`SonarRing.left`, :attr:`SonarRing.right`); farther round it looks back."""


def odometry_pose(info: Mapping[str, Any]) -> np.ndarray:
    """The robot's ``(x, y, heading)`` odometry pose (its own start frame) from its ``info``."""
    return np.asarray(info["odometry"], dtype=np.float64)[:3]


@dataclass(frozen=True, slots=True, eq=False)
class SonarRing:
    """How to read a robot's ``sonar`` observation: the env's sonar layout, which an explorer
    takes from the env it is bound to (:meth:`Explorer.bind`), so that any ``sonar`` config
    (angles, order, range) is read right.

    Attributes:
        angles: ``(S,)`` sonar directions in the robot frame, radians in ``(-pi, pi]``.
        max_range: metres that an observation of 1 stands for (the env's ``sonar.max_range``).
        front: ``(S,)`` bool, the sonars within :data:`FRONT_HALF_WIDTH_DEG` of ahead.
        left, right: ``(S,)`` bool, the sonars to the left (CCW) / right, up to
            :data:`SIDE_LIMIT_DEG` from ahead.
    """

    angles: np.ndarray
    max_range: float
    front: np.ndarray
    left: np.ndarray
    right: np.ndarray

    @classmethod
    def from_degrees(cls, angles_deg: Any, max_range: float) -> SonarRing:
        """The ring of sonars at ``angles_deg`` (degrees CCW from the heading) reading up to
        ``max_range`` metres."""
        a = np.radians(np.asarray(angles_deg, dtype=np.float64))
        a = np.arctan2(np.sin(a), np.cos(a))
        front = np.abs(a) < math.radians(FRONT_HALF_WIDTH_DEG)
        side = ~front & (np.abs(a) <= math.radians(SIDE_LIMIT_DEG))
        return cls(a, float(max_range), front, side & (a > 0), side & (a < 0))

    def metres(self, observation: Mapping[str, Any]) -> np.ndarray:
        """The ``sonar`` observation in metres."""
        return np.asarray(observation["sonar"], dtype=np.float64) * self.max_range

    @staticmethod
    def nearest(ranges: np.ndarray, mask: np.ndarray) -> float:
        """The nearest of ``ranges[mask]`` (``inf`` when the mask selects no sonar)."""
        return float(ranges[mask].min()) if mask.any() else math.inf


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
        self.sonar: SonarRing | None = None
        """The bound env's sonar layout (:meth:`bind`), ``None`` before."""

    def bind(self, env: Any, agent: str) -> None:
        """Drive robot ``agent`` of ``env`` (a ``two_robot_explore`` or
        ``multi_robot_explore`` env, wrapped or not):
        read access to that robot's maps, ``env.unwrapped.robot_map(agent)``, and to
        ``merge_state()``, for explorers that plan on maps, and the env's sonar layout
        (:attr:`sonar`). :func:`run_episode` and ``make_team(name, env=env)`` call it."""
        raw = getattr(env, "unwrapped", env)
        if not all(hasattr(raw, a) for a in ("robot_map", "merge_state", "config")):
            raise TypeError(f"env must be a two_robot_explore env (with robot_map, merge_state "
                            f"and config), got {type(env).__name__}")
        if agent not in raw.possible_agents:
            raise ValueError(f"agent must be one of {list(raw.possible_agents)}, got {agent!r}")
        self.env = raw
        self.agent = agent
        self.sonar = SonarRing.from_degrees(raw.config.sonar.angles, raw.config.sonar.max_range)

    def sonar_ring(self) -> SonarRing:
        """:attr:`sonar`, the bound env's sonar layout.

        Raises:
            RuntimeError: the explorer is not bound yet (:meth:`bound_env`).
        """
        self.bound_env()
        return self.sonar

    def bound_env(self) -> Any:
        """The env bound by :meth:`bind`, which maps and the sonar layout are read from.

        Raises:
            RuntimeError: the explorer is not bound yet.
        """
        if self.env is None:
            raise RuntimeError(f"{type(self).__name__} reads its robot's sonar layout and maps "
                               f"from the env: bind it first (explorer.bind(env, agent), "
                               f"make_team(name, env=env), or run_episode)")
        return self.env

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
