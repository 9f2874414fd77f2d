"""Frontier planning on a robot's occupancy grid: frontier cells (known free next to unknown)
clustered, path costs through the configuration space (``skimage.graph.MCP_Geometric``), and
pure pursuit along the chosen path. :class:`agents.scripted.Frontier` and the learned goal
selection of :mod:`agents.goals` plan with it."""

from __future__ import annotations

import math
from collections.abc import Sequence
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
        replan_every: steps between plans while a goal is being followed (with
            ``max_plan_age``: between checks of it).
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
        search_radius: metres; :class:`Frontier` looks for its goal within this of the robot
            first, then twice as far, and so on until the answer is that of the whole map
            (:meth:`FrontierMap.nearest` with ``exact_below``): a plan costs the neighbourhood
            of the nearest frontier, not the whole (large) building's map.
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
    search_radius: float = 6.0
    max_plan_age: int = 0

    def __post_init__(self) -> None:
        for name in ("clearance", "wall_cost_distance", "arrive_distance", "lookahead",
                     "occupied_log_odds", "give_up_radius", "min_progress",
                     "blocked_distance", "min_goal_distance", "min_unknown_area",
                     "search_radius"):
            check_real(getattr(self, name), f"FrontierConfig.{name}", low=0.0)
        check_real(self.hysteresis, "FrontierConfig.hysteresis", low=0.0, low_inclusive=True)
        check_int(self.min_cluster_cells, "FrontierConfig.min_cluster_cells", low=1)
        check_int(self.replan_every, "FrontierConfig.replan_every", low=1)
        check_int(self.stall_steps, "FrontierConfig.stall_steps", low=1)
        check_int(self.max_blocks, "FrontierConfig.max_blocks", low=1)
        check_int(self.max_plan_age, "FrontierConfig.max_plan_age", low=0)


@dataclass(slots=True)
class Plan:
    """A path to a frontier goal in the robot's own frame (``path`` ``(K, 2)`` metres)."""

    path: np.ndarray
    goal: np.ndarray
    cost: float
    age: int = 0
    checks: int = 0


