"""Scripted explorers: random walk, wall following, frontier exploration and its coordinated
two-robot version (:func:`agents.team.make_team` builds a team of any of them by name).

All drive from the robot's own sensing: the ``sonar`` observation, read with the bound env's
sonar layout (:attr:`agents.base.Explorer.sonar`: its angles and ``max_range``, whatever the
``sonar`` config), ``info["odometry"]`` (pose in the robot's own start frame) and, for the
frontier explorers, the robot's own :class:`topo.OccupancyGrid`, read when they plan from the
env they are bound to (``env.robot_map(agent).grid``, see :meth:`agents.base.Explorer.bind`).
None of them reads the true pose.

* :class:`RandomWalk` — bump and turn: drive ahead, turn away for a random time when the front
  sonars see something close.
* :class:`WallFollower` — keep a wall on the right at a set distance.
* :class:`Frontier` — Yamauchi (1997): frontier cells (known free next to unknown) of the
  robot's own grid, clustered; the nearest cluster by path cost through the configuration
  space (:mod:`agents.frontier_planning`), followed by pure pursuit; re-plan on arrival,
  blockage, or every ``replan_every`` steps.
* :class:`CoordinatedFrontier` — once a merge is accepted, each robot announces its goal on a
  shared :class:`Blackboard` and the other discounts frontiers near it (utility = gain − cost,
  Burgard et al. 2005), so the two do not chase the same frontier.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import ndimage

from agents.base import CommandExplorer, odometry_pose
from agents.frontier_planning import (
    FrontierConfig,
    FrontierMap,
    Plan,
    frontier_map,
    pure_pursuit,
)
from fusion.rigid import Rigid2D
from topo.validation import check_real


# ---------------------------------------------------------------------------- random walk
class RandomWalk(CommandExplorer):
    """Bump and turn: drive ahead with a little random steering; when a front sonar reads
    less than ``bump_distance``, turn (away from the nearer side) for a random 5–20 steps.

    Args:
        bump_distance: metres; front echo closer than this triggers a turn.
        action_type: see :class:`~agents.base.Explorer`.
    """

    name = "random_walk"

    def __init__(self, bump_distance: float = 0.6, action_type: str = "continuous") -> None:
        super().__init__(action_type)
        self.bump_distance = check_real(bump_distance, "bump_distance", low=0.0)
        self._turn_left = 0
        self._turn_steps = 0

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self._turn_steps = 0

    def command(self, observation, info) -> np.ndarray:
        ring = self.sonar_ring()
        ranges = ring.metres(observation)
        if self._turn_steps > 0:
            self._turn_steps -= 1
            return np.array([0.0, self._turn_left])
        if ring.nearest(ranges, ring.front) < self.bump_distance:
            left, right = ring.nearest(ranges, ring.left), ring.nearest(ranges, ring.right)
            self._turn_left = 1.0 if left > right else -1.0
            self._turn_steps = int(self.rng.integers(5, 21))
            return np.array([0.0, self._turn_left])
        return np.array([1.0, float(self.rng.normal(0.0, 0.2))])


# ---------------------------------------------------------------------------- wall follower
class WallFollower(CommandExplorer):
    """Keep a wall on the right at ``distance`` metres (proportional steering on the right
    sonars); turn left in place when the way ahead is blocked; curve right to find a wall.

    Args:
        distance: target wall distance, metres.
        gain: steering gain per metre of distance error.
        action_type: see :class:`~agents.base.Explorer`.
    """

    name = "wall_follower"

    def __init__(self, distance: float = 0.7, gain: float = 1.5,
                 action_type: str = "continuous") -> None:
        super().__init__(action_type)
        self.distance = check_real(distance, "distance", low=0.0)
        self.gain = check_real(gain, "gain", low=0.0)

    def command(self, observation, info) -> np.ndarray:
        ring = self.sonar_ring()
        ranges = ring.metres(observation)
        if ring.nearest(ranges, ring.front) < self.distance:
            return np.array([0.0, 1.0])
        right = ring.nearest(ranges, ring.right)
        if right >= ring.max_range * 0.95:  # no wall: curve right to find one
            return np.array([0.6, -0.5])
        return np.array([0.8, float(np.clip(self.gain * (right - self.distance), -1, 1))])


class Frontier(CommandExplorer):
    """Frontier-based exploration (Yamauchi 1997) on the robot's own grid.

    Every plan: frontier cells of the robot's grid are clustered (8-connected), path costs from
    the robot through the configuration space come from one ``MCP_Geometric`` run, and the goal
    is the cheapest cell of the best cluster (:meth:`_choose`: the nearest here, the current
    goal's cluster favoured by ``hysteresis``). Between plans the path is followed by pure
    pursuit. Goals that driving does not clear are given up (:class:`FrontierConfig`:
    reached while the frontier stays, no progress for ``stall_steps``, blocked ``max_blocks``
    times); when every frontier has been given up the list is forgotten once, and with no
    reachable frontier at all it falls back to a random walk.
    """

    name = "frontier"

    def __init__(self, config: FrontierConfig | None = None,
                 action_type: str = "continuous") -> None:
        super().__init__(action_type)
        if config is not None and not isinstance(config, FrontierConfig):
            raise TypeError(f"config must be a FrontierConfig, got {type(config).__name__}")
        self.cfg = config or FrontierConfig()
        self._fallback = RandomWalk()
        self.plan: Plan | None = None
        self.given_up: list[np.ndarray] = []
        """Goals given up this episode (own frame)."""
        self._backoff = 0
        self._idle = 0
        self._steps = 0
        self._track: dict[str, Any] = {}
        self.events: dict[str, int] = {}
        """Counts of this episode's plans, blocks, fallback steps and goals given up (by
        reason), for diagnosis."""

    def _count(self, event: str) -> None:
        self.events[event] = self.events.get(event, 0) + 1

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self._fallback.reset(int(self.rng.integers(2**31)))
        self.plan = None
        self.given_up = []
        self._backoff = 0
        self._idle = 0
        self._steps = 0
        self._track = {}
        self.events = {}

    def command(self, observation, info) -> np.ndarray:
        self._steps += 1
        pose = odometry_pose(info)
        ring = self.sonar_ring()
        if self._backoff > 0:
            self._backoff -= 1
            return np.array([-0.5, 0.0])
        if ring.nearest(ring.metres(observation), ring.front) < self.cfg.blocked_distance:
            self._count("blocked")
            if self.plan is not None and self._track:
                self._track["blocks"] += 1
                if self._track["blocks"] >= self.cfg.max_blocks:
                    self._give_up(self._track["goal"], "given_up_blocked")
            self.plan = None
            self._backoff = 3
            return np.array([-0.5, 0.0])
        if self._idle > 0:
            self._idle -= 1
        elif self._needs_plan(pose):
            self.plan = self._make_plan(info, pose)
            if self.plan is None:  # nothing reachable: wander a while before looking again
                self._idle = self.cfg.replan_every
        if self.plan is None:
            self._count("fallback_steps")
            return self._fallback.command(observation, info)
        self.plan.age += 1
        return pure_pursuit(pose, self.plan.path, self.cfg.lookahead)

    def _give_up(self, goal: np.ndarray, reason: str) -> None:
        self._count(reason)
        self.given_up.append(np.asarray(goal, dtype=np.float64).copy())
        self._track = {}

    def _needs_plan(self, pose: np.ndarray) -> bool:
        if self.plan is None or self.plan.age >= self.cfg.replan_every:
            return True
        if np.linalg.norm(self.plan.goal - pose[:2]) < self.cfg.arrive_distance:
            # reached: if the frontier had gone the goal would not be there to reach
            self._give_up(self.plan.goal, "given_up_reached")
            return True
        return False

    def bind(self, env: Any, agent: str) -> None:
        super().bind(env, agent)
        self._fallback.bind(env, agent)

    def _grid(self, agent: str | None = None) -> Any:
        """The occupancy grid of robot ``agent`` (default: this explorer's) now, a snapshot
        read from the bound env."""
        return self.bound_env().robot_map(agent or self.agent).grid

    def _frontier_map(self, info: Mapping[str, Any], pose: np.ndarray) -> FrontierMap | None:
        exclude = np.array(self.given_up) if self.given_up else None
        return frontier_map(self._grid(), pose[:2], self.cfg, exclude=exclude)

    def _make_plan(self, info: Mapping[str, Any], pose: np.ndarray) -> Plan | None:
        self._count("plans")
        fmap = self._frontier_map(info, pose)
        if fmap is None:
            return None
        clusters = fmap.clusters(self.cfg.min_cluster_cells)
        if not clusters and self.given_up:
            self.given_up = []  # everything given up: try them all again, once
            fmap = self._frontier_map(info, pose)
            clusters = fmap.clusters(self.cfg.min_cluster_cells) if fmap is not None else []
        if not clusters:
            return None
        current = self._track.get("goal")
        for c in clusters:
            c["current"] = bool(current is not None and np.linalg.norm(
                fmap.cell_to_xy(np.array([c["cell"]]))[0] - current) < self.cfg.give_up_radius)
        best = self._choose(clusters, info, pose)
        path = fmap.path_to(best["cell"])
        self._follow(path[-1], best["cost"])
        return Plan(path=path, goal=path[-1], cost=best["cost"])

    def _follow(self, goal: np.ndarray, cost: float) -> None:
        """Progress bookkeeping: the same target (within ``give_up_radius``) must get
        ``min_progress`` cheaper every ``stall_steps`` steps, or it is given up."""
        track = self._track
        if not track or np.linalg.norm(goal - track["goal"]) >= self.cfg.give_up_radius:
            self._track = {"goal": goal, "best": cost, "since": self._steps, "blocks": 0}
            return
        track["goal"] = goal
        if cost < track["best"] - self.cfg.min_progress:
            track["best"], track["since"] = cost, self._steps
        elif self._steps - track["since"] > self.cfg.stall_steps:
            self._give_up(goal, "given_up_stalled")

    def _choose(self, clusters: list[dict[str, Any]], info: Mapping[str, Any],
                pose: np.ndarray) -> dict[str, Any]:
        """The nearest cluster by path cost (Yamauchi), the current target's favoured."""
        return min(clusters, key=lambda c: c["cost"] - self.cfg.hysteresis * c["current"])


@dataclass
class Blackboard:
    """What two :class:`CoordinatedFrontier` robots share: each robot's current goal in its
    own frame, and the merge transform in use (robot 1's frame → robot 0's; ``None`` when
    none is). Each robot reads its teammate's grid from the env when it plans."""

    goals: dict[int, np.ndarray] = field(default_factory=dict)
    transform: Rigid2D | None = None

    def clear(self) -> None:
        self.goals.clear()
        self.transform = None


class CoordinatedFrontier(Frontier):
    """Frontier exploration for a team (Burgard et al. 2005 style).

    While no merge transform is in use it is :class:`Frontier`. With one in use (the env's
    ``merge_state().transform``), each robot:

    * plans on the shared map: its teammate's grid evidence is added to its own, so frontiers
      the teammate has already explored are not goals;
    * with the teammate's estimated position (the ``teammate`` observation) on that map,
      assigns the two robots to distinct frontier clusters: the pair minimising its own path
      cost plus the teammate's, plus ``mate_penalty · (1 − d / R)`` for clusters ``d`` apart
      within ``R = coordination_radius`` (one target in all but name) — Burgard's utility with
      the frontier going to the robot it is cheaper for;
    * otherwise (``assign=False``, a single cluster, or the teammate off the map) scores a
      cluster by path cost plus ``mate_penalty · (1 − d / R)`` for ``d``, its distance to the
      teammate's announced goal (on the :class:`Blackboard`) and position.

    Args:
        index: 0 for ``robot_0`` (frame A), 1 for ``robot_1`` (frame B).
        blackboard: shared by the two robots of a team (:func:`agents.make_team` wires it).
        config: see :class:`Frontier`.
        mate_penalty: metres of path cost added to a frontier at the teammate's goal or
            position, or between the two robots' targets (less farther out, none beyond
            ``coordination_radius``).
        coordination_radius: metres.
        assign: the joint assignment above (else the penalty alone).
        action_type: see :class:`Explorer`.
    """

    name = "coordinated_frontier"

    def __init__(self, index: int, blackboard: Blackboard, config: FrontierConfig | None = None,
                 mate_penalty: float = 8.0, coordination_radius: float = 5.0,
                 assign: bool = True, action_type: str = "continuous") -> None:
        super().__init__(config, action_type)
        self.assign = bool(assign)
        if index not in (0, 1):
            raise ValueError(f"index must be 0 or 1, got {index!r}")
        if not isinstance(blackboard, Blackboard):
            raise TypeError(f"blackboard must be a Blackboard, got {type(blackboard).__name__}")
        self.index = index
        self.board = blackboard
        self.mate_penalty = check_real(mate_penalty, "mate_penalty", low=0.0,
                                       low_inclusive=True)
        self.coordination_radius = check_real(coordination_radius, "coordination_radius",
                                              low=0.0)
        self._mate_xy: np.ndarray | None = None
        self._fmap: FrontierMap | None = None

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self.board.clear()
        self._mate_xy = None
        self._fmap = None

    def _to_mate(self) -> Rigid2D | None:
        """Transform from this robot's frame into the teammate's (``None`` before a merge)."""
        t = self.board.transform
        if t is None:
            return None
        return t.inverse() if self.index == 0 else t

    def _teammate_goal(self) -> np.ndarray | None:
        goal = self.board.goals.get(1 - self.index)
        to_mate = self._to_mate()
        if goal is None or to_mate is None:
            return None
        return to_mate.inverse().apply(goal)

    def bind(self, env: Any, agent: str) -> None:
        if agent != f"robot_{self.index}":
            raise ValueError(f"agent of CoordinatedFrontier(index={self.index}) must be "
                             f"'robot_{self.index}', got {agent!r}")
        super().bind(env, agent)

    def command(self, observation, info) -> np.ndarray:
        self.board.transform = self.bound_env().merge_state().transform
        mate = np.asarray(observation["teammate"], dtype=np.float64)
        if mate[4] > 0.5:  # valid: robot-frame offset of the teammate -> own frame
            pose = odometry_pose(info)
            c, s = math.cos(pose[2]), math.sin(pose[2])
            self._mate_xy = pose[:2] + np.array([c * mate[0] - s * mate[1],
                                                 s * mate[0] + c * mate[1]])
        return super().command(observation, info)

    def _frontier_map(self, info, pose):
        to_mate = self._to_mate()
        if to_mate is None:
            return super()._frontier_map(info, pose)
        exclude = np.array(self.given_up) if self.given_up else None
        self._fmap = frontier_map(self._grid(), pose[:2], self.cfg, exclude=exclude,
                                  teammate=(self._grid(f"robot_{1 - self.index}"), to_mate))
        return self._fmap

    def _mate_costs(self, clusters, pose) -> np.ndarray | None:
        """Path cost (m) from the teammate's estimated position to each cluster on this
        robot's shared map (``None`` if unknown or the teammate is off the map)."""
        fmap = self._fmap
        if fmap is None or self._mate_xy is None or self._to_mate() is None:
            return None
        shape = np.array(fmap.labels.shape)
        mate_rc = np.floor((self._mate_xy - fmap.origin) / fmap.resolution).astype(int)[::-1]
        own_rc = np.floor((pose[:2] - fmap.origin) / fmap.resolution).astype(int)[::-1]
        own_rc = np.clip(own_rc, 0, shape - 1)
        if np.any(mate_rc < 0) or np.any(mate_rc >= shape):
            return None
        mate_cost, _ = fmap.mcp.find_costs([tuple(mate_rc)])
        mate_cost = mate_cost.copy()
        fmap.mcp.find_costs([tuple(own_rc)])  # the own paths' traceback again
        idx = np.arange(1, fmap.n_clusters + 1)
        per_label = np.asarray(ndimage.minimum(mate_cost, fmap.labels, idx), dtype=np.float64)
        out = np.array([per_label[fmap.labels[c["cell"]] - 1] for c in clusters])
        return out if np.isfinite(out).any() else None

    def _choose(self, clusters, info, pose):
        radius = self.coordination_radius
        own = np.array([c["cost"] - self.cfg.hysteresis * c["current"] for c in clusters])
        mate = self._mate_costs(clusters, pose) if self.assign and len(clusters) > 1 else None
        if mate is not None:
            # joint assignment of the two robots to distinct clusters (the teammate taking
            # whatever is cheaper for it), frontiers close together counting as one target
            xy = np.array([c["centroid"] for c in clusters])
            d = np.linalg.norm(xy[:, None] - xy[None, :], axis=-1)
            total = own[:, None] + np.where(np.isfinite(mate), mate, 1e6)[None, :]
            total = total + self.mate_penalty * np.clip(1.0 - d / radius, 0.0, None)
            np.fill_diagonal(total, np.inf)
            best = clusters[int(np.unravel_index(np.argmin(total), total.shape)[0])]
            self._count("assigned")
        else:
            near = [p for p in (self._teammate_goal(), self._mate_xy if self._to_mate() else None)
                    if p is not None]
            score = own.copy()
            for p in near:
                dist = np.linalg.norm(np.array([c["centroid"] for c in clusters]) - p, axis=1)
                score += self.mate_penalty * np.clip(1.0 - dist / radius, 0.0, None)
            best = clusters[int(np.argmin(score))]
        self.board.goals[self.index] = best["centroid"]
        return best
