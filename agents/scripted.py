"""Scripted explorers: random walk, wall following, frontier exploration and its coordinated
two-robot version.

All drive from the robot's own sensing: the ``sonar`` observation (ranges normalised by the
sonar's ``max_range``), ``info["odometry"]`` (pose in the robot's own start frame) and, for the
frontier explorers, the robot's own :class:`topo.OccupancyGrid`, read when they plan from the
env they are bound to (``env.robot_map(agent).grid``, see :meth:`agents.base.Explorer.bind`).
None of them reads the true pose.

* :class:`RandomWalk` — bump and turn: drive ahead, turn away for a random time when the front
  sonars see something close.
* :class:`WallFollower` — keep a wall on the right at a set distance.
* :class:`Frontier` — Yamauchi (1997): frontier cells (known free next to unknown) of the
  robot's own grid, clustered; the nearest cluster by path cost through the configuration
  space (``skimage.graph.MCP_Geometric``), followed by pure pursuit; re-plan on arrival,
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
from skimage.graph import MCP_Geometric

from agents.base import CommandExplorer, Explorer
from envs.two_robot_explore.config import SonarConfig
from fusion.rigid import Rigid2D
from topo.grid import CellState
from topo.validation import check_int, check_real

_SONAR = SonarConfig()
SONAR_ANGLES = np.radians(np.asarray(_SONAR.angles, dtype=np.float64))
"""Sonar directions (robot frame) the explorers assume: the env's default Pioneer ring."""
FRONT = np.abs(SONAR_ANGLES) < math.radians(35.0)
RIGHT = SONAR_ANGLES < -math.radians(35.0)
LEFT = SONAR_ANGLES > math.radians(35.0)


def sonar_metres(observation: Mapping[str, Any], max_range: float) -> np.ndarray:
    """The ``sonar`` observation in metres."""
    return np.asarray(observation["sonar"], dtype=np.float64) * max_range


def _pose(info: Mapping[str, Any]) -> np.ndarray:
    return np.asarray(info["odometry"], dtype=np.float64)[:3]


