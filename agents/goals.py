"""Learned goal selection over the frontier planner: the policy picks *where* to explore next,
:class:`agents.scripted.Frontier`'s planner and pure pursuit drive there.

Learning exploration from raw velocity commands is slow (long horizons); choosing among
frontiers is the decision that matters (which room next, whether to follow the teammate), so
the policy acts at that level, as in hierarchical exploration policies (e.g. Active Neural SLAM's
global policy over a local planner):

* :class:`GoalFrontier` — a ``CoordinatedFrontier`` explorer steered by a **sector**: one of
  :data:`SECTORS` directions around the robot (0 ahead, counter-clockwise, 45° each). At each
  decision it plans to the cheapest frontier cluster whose centroid lies in that sector (the
  cheapest anywhere if that sector has none); once a merge is in use it plans on the shared
  map (frontiers the teammate has explored are gone) and posts its goal on the team's
  :class:`~agents.scripted.Blackboard`. :meth:`GoalFrontier.frontier_features` summarises
  the frontier clusters per sector for the policy (:data:`FRONTIER_FEATURES`).
* :class:`FrontierGoalEnv` — a PettingZoo ``ParallelEnv`` wrapper of ``two_robot_explore``
  whose action is a sector (``Discrete(8)``) held for ``hold`` env steps (the reward is their
  sum) and whose observation adds ``frontiers`` (:data:`SECTORS` ×
  ``len(FRONTIER_FEATURES)``) to the env's own. Its first column says which sectors hold a
  reachable frontier: :class:`agents.policy.SectorPolicy` masks the others.
* ``agents.SB3Explorer`` runs a policy trained on the wrapper on the plain env (same decisions
  every ``hold`` steps), so it evaluates and generates datasets like any explorer.
* :class:`SectorRule` — the same decisions made by a fixed rule (always ahead, or a random
  sector): the baselines a learnt goal-level policy has to beat.
* :func:`make_env` — the training env of either level (the plain env, or wrapped), shared by
  ``train.py``'s SB3 workers and RLlib's env runners.

A policy that picks sectors uniformly at random is already a frontier explorer; PPO learns
which frontier to prefer.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from agents.base import Explorer, odometry_pose
from agents.frontier_planning import FrontierConfig, FrontierMap
from agents.scripted import Blackboard, CoordinatedFrontier, robot_index
from topo.validation import check_int

SECTORS = 8
"""Directions a goal can be chosen in: 45° sectors around the robot, 0 ahead, CCW."""

DEFAULT_HOLD = 10
"""Env steps a goal decision is held (1 s at the default ``dt``)."""

COST_SCALE = 20.0
"""Path cost (m) that maps to feature 1.0."""

AREA_SCALE = 10.0
"""Frontier cluster area (m²) that maps to feature 1.0."""

FRONTIER_FEATURES = ("reachable", "cost", "area", "cost_gap", "current", "teammate")
"""Columns of :meth:`GoalFrontier.frontier_features`, per sector: a reachable frontier
cluster is there (0/1); the path cost to its cheapest one (``/ COST_SCALE``, 1 if none); the
clusters' total area (``/ AREA_SCALE``); how much dearer than the cheapest frontier anywhere
(``/ COST_SCALE``, 1 if none: 0 marks the sector ``Frontier`` would choose); whether the goal
being driven to lies there (0/1: keeping it costs no turn-around); how close its nearest
frontier is to the teammate or the teammate's goal (``1 − d / coordination_radius``, clipped at
0; always 0 before a merge, when the teammate's place is unknown)."""


def sector_of(xy: np.ndarray, pose: np.ndarray) -> int:
    """The sector (0 ahead, CCW) in which point ``xy`` lies, seen from ``pose``."""
    bearing = math.atan2(xy[1] - pose[1], xy[0] - pose[0]) - pose[2]
    return int(round(bearing / (2 * math.pi / SECTORS))) % SECTORS


