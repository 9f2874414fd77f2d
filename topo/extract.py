"""``extract_topomap``: free space → skeleton → topological map (junctions, dead ends, corners).

Pipeline (all parameters in :class:`ExtractConfig`):

1. **Free space** — a boolean mask (or an :class:`~topo.grid.OccupancyGrid`'s free cells),
   cropped to its free cells' bounding box; holes smaller than ``min_hole_area`` (sonar
   speckle) are filled, the mask is optionally eroded by ``erode_radius`` (the robot), and free
   components smaller than ``min_component_area`` are dropped: skimage's ``remove_small_holes``,
   scipy's ``binary_erosion`` by a ``disk`` and ``ndimage.label``, computed in one compiled pass
   each (:func:`topo._extract_kernels.clean_free`, tested to give the libraries' mask).
2. **Skeleton** — ``skimage.morphology.skeletonize`` (Zhang–Suen thinning), bit for bit, by the
   compiled :func:`topo._extract_kernels.skeletonize` (skimage's lookup table; it re-examines
   only pixels beside removed ones instead of rescanning the image every subpass).
3. **Graph** — the skeleton is traced into paths between junction and end pixels exactly as
   ``skan.csr.Skeleton`` does (``pixel_graph``, each cluster of junction pixels reduced to
   scipy's minimum spanning tree, ``PathGraph``): the same paths, pixel for pixel and in the
   same order, by the compiled kernel :func:`topo._extract_kernels.skeleton_paths` (on the
   env's ~100-cell sonar grids the library calls' fixed cost, building scipy sparse matrices,
   was a third of an extraction); ``tests/topo`` checks it against skan itself.
4. **Spurs** — a dead-end path is pruned when it *protrudes* less than ``min_spur_length``
   beyond the free disc at its junction: ``length − (r_junction − r_end)``, with ``r`` the
   distance to the nearest non-free cell. A bump in a wall makes a skeleton branch about as
   long as the corridor's half width plus the bump's depth but protruding only by the depth, so
   it goes whatever the corridor's width, while a real side corridor protrudes by its length (a
   room's 90° corner protrudes by ~0.3 of its branch: corners of rooms over ~4 m across stay as
   dead ends). Pruning goes in rounds, all short spurs of a round at once so that the result
   does not depend on their order; a junction left with two paths joins them, one left with
   one path becomes a dead end.
5. **Merging** — nodes joined by a path shorter than ``merge_radius`` are merged, shortest path
   first, into their mean position (skeleton junctions come in pixel clusters).
6. **Corners** — the turn of a path at a pixel is the angle between the chords to the path
   points ``corner_arm`` before and after it; each stretch turning by more than
   ``corner_angle`` gets one corner node at its sharpest pixel, at least ``merge_radius`` from
   the path's ends. Measuring over arms rather than between neighbouring pixels sees a rounded
   90° skeleton corner as one 90° turn, and a corridor's short sideways jog as no corner.
   Closed loops are treated as closed curves; a loop with fewer than two corners gets extra
   nodes at thirds of its length (a map has no self-loops).
7. **Kinds** from degree: 1 → dead end, 2 → corner, ≥ 3 → junction (an isolated free blob
   with no path is one dead-end node). Edges keep their polyline and its length.

Steps 1–3, the free-disc radii of step 4, polyline lengths, step 6 on open paths (all but
numpy's ``arctan2``) and the output's polylines in metres run as compiled kernels
(:mod:`topo._extract_kernels`), each tested to give exactly the library's or numpy's result,
on random masks and on every extraction of an env episode. Steps 4–7 run as compiled passes
(there too, around numpy's ``arctan2``) that give bit for bit the map of the Python passes of
``_Graph`` (``_graph_topomap_reference``, tested the same way). Both visit nodes and paths in
an explicit order — by ascending id, a node's paths included — so the map depends on no hash
set's layout.

Nodes are numbered in a deterministic order (by ``y``, then ``x``). Coordinates are metres in the
mask's frame: cell ``(iy, ix)`` has its centre at ``origin + (ix + 0.5, iy + 0.5) · resolution``
(row 0 at the bottom, CONTRIBUTING.md).

Counts seen on the real maps in ``shared/maps`` with the default config, as (junctions, dead
ends, corners) (``benchmarks/topo_gallery.py`` draws them): ROS ``turtlebot3_world`` and
``tb3_sandbox`` (0.05 m) 12 nodes, (12, 0, 0) — the lattice of paths around their nine pillars
(the outer ring turns by 45–60° at a time, under ``corner_angle``); ``depot`` (0.05 m, half-mapped
boxes with free speckle inside) 75 nodes, (49, 17, 9). DungeonMaps at 0.1 m/pixel: ``1`` 17
(7, 6, 4), ``10`` 12 (5, 3, 4), ``100`` 13 (4, 4, 5), ``101`` 10 (5, 5, 0), ``102`` 15 (8, 3, 4),
``103`` 17 (8, 4, 5), ``104`` 14 (7, 5, 2), ``105`` 10 (5, 3, 2).

Rotating a map by 90° (``np.rot90``) gives the same counts on all of those but ``depot`` (counts
within 7 %, 81–85 % of its nodes matched); junctions land within one cell (diagonal included)
of their rotated twins, corners within 2.9 cells and dead ends within 3.2 cells: ``skeletonize``
is not symmetric under rotation, and thinning stops a pixel or two early or late at a dead end.
A 90° bend of a corridor wider than ~1.5 m whose skeleton cuts the corner on a long diagonal may
measure under ``corner_angle`` and get no corner node.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from skimage.morphology import disk

from topo._checks import check_real
from topo._extract_kernels import (
    N_EDGES,
    N_NODES,
    N_PTS,
    OVER,
    clean_free,
    corner_arms,
    corner_cuts,
    free_crop,
    graph_first,
    graph_second,
    path_lengths,
    path_nodes,
    peaks,
    polyline_length,
    skeleton_paths,
    skeletonize,
    topomap_arrays,
    wall_distances,
)
from topo.graph import TopoMap


@dataclass(frozen=True, slots=True)
class ExtractConfig:
    """Settings of :func:`extract_topomap` (metres, m², and degrees for the angle; validated).

    Attributes:
        erode_radius: shrink free space by this much first (e.g. the robot radius); 0 = off.
        min_hole_area: fill holes in free space smaller than this (m²).
        min_spur_length: prune dead-end paths that protrude less than this beyond the free disc
            at their junction (module docstring, step 4).
        merge_radius: merge nodes joined by a path shorter than this.
        corner_angle: a path turning by more than this (degrees) gets a corner node.
        corner_arm: the turn of a path is measured between chords this long (metres).
        min_component_area: ignore free components smaller than this (m²).
    """

    erode_radius: float = 0.0
    min_hole_area: float = 0.04
    min_spur_length: float = 0.6
    merge_radius: float = 0.5
    corner_angle: float = 70.0
    corner_arm: float = 1.0
    min_component_area: float = 0.5

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            name = f"ExtractConfig.{f.name}"
            if f.name == "corner_angle":
                check_real(value, name, low=0.0, high=180.0)
            elif f.name == "corner_arm":
                check_real(value, name, low=0.0)
            else:
                check_real(value, name, low=0.0, low_inclusive=True)

    @classmethod
    def for_sonar(cls) -> ExtractConfig:
        """Settings for robots' sonar grids (0.1 m cells): sonar maps have ragged, speckled
        free space that leaks through gaps in thinly mapped walls, so free space is eroded by
        the robot's radius and short spurs and close nodes are removed more eagerly."""
        return cls(erode_radius=0.3, min_hole_area=0.5, min_spur_length=1.5, merge_radius=0.8)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ExtractConfig:
        """A config from a plain dict; unknown keys are an error naming the allowed ones."""
        allowed = [f.name for f in dataclasses.fields(cls)]
        unknown = sorted(set(data) - set(allowed))
        if unknown:
            raise ValueError(f"ExtractConfig has unknown keys {unknown}; allowed: {allowed}")
        return cls(**data)