# ---------------------------------------------------------------------------- random walk
class RandomWalk(CommandExplorer):
    """Bump and turn: drive ahead with a little random steering; when a front sonar reads
    less than ``bump_distance``, turn (away from the nearer side) for a random 5–20 steps.

    Args:
        bump_distance: metres; front echo closer than this triggers a turn.
        max_range: the env's sonar ``max_range`` (to read the normalised observation).
        action_type: see :class:`Explorer`.
    """

    name = "random_walk"

    def __init__(self, bump_distance: float = 0.6, max_range: float = _SONAR.max_range,
                 action_type: str = "continuous") -> None:
        super().__init__(action_type)
        self.bump_distance = check_real(bump_distance, "bump_distance", low=0.0)
        self.max_range = check_real(max_range, "max_range", low=0.0)
        self._turn_left = 0
        self._turn_steps = 0

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self._turn_steps = 0

    def command(self, observation, info) -> np.ndarray:
        ranges = sonar_metres(observation, self.max_range)
        if self._turn_steps > 0:
            self._turn_steps -= 1
            return np.array([0.0, self._turn_left])
        if ranges[FRONT].min() < self.bump_distance:
            self._turn_left = 1.0 if ranges[LEFT].min() > ranges[RIGHT].min() else -1.0
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
        max_range: the env's sonar ``max_range``.
        action_type: see :class:`Explorer`.
    """

    name = "wall_follower"

    def __init__(self, distance: float = 0.7, gain: float = 1.5,
                 max_range: float = _SONAR.max_range, action_type: str = "continuous") -> None:
        super().__init__(action_type)
        self.distance = check_real(distance, "distance", low=0.0)
        self.gain = check_real(gain, "gain", low=0.0)
        self.max_range = check_real(max_range, "max_range", low=0.0)

    def command(self, observation, info) -> np.ndarray:
        ranges = sonar_metres(observation, self.max_range)
        if ranges[FRONT].min() < self.distance:
            return np.array([0.0, 1.0])
        right = ranges[RIGHT].min()
        if right >= self.max_range * 0.95:  # no wall: curve right to find one
            return np.array([0.6, -0.5])
        return np.array([0.8, float(np.clip(self.gain * (right - self.distance), -1, 1))])


# ---------------------------------------------------------------------------- frontier
@dataclass(frozen=True, slots=True)
class FrontierConfig:
    """Settings of :class:`Frontier` (validated; metres, steps).

    Attributes:
        clearance: paths keep at least this far from obstacles (the rest of the robot's radius
            is left to the soft cost and the bump reflex: sonar maps make doorways narrow).
        wall_cost_distance: cells closer than this to an obstacle cost up to 5× more, which
            keeps paths centred in corridors and doorways.
        occupied_log_odds: a cell blocks planning only above this log-odds (a sonar arc marks
            a whole arc once; walls are hit again and again).
        min_cluster_cells: frontier clusters smaller than this are noise.
        min_goal_distance: frontier cells closer than this to the robot are already being
            sensed and are not goals.
        min_unknown_area: unknown pockets smaller than this (m²) are gaps between sonar cones
            inside explored space, not territory: they make no frontier.
        replan_every: steps between plans while a goal is being followed.
        arrive_distance: the goal counts as reached within this distance.
        lookahead: pure-pursuit look-ahead along the path.
        blocked_distance: a front echo closer than this means "blocked": back off and re-plan.
        give_up_radius: frontier cells within this of a goal given up (reached without the
            frontier going away, no progress, or blocked again and again) are no longer goals.
            Sonar maps leave frontiers that driving to them does not clear: free space seen
            through walls (lost echoes) and cone gaps; without this the robot circles them.
        stall_steps: a goal whose path cost has not dropped by ``min_progress`` within this
            many steps is given up.
        min_progress: metres, see ``stall_steps``.
        max_blocks: a goal is given up after this many "blocked" back-offs on the way to it.
        hysteresis: metres; at a re-plan the current goal is kept unless another frontier is
            this much cheaper (no dithering between two frontiers of similar cost).
        max_range: the env's sonar ``max_range``.
    """

    clearance: float = 0.2
    wall_cost_distance: float = 0.6
    occupied_log_odds: float = 1.2
    min_cluster_cells: int = 8
    min_goal_distance: float = 1.0
    min_unknown_area: float = 1.0
    replan_every: int = 15
    arrive_distance: float = 0.4
    lookahead: float = 0.6
    blocked_distance: float = 0.3
    give_up_radius: float = 1.0
    stall_steps: int = 60
    min_progress: float = 0.5
    max_blocks: int = 3
    hysteresis: float = 1.0
    max_range: float = _SONAR.max_range

    def __post_init__(self) -> None:
        for name in ("clearance", "wall_cost_distance", "arrive_distance", "lookahead",
                     "occupied_log_odds", "give_up_radius", "min_progress",
                     "blocked_distance", "max_range", "min_goal_distance", "min_unknown_area"):
            check_real(getattr(self, name), f"FrontierConfig.{name}", low=0.0)
        check_real(self.hysteresis, "FrontierConfig.hysteresis", low=0.0, low_inclusive=True)
        check_int(self.min_cluster_cells, "FrontierConfig.min_cluster_cells", low=1)
        check_int(self.replan_every, "FrontierConfig.replan_every", low=1)
        check_int(self.stall_steps, "FrontierConfig.stall_steps", low=1)
        check_int(self.max_blocks, "FrontierConfig.max_blocks", low=1)


@dataclass(slots=True)
class Plan:
    """A path to a frontier goal in the robot's own frame (``path`` ``(K, 2)`` metres)."""

    path: np.ndarray
    goal: np.ndarray
    cost: float
    age: int = 0