class GoalFrontier(CoordinatedFrontier):
    """A :class:`~agents.scripted.CoordinatedFrontier` explorer whose goals lie in a chosen
    sector (module docstring). Without a sector (``sector is None``) it is plain
    ``CoordinatedFrontier``; its robot (any ``robot_<k>``) is the one it is bound to.

    Args:
        config: see :class:`~agents.scripted.Frontier`.
        action_type: the env's ``action_type``.
        blackboard: shared with the teammate's controller, so that each sees the other's goal
            (default: a board of its own; the shared map and the teammate's position still
            come from the env).
    """

    name = "goal_frontier"

    def __init__(self, config: FrontierConfig | None = None,
                 action_type: str = "continuous", blackboard: Blackboard | None = None) -> None:
        super().__init__(0, blackboard if blackboard is not None else Blackboard(), config,
                         action_type=action_type)
        self.sector: int | None = None
        self._cached: tuple[tuple[int, int], FrontierMap | None] | None = None

    def bind(self, env: Any, agent: str) -> None:
        self.index = robot_index(agent)
        super().bind(env, agent)

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self.sector = None
        self._cached = None

    def choose_sector(self, sector: int) -> None:
        """Steer to ``sector`` (``0 <= sector < SECTORS``): re-plan at the next step."""
        if isinstance(sector, bool) or not isinstance(sector, (int, np.integer)) or not (
                0 <= sector < SECTORS):
            raise ValueError(f"sector must be an int in [0, {SECTORS}), got {sector!r}")
        self.sector = int(sector)
        self.plan = None

    def frontier_features(self, info: Mapping[str, Any]) -> np.ndarray:
        """``(SECTORS, len(FRONTIER_FEATURES))`` float32 in ``[0, 1]``: the columns of
        :data:`FRONTIER_FEATURES` for each sector, from this robot's map at ``info``'s
        odometry pose."""
        pose = odometry_pose(info)
        fmap = self._frontier_map(info, pose)
        # the plan of the very next step reuses it (unless a goal was given up meanwhile)
        self._cached = ((len(self.given_up), self._steps + 1), fmap)
        out = np.zeros((SECTORS, len(FRONTIER_FEATURES)), dtype=np.float32)
        out[:, 1] = out[:, 3] = 1.0
        goal = self._track.get("goal") if self.plan is not None else None
        if goal is not None:
            out[sector_of(goal, pose), 4] = 1.0
        if fmap is None:
            return out
        cell_area = fmap.resolution ** 2
        clusters = fmap.clusters(self.cfg.min_cluster_cells)
        if not clusters:
            return out
        cheapest = min(c["cost"] for c in clusters)
        mates = self._near_points()
        for c in clusters:
            k = sector_of(c["centroid"], pose)
            out[k, 0] = 1.0
            out[k, 1] = min(out[k, 1], c["cost"] / COST_SCALE)
            out[k, 2] = min(out[k, 2] + c["size"] * cell_area / AREA_SCALE, 1.0)
            out[k, 3] = min(out[k, 3], (c["cost"] - cheapest) / COST_SCALE)
            for p in mates:
                near = 1.0 - float(np.linalg.norm(c["centroid"] - p)) / self.coordination_radius
                out[k, 5] = max(out[k, 5], near)
        return out

    def _frontier_map(self, info: Mapping[str, Any], pose: np.ndarray,
                      radius: float | None = None) -> FrontierMap | None:
        cached, self._cached = self._cached, None
        if cached is not None and cached[0] == (len(self.given_up), self._steps):
            self._fmap = cached[1]
            return cached[1]
        return super()._frontier_map(info, pose, radius)

    def _select(self, info: Mapping[str, Any], pose: np.ndarray
                ) -> tuple[FrontierMap | None, dict[str, Any] | None]:
        if self.sector is None:
            return super()._select(info, pose)
        return self._select_among_all(info, pose)

    def _choose(self, clusters: list[dict[str, Any]], info: Mapping[str, Any],
                pose: np.ndarray) -> dict[str, Any]:
        if self.sector is None:
            return super()._choose(clusters, info, pose)
        inside = [c for c in clusters if sector_of(c["centroid"], pose) == self.sector]
        best = min(inside or clusters, key=lambda c: c["cost"])
        self.board.goals[self.index] = best["centroid"]
        return best


SECTOR_RULES = ("ahead", "random")
"""Fixed goal-level rules of :class:`SectorRule`."""