def _as_mask(grid_or_free_mask: Any, resolution: float | None,
             origin: Any) -> tuple[np.ndarray, float, tuple[float, float]]:
    from topo.grid import OccupancyGrid

    if isinstance(grid_or_free_mask, OccupancyGrid):
        g = grid_or_free_mask
        if resolution is not None and resolution != g.resolution:
            raise ValueError(f"resolution {resolution} differs from the grid's {g.resolution}")
        return g.free_mask(), g.resolution, g.origin
    mask = grid_or_free_mask
    if not isinstance(mask, np.ndarray):
        raise TypeError("grid_or_free_mask must be an OccupancyGrid or a 2-D boolean array, got "
                        f"{type(mask).__name__}")
    if mask.ndim != 2 or min(mask.shape) < 1:
        raise ValueError(f"grid_or_free_mask must be a 2-D array, got shape {mask.shape}")
    if mask.dtype != bool:
        raise TypeError(f"grid_or_free_mask must have dtype bool, got {mask.dtype}")
    if resolution is None:
        raise ValueError("resolution is required with a mask (metres per cell), got None")
    res = check_real(resolution, "resolution", low=0.0)
    if origin is None or isinstance(origin, (str, bytes)):
        raise ValueError(f"origin must be (x, y), got {origin!r}")
    try:
        ox, oy = (float(v) for v in origin)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"origin must be (x, y), got {origin!r}") from exc
    if not (math.isfinite(ox) and math.isfinite(oy)):
        raise ValueError(f"origin must be finite, got {(ox, oy)}")
    return mask, res, (ox, oy)