@dataclass(slots=True)
class FrontierMap:
    """Frontier clusters and path costs from the robot, on a crop of its grid."""

    cost_to: np.ndarray
    """Cumulative path cost (m) from the robot to every crop cell (inf: unreachable)."""
    labels: np.ndarray
    """Frontier cluster label per crop cell (0: none)."""
    n_clusters: int
    mcp: MCP_Geometric
    origin: np.ndarray
    """World position of the crop's cell (0, 0) corner."""
    resolution: float

    def cell_to_xy(self, cells: np.ndarray) -> np.ndarray:
        return self.origin + (np.asarray(cells)[:, ::-1] + 0.5) * self.resolution

    def path_to(self, cell: tuple[int, int]) -> np.ndarray:
        return self.cell_to_xy(np.asarray(self.mcp.traceback(cell)))

    def clusters(self, min_cells: int) -> list[dict[str, Any]]:
        """Reachable clusters: size, cheapest cell, its cost, centroid (world)."""
        if self.n_clusters == 0:
            return []
        idx = np.arange(1, self.n_clusters + 1)
        sizes = ndimage.sum_labels(np.ones_like(self.labels), self.labels, idx)
        cost = np.where(self.labels > 0, self.cost_to, np.inf)
        best = ndimage.minimum_position(cost, self.labels, idx)
        centroids = ndimage.center_of_mass(np.ones_like(self.labels), self.labels, idx)
        out = []
        for k in range(self.n_clusters):
            c = best[k]
            if sizes[k] < min_cells or not np.isfinite(self.cost_to[c]):
                continue
            out.append({"size": int(sizes[k]), "cell": c, "cost": float(self.cost_to[c]),
                        "centroid": self.cell_to_xy(np.array([centroids[k]]))[0]})
        return out


def frontier_map(grid: Any, pose_xy: np.ndarray, cfg: FrontierConfig,
                 exclude: np.ndarray | None = None,
                 teammate: tuple[Any, Rigid2D] | None = None) -> FrontierMap | None:
    """Frontier clusters and path costs from ``pose_xy`` on ``grid`` (cropped to its known
    cells); ``None`` if nothing is known yet.

    Args:
        exclude: ``(K, 2)`` points (own frame): frontier cells within ``cfg.give_up_radius`` of
            one are dropped (goals given up).
        teammate: the teammate's grid and the transform from this robot's frame into the
            teammate's: its evidence (log-odds, nearest cell) is added to this robot's over
            both robots' known area, so frontiers and paths are those of the shared map
            (frontiers the teammate has already explored disappear).
    """
    states = grid.states()
    known = states != CellState.UNKNOWN
    rows, cols = np.nonzero(known)
    if len(rows) == 0:
        return None
    res = float(grid.resolution)
    r0, r1 = rows.min(), rows.max() + 1
    c0, c1 = cols.min(), cols.max() + 1
    if teammate is not None:
        box = _known_box_in(teammate[0], teammate[1].inverse(), grid)
        if box is not None:
            r0, r1 = min(r0, box[0]), max(r1, box[1])
            c0, c1 = min(c0, box[2]), max(c1, box[3])
    r0, r1 = max(r0 - 2, 0), min(r1 + 2, states.shape[0])
    c0, c1 = max(c0 - 2, 0), min(c1 + 2, states.shape[1])
    origin = np.asarray(grid.origin, dtype=np.float64) + np.array([c0, r0]) * res
    log_odds = grid.log_odds[r0:r1, c0:c1]
    if teammate is None:
        crop = states[r0:r1, c0:c1]
    else:
        log_odds = log_odds + _sample_log_odds(teammate[0], teammate[1], origin, res,
                                               log_odds.shape)
        t = grid.model.threshold
        crop = np.full(log_odds.shape, CellState.UNKNOWN, dtype=np.int8)
        crop[log_odds < -t] = CellState.FREE
        crop[log_odds > t] = CellState.OCCUPIED

    free = crop == CellState.FREE
    unknown = crop == CellState.UNKNOWN
    # Sonar arcs smear walls into doorways; only cells hit again and again block the way.
    occupied = log_odds > cfg.occupied_log_odds
    dist = ndimage.distance_transform_edt(~occupied) * res
    blocked = dist < cfg.clearance
    costs = np.where(free & ~blocked, 1.0, np.inf)
    near = np.isfinite(costs) & (dist < cfg.wall_cost_distance)
    costs[near] += 4.0 * (cfg.wall_cost_distance - dist[near]) / cfg.wall_cost_distance
    grow = max(1, int(math.ceil(cfg.clearance / res)))

    rc = np.floor((pose_xy - origin) / res).astype(int)[::-1]
    rc = np.clip(rc, 0, np.array(crop.shape) - 1)
    # the robot's own cell and its disc are drivable whatever the (noisy) map says
    rr, cc = np.ogrid[: crop.shape[0], : crop.shape[1]]
    own = (rr - rc[0]) ** 2 + (cc - rc[1]) ** 2 <= grow ** 2
    costs[own & ~occupied] = np.minimum(costs[own & ~occupied], 1.0)
    costs[rc[0], rc[1]] = 1.0

    labels_u, n_u = ndimage.label(unknown)
    if n_u:
        sizes = np.bincount(labels_u.ravel(), minlength=n_u + 1)
        big = sizes >= cfg.min_unknown_area / (res * res)
        big[0] = False
        # the crop's border touches the unexplored outside: pockets reaching it are territory
        border = np.unique(np.concatenate([labels_u[0], labels_u[-1], labels_u[:, 0],
                                           labels_u[:, -1]]))
        big[border[border > 0]] = True
        unknown = big[labels_u]
    frontier = free & ~blocked & ndimage.binary_dilation(unknown, structure=np.ones((3, 3)))
    near_robot = (rr - rc[0]) ** 2 + (cc - rc[1]) ** 2 < (cfg.min_goal_distance / res) ** 2
    frontier &= ~near_robot
    if exclude is not None and len(exclude) and frontier.any():
        fy, fx = np.nonzero(frontier)
        xy = origin + (np.stack([fx, fy], 1) + 0.5) * res
        d2 = ((xy[:, None, :] - np.asarray(exclude)[None, :, :2]) ** 2).sum(-1).min(1)
        drop = d2 < cfg.give_up_radius ** 2
        frontier[fy[drop], fx[drop]] = False
    labels, n = ndimage.label(frontier, structure=np.ones((3, 3)))
    mcp = MCP_Geometric(costs * res, fully_connected=True)
    cost_to, _ = mcp.find_costs([tuple(rc)])
    return FrontierMap(cost_to, labels, n, mcp, origin, res)