class SectorRule(Explorer):
    """A goal-level baseline without learning: every ``hold`` steps a :class:`GoalFrontier`
    is steered by a fixed rule, ``"ahead"`` (always sector 0, the frontier in front) or
    ``"random"`` (a uniformly random sector, from the explorer's generator). What a learnt
    goal-level policy must beat to have learnt more than a direction.

    Args:
        rule: one of :data:`SECTOR_RULES`.
        hold: env steps each choice is held, ``>= 1`` (as :class:`FrontierGoalEnv`'s).
        action_type: the env's ``action_type``.
        blackboard: shared with the teammate's (see :class:`GoalFrontier`).
    """

    name = "sector_rule"

    def __init__(self, rule: str = "ahead", hold: int = DEFAULT_HOLD,
                 action_type: str = "continuous", blackboard: Blackboard | None = None) -> None:
        super().__init__(action_type)
        if rule not in SECTOR_RULES:
            raise ValueError(f"rule must be one of {list(SECTOR_RULES)}, got {rule!r}")
        self.rule = rule
        self.hold = check_int(hold, "hold", low=1)
        self.controller = GoalFrontier(action_type=action_type, blackboard=blackboard)
        self._since = self.hold

    def bind(self, env: Any, agent: str) -> None:
        super().bind(env, agent)
        self.controller.bind(env, agent)

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self.controller.reset(int(self.rng.integers(2**31)))
        self._since = self.hold

    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> np.ndarray | int:
        if self._since >= self.hold:
            sector = 0 if self.rule == "ahead" else int(self.rng.integers(SECTORS))
            self.controller.choose_sector(sector)
            self._since = 0
        self._since += 1
        return self.controller.act(observation, info)