@dataclass(slots=True)
class FrontierMap:
    """Frontier clusters and the configuration space around the robot, on a crop of its grid.

    Path costs come from ``MCP_Geometric`` searches from the robot's cell, run when first
    needed: :meth:`clusters` (and :attr:`cost_to`, :attr:`mcp`) search the whole crop;
    :meth:`nearest` stops at the first frontier reached (what :class:`Frontier` needs, and a
    small part of a large building's map)."""

    costs: np.ndarray
    """Step cost (m per cell) of every crop cell (inf: not drivable)."""
    start: tuple[int, int]
    """The robot's crop cell (row, col)."""
    labels: np.ndarray
    """Frontier cluster label per crop cell (0: none)."""
    n_clusters: int
    origin: np.ndarray
    """World position of the crop's cell (0, 0) corner."""
    resolution: float
    exact_below: float = math.inf
    """Path costs (m) below this are those of the whole map (``inf`` unless the crop is a
    window around the robot, ``frontier_map(radius=...)``): a cheaper path cannot reach the
    window's edge, where walls, frontiers and pockets beyond it are not seen."""
    _search: tuple[MCP_Geometric, np.ndarray] | None = None
    _complete: bool = False
    _cells: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def cell_to_xy(self, cells: np.ndarray) -> np.ndarray:
        return self.origin + (np.asarray(cells)[:, ::-1] + 0.5) * self.resolution

    # ----------------------------------------------------------------- searches
    def _full(self) -> tuple[MCP_Geometric, np.ndarray]:
        if not self._complete:
            mcp = MCP_Geometric(self.costs, fully_connected=True)
            cost_to, _ = mcp.find_costs([self.start])
            self._search, self._complete = (mcp, cost_to), True
        return self._search

    @property
    def cost_to(self) -> np.ndarray:
        """Cumulative path cost (m) from the robot to every crop cell (inf: unreachable)."""
        return self._full()[1]

    @property
    def mcp(self) -> MCP_Geometric:
        """The whole-crop search from the robot (its traceback gives :meth:`path_to`)."""
        return self._full()[0]

    def costs_from(self, cell: tuple[int, int]) -> np.ndarray:
        """Cumulative path cost (m) from crop cell ``cell`` to every crop cell (a search of
        its own: the robot's paths are kept)."""
        cost, _ = MCP_Geometric(self.costs, fully_connected=True).find_costs([tuple(cell)])
        return cost

    def path_to(self, cell: tuple[int, int]) -> np.ndarray:
        """``(K, 2)`` world points of the cheapest path from the robot to ``cell`` (a cell
        the last search reached)."""
        mcp = self._search[0] if self._search is not None else self.mcp
        return self.cell_to_xy(np.asarray(mcp.traceback(tuple(cell))))

    # ----------------------------------------------------------------- clusters
    def _frontier_cells(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rows, cols and labels of the frontier cells (raster order)."""
        if self._cells is None:
            rows, cols = np.nonzero(self.labels)
            self._cells = (rows, cols, self.labels[rows, cols])
        return self._cells

    def labels_near(self, xy: np.ndarray, radius: float) -> np.ndarray:
        """Labels of the clusters with a cell within ``radius`` of world point ``xy``."""
        rows, cols, lab = self._frontier_cells()
        d2 = ((self.cell_to_xy(np.stack([rows, cols], 1)) - np.asarray(xy)[:2]) ** 2).sum(1)
        return np.unique(lab[d2 < radius * radius])

    def _stats(self, min_cells: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per cluster: size, centroid (world), kept (size >= ``min_cells``)."""
        rows, cols, lab = self._frontier_cells()
        idx = np.arange(1, self.n_clusters + 1)
        sizes = np.asarray(ndimage.sum_labels(np.ones(len(lab)), lab, idx))
        centre = np.stack([ndimage.mean(rows.astype(np.float64), lab, idx),
                           ndimage.mean(cols.astype(np.float64), lab, idx)], axis=1)
        return sizes, self.cell_to_xy(centre.reshape(-1, 2)), sizes >= min_cells

    def _cluster(self, k: int, cell: tuple[int, int], cost: float, sizes: np.ndarray,
                 centroids: np.ndarray) -> dict[str, Any]:
        return {"size": int(sizes[k]), "cell": cell, "cost": cost, "centroid": centroids[k],
                "label": k + 1}

    def clusters(self, min_cells: int) -> list[dict[str, Any]]:
        """Reachable clusters of at least ``min_cells`` cells: size, cheapest cell, its cost,
        centroid (world), label."""
        if self.n_clusters == 0:
            return []
        cost_to = self.cost_to
        rows, cols, lab = self._frontier_cells()
        idx = np.arange(1, self.n_clusters + 1)
        sizes, centroids, kept = self._stats(min_cells)
        best = ndimage.minimum_position(cost_to[rows, cols], lab, idx)
        out = []
        for k in range(self.n_clusters):
            i = best[k][0]
            cell = (int(rows[i]), int(cols[i]))
            if not kept[k] or not np.isfinite(cost_to[cell]):
                continue
            out.append(self._cluster(k, cell, float(cost_to[cell]), sizes, centroids))
        return out

    def nearest(self, min_cells: int, goal: np.ndarray | None = None, radius: float = 0.0,
                bonus: float = 0.0) -> dict[str, Any] | None:
        """The cluster (at least ``min_cells`` cells) of least path cost, ``bonus`` metres
        less if its cheapest cell is within ``radius`` of ``goal`` (the current goal's
        cluster), as :meth:`clusters` gives it; ``None`` if none is reachable.

        The search stops at the first frontier cell reached (then at the first cell of each
        cluster near ``goal`` that could still win), so it costs the area closer than the
        goal, not the whole map."""
        if self.n_clusters == 0:
            return None
        sizes, centroids, kept = self._stats(min_cells)
        best = self._first_reached(kept)
        if best is None:
            return None
        if goal is not None and not self._near(best[1], goal, radius):
            # a cluster near the goal wins if its cheapest cell is near it and within bonus
            candidates = kept & np.isin(np.arange(1, self.n_clusters + 1),
                                        self.labels_near(goal, radius))
            candidates[best[0]] = False
            while candidates.any():
                other = self._first_reached(candidates)
                if other is None or other[2] - bonus >= best[2]:
                    break
                if self._near(other[1], goal, radius):
                    best = other
                    break
                candidates[other[0]] = False
        k, cell, cost, search = best
        self._search, self._complete = search, False
        return self._cluster(k, cell, cost, sizes, centroids)

    def _near(self, cell: tuple[int, int], xy: np.ndarray, radius: float) -> bool:
        return bool(np.linalg.norm(self.cell_to_xy(np.array([cell]))[0] - xy) < radius)

    def _first_reached(self, wanted: np.ndarray) -> tuple | None:
        """Search from the robot until the first cell of a cluster with ``wanted[label - 1]``:
        ``(cluster index, cell, cost, (mcp, cost_to))``, ``None`` if none is reachable."""
        rows, cols, lab = self._frontier_cells()
        ends = np.flatnonzero(wanted[lab - 1])
        if len(ends) == 0:
            return None
        mcp = MCP_Geometric(self.costs, fully_connected=True)
        cost_to, _ = mcp.find_costs([self.start], ends=np.stack([rows[ends], cols[ends]], 1),
                                    find_all_ends=False)
        end_costs = cost_to[rows[ends], cols[ends]]
        if not np.isfinite(end_costs).any():
            return None
        i = int(ends[np.argmin(end_costs)])
        cell = (int(rows[i]), int(cols[i]))
        return int(lab[i]) - 1, cell, float(cost_to[cell]), (mcp, cost_to)


def frontier_map(grid: Any, pose_xy: np.ndarray, cfg: FrontierConfig,
                 exclude: np.ndarray | None = None,
                 teammates: Sequence[tuple[Any, Rigid2D]] = (),
                 within: tuple[int, int, int, int] | None = None,
                 radius: float | None = None) -> FrontierMap | None:
    """Frontier clusters and the configuration space from ``pose_xy`` on ``grid`` (cropped to
    its known cells); ``None`` if nothing is known yet.

    Args:
        exclude: ``(K, 2)`` points (own frame): frontier cells within ``cfg.give_up_radius`` of
            one are dropped (goals given up).
        teammates: ``(grid, transform)`` per teammate, the transform from this robot's frame
            into the teammate's: their evidence (log-odds, nearest cell) is added to this
            robot's, in this order, over all their known area, so frontiers and paths are
            those of the fused map (frontiers a teammate has already explored disappear).
        within: rows and columns ``(r0, r1, c0, c1)`` of ``grid`` that hold all its known
            cells (e.g. the robot's path so far, widened by the sensing range): the known
            cells are looked for there only, not over the whole grid (a large building's
            grid is millions of cells). A known cell on the box's edge (or an empty box)
            means it was too small: the whole grid is searched then.
        radius: only the window within ``radius`` + :data:`WINDOW_MARGIN` metres of the
            robot (in each axis) is mapped (no ``teammates`` then); the map's
            :attr:`FrontierMap.exact_below` says which answers are those of the whole map.
    """
    states = grid.states()
    h, w = states.shape
    b0, b1, a0, a1 = 0, h, 0, w
    if within is not None:
        b0, b1 = max(int(within[0]), 0), min(int(within[1]), h)
        a0, a1 = max(int(within[2]), 0), min(int(within[3]), w)
    known = states[b0:b1, a0:a1] != CellState.UNKNOWN
    if within is not None and (
            known.size == 0 or (b0 > 0 and known[0].any()) or (b1 < h and known[-1].any())
            or (a0 > 0 and known[:, 0].any()) or (a1 < w and known[:, -1].any())):
        b0, b1, a0, a1 = 0, h, 0, w
        known = states != CellState.UNKNOWN
    rows = np.flatnonzero(known.any(axis=1))
    if len(rows) == 0:
        return None
    cols = np.flatnonzero(known.any(axis=0))
    res = float(grid.resolution)
    r0, r1 = b0 + rows[0], b0 + rows[-1] + 1
    c0, c1 = a0 + cols[0], a0 + cols[-1] + 1
    for mate, to_mate in teammates:
        box = _known_box_in(mate, to_mate.inverse(), grid)
        if box is not None:
            r0, r1 = min(r0, box[0]), max(r1, box[1])
            c0, c1 = min(c0, box[2]), max(c1, box[3])
    r0, r1 = max(r0 - 2, 0), min(r1 + 2, h)
    c0, c1 = max(c0 - 2, 0), min(c1 + 2, w)
    exact_below = math.inf
    if radius is not None:
        if teammates:
            raise ValueError("radius applies without teammates only")
        margin = max(WINDOW_MARGIN, cfg.wall_cost_distance + 2 * res,
                     (cfg.min_cluster_cells + 1) * res)
        r0, r1, c0, c1, exact_below = _window(grid, pose_xy, radius, margin,
                                              (r0, r1, c0, c1))
    origin = np.asarray(grid.origin, dtype=np.float64) + np.array([c0, r0]) * res
    log_odds = grid.log_odds[r0:r1, c0:c1]
    if not teammates:
        crop = states[r0:r1, c0:c1]
    else:
        for mate, to_mate in teammates:
            log_odds = log_odds + _sample_log_odds(mate, to_mate, origin, res, log_odds.shape)
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
    win, disc = _disc(rc, grow ** 2, crop.shape, inclusive=True)
    mine = disc & ~occupied[win]
    costs[win][mine] = np.minimum(costs[win][mine], 1.0)
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
    win, disc = _disc(rc, (cfg.min_goal_distance / res) ** 2, crop.shape, inclusive=False)
    frontier[win] &= ~disc
    if exclude is not None and len(exclude) and frontier.any():
        fy, fx = np.nonzero(frontier)
        xy = origin + (np.stack([fx, fy], 1) + 0.5) * res
        d2 = ((xy[:, None, :] - np.asarray(exclude)[None, :, :2]) ** 2).sum(-1).min(1)
        drop = d2 < cfg.give_up_radius ** 2
        frontier[fy[drop], fx[drop]] = False
    labels, n = ndimage.label(frontier, structure=np.ones((3, 3)))
    return FrontierMap(costs * res, (int(rc[0]), int(rc[1])), labels, n, origin, res,
                       exact_below)


WINDOW_MARGIN = 1.5
"""Metres (at least) of a ``frontier_map(radius=...)`` window beyond its exact part: a
frontier cluster of fewer than ``min_cluster_cells`` cells cannot span it, nor clearance and
wall costs (from walls up to ``wall_cost_distance`` away) reach across it; an unknown pocket
smaller than ``min_unknown_area`` that does (a strip 1.5 m long) is taken for territory."""


def _window(grid: Any, pose_xy: np.ndarray, radius: float, margin: float,
            crop: tuple[int, int, int, int]) -> tuple[int, int, int, int, float]:
    """``crop`` (rows, cols) cut to the robot's ``radius`` + ``margin`` window, and the cost
    below which paths in it are exact (inf if the window holds the crop)."""
    res = float(grid.resolution)
    r0, r1, c0, c1 = crop
    half = int(math.ceil((radius + margin) / res))
    col = int(math.floor((pose_xy[0] - grid.origin[0]) / res))
    row = int(math.floor((pose_xy[1] - grid.origin[1]) / res))
    w0, w1 = max(r0, row - half), min(r1, row + half + 1)
    v0, v1 = max(c0, col - half), min(c1, col + half + 1)
    if w1 <= w0 or v1 <= v0:  # the robot is off its own known area: map it all
        return r0, r1, c0, c1, math.inf
    # distance from the robot to each cut edge (edges of the crop itself are exact)
    y = pose_xy[1] - grid.origin[1]
    x = pose_xy[0] - grid.origin[0]
    cuts = [d for d, cut in ((y - w0 * res, w0 > r0), (w1 * res - y, w1 < r1),
                             (x - v0 * res, v0 > c0), (v1 * res - x, v1 < c1)) if cut]
    exact = min(cuts) - margin if cuts else math.inf
    return w0, w1, v0, v1, exact


def _disc(rc: np.ndarray, radius2: float, shape: tuple[int, int],
          inclusive: bool) -> tuple[tuple[slice, slice], np.ndarray]:
    """The window of ``shape`` around cell ``rc`` that holds the cells within ``radius2``
    (squared cells; on it with ``inclusive``), and the mask of those cells in it."""
    r = int(math.isqrt(int(math.floor(radius2)))) + 1
    win = (slice(max(rc[0] - r, 0), min(rc[0] + r + 1, shape[0])),
           slice(max(rc[1] - r, 0), min(rc[1] + r + 1, shape[1])))
    rr, cc = np.ogrid[win[0], win[1]]
    d2 = (rr - rc[0]) ** 2 + (cc - rc[1]) ** 2
    return win, (d2 <= radius2) if inclusive else (d2 < radius2)


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


def is_frontier_cell(grid: Any, xy: np.ndarray) -> bool:
    """Whether the cell of ``grid`` at ``xy`` or one of its 8 neighbours is known free next
    to an unknown cell (a frontier cell of :func:`frontier_map`, pockets aside): a look at a
    5 × 5 block of the grid, not a plan."""
    res = float(grid.resolution)
    col = int(math.floor((xy[0] - grid.origin[0]) / res))
    row = int(math.floor((xy[1] - grid.origin[1]) / res))
    states = grid.states()
    h, w = states.shape
    if not (2 <= row < h - 2 and 2 <= col < w - 2):
        return False
    block = states[row - 2:row + 3, col - 2:col + 3]
    unknown = ndimage.binary_dilation(block == CellState.UNKNOWN, structure=np.ones((3, 3)))
    return bool((unknown & (block == CellState.FREE))[1:4, 1:4].any())


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