def _sample_log_odds(grid: Any, transform: Rigid2D, origin: np.ndarray, res: float,
                     shape: tuple[int, int]) -> np.ndarray:
    """``shape`` log-odds of ``grid`` (nearest cell; 0 outside it) at the centres of a crop
    (``origin``, ``res``), ``transform`` taking the crop's frame into ``grid``'s."""
    h, w = shape
    xs = origin[0] + (np.arange(w) + 0.5) * res
    ys = origin[1] + (np.arange(h) + 0.5) * res
    c, s_ = math.cos(transform.theta), math.sin(transform.theta)
    tx, ty = transform.T
    g_res = float(grid.resolution)
    ix = np.floor((c * xs[None, :] - s_ * ys[:, None] + tx - grid.origin[0]) / g_res)
    iy = np.floor((s_ * xs[None, :] + c * ys[:, None] + ty - grid.origin[1]) / g_res)
    ix, iy = ix.astype(np.int64), iy.astype(np.int64)
    gh, gw = grid.log_odds.shape
    inside = (ix >= 0) & (ix < gw) & (iy >= 0) & (iy < gh)
    out = np.zeros(shape, dtype=np.float64)
    out[inside] = grid.log_odds[iy[inside], ix[inside]]
    return out


def _known_box_in(other: Any, transform: Rigid2D, grid: Any) -> tuple[int, int, int, int] | None:
    """Rows/cols ``(r0, r1, c0, c1)`` of ``grid`` covering ``other``'s known cells moved by
    ``transform`` (``other``'s frame → ``grid``'s); ``None`` if ``other`` knows nothing."""
    rows, cols = np.nonzero(other.states() != CellState.UNKNOWN)
    if len(rows) == 0:
        return None
    res_o = float(other.resolution)
    x = other.origin[0] + np.array([cols.min(), cols.max() + 1]) * res_o
    y = other.origin[1] + np.array([rows.min(), rows.max() + 1]) * res_o
    corners = transform.apply(np.array([[x[0], y[0]], [x[1], y[0]], [x[0], y[1]],
                                        [x[1], y[1]]]))
    res = float(grid.resolution)
    c = np.floor((corners[:, 0] - grid.origin[0]) / res).astype(int)
    r = np.floor((corners[:, 1] - grid.origin[1]) / res).astype(int)
    h, w = grid.log_odds.shape
    return (int(np.clip(r.min(), 0, h)), int(np.clip(r.max() + 1, 0, h)),
            int(np.clip(c.min(), 0, w)), int(np.clip(c.max() + 1, 0, w)))