class FrontierGoalEnv(ParallelEnv):
    """``two_robot_explore`` with goal-level actions (module docstring).

    Args:
        env: a ``two_robot_explore_v0`` ``ParallelEnv``.
        hold: env steps each decision is held (the reward is their sum), ``>= 1``.
        config: the :class:`~agents.scripted.FrontierConfig` of the robots' planners.
        global_state: add the env's ``state()`` (the global view: true poses, coverage and
            world maps; the env manual's State) to every robot's observation as ``state``,
            for a centralised critic (MAPPO-style: :class:`agents.policy.SectorPolicy` feeds
            it to the value only; the actor never reads it).

    ``infos`` are the env's after the last held step, plus ``env_steps`` (how many were taken:
    fewer than ``hold`` when the episode ended).
    """

    metadata = {"name": "two_robot_explore_goals_v0", "render_modes": ["rgb_array", "human"],
                "is_parallelizable": True}

    def __init__(self, env: Any, hold: int = DEFAULT_HOLD,
                 config: FrontierConfig | None = None, global_state: bool = False) -> None:
        if not hasattr(env, "possible_agents") or not hasattr(env, "config"):
            raise TypeError(f"env must be a two_robot_explore ParallelEnv, got "
                            f"{type(env).__name__}")
        self.env = env
        self.hold = check_int(hold, "hold", low=1)
        self.possible_agents = list(env.possible_agents)
        self.agents: list[str] = []
        self.render_mode = env.render_mode
        action_type = env.config.action_type
        board = Blackboard()
        self.controllers = {a: GoalFrontier(config, action_type=action_type, blackboard=board)
                            for a in self.possible_agents}
        for agent, controller in self.controllers.items():
            controller.bind(env, agent)
        inner = env.observation_space(self.possible_agents[0])
        self.global_state = bool(global_state)
        self._obs_space = spaces.Dict({
            **inner.spaces,
            "frontiers": spaces.Box(0.0, 1.0, (SECTORS, len(FRONTIER_FEATURES)),
                                    dtype=np.float32),
            **({"state": env.unwrapped.state_space} if self.global_state else {}),
        })
        self._act_space = spaces.Discrete(SECTORS)
        self._rng: np.random.Generator | None = None
        self._last: tuple[dict, dict] | None = None

    @property
    def unwrapped(self) -> Any:
        """The wrapped ``two_robot_explore`` env, unwrapped (as PettingZoo's wrappers do)."""
        return self.env.unwrapped

    def observation_space(self, agent: str) -> spaces.Space:
        return self._obs_space

    def action_space(self, agent: str) -> spaces.Space:
        return self._act_space

    def reset(self, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[dict, dict]:
        """Reset the env; the planners' generators derive from ``seed``."""
        if seed is not None or self._rng is None:
            self._rng = np.random.default_rng(seed)
        obs, infos = self.env.reset(seed=seed, options=options)
        for c in self.controllers.values():
            c.reset(int(self._rng.integers(2**31)))
        self.agents = list(self.env.agents)
        self._last = (obs, infos)
        return self._augment(obs, infos), infos

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Steer each robot to its chosen sector and run ``hold`` env steps."""
        if self._last is None:
            raise RuntimeError("call reset() before step()")
        if not self.agents:
            raise RuntimeError("step() called after the episode ended; call reset()")
        if not isinstance(actions, dict) or sorted(actions) != sorted(self.agents):
            raise ValueError(f"actions must be a dict with one sector per agent "
                             f"{self.agents}, got {actions!r}")
        for a in self.agents:
            try:
                self.controllers[a].choose_sector(actions[a])
            except ValueError as exc:
                raise ValueError(f"action of {a}: {exc}") from None
        obs, infos = self._last
        total = dict.fromkeys(self.agents, 0.0)
        taken = 0
        while taken < self.hold and self.env.agents:
            low = {a: self.controllers[a].act(obs[a], infos[a]) for a in self.env.agents}
            obs, rewards, terms, truncs, infos = self.env.step(low)
            taken += 1
            for a, r in rewards.items():
                total[a] += r
        infos = {a: {**i, "env_steps": taken} for a, i in infos.items()}
        self.agents = list(self.env.agents)
        self._last = (obs, infos)
        return self._augment(obs, infos), total, terms, truncs, infos

    def _augment(self, obs: dict, infos: dict) -> dict:
        extra = {"state": self.env.unwrapped.state()} if self.global_state and obs else {}
        return {a: {**o, "frontiers": self.controllers[a].frontier_features(infos[a]),
                    **extra} for a, o in obs.items()}

    def render(self) -> Any:
        return self.env.render()

    def close(self) -> None:
        self.env.close()


LEVELS = ("goals", "motion")
"""What a policy decides: a frontier sector every ``hold`` steps, or the velocity command."""


def default_hold(level: str) -> int:
    """Env steps a decision is held unless said otherwise: :data:`DEFAULT_HOLD` at the goal
    level, 1 (every step) at the motion level."""
    return DEFAULT_HOLD if level == "goals" else 1


def make_env(config: Mapping[str, Any], level: str = "motion", hold: int | None = None,
             frontier_shaping: float = 0.0, global_state: bool = False,
             commands: str = "continuous") -> ParallelEnv:
    """One ``ParallelEnv`` built from ``config`` (``EnvConfig`` fields:
    ``two_robot_explore_v0`` for two robots, ``multi_robot_explore_v0`` for a larger
    ``n_robots``, :func:`envs.parallel_env_for`), wrapped in :class:`FrontierGoalEnv`
    (holding decisions ``hold`` steps) when
    ``level`` is ``"goals"`` (with ``global_state``, observations carry the env's ``state()``
    for a centralised critic), or at the motion level in :class:`agents.motion.MotionEnv` when
    ``hold > 1``, ``frontier_shaping > 0`` or ``commands="arcs"`` (commands held ``hold``
    steps, progress towards frontiers rewarded, a few discrete commands); ``hold`` defaults
    to :func:`default_hold`. A top-level
    function, so it pickles for worker processes."""
    if level not in LEVELS:
        raise ValueError(f"level must be one of {list(LEVELS)}, got {level!r}")
    if hold is None:
        hold = default_hold(level)
    from envs import parallel_env_for

    env = parallel_env_for(config)
    if level == "goals":
        return FrontierGoalEnv(env, hold=hold, global_state=global_state)
    if global_state:
        raise ValueError("global_state applies to level='goals' only")
    if hold == 1 and not frontier_shaping and commands == "continuous":
        return env
    from agents.motion import MotionEnv

    return MotionEnv(env, hold=hold, frontier_shaping=frontier_shaping, commands=commands)
