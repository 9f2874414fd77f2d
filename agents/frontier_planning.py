"""Frontier planning on a robot's occupancy grid: frontier cells (known free next to unknown)
clustered, path costs through the configuration space (``skimage.graph.MCP_Geometric``), and
pure pursuit along the chosen path. :class:`agents.scripted.Frontier` and the learned goal
selection of :mod:`agents.goals` plan with it."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage
from skimage.graph import MCP_Geometric

from fusion.rigid import Rigid2D
from topo.grid import CellState
from topo.validation import check_int, check_real


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

    def __post_init__(self) -> None:
        for name in ("clearance", "wall_cost_distance", "arrive_distance", "lookahead",
                     "occupied_log_odds", "give_up_radius", "min_progress",
                     "blocked_distance", "min_goal_distance", "min_unknown_area"):
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
