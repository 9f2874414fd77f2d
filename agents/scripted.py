"""Scripted explorers: random walk, wall following, frontier exploration and its coordinated
team version, for teams of any size (:func:`agents.registry.make_team` builds a team of any of
them by name).

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
  space (:mod:`agents.frontier_planning`), searched in a window around the robot that grows
  until its answer is the whole map's (so a plan costs the neighbourhood, not the building),
  followed by pure pursuit; re-plan on arrival, blockage, or every ``replan_every`` steps.
* :class:`CoordinatedFrontier` — once teammates are in its fused map, each robot plans on the
  fused map, announces its goal on a shared :class:`Blackboard`, and the robots in contact
  are assigned distinct frontiers (utility = gain − cost, Burgard et al. 2005), so they do not
  chase the same frontier.
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
    is_frontier_cell,
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
        self._seen: list[float] | None = None
        self._reach = 0.0
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
        self._seen = None
        self.events = {}

    def command(self, observation, info) -> np.ndarray:
        self._steps += 1
        pose = odometry_pose(info)
        self._note(pose)
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
        if self.plan is None:
            return True
        if self.plan.age >= self.cfg.replan_every:
            if not self.cfg.max_plan_age or self._superseded(pose):
                return True
        if np.linalg.norm(self.plan.goal - pose[:2]) < self.cfg.arrive_distance:
            # reached: if the frontier had gone the goal would not be there to reach
            self._give_up(self.plan.goal, "given_up_reached")
            return True
        return False

    def _superseded(self, pose: np.ndarray) -> bool:
        """At a check (``max_plan_age``): whether the plan must be re-made — it is
        ``max_plan_age`` steps old, its goal is no frontier cell any more, or the robot got
        no nearer (the stall rule, on the plan's cost for the path left)."""
        plan = self.plan
        plan.checks += 1
        if plan.checks * self.cfg.replan_every >= self.cfg.max_plan_age:
            return True
        if not is_frontier_cell(self._grid(), plan.goal):
            self._count("superseded")
            return True
        i = int(np.argmin(np.linalg.norm(plan.path - pose[:2], axis=1)))
        left = float(np.linalg.norm(np.diff(plan.path[i:], axis=0), axis=1).sum())
        whole = float(np.linalg.norm(np.diff(plan.path, axis=0), axis=1).sum())
        before = len(self.given_up)
        self._follow(plan.goal, plan.cost * left / whole if whole > 0 else 0.0)
        plan.age = 0
        return len(self.given_up) > before

    def bind(self, env: Any, agent: str) -> None:
        super().bind(env, agent)
        self._fallback.bind(env, agent)
        # the grid knows cells within this of the poses its robot drove through
        self._reach = float(self.env.config.sonar.max_range + self.env.config.robot.radius)

    def _grid(self, agent: str | None = None) -> Any:
        """The occupancy grid of robot ``agent`` (default: this explorer's) now, a snapshot
        read from the bound env."""
        return self.bound_env().robot_map(agent or self.agent).grid

    def _note(self, pose: np.ndarray) -> None:
        """Widen the box of the poses driven through (what the grid can know lies within the
        sensing range of it)."""
        x, y = float(pose[0]), float(pose[1])
        if self._seen is None:
            self._seen = [x, y, x, y]
        else:
            seen = self._seen
            seen[0], seen[1] = min(seen[0], x), min(seen[1], y)
            seen[2], seen[3] = max(seen[2], x), max(seen[3], y)

    def _within(self, grid: Any) -> tuple[int, int, int, int] | None:
        """Rows and columns of ``grid`` within sensing range of the poses driven through."""
        if self._seen is None:
            return None
        res, (ox, oy) = float(grid.resolution), grid.origin
        x0, y0, x1, y1 = self._seen
        reach = self._reach + 2 * res
        return (int(math.floor((y0 - reach - oy) / res)), int(math.ceil((y1 + reach - oy) / res)),
                int(math.floor((x0 - reach - ox) / res)), int(math.ceil((x1 + reach - ox) / res)))

    def _frontier_map(self, info: Mapping[str, Any], pose: np.ndarray,
                      radius: float | None = None) -> FrontierMap | None:
        self._note(pose)
        exclude = np.array(self.given_up) if self.given_up else None
        grid = self._grid()
        return frontier_map(grid, pose[:2], self.cfg, exclude=exclude,
                            within=self._within(grid), radius=radius)

    def _select(self, info: Mapping[str, Any], pose: np.ndarray
                ) -> tuple[FrontierMap | None, dict[str, Any] | None]:
        """The map planned on and the chosen cluster (``None``: none reachable): the nearest
        by path cost (Yamauchi), the current goal's ``hysteresis`` metres cheaper. Searched
        in a window around the robot (``search_radius``, or the current goal's cost if more),
        widened until its answer is the whole map's (:attr:`FrontierMap.exact_below`)."""
        goal = self._track.get("goal")
        slack = self.cfg.hysteresis if goal is not None else 0.0
        # the current goal's cost is a good guess of how far to look
        radius = max(self.cfg.search_radius, self._track.get("best", 0.0) + slack + 0.5)
        while True:
            fmap = self._frontier_map(info, pose, radius)
            if fmap is None:
                return None, None
            best = fmap.nearest(self.cfg.min_cluster_cells, goal, self.cfg.give_up_radius,
                                self.cfg.hysteresis)
            if math.isinf(fmap.exact_below) or (
                    best is not None and best["cost"] + slack < fmap.exact_below):
                return fmap, best
            radius = max(2.0 * radius, best["cost"] + slack + 0.5 if best else 0.0)

    def _select_among_all(self, info: Mapping[str, Any], pose: np.ndarray
                          ) -> tuple[FrontierMap | None, dict[str, Any] | None]:
        """:meth:`_select` over every reachable cluster of the whole map, by :meth:`_choose`
        (the current goal's cluster: the one whose cheapest cell is within
        ``give_up_radius`` of it)."""
        fmap = self._frontier_map(info, pose)
        clusters = fmap.clusters(self.cfg.min_cluster_cells) if fmap is not None else []
        if not clusters:
            return fmap, None
        current = self._track.get("goal")
        for c in clusters:
            c["current"] = bool(current is not None and np.linalg.norm(
                fmap.cell_to_xy(np.array([c["cell"]]))[0] - current) < self.cfg.give_up_radius)
        return fmap, self._choose(clusters, info, pose)

    def _make_plan(self, info: Mapping[str, Any], pose: np.ndarray) -> Plan | None:
        self._count("plans")
        fmap, best = self._select(info, pose)
        if best is None and self.given_up:
            self.given_up = []  # everything given up: try them all again, once
            fmap, best = self._select(info, pose)
        if best is None:
            return None
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
    """What the :class:`CoordinatedFrontier` robots of a team share: each robot's current goal
    in its own frame (``goals[k]`` for ``robot_k``), and what each robot knows of the team
    from the env's merge state (``frames[k][j]``: robot j's frame → robot k's, for the robots
    of robot k's fused map, itself included; ``contacts[k]``: the teammates it is in contact
    with). Each robot reads its teammates' grids from the env when it plans."""

    goals: dict[int, np.ndarray] = field(default_factory=dict)
    frames: dict[int, dict[int, Rigid2D]] = field(default_factory=dict)
    contacts: dict[int, tuple[int, ...]] = field(default_factory=dict)

    def clear(self) -> None:
        self.goals.clear()
        self.frames.clear()
        self.contacts.clear()


def robot_index(agent: Any) -> int:
    """``k`` of an agent name ``"robot_<k>"``.

    Raises:
        ValueError: ``agent`` is not of that form.
    """
    name, sep, k = str(agent).partition("_") if isinstance(agent, str) else ("", "", "")
    if name != "robot" or not sep or not k.isdigit() or (len(k) > 1 and k[0] == "0"):
        raise ValueError(f"agent must be 'robot_<k>' (k = 0, 1, ...), got {agent!r}")
    return int(k)


class CoordinatedFrontier(Frontier):
    """Frontier exploration for a team of any size (Burgard et al. 2005 style).

    While no teammate is in its fused map it is :class:`Frontier`. With teammates in it (the
    env's ``merge_state().frames``; on an env without them, the two-robot
    ``merge_state().transform``), each robot:

    * plans on the fused map: its fused teammates' grid evidence (``teammate_map``, the maps
      as this robot knows them) is added to its own, so frontiers they have explored are not
      goals;
    * with the estimated positions (the ``teammates`` / ``teammate`` observation) of the
      fused teammates it is in contact with, assigns the robots to distinct frontier
      clusters. With one such teammate: the pair minimising its own path cost plus the
      teammate's, plus ``mate_penalty · (1 − d / R)`` for clusters ``d`` apart within
      ``R = coordination_radius`` (one target in all but name) — Burgard's utility with the
      frontier going to the robot it is cheaper for. With more: sequentially, the cheapest
      (robot, cluster) pair first, every cluster near a taken one costing that penalty more,
      until this robot has its cluster;
    * otherwise (``assign=False``, a single cluster, or no teammate's position on the map)
      scores a cluster by path cost plus ``mate_penalty · (1 − d / R)`` for each ``d``, its
      distance to a fused teammate's announced goal (on the :class:`Blackboard`, while in
      contact) and position.

    Args:
        index: ``k`` of the robot ``robot_k`` it drives (frame of its own map).
        blackboard: shared by the robots of a team (:func:`agents.registry.make_team` wires it).
        config: see :class:`Frontier`.
        mate_penalty: metres of path cost added to a frontier at a teammate's goal or
            position, or between two robots' targets (less farther out, none beyond
            ``coordination_radius``).
        coordination_radius: metres.
        assign: the assignment above (else the penalty alone).
        action_type: see :class:`Explorer`.
    """

    name = "coordinated_frontier"

    def __init__(self, index: int, blackboard: Blackboard, config: FrontierConfig | None = None,
                 mate_penalty: float = 8.0, coordination_radius: float = 5.0,
                 assign: bool = True, action_type: str = "continuous") -> None:
        super().__init__(config, action_type)
        self.assign = bool(assign)
        if isinstance(index, bool) or not isinstance(index, (int, np.integer)) or index < 0:
            raise ValueError(f"index must be an int >= 0, got {index!r}")
        if not isinstance(blackboard, Blackboard):
            raise TypeError(f"blackboard must be a Blackboard, got {type(blackboard).__name__}")
        self.index = int(index)
        self.board = blackboard
        self.mate_penalty = check_real(mate_penalty, "mate_penalty", low=0.0,
                                       low_inclusive=True)
        self.coordination_radius = check_real(coordination_radius, "coordination_radius",
                                              low=0.0)
        self._mate_xy: dict[int, np.ndarray] = {}
        self._fmap: FrontierMap | None = None

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self.board.clear()
        self._mate_xy = {}
        self._fmap = None

    def _fused(self) -> dict[int, Rigid2D]:
        """``{j: robot j's frame → this robot's}`` for the teammates in its fused map."""
        return {j: t for j, t in sorted(self.board.frames.get(self.index, {}).items())
                if j != self.index}

    def _in_contact(self, j: int) -> bool:
        return j in self.board.contacts.get(self.index, ())

    def _teammate_goals(self) -> dict[int, np.ndarray]:
        """The announced goals (this robot's frame) of the fused teammates in contact."""
        return {j: t.apply(self.board.goals[j]) for j, t in self._fused().items()
                if j in self.board.goals and self._in_contact(j)}

    def _near_points(self) -> list[np.ndarray]:
        """What a frontier is penalised near: each fused teammate's goal (in contact) and
        position (own frame)."""
        goals = self._teammate_goals()
        out = []
        for j in self._fused():
            out += [p for p in (goals.get(j), self._mate_xy.get(j)) if p is not None]
        return out

    def bind(self, env: Any, agent: str) -> None:
        if agent != f"robot_{self.index}":
            raise ValueError(f"agent of CoordinatedFrontier(index={self.index}) must be "
                             f"'robot_{self.index}', got {agent!r}")
        super().bind(env, agent)

    def _read_team(self) -> None:
        """This robot's fused frames and contacts from the env's merge state, onto the
        board."""
        state = self.bound_env().merge_state()
        i = self.index
        frames = getattr(state, "frames", ())
        if frames:
            self.board.frames[i] = dict(frames[i])
            self.board.contacts[i] = tuple(state.contacts[i])
            return
        # an env without teams: two robots always in contact, robot 1's frame -> robot 0's
        mine = {i: Rigid2D.identity()}
        if state.transform is not None:
            mine[1 - i] = state.transform if i == 0 else state.transform.inverse()
        self.board.frames[i] = mine
        self.board.contacts[i] = (1 - i,)

    def _teammate_order(self) -> list[int]:
        """Teammate indices in the order of the ``teammates`` observation's rows."""
        n = len(self.bound_env().possible_agents)
        return [j for j in range(n) if j != self.index]

    def command(self, observation, info) -> np.ndarray:
        self._read_team()
        rows = observation.get("teammates")
        if rows is None:
            rows = np.asarray(observation["teammate"], dtype=np.float64)[None]
        rows = np.asarray(rows, dtype=np.float64)
        pose = odometry_pose(info)
        c, s = math.cos(pose[2]), math.sin(pose[2])
        for row, j in zip(rows, self._teammate_order(), strict=False):
            if row[4] > 0.5:  # valid: robot-frame offset of the teammate -> own frame
                self._mate_xy[j] = pose[:2] + np.array([c * row[0] - s * row[1],
                                                        s * row[0] + c * row[1]])
        return super().command(observation, info)

    def _teammate_grid(self, j: int) -> Any:
        """Teammate j's grid as this robot knows it (``None`` if it never did)."""
        env = self.bound_env()
        if hasattr(env, "teammate_map"):
            snap = env.teammate_map(self.agent, f"robot_{j}")
            return None if snap is None else snap.grid
        return env.robot_map(f"robot_{j}").grid

    def _frontier_map(self, info, pose, radius=None):
        fused = self._fused()
        if not fused:
            return super()._frontier_map(info, pose, radius)
        self._note(pose)
        exclude = np.array(self.given_up) if self.given_up else None
        grid = self._grid()
        mates = [(g, t.inverse()) for g, t in ((self._teammate_grid(j), t)
                                               for j, t in fused.items()) if g is not None]
        self._fmap = frontier_map(grid, pose[:2], self.cfg, exclude=exclude, teammates=mates,
                                  within=self._within(grid))
        return self._fmap

    def _select(self, info, pose):
        if not self._fused():  # alone: Frontier's choice, announced
            fmap, best = super()._select(info, pose)
            if best is not None:
                self.board.goals[self.index] = best["centroid"]
            return fmap, best
        return self._select_among_all(info, pose)

    def _mate_costs(self, clusters, pose) -> dict[int, np.ndarray]:
        """Path cost (m) from each fused teammate in contact, at its estimated position, to
        each cluster on this robot's fused map (those off the map or reaching no cluster
        left out)."""
        fmap = self._fmap
        out: dict[int, np.ndarray] = {}
        if fmap is None:
            return out
        shape = np.array(fmap.labels.shape)
        idx = np.arange(1, fmap.n_clusters + 1)
        for j in self._fused():
            xy = self._mate_xy.get(j)
            if xy is None or not self._in_contact(j):
                continue
            rc = np.floor((xy - fmap.origin) / fmap.resolution).astype(int)[::-1]
            if np.any(rc < 0) or np.any(rc >= shape):
                continue
            cost = fmap.costs_from(tuple(rc))
            per_label = np.asarray(ndimage.minimum(cost, fmap.labels, idx), dtype=np.float64)
            costs = np.array([per_label[fmap.labels[c["cell"]] - 1] for c in clusters])
            if np.isfinite(costs).any():
                out[j] = costs
        return out

    def _choose(self, clusters, info, pose):
        radius = self.coordination_radius
        own = np.array([c["cost"] - self.cfg.hysteresis * c["current"] for c in clusters])
        mates = self._mate_costs(clusters, pose) if self.assign and len(clusters) > 1 else {}
        if mates:
            # frontiers close together count as one target
            xy = np.array([c["centroid"] for c in clusters])
            d = np.linalg.norm(xy[:, None] - xy[None, :], axis=-1)
            near = self.mate_penalty * np.clip(1.0 - d / radius, 0.0, None)
            costs = [np.where(np.isfinite(m), m, 1e6) for m in mates.values()]
            best = clusters[_assign(own, costs, near)]
            self._count("assigned")
        else:
            score = own.copy()
            centroids = np.array([c["centroid"] for c in clusters])
            for p in self._near_points():
                dist = np.linalg.norm(centroids - p, axis=1)
                score += self.mate_penalty * np.clip(1.0 - dist / radius, 0.0, None)
            best = clusters[int(np.argmin(score))]
        self.board.goals[self.index] = best["centroid"]
        return best


def _assign(own: np.ndarray, mates: list[np.ndarray], near: np.ndarray) -> int:
    """The cluster this robot takes: costs ``own`` (its own, per cluster) and ``mates`` (each
    teammate's), ``near[a, b]`` the penalty of targets ``a`` and ``b`` taken together. One
    teammate: the pair of distinct clusters of least total cost. More: sequential assignment,
    the cheapest (robot, cluster) pair first, each taken cluster adding its ``near`` row to
    every robot's costs, until this robot has its cluster."""
    if len(mates) == 1:
        total = own[:, None] + mates[0][None, :] + near
        np.fill_diagonal(total, np.inf)
        return int(np.unravel_index(np.argmin(total), total.shape)[0])
    costs = np.stack([own, *mates])  # row 0: this robot
    free = np.ones(len(own), dtype=bool)
    while True:
        if not free.any():  # more robots than clusters: this one takes the best left
            return int(np.argmin(costs[0]))
        masked = np.where(free[None, :], costs, np.inf)
        r, c = np.unravel_index(np.argmin(masked), masked.shape)
        if r == 0:
            return int(c)
        free[c] = False
        costs = np.delete(costs, r, axis=0)
        costs = costs + near[c][None, :]
