"""``extract_topomap``: free space → skeleton → topological map (junctions, dead ends, corners).

Pipeline (all parameters in :class:`ExtractConfig`):

1. **Free space** — a boolean mask (or an :class:`~topo.grid.OccupancyGrid`'s free cells),
   cropped to its free cells' bounding box; holes smaller than ``min_hole_area`` (sonar
   speckle) are filled, and the mask is optionally eroded by ``erode_radius`` (the robot).
2. **Skeleton** — ``skimage.morphology.skeletonize``.
3. **Graph** — ``skan.csr.Skeleton`` traces the skeleton into paths between junction and end
   pixels (no hand-written tracing).
4. **Clean-up** — dead-end spurs shorter than ``min_spur_length`` are pruned (repeatedly: a
   junction left with two paths joins them); nodes joined by a path shorter than
   ``merge_radius`` are merged (skeleton junctions come in pixel clusters).
5. **Corners** — each path is simplified (Douglas–Peucker, ``corner_tolerance``) and split at
   vertices where it turns by more than ``corner_angle``; a closed loop with no such vertex
   gets three evenly spaced corner nodes (a map has no self-loops).
6. **Kinds** from degree: 1 → dead end, 2 → corner, ≥ 3 → junction (an isolated free blob
   with no path is one dead-end node). Edges keep their polyline and its length.

Nodes are numbered in a deterministic order (by ``y``, then ``x``). Coordinates are metres in the
mask's frame: cell ``(iy, ix)`` has its centre at ``origin + (ix + 0.5, iy + 0.5) · resolution``
(row 0 at the bottom, CONTRIBUTING.md).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage
from skan.csr import Skeleton
from skimage.measure import approximate_polygon
from skimage.morphology import disk, remove_small_holes, skeletonize

from topo._checks import check_real
from topo.graph import TopoMap


@dataclass(frozen=True, slots=True)
class ExtractConfig:
    """Settings of :func:`extract_topomap` (metres and degrees; validated).

    Attributes:
        erode_radius: shrink free space by this much first (e.g. the robot radius); 0 = off.
        min_hole_area: fill holes in free space smaller than this (m²).
        min_spur_length: prune dead-end paths shorter than this.
        merge_radius: merge nodes joined by a path shorter than this.
        corner_angle: a path turning by more than this (degrees) gets a corner node.
        corner_tolerance: Douglas–Peucker tolerance for finding corners.
        min_component_area: ignore free components smaller than this (m²).
    """

    erode_radius: float = 0.0
    min_hole_area: float = 0.04
    min_spur_length: float = 0.6
    merge_radius: float = 0.5
    corner_angle: float = 50.0
    corner_tolerance: float = 0.25
    min_component_area: float = 0.5

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name in ("erode_radius", "min_hole_area", "min_spur_length", "merge_radius",
                          "min_component_area"):
                check_real(value, f"ExtractConfig.{f.name}", low=0.0, low_inclusive=True)
            elif f.name == "corner_angle":
                check_real(value, "ExtractConfig.corner_angle", low=0.0, high=180.0)
            else:
                check_real(value, f"ExtractConfig.{f.name}", low=0.0)

    @classmethod
    def for_sonar(cls) -> ExtractConfig:
        """Settings for robots' sonar grids (0.1 m cells): sonar maps have ragged, speckled
        free space that leaks through gaps in thinly mapped walls, so free space is eroded by
        the robot's radius and short spurs and close nodes are removed more eagerly. On a
        frontier-explored 20 m building this gives ~35 nodes where the defaults give ~110."""
        return cls(erode_radius=0.3, min_hole_area=0.5, min_spur_length=1.5, merge_radius=0.8)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ExtractConfig:
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
    try:
        ox, oy = (float(v) for v in origin)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"origin must be (x, y), got {origin!r}") from exc
    if not (math.isfinite(ox) and math.isfinite(oy)):
        raise ValueError(f"origin must be finite, got {(ox, oy)}")
    return mask, res, (ox, oy)


def _polyline_length(poly: np.ndarray) -> float:
    d = poly[1:] - poly[:-1]
    return float(np.sqrt((d * d).sum(axis=1)).sum())


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
    up to date so that every clean-up pass is linear in the graph's size."""

    def __init__(self) -> None:
        self.pos: dict[int, np.ndarray] = {}
        self.edges: dict[int, _Edge] = {}
        self.inc: dict[int, set[int]] = {}
        self.corners: set[int] = set()  # nodes placed where a path turns: never dissolved
        self._next_edge = 0
        self._next_node = 0

    def add_node(self, rc: np.ndarray) -> int:
        nid = self._next_node
        self._next_node += 1
        self.pos[nid] = np.asarray(rc, dtype=np.float64)
        self.inc[nid] = set()
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

    def remove_node(self, n: int) -> None:
        for e in list(self.inc[n]):
            self.remove_edge(e)
        del self.pos[n], self.inc[n]
        self.corners.discard(n)

    def degree(self, n: int) -> int:
        # a self-loop counts twice, as in networkx
        return sum(2 if self.edges[e].u == self.edges[e].v else 1 for e in self.inc[n])

    def prune_spurs(self, min_len: float) -> None:
        """Remove dead-end paths shorter than ``min_len`` that hang off a junction, shortest
        first, in rounds until none is left (a junction left with two paths is dissolved)."""
        while True:
            removed = False
            for e in sorted(self.edges, key=lambda k: self.edges[k].length):
                edge = self.edges.get(e)
                if edge is None or edge.u == edge.v or edge.length >= min_len:
                    continue
                du, dv = self.degree(edge.u), self.degree(edge.v)
                if du == 1 and dv >= 3:
                    leaf, hub = edge.u, edge.v
                elif dv == 1 and du >= 3:
                    leaf, hub = edge.v, edge.u
                else:
                    continue
                self.remove_node(leaf)
                self.dissolve(hub)
                removed = True
            if not removed:
                return

    def dissolve(self, n: int) -> None:
        """Join the two paths of ``n`` into one if ``n`` has degree 2 and is not a corner."""
        if n not in self.pos or n in self.corners or len(self.inc[n]) != 2:
            return
        ea, eb = self.inc[n]
        a, b = self.edges[ea], self.edges[eb]
        if a.u == a.v or b.u == b.v:
            return
        ua, vb = a.other(n), b.other(n)
        pa, pb = a.from_node(n)[::-1], b.from_node(n)
        self.remove_edge(ea)
        self.remove_edge(eb)
        del self.pos[n], self.inc[n]
        self.add_edge(ua, vb, np.vstack([pa, pb[1:]]))

    def dissolve_degree_two(self) -> None:
        for n in list(self.pos):
            self.dissolve(n)

    def merge_short(self, radius: float) -> None:
        """Contract paths shorter than ``radius``, shortest first; the more connected end stays
        where it is (a junction keeps its place) and takes over the other's paths."""
        for e in sorted(self.edges, key=lambda k: self.edges[k].length):
            edge = self.edges.get(e)
            if edge is None or edge.u == edge.v or edge.length >= radius:
                continue
            self.remove_edge(e)
            keep, drop = ((edge.u, edge.v) if len(self.inc[edge.u]) >= len(self.inc[edge.v])
                          else (edge.v, edge.u))
            for k in list(self.inc[drop]):
                other = self.remove_edge(k)
                a = keep if other.u == drop else other.u
                b = keep if other.v == drop else other.v
                poly = other.poly
                if other.u == drop:
                    poly = np.vstack([self.pos[keep], poly])
                if other.v == drop:
                    poly = np.vstack([poly, self.pos[keep]])
                self.add_edge(a, b, poly)
            del self.pos[drop], self.inc[drop]
            self.corners.discard(drop)

    def split_corners(self, angle_deg: float, tol: float) -> None:
        for e in list(self.edges):
            edge = self.edges[e]
            poly = edge.poly
            if len(poly) < 3:
                continue
            simple = approximate_polygon(poly, tolerance=tol)
            if len(simple) < 3:
                continue
            d1 = simple[1:-1] - simple[:-2]
            d2 = simple[2:] - simple[1:-1]
            turn = np.degrees(np.abs(np.arctan2(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0],
                                                (d1 * d2).sum(1))))
            cut_pts = simple[1:-1][turn > angle_deg]
            if len(cut_pts) == 0:
                continue
            # cut at the polyline pixels nearest the simplified corner vertices, in path order
            cuts = sorted({int(np.argmin(((poly - p) ** 2).sum(1))) for p in cut_pts})
            cuts = [c for c in cuts if 0 < c < len(poly) - 1]
            if not cuts:
                continue
            self.remove_edge(e)
            prev_node, prev_cut = edge.u, 0
            for c in cuts:
                node = self.add_node(poly[c])
                self.corners.add(node)
                self.add_edge(prev_node, node, poly[prev_cut: c + 1])
                prev_node, prev_cut = node, c
            self.add_edge(prev_node, edge.v, poly[prev_cut:])

    def break_self_loops(self) -> None:
        for e in [k for k, edge in self.edges.items() if edge.u == edge.v]:
            edge = self.remove_edge(e)
            poly, u = edge.poly, edge.u
            if len(poly) < 4:
                continue
            third = [len(poly) // 3, 2 * len(poly) // 3]
            a, b = self.add_node(poly[third[0]]), self.add_node(poly[third[1]])
            self.add_edge(u, a, poly[: third[0] + 1])
            self.add_edge(a, b, poly[third[0]: third[1] + 1])
            self.add_edge(b, u, poly[third[1]:])


def _skeleton_graph(skel: np.ndarray) -> _Graph:
    g = _Graph()
    if not skel.any():
        return g
    sk = Skeleton(skel, keep_images=False)
    coords = sk.coordinates.astype(np.float64)
    pixel_node: dict[int, int] = {}

    def node_of(pixel: int) -> int:
        if pixel not in pixel_node:
            pixel_node[pixel] = g.add_node(coords[pixel])
        return pixel_node[pixel]

    for path in sk.paths_list():
        path = np.asarray(path)
        u, v = node_of(int(path[0])), node_of(int(path[-1]))
        g.add_edge(u, v, coords[path])
    # isolated single pixels (a tiny blob) are nodes without paths
    on_path = np.zeros(len(coords), dtype=bool)
    for path in sk.paths_list():
        on_path[np.asarray(path)] = True
    for pixel in np.flatnonzero(~on_path):
        node_of(int(pixel))
    return g


def extract_topomap(grid_or_free_mask: Any, resolution: float | None = None,
                    origin: Any = (0.0, 0.0), config: ExtractConfig | None = None) -> TopoMap:
    """Extract the topological map of a free-space mask or an occupancy grid's free cells.

    Args:
        grid_or_free_mask: a :class:`topo.OccupancyGrid` (its free cells, resolution and
            origin) or a 2-D boolean array of free cells (``[iy, ix]``, row 0 at the bottom).
        resolution: metres per cell (required with a mask).
        origin: world position of cell (0, 0)'s lower-left corner (with a mask).
        config: :class:`ExtractConfig` (defaults if ``None``).

    Returns:
        A :class:`~topo.graph.TopoMap` in metres with polylines; empty if there is no free space
        large enough.

    Raises:
        TypeError / ValueError: a non-boolean or non-2-D mask, a missing or non-positive
            resolution, a bad origin or config.
    """
    mask, res, (ox, oy) = _as_mask(grid_or_free_mask, resolution, origin)
    if config is None:
        config = ExtractConfig()
    elif isinstance(config, dict):
        config = ExtractConfig.from_dict(config)
    elif not isinstance(config, ExtractConfig):
        raise TypeError(f"config must be an ExtractConfig or dict, got {type(config).__name__}")

    rows = np.flatnonzero(mask.any(axis=1))
    if len(rows) == 0:
        return TopoMap.empty()
    cols = np.flatnonzero(mask.any(axis=0))
    r0, c0 = max(rows[0] - 1, 0), max(cols[0] - 1, 0)
    free = np.pad(mask[r0: rows[-1] + 2, c0: cols[-1] + 2], 1)  # a border of non-free cells
    cell_area = res * res
    if config.min_hole_area > 0:
        free = remove_small_holes(free, max_size=int(config.min_hole_area / cell_area))
    if config.erode_radius > 0:
        free = ndimage.binary_erosion(free, structure=disk(int(round(config.erode_radius / res))))
    if config.min_component_area > 0:
        labels, n = ndimage.label(free)
        if n:
            sizes = np.bincount(labels.ravel(), minlength=n + 1)
            small = sizes < config.min_component_area / cell_area
            small[0] = False
            free = free & ~small[labels]

    g = _skeleton_graph(skeletonize(free))
    to_px = 1.0 / res
    g.prune_spurs(config.min_spur_length * to_px)
    g.dissolve_degree_two()
    g.merge_short(config.merge_radius * to_px)
    corner_args = (config.corner_angle, config.corner_tolerance * to_px)
    g.split_corners(*corner_args)
    g.dissolve_degree_two()  # a loop's arbitrary start pixel goes; corners stay
    g.split_corners(*corner_args)  # a corner that sat on that start pixel is found now
    g.merge_short(config.merge_radius * to_px)
    g.break_self_loops()
    return _to_topomap(g, res, (ox + (c0 - 1) * res, oy + (r0 - 1) * res))


def _to_topomap(g: _Graph, res: float, origin: tuple[float, float]) -> TopoMap:
    if not g.pos:
        return TopoMap.empty()
    ids = list(g.pos)
    rc = np.array([g.pos[n] for n in ids])
    xy = np.stack([origin[0] + (rc[:, 1] + 0.5) * res, origin[1] + (rc[:, 0] + 0.5) * res], 1)
    order = np.lexsort((xy[:, 0], xy[:, 1]))
    index = {ids[k]: i for i, k in enumerate(order)}
    xy = xy[order]
    edges, paths, lengths = [], [], []
    for e in sorted(g.edges, key=lambda k: (index[g.edges[k].u], index[g.edges[k].v])):
        u, v, poly = g.edges[e].u, g.edges[e].v, g.edges[e].poly
        iu, iv = index[u], index[v]
        pts = np.stack([origin[0] + (poly[:, 1] + 0.5) * res,
                        origin[1] + (poly[:, 0] + 0.5) * res], 1)
        pts[0], pts[-1] = xy[iu], xy[iv]
        if iu > iv:
            iu, iv, pts = iv, iu, pts[::-1]
        edges.append((iu, iv))
        paths.append(pts)
        lengths.append(max(_polyline_length(pts), float(np.linalg.norm(xy[iu] - xy[iv]))))
    return TopoMap.from_arrays(xy, np.asarray(edges, dtype=np.int64).reshape(-1, 2),
                               lengths=lengths, paths=paths)