def _polyline_length(poly: np.ndarray) -> float:
    """Length of a float64 ``(K, 2)`` polyline (the compiled form of
    ``np.sqrt((d * d).sum(axis=1)).sum()`` over its steps ``d``, the same float)."""
    return float(polyline_length(poly))


def _turns(points: np.ndarray, arc: np.ndarray, lo: np.ndarray, hi: np.ndarray,
           arm: float) -> np.ndarray:
    """Absolute turn (radians) at each point between the chords to the points ``arm`` before
    and after it along the path (clipped to the path); ``arc`` is the increasing arc length,
    ``lo``/``hi`` the first and last index of each point's own path."""
    back = np.maximum(np.searchsorted(arc, arc - arm, side="right") - 1, lo)
    ahead = np.minimum(np.searchsorted(arc, arc + arm, side="left"), hi)
    a = points - points[back]
    b = points[ahead] - points
    return np.abs(np.arctan2(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0], (a * b).sum(axis=1)))


def _open_corners(polys: list[np.ndarray], arm: float, min_turn: float,
                  margin: float) -> list[list[int]]:
    """Corner pixel indices of each open polyline, all polylines at once: the compiled form of
    :func:`_open_corners_numpy` (the same indices; numpy's ``arctan2`` in between, so the
    same turns), which ``tests/topo`` and ``tests/envs`` compare."""
    if not polys:
        return []
    lens = np.fromiter((len(p) for p in polys), dtype=np.int64, count=len(polys))
    arc, cross, dot = corner_arms(np.concatenate(polys), lens, arm)
    cuts, counts = corner_cuts(np.abs(np.arctan2(cross, dot)), arc, lens, min_turn, margin)
    cuts = cuts.tolist()
    out, start = [], 0
    for c in counts.tolist():
        out.append(cuts[start: start + c])
        start += c
    return out


def _open_corners_numpy(polys: list[np.ndarray], arm: float, min_turn: float,
                        margin: float) -> list[list[int]]:
    """Corner pixel indices of each open polyline, all polylines in one vectorised pass (the
    reference of :func:`_open_corners`)."""
    if not polys:
        return []
    lens = np.fromiter((len(p) for p in polys), dtype=np.int64, count=len(polys))
    points = np.concatenate(polys)
    first = np.concatenate([[0], np.cumsum(lens)[:-1]])
    last = first + lens - 1
    group = np.repeat(np.arange(len(polys)), lens)
    step = np.zeros(len(points))
    d = np.diff(points, axis=0)
    step[1:] = np.sqrt((d * d).sum(axis=1))
    step[first] = 2.0 * arm + 1.0  # a gap between paths: no stretch reaches the next path
    step[0] = 0.0
    arc = np.cumsum(step)
    turn = _turns(points, arc, first[group], last[group], arm)
    candidate = ((turn > min_turn) & (arc - arc[first][group] >= margin)
                 & (arc[last][group] - arc >= margin))
    at = peaks(turn, candidate, group)  # ascending, so grouped by polyline
    cuts = (at - first[group[at]]).tolist()
    bounds = np.searchsorted(group[at], np.arange(len(polys) + 1)).tolist()
    return [cuts[a:b] for a, b in zip(bounds[:-1], bounds[1:], strict=True)]