def pure_pursuit(pose: np.ndarray, path: np.ndarray, lookahead: float) -> np.ndarray:
    """Normalised ``(v, ω)`` steering ``pose`` along ``path`` (look-ahead point on the path)."""
    d = np.linalg.norm(path - pose[:2], axis=1)
    i = int(np.argmin(d))
    ahead = np.flatnonzero(d[i:] >= lookahead)
    target = path[i + ahead[0]] if len(ahead) else path[-1]
    heading = math.atan2(target[1] - pose[1], target[0] - pose[0])
    err = math.remainder(heading - pose[2], 2 * math.pi)
    turn = float(np.clip(2.0 * err, -1.0, 1.0))
    speed = 0.0 if abs(err) > math.radians(60) else math.cos(err)
    return np.array([speed, turn])


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
        self._fallback = RandomWalk(max_range=self.cfg.max_range)
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
        pose = _pose(info)
        ranges = sonar_metres(observation, self.cfg.max_range)
        if self._backoff > 0:
            self._backoff -= 1
            return np.array([-0.5, 0.0])
        if ranges[FRONT].min() < self.cfg.blocked_distance:
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

    def _maps(self) -> Any:
        """The bound env, which the robots' maps are read from."""
        if self.env is None:
            raise RuntimeError(f"{type(self).__name__} plans on its robot's occupancy grid, read "
                               f"from the env: bind it first (explorer.bind(env, agent), "
                               f"make_team(name, env=env), or run_episode)")
        return self.env

    def _grid(self, agent: str | None = None) -> Any:
        """The occupancy grid of robot ``agent`` (default: this explorer's) now, a snapshot
        read from the bound env."""
        return self._maps().robot_map(agent or self.agent).grid

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
        self.board.transform = self._maps().merge_state().transform
        mate = np.asarray(observation["teammate"], dtype=np.float64)
        if mate[4] > 0.5:  # valid: robot-frame offset of the teammate -> own frame
            pose = _pose(info)
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


EXPLORERS = {
    "random_walk": RandomWalk,
    "wall_follower": WallFollower,
    "frontier": Frontier,
    "coordinated_frontier": CoordinatedFrontier,
}
"""Scripted explorers by name (``make_team`` also accepts ``"sb3:PATH"``)."""


def make_team(name: str, action_type: str = "continuous", env: Any = None
              ) -> dict[str, Explorer]:
    """One explorer per robot, ``{"robot_0": ..., "robot_1": ...}``; the coordinated team
    shares one :class:`Blackboard`. With ``env``, each is bound to its robot of it
    (:meth:`agents.base.Explorer.bind`: the frontier explorers read their maps there)."""
    if name.startswith("sb3:"):
        from agents.sb3_explorer import SB3Explorer

        policy = SB3Explorer.load_policy(name[4:])
        team = {f"robot_{i}": SB3Explorer(policy, action_type=action_type) for i in range(2)}
    elif name == "coordinated_frontier":
        board = Blackboard()
        team = {f"robot_{i}": CoordinatedFrontier(i, board, action_type=action_type)
                for i in range(2)}
    elif name not in EXPLORERS:
        raise ValueError(f"explorer must be one of {sorted(EXPLORERS)} or 'sb3:PATH', "
                         f"got {name!r}")
    else:
        team = {f"robot_{i}": EXPLORERS[name](action_type=action_type) for i in range(2)}
    if env is not None:
        for agent, explorer in team.items():
            explorer.bind(env, agent)
    return team