def _loop_corner_sets(poly: np.ndarray, arm: float, min_turn: float,
                      margins: tuple[float, ...]) -> list[np.ndarray]:
    """:func:`_loop_corners` for each of ``margins`` (the turns computed once): the arc lengths
    and chord products by the compiled :func:`topo._extract_kernels.corner_arms` and numpy's
    ``arctan2``, the same floats as :func:`_loop_corners_numpy` (``tests/topo`` compares)."""
    ring = poly[:-1]
    n = len(ring)
    if n < 4:
        return [np.empty(0, dtype=np.int64) for _ in margins]
    points = np.concatenate([ring, ring, ring, ring[:1]])
    arc, cross, dot = corner_arms(points, np.array([len(points)], dtype=np.int64), arm)
    total = arc[n]
    if total <= 2.0 * arm:
        return [np.empty(0, dtype=np.int64) for _ in margins]
    turn = np.abs(np.arctan2(cross, dot))
    local = arc - arc[n]
    candidate = np.zeros(len(points), dtype=bool)
    candidate[n // 2: 2 * n + n // 2] = turn[n // 2: 2 * n + n // 2] > min_turn
    at = peaks(turn, candidate, np.zeros(len(points), dtype=np.int64))
    at = at[(at >= n) & (at < 2 * n)]
    return [np.sort(at[(local[at] >= m) & (total - local[at] >= m)] - n) for m in margins]


def _loop_corners(poly: np.ndarray, arm: float, min_turn: float, margin: float) -> np.ndarray:
    """Corner indices of a closed polyline (``poly[0] == poly[-1]``) into ``poly[:-1]``,
    ignoring the stretch within ``margin`` of the anchor ``poly[0]`` (0 = no anchor)."""
    return _loop_corner_sets(poly, arm, min_turn, (margin,))[0]


def _loop_corners_numpy(poly: np.ndarray, arm: float, min_turn: float,
                        margin: float) -> np.ndarray:
    """The numpy form of :func:`_loop_corners` (its reference in ``tests/topo``)."""
    ring = poly[:-1]
    n = len(ring)
    if n < 4:
        return np.empty(0, dtype=np.int64)
    points = np.concatenate([ring, ring, ring, ring[:1]])
    d = np.diff(points, axis=0)
    arc = np.concatenate([[0.0], np.cumsum(np.sqrt((d * d).sum(axis=1)))])
    total = arc[n]
    if total <= 2.0 * arm:
        return np.empty(0, dtype=np.int64)
    zeros = np.zeros(len(points), dtype=np.int64)
    turn = _turns(points, arc, zeros, zeros + len(points) - 1, arm)
    local = arc - arc[n]
    candidate = np.zeros(len(points), dtype=bool)
    candidate[n // 2: 2 * n + n // 2] = turn[n // 2: 2 * n + n // 2] > min_turn
    at = peaks(turn, candidate, zeros)
    at = at[(at >= n) & (at < 2 * n)]
    away = (local[at] >= margin) & (total - local[at] >= margin)
    return np.sort(at[away] - n)


@dataclass(slots=True)
class _Edge:
    u: int
    v: int
    poly: np.ndarray
    """Pixel polyline ``(K, 2)`` (float ``row, col``) from ``u`` to ``v``."""
    length: float

    def other(self, n: int) -> int:
        return self.v if self.u == n else self.u

    def from_node(self, n: int) -> np.ndarray:
        return self.poly if self.u == n else self.poly[::-1]


class _Graph:
    """Nodes (pixel positions) and edges (pixel polylines) during clean-up, with incidence kept
    up to date so that every clean-up pass is linear in the graph's size: the reference of the
    compiled passes (``graph_first``/``graph_second`` in :mod:`topo._extract_kernels`), which
    visit everything in the same order.

    That order is explicit, so that the map does not depend on how Python lays out a ``set``:
    nodes and paths are visited by ascending id (ids are handed out in increasing order and
    ``pos``/``edges`` keep insertion order), and a node's paths (the set ``inc[n]``) always in
    ascending path id (:meth:`paths_of`); ``merge_short`` takes paths by length, equal lengths by
    id. Which of a degree-two node's two paths comes first sets the direction of the joined
    polyline, and so later floats and choices."""

    def __init__(self, free: np.ndarray) -> None:
        self.free = free
        self.pos: dict[int, np.ndarray] = {}
        self.edges: dict[int, _Edge] = {}
        self.inc: dict[int, set[int]] = {}
        self.mass: dict[int, int] = {}  # how many skeleton nodes a node stands for
        self.radius: dict[int, float] = {}  # free-disc radius (pixels) at skeleton nodes
        self.corners: set[int] = set()  # nodes placed where a path turns: never dissolved
        self._next_edge = 0
        self._next_node = 0

    def start(self, node_rc: np.ndarray, ends: list[list[int]], polys: list[np.ndarray],
              lengths: list[float]) -> None:
        """Fill an empty graph at once: nodes ``0..N-1`` at the rows of ``node_rc``, edge ``k``
        from ``ends[k][0]`` to ``ends[k][1]`` along ``polys[k]`` of length ``lengths[k]`` (what
        as many :meth:`add_node` and :meth:`add_edge` calls do)."""
        n = len(node_rc)
        self.pos = dict(enumerate(node_rc))
        self.inc = {k: set() for k in range(n)}
        self.mass = dict.fromkeys(range(n), 1)
        self._next_node = n
        for e, ((u, v), poly, length) in enumerate(zip(ends, polys, lengths, strict=True)):
            self.edges[e] = _Edge(u, v, poly, length)
            self.inc[u].add(e)
            self.inc[v].add(e)
        self._next_edge = len(polys)

    def add_node(self, rc: np.ndarray) -> int:
        nid = self._next_node
        self._next_node += 1
        self.pos[nid] = np.asarray(rc, dtype=np.float64)
        self.inc[nid] = set()
        self.mass[nid] = 1
        return nid

    def add_edge(self, u: int, v: int, poly: np.ndarray) -> int:
        e = self._next_edge
        self._next_edge += 1
        self.edges[e] = _Edge(u, v, poly, _polyline_length(poly))
        self.inc[u].add(e)
        self.inc[v].add(e)
        return e

    def remove_edge(self, e: int) -> _Edge:
        edge = self.edges.pop(e)
        self.inc[edge.u].discard(e)
        self.inc[edge.v].discard(e)
        return edge

    def _forget(self, n: int) -> None:
        del self.pos[n], self.inc[n], self.mass[n]
        self.corners.discard(n)
        self.radius.pop(n, None)

    def remove_node(self, n: int) -> None:
        for e in self.paths_of(n):
            self.remove_edge(e)
        self._forget(n)

    def paths_of(self, n: int) -> list[int]:
        """The paths at node ``n`` in ascending id (the order every pass visits them in)."""
        return sorted(self.inc[n])

    def degree(self, n: int) -> int:
        # a self-loop counts twice, as in networkx
        return sum(2 if self.edges[e].u == self.edges[e].v else 1 for e in self.inc[n])

    def prune_spurs(self, min_protrusion: float) -> None:
        """Remove dead-end paths that protrude less than ``min_protrusion`` beyond the free
        disc at their junction (module docstring), in rounds: all such paths of a round go at
        once, so the result does not depend on their order; a junction left with two paths is
        dissolved, one left with one path becomes a dead end."""
        while True:
            doomed: list[tuple[int, int]] = []
            for edge in self.edges.values():
                if edge.u == edge.v:
                    continue
                du, dv = len(self.inc[edge.u]), len(self.inc[edge.v])
                if du == 1 and dv >= 3:
                    leaf, hub = edge.u, edge.v
                elif dv == 1 and du >= 3:
                    leaf, hub = edge.v, edge.u
                else:
                    continue
                inside = max(self.radius.get(hub, 0.0) - self.radius.get(leaf, 0.0), 0.0)
                if edge.length - inside < min_protrusion:
                    doomed.append((leaf, hub))
            if not doomed:
                return
            for leaf, _ in doomed:
                self.remove_node(leaf)
            for _, hub in doomed:
                self.dissolve(hub)

    def dissolve(self, n: int) -> None:
        """Join the two paths of ``n`` into one if ``n`` has degree 2 and is not a corner: the
        lower-numbered path, then the other (the new path runs from the first one's far end)."""
        if n not in self.pos or n in self.corners or len(self.inc[n]) != 2:
            return
        ea, eb = self.paths_of(n)
        a, b = self.edges[ea], self.edges[eb]
        if a.u == a.v or b.u == b.v:
            return
        ua, vb = a.other(n), b.other(n)
        pa, pb = a.from_node(n)[::-1], b.from_node(n)
        self.remove_edge(ea)
        self.remove_edge(eb)
        self._forget(n)
        self.add_edge(ua, vb, np.concatenate((pa, pb[1:])))

    def dissolve_degree_two(self) -> None:
        for n in list(self.pos):
            self.dissolve(n)

    def _is_free(self, rc: np.ndarray) -> bool:
        # the cell holding the point
        return bool(self.free[math.floor(rc[0] + 0.5), math.floor(rc[1] + 0.5)])

    def _free_at(self, points: np.ndarray) -> np.ndarray:
        """:meth:`_is_free` of each row of ``points``."""
        cells = np.floor(points + 0.5).astype(np.intp)
        return self.free[cells[:, 0], cells[:, 1]]

    def snap_to_free(self) -> None:
        """Move a node that sits on a non-free cell (a filled speck, or a merged mean) to the
        nearest free pixel of its own paths, so that every node lies in free space (of equally
        near pixels, the first of the lowest-numbered path)."""
        for n, rc in self.pos.items():
            if self._is_free(rc):
                continue
            best, best_d = None, np.inf
            for e in self.paths_of(n):
                poly = self.edges[e].poly
                ok = self._free_at(poly)
                if ok.any():
                    d = np.sqrt(((poly[ok] - rc) ** 2).sum(axis=1))
                    if d.min() < best_d:
                        best, best_d = poly[ok][int(np.argmin(d))], float(d.min())
            if best is not None:
                self.pos[n] = best.copy()

    def merge_short(self, radius: float) -> None:
        """Contract paths shorter than ``radius``, shortest first, into one node at the mean of
        the skeleton nodes both ends stand for (the better connected end's place if that mean
        is not free); it takes over both ends' other paths (the dropped end's in ascending id,
        each becoming a new path). Equal lengths go by path id (a stable sort of ``edges``,
        which is in id order)."""
        for e in sorted(self.edges, key=lambda k: self.edges[k].length):
            edge = self.edges.get(e)
            if edge is None or edge.u == edge.v or edge.length >= radius:
                continue
            self.remove_edge(e)
            keep, drop = ((edge.u, edge.v) if len(self.inc[edge.u]) >= len(self.inc[edge.v])
                          else (edge.v, edge.u))
            mk, md = self.mass[keep], self.mass[drop]
            mean = (mk * self.pos[keep] + md * self.pos[drop]) / (mk + md)
            if self._is_free(mean):
                self.pos[keep] = mean
            for k in self.paths_of(drop):
                other = self.remove_edge(k)
                a = keep if other.u == drop else other.u
                b = keep if other.v == drop else other.v
                self.add_edge(a, b, other.poly)
            self.mass[keep] = mk + md
            if drop in self.corners:
                self.corners.add(keep)
            self._forget(drop)

    def split_corners(self, arm: float, min_turn: float, margin: float) -> None:
        """Put a corner node wherever a path turns (module docstring, step 6)."""
        open_ids = [e for e, edge in self.edges.items() if edge.u != edge.v]
        found = _open_corners([self.edges[e].poly for e in open_ids], arm, min_turn, margin)
        for e, cuts in zip(open_ids, found, strict=True):
            if cuts:
                self._split(e, cuts)
        for e in [k for k, edge in self.edges.items() if edge.u == edge.v]:
            edge = self.edges[e]
            anchored = self.degree(edge.u) > 2 or edge.u in self.corners
            cuts = _loop_corners(edge.poly, arm, min_turn, margin if anchored else 0.0)
            if len(cuts):
                self._split(e, [c for c in cuts.tolist() if c > 0], at_start=0 in cuts)

    def _split(self, e: int, cuts: list[int], at_start: bool = False) -> None:
        edge = self.remove_edge(e)
        poly = edge.poly
        if at_start:  # a loop's corner on its start pixel: the start node is that corner
            self.corners.add(edge.u)
        prev_node, prev_cut = edge.u, 0
        for c in cuts:
            node = self.add_node(poly[c])
            self.corners.add(node)
            self.add_edge(prev_node, node, poly[prev_cut: c + 1])
            prev_node, prev_cut = node, c
        self.add_edge(prev_node, edge.v, poly[prev_cut:])

    def break_self_loops(self) -> None:
        """Split every remaining loop path at thirds of its length (no self-loops in a map)."""
        for e in [k for k, edge in self.edges.items() if edge.u == edge.v]:
            edge = self.edges[e]
            if len(edge.poly) < 4:
                self.remove_edge(e)
                continue
            d = np.diff(edge.poly, axis=0)
            arc = np.concatenate([[0.0], np.cumsum(np.sqrt((d * d).sum(axis=1)))])
            cuts = np.searchsorted(arc, arc[-1] * np.array([1.0, 2.0]) / 3.0)
            cuts = np.clip(cuts, 1, len(edge.poly) - 2)
            self._split(e, sorted(set(cuts.tolist())))


@functools.lru_cache(maxsize=8)
def _disk(radius: int) -> np.ndarray:
    """``skimage.morphology.disk``, made once per radius (read-only)."""
    out = disk(radius)
    out.setflags(write=False)
    return out


def _skeleton_graph(skel: np.ndarray, free: np.ndarray, given: np.ndarray) -> _Graph:
    """The skan graph of ``skel``; free-disc radii from ``free`` (the cleaned mask); nodes are
    kept in ``given`` (the caller's free cells)."""
    g = _Graph(given)
    if not skel.any():
        return g
    coords, bounds, pixels = skeleton_paths(skel)
    node_pixels, ends = path_nodes(len(coords), bounds, pixels)
    node_rc = coords[node_pixels]
    points = coords[pixels]
    g.start(node_rc, ends.tolist(),
            [points[a:b] for a, b in zip(bounds[:-1].tolist(), bounds[1:].tolist(), strict=True)],
            path_lengths(points, bounds).tolist())
    g.radius = dict(enumerate(wall_distances(free, node_rc).tolist()))
    return g


def extract_topomap(grid_or_free_mask: Any, resolution: float | None = None,
                    origin: Any = (0.0, 0.0), config: ExtractConfig | None = None) -> TopoMap:
    """Extract the topological map of a free-space mask or an occupancy grid's free cells.

    Args:
        grid_or_free_mask: a :class:`topo.OccupancyGrid` (its free cells, resolution and
            origin) or a 2-D boolean array of free cells (``[iy, ix]``, row 0 at the bottom).
        resolution: metres per cell (required with a mask).
        origin: world position of cell (0, 0)'s lower-left corner (with a mask).
        config: :class:`ExtractConfig` or a dict of its fields (defaults if ``None``).

    Returns:
        A :class:`~topo.graph.TopoMap` in metres with polylines. A mask or grid without free
        cells (a robot that has seen nothing yet) gives :meth:`TopoMap.empty`, as does free
        space that the config removes entirely (all components below ``min_component_area``).

    Raises:
        TypeError / ValueError: a non-boolean or non-2-D mask, a missing or non-positive
            resolution, a bad origin or config; each message names the argument.
    """
    mask, res, (ox, oy) = _as_mask(grid_or_free_mask, resolution, origin)
    if config is None:
        config = ExtractConfig()
    elif isinstance(config, dict):
        config = ExtractConfig.from_dict(config)
    elif not isinstance(config, ExtractConfig):
        raise TypeError(f"config must be an ExtractConfig or dict, got {type(config).__name__}")

    given, r0, c0 = free_crop(mask)  # with a border of non-free cells
    if given.size == 0:
        return TopoMap.empty()
    cell_area = res * res
    footprint = (_disk(int(round(config.erode_radius / res))) if config.erode_radius > 0
                 else None)
    free = clean_free(given, int(config.min_hole_area / cell_area), footprint,
                      config.min_component_area / cell_area)

    return _graph_topomap(skeletonize(free), free, given, config, res,
                          (ox + (c0 - 1) * res, oy + (r0 - 1) * res))


def _graph_topomap_reference(skel: np.ndarray, free: np.ndarray, given: np.ndarray,
                             config: ExtractConfig, res: float,
                             origin: tuple[float, float]) -> TopoMap:
    """Steps 3–7 and the output by :class:`_Graph`'s Python passes (the reference of the
    compiled :func:`_graph_topomap`): the map of skeleton ``skel`` of the cleaned mask ``free``
    (``given``: the caller's free cells), ``origin`` the metre position of pixel (0, 0)'s
    corner."""
    g = _skeleton_graph(skel, free, given)
    to_px = 1.0 / res
    merge_px = config.merge_radius * to_px
    g.prune_spurs(config.min_spur_length * to_px)
    g.dissolve_degree_two()
    g.merge_short(merge_px)
    g.split_corners(config.corner_arm * to_px, math.radians(config.corner_angle), merge_px)
    g.dissolve_degree_two()  # a pure loop's arbitrary start pixel goes; corners stay
    g.merge_short(merge_px)
    g.break_self_loops()
    g.snap_to_free()
    return _to_topomap(g, res, origin)


_SHRINK = 1  # the clean-up kernels' first capacities are divided by this (tests: re-runs)
_NO_INTS = np.empty(0, dtype=np.int64)  # no loops' cuts (not read-only: one kernel signature)


def _graph_topomap(skel: np.ndarray, free: np.ndarray, given: np.ndarray, config: ExtractConfig,
                   res: float, origin: tuple[float, float]) -> TopoMap:
    """:func:`_graph_topomap_reference` by the compiled passes of :mod:`topo._extract_kernels`
    (the same map, bit for bit), with numpy's ``arctan2`` between them on the same arrays as
    :meth:`_Graph.split_corners` (the open paths' turns at once, each loop's by
    :func:`_loop_corners`); arrays that are too small are made larger and the pass re-run."""
    if not skel.any():
        return TopoMap.empty()
    coords, bounds, pixels = skeleton_paths(skel)
    node_pixels, ends = path_nodes(len(coords), bounds, pixels)
    node_rc = coords[node_pixels]
    points = coords[pixels]
    radius = wall_distances(free, node_rc)
    to_px = 1.0 / res
    merge_px = config.merge_radius * to_px
    arm, min_turn = config.corner_arm * to_px, math.radians(config.corner_angle)
    n, m, p = len(node_rc), len(ends), len(points)
    # nodes, paths, points, and paths per node (a junction cluster merged into one node)
    caps = np.array([n, 2 * m + 16, 3 * p + 256, 16], dtype=np.int64) // _SHRINK
    while True:
        first = graph_first(node_rc, ends, points, bounds, path_lengths(points, bounds), radius,
                            given, config.min_spur_length * to_px, merge_px, arm, caps)
        if not first[0][-1][OVER]:
            break
        caps = 2 * caps + 16
    state, open_ids, open_lens, arc, cross, dot, loop_ids, loop_lens, loop_pts = first
    cuts = counts = (_NO_INTS, _NO_INTS)
    if len(loop_ids):
        loop_cuts: tuple[list[np.ndarray], list[np.ndarray]] = ([], [])
        start = 0
        for size in loop_lens.tolist():
            poly = loop_pts[start: start + size]
            start += size
            anchored, free = _loop_corner_sets(poly, arm, min_turn, (merge_px, 0.0))
            loop_cuts[0].append(anchored)
            loop_cuts[1].append(free)
        cuts = tuple(np.concatenate(c).astype(np.int64) for c in loop_cuts)
        counts = tuple(np.array([len(k) for k in c], dtype=np.int64) for c in loop_cuts)
    used = state[-1]
    caps = np.array([used[N_NODES] + len(arc) + 2 * m + 16, 2 * used[N_EDGES] + len(arc) + 16,
                     used[N_PTS] + 64, state[5].shape[1]], dtype=np.int64) // _SHRINK
    while True:
        cnt, arrays = graph_second(state, open_ids, open_lens, arc, np.abs(np.arctan2(cross, dot)),
                                   loop_ids, cuts[0], counts[0], cuts[1], counts[1], given,
                                   min_turn, merge_px, res, *origin, caps)
        if not cnt[OVER]:
            break
        caps = 2 * caps + 16
    if len(arrays[0]) == 0:
        return TopoMap.empty()
    return _topomap(*arrays)


def _node_order(g: _Graph, res: float, origin: tuple[float, float]):
    """Node positions in metres in output order (by ``y``, then ``x``) and each graph node's
    output index."""
    ids = list(g.pos)
    rc = np.array([g.pos[n] for n in ids])
    xy = np.stack([origin[0] + (rc[:, 1] + 0.5) * res, origin[1] + (rc[:, 0] + 0.5) * res], 1)
    order = np.lexsort((xy[:, 0], xy[:, 1]))
    index = {ids[k]: i for i, k in enumerate(order.tolist())}
    return xy[order], index


def _to_topomap(g: _Graph, res: float, origin: tuple[float, float]) -> TopoMap:
    """The :class:`TopoMap` in metres: nodes ordered by :func:`_node_order`, edges by their
    ends' indices, each polyline from its lower- to its higher-numbered node with its ends on
    the nodes; ordered, converted, re-pointed, turned and measured by one compiled kernel
    (:func:`topo._extract_kernels.topomap_arrays`): the same floats as :func:`_to_topomap_loop`,
    one edge at a time, which ``tests/topo`` and ``tests/envs`` compare (on the env's ~10-edge
    maps that loop's small numpy calls were most of this step's cost)."""
    if not g.pos:
        return TopoMap.empty()
    edges = list(g.edges.values())
    ends = np.array([(edge.u, edge.v) for edge in edges], dtype=np.int64).reshape(-1, 2)
    cells = (np.concatenate([edge.poly for edge in edges]) if edges
             else np.empty((0, 2), dtype=np.float64))
    return _topomap(*topomap_arrays(
        np.concatenate(list(g.pos.values())).reshape(-1, 2),
        np.fromiter(g.pos, dtype=np.int64, count=len(g.pos)), ends, cells,
        np.fromiter((len(edge.poly) for edge in edges), dtype=np.int64, count=len(edges)),
        res, *origin))


def _topomap(xy: np.ndarray, pairs: np.ndarray, metres: np.ndarray, lengths: np.ndarray,
             near: np.ndarray, sizes: np.ndarray) -> TopoMap:
    """The :class:`TopoMap` of :func:`topo._extract_kernels.topomap_arrays`' arrays: the
    lengths of the paths ``near`` their chord made at least numpy's chord, the polylines cut
    apart."""
    for k in np.flatnonzero(near).tolist():
        # chord length as np.linalg.norm computes it (sqrt of the dot product: BLAS, maybe fused)
        c = xy[pairs[k, 0]] - xy[pairs[k, 1]]
        lengths[k] = max(lengths[k], math.sqrt(c.dot(c)))
    paths, start = [], 0
    for n in sizes.tolist():
        paths.append(metres[start: start + n])
        start += n
    return TopoMap.from_valid_arrays(xy, pairs, lengths, paths)


def _to_topomap_loop(g: _Graph, res: float, origin: tuple[float, float]) -> TopoMap:
    """:func:`_to_topomap` one edge at a time (its reference in ``tests/topo``)."""
    if not g.pos:
        return TopoMap.empty()
    xy, index = _node_order(g, res, origin)
    edges = sorted(g.edges.values(), key=lambda edge: (index[edge.u], index[edge.v]))
    pairs, paths, lengths = [], [], []
    if edges:
        # all polylines to metres at once (the same arithmetic per point), then cut apart
        cells = np.concatenate([edge.poly for edge in edges])
        metres = np.stack([origin[0] + (cells[:, 1] + 0.5) * res,
                           origin[1] + (cells[:, 0] + 0.5) * res], 1)
        stops = np.cumsum([len(edge.poly) for edge in edges]).tolist()
        for edge, start, stop in zip(edges, [0, *stops[:-1]], stops, strict=True):
            iu, iv = index[edge.u], index[edge.v]
            pts = metres[start:stop]
            pts[0], pts[-1] = xy[iu], xy[iv]
            if iu > iv:
                iu, iv, pts = iv, iu, pts[::-1]
            chord = xy[iu] - xy[iv]
            pairs.append((iu, iv))
            paths.append(pts)
            # chord length as np.linalg.norm computes it (sqrt of the dot product)
            lengths.append(max(_polyline_length(pts), math.sqrt(chord.dot(chord))))
    return TopoMap.from_valid_arrays(xy, np.asarray(pairs, dtype=np.int64).reshape(-1, 2),
                                     lengths, paths)
