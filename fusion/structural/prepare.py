"""What a merge reads of two maps, computed once per pair: node descriptors and which may match
(:data:`MATCH_COMPATIBLE`), node pairs for the hypotheses, path points and distance-to-path
rasters for the path evidence (:class:`Prepared`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fusion.structural import _kernels as K
from fusion.structural.config import MergeConfig
from topo.graph import NodeKind, TopoMap

KIND_COMPATIBLE = np.zeros((len(NodeKind), len(NodeKind)), dtype=np.bool_)
"""``[kind_a, kind_b]``: may a node of A of ``kind_a`` be the same place as one of B of ``kind_b``?
Same kinds; junction ↔ corner (a side branch one robot did not see); dead end ↔ corner (a corner
at the edge of one robot's explored space, its second corridor unseen). Not dead end ↔ junction
(a frontier dead end sits part-way along a corridor; allowing it adds chance matches)."""


for _a, _b in [(NodeKind.JUNCTION, NodeKind.JUNCTION), (NodeKind.CORNER, NodeKind.CORNER),
               (NodeKind.DEAD_END, NodeKind.DEAD_END), (NodeKind.JUNCTION, NodeKind.CORNER),
               (NodeKind.CORNER, NodeKind.JUNCTION), (NodeKind.DEAD_END, NodeKind.CORNER),
               (NodeKind.CORNER, NodeKind.DEAD_END), (NodeKind.GATEWAY, NodeKind.GATEWAY)]:
    KIND_COMPATIBLE[_a, _b] = True


KIND_COMPATIBLE.setflags(write=False)


CLEARANCE_STEP = 0.2
"""Width in metres of the clearance classes (:attr:`topo.TopoMap.clearance`) of matched nodes."""


CLEARANCE_CLASSES = 16
"""Clearance classes (the last one holds every clearance beyond)."""


CLEARANCE_TOLERANCE = 2
"""Two nodes may be the same place only if their clearance classes differ by at most this."""


_N_KINDS = len(NodeKind)


_PLACE_KINDS = (NodeKind.JUNCTION, NodeKind.CORNER, NodeKind.DEAD_END)


def _match_table() -> np.ndarray:
    """``[code_a, code_b]`` over descriptor codes ``kind + len(NodeKind) · clearance class``:
    may a node of A and one of B be the same place? Kinds as :data:`KIND_COMPATIBLE`, except
    that any two places with a clearance (class ≥ 1: made by ``topo.extract_topomap``) may
    match whatever their number of paths, which depends on how many exits each robot saw; and
    clearances within :data:`CLEARANCE_TOLERANCE` classes. Maps without clearances (all
    class 0) match by kind alone."""
    n = _N_KINDS * CLEARANCE_CLASSES
    code = np.arange(n)
    kind, cls = code % _N_KINDS, code // _N_KINDS
    place = np.isin(kind, [int(k) for k in _PLACE_KINDS]) & (cls > 0)
    kinds_ok = KIND_COMPATIBLE[kind[:, None], kind[None, :]] | (place[:, None] & place[None, :])
    table = kinds_ok & (np.abs(cls[:, None] - cls[None, :]) <= CLEARANCE_TOLERANCE)
    table.setflags(write=False)
    return table


MATCH_COMPATIBLE = _match_table()
"""The node compatibility the merge uses, over descriptor codes (:func:`_match_table`)."""


def descriptor_codes(m: TopoMap) -> np.ndarray:
    """``(N,)`` int64 descriptor code of each node: ``kind + len(NodeKind) · class`` with
    ``class = min(clearance // CLEARANCE_STEP, CLEARANCE_CLASSES − 1)``."""
    cls = np.minimum((m.clearance / CLEARANCE_STEP).astype(np.int64), CLEARANCE_CLASSES - 1)
    return m.kinds.astype(np.int64) + _N_KINDS * cls


def matchable(m: TopoMap) -> tuple[TopoMap, np.ndarray]:
    """The part of ``m`` a merge matches, and the index in ``m`` of each of its nodes: the
    nodes not flagged :attr:`topo.TopoMap.frontier` and the paths between them (a node on the
    frontier moves as its robot explores on)."""
    keep = ~m.frontier
    if keep.all():
        return m, np.arange(m.n_nodes)
    index = np.flatnonzero(keep)
    renumber = np.full(m.n_nodes, -1, dtype=np.int64)
    renumber[index] = np.arange(len(index))
    kept = keep[m.edges].all(axis=1) if m.n_edges else np.zeros(0, dtype=bool)
    paths = None if m.paths is None else [q for q, k in zip(m.paths, kept, strict=True) if k]
    view = TopoMap.from_arrays(m.xy[index], renumber[m.edges[kept]], m.kinds[index],
                               m.lengths[kept], paths, m.clearance[index], m.frontier[index])
    return view, index


PATH_STEP = 1.2
"""Spacing (m) of the points along each map's paths that the path evidence moves."""


PATH_CELL = 0.4
"""Cell (m) of the distance-to-path raster of each map."""


PATH_REACH = 2.0
"""The raster's cap (m): a path point farther than this from every path of the other map
tells nothing (outside what the other robot explored)."""


PATH_TOL = 0.5
"""A path point within this of the other map's paths lies on one (soft: ``1 − d²/tol²``)."""


PATH_OFF = 0.9
"""A path point between this and :data:`PATH_REACH` from the other map's paths runs beside
one: two corridors that close would be the same corridor."""


PATH_CHORD = 0.4
"""Polylines (pixel-fine paths of extracted maps) are read as chords about this long (m): a
sample per :data:`PATH_STEP` at most, as for straight paths, and less raster work; a chord
strays from its pixels by a few centimetres, well inside :data:`PATH_TOL`."""


PATH_FIT_WEIGHT = 10.0
"""Weight of a metre of B's paths lying on A's against a matched node in the final fit, for
maps whose paths are straight node-to-node segments; maps with polylines (extracted ones) fit
on their nodes alone (:attr:`Prepared.polylines`)."""


@dataclass(frozen=True, slots=True, eq=False)
class Prepared:
    xy: np.ndarray
    kinds: np.ndarray
    edges: np.ndarray
    near: np.ndarray  # (n, n) bool: joined by a path or by two
    pair_i: np.ndarray
    pair_j: np.ndarray
    pair_len: np.ndarray
    both_i: np.ndarray  # the pairs in both orientations, by length (stable): B's hypotheses
    both_j: np.ndarray
    both_len: np.ndarray
    margin: np.ndarray  # (E,) fraction of each path within eps of its ends
    branches: np.ndarray  # (n, max degree) direction of each path leaving a node, nan padded
    segments: np.ndarray  # (S, 4) straight pieces of the paths (path_segments)
    path_pts: np.ndarray  # (S, 2) points along the paths, every ~PATH_STEP
    path_w: np.ndarray  # (S,) metres of path each stands for
    field: np.ndarray  # squared distance to the nearest path (K.path_field), PATH_CELL cells
    field_origin: tuple[float, float]
    compat: np.ndarray  # [code, code] of the pair's codes (MATCH_COMPATIBLE, renumbered)
    loose: int  # the code of an undescribed dead end (makes no conflicts), -1 if unused
    polylines: bool  # paths are polylines (routes through free space), not node-to-node


def prepare_pair(map_a: TopoMap, map_b: TopoMap, cfg: MergeConfig
                 ) -> tuple[Prepared, Prepared]:
    """What the search and the evidence read of two maps. Their ``kinds`` are their
    :func:`descriptor_codes` renumbered over the codes the two maps use, ``compat`` the rows
    and columns of :data:`MATCH_COMPATIBLE` for those codes (a small table: the search's
    raster holds one entry per code)."""
    code_a, code_b = descriptor_codes(map_a), descriptor_codes(map_b)
    used = np.unique(np.concatenate([code_a, code_b]))
    compat = np.ascontiguousarray(MATCH_COMPATIBLE[np.ix_(used, used)])
    loose = np.flatnonzero(used == _LOOSE_KIND)
    loose = int(loose[0]) if len(loose) else -1
    return (_prepare(map_a, cfg, np.searchsorted(used, code_a), compat, loose),
            _prepare(map_b, cfg, np.searchsorted(used, code_b), compat, loose))


def _prepare(m: TopoMap, cfg: MergeConfig, codes: np.ndarray, compat: np.ndarray,
             loose: int) -> Prepared:
    xy = np.ascontiguousarray(m.xy, dtype=np.float64)
    edges = np.ascontiguousarray(m.edges, dtype=np.int64)
    pieces = path_segments(m)
    near, i, j, length = _node_pairs(xy, edges, cfg.knn, max(cfg.min_pair_distance, 1e-9))
    both_len = np.concatenate((length, length))  # both orientations by length: B's hypotheses
    order = np.argsort(both_len, kind="stable")
    both_i, both_j = np.concatenate((i, j))[order], np.concatenate((j, i))[order]
    gap = xy[edges[:, 0]] - xy[edges[:, 1]]
    margin = np.minimum(0.5, cfg.eps / np.maximum(np.sqrt(gap[:, 0] * gap[:, 0]
                                                          + gap[:, 1] * gap[:, 1]), 1e-12))
    every = np.vstack((xy, pieces.reshape(-1, 2)))  # the raster: nodes and paths, padded
    x0, y0 = (float(v) - PATH_REACH - PATH_CELL for v in every.min(axis=0))
    x1, y1 = (float(v) + PATH_REACH + PATH_CELL for v in every.max(axis=0))
    field = K.path_field(pieces, x0, y0, PATH_CELL, math.ceil((y1 - y0) / PATH_CELL) + 1,
                         math.ceil((x1 - x0) / PATH_CELL) + 1, PATH_REACH)
    pts, w = _path_samples(pieces, PATH_STEP)
    return Prepared(xy, codes.astype(np.int64), edges, near, i, j, length, both_i, both_j,
                    both_len[order], margin, _branches(xy, edges),
                    pieces, pts, w, field, (x0, y0), compat, loose,
                    m.paths is not None and len(m.paths) > 0)


def _node_pairs(xy: np.ndarray, edges: np.ndarray, knn: int, min_dist: float
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The node pairs 2-point consensus uses: ``(near, i, j, length)``, ``near[a, b]`` when
    ``a`` and ``b`` are joined by a path or by two; pairs ``i < j`` that are near or among each
    other's ``knn`` nearest nodes (ties to the lower index), at least ``min_dist`` apart, and
    their distances."""
    n = len(xy)
    adj = np.zeros((n, n))  # float: the product is BLAS's, and exact (counts of at most n)
    adj[edges[:, 0], edges[:, 1]] = adj[edges[:, 1], edges[:, 0]] = 1.0
    near = (adj + adj @ adj) > 0
    np.fill_diagonal(near, False)
    dist = np.hypot(xy[:, None, 0] - xy[None, :, 0], xy[:, None, 1] - xy[None, :, 1])
    cand = near.copy()
    k = min(knn, n - 1)
    if k > 0:
        others = dist.copy()
        np.fill_diagonal(others, np.inf)
        nearest = np.argsort(others, axis=1, kind="stable")[:, :k]
        cand[np.repeat(np.arange(n), k), nearest.ravel()] = True
        cand |= cand.T
    i, j = np.nonzero(np.triu(cand & (dist >= min_dist), 1))
    return near, i.astype(np.int64), j.astype(np.int64), dist[i, j]


def _path_samples(seg: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Points along the segments ``seg[k] = (x1, y1, x2, y2)``: each cut into
    ``max(1, ceil(length / step))`` equal pieces, a point at each piece's middle. Returns
    ``(points (S, 2), metres of path each stands for (S,))``."""
    length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
    count = np.maximum(1, np.ceil(length / step)).astype(np.int64)
    k = np.repeat(np.arange(len(seg)), count)
    f = (np.arange(len(k)) - np.repeat(np.cumsum(count) - count, count) + 0.5) / count[k]
    pts = np.column_stack((seg[k, 0] + f * (seg[k, 2] - seg[k, 0]),
                           seg[k, 1] + f * (seg[k, 3] - seg[k, 1])))
    return pts, length[k] / count[k]


def path_segments(m: TopoMap) -> np.ndarray:
    """``(S, 4)`` straight pieces ``(x1, y1, x2, y2)`` of the map's paths: chords of its
    polylines about :data:`PATH_CHORD` long (a chord end at the first point past each multiple
    of it of arc length along the polyline, and at its ends), or the straight node-to-node
    segments of a map without polylines."""
    if m.paths is None or not len(m.paths):
        return np.hstack([m.xy[m.edges[:, 0]], m.xy[m.edges[:, 1]]]).reshape(-1, 4).astype(
            np.float64)
    return _polyline_chords(np.concatenate(m.paths).astype(np.float64),
                            np.array([len(q) for q in m.paths]), PATH_CHORD)


def _polyline_chords(pts: np.ndarray, sizes: np.ndarray, chord: float) -> np.ndarray:
    """``(S, 4)`` chords of the polylines stacked in ``pts`` (``sizes[k]`` points each)."""
    last = np.cumsum(sizes) - 1
    first = last - sizes + 1
    step = np.zeros(len(pts))
    step[1:] = np.hypot(*(pts[1:] - pts[:-1]).T)
    step[first] = 0.0
    arc = np.cumsum(step)
    arc -= np.repeat(arc[first], sizes)
    bucket = np.floor(arc / chord)
    keep = np.ones(len(pts), dtype=bool)
    keep[1:] = bucket[1:] != bucket[:-1]
    keep[first] = keep[last] = True
    kept = np.flatnonzero(keep)
    starts = np.zeros(len(pts), dtype=bool)
    starts[first] = True
    inner = ~starts[kept[1:]]
    return np.hstack([pts[kept[:-1][inner]], pts[kept[1:][inner]]])


def _branches(xy: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """``(n, max degree)`` angle of each path leaving each node (toward its other end), in
    order of listing, NaN padded."""
    ends = np.concatenate((edges, edges[:, ::-1]))
    ends = ends[np.argsort(ends[:, 0], kind="stable")]
    degree = np.bincount(ends[:, 0], minlength=len(xy))
    slot = np.arange(len(ends)) - np.repeat(np.cumsum(degree) - degree, degree)
    out = np.full((len(xy), max(1, int(degree.max(initial=0)))), np.nan)
    if len(ends):
        d = xy[ends[:, 1]] - xy[ends[:, 0]]
        out[ends[:, 0], slot] = np.arctan2(d[:, 1], d[:, 0])
    return out


_LOOSE_KIND = int(NodeKind.DEAD_END)  # the kind that makes no conflicts (frontier artefacts)


def check_map(value: object, name: str) -> TopoMap:
    if not isinstance(value, TopoMap):
        raise TypeError(f"{name} must be a topo.TopoMap, got {type(value).__name__}")
    if not np.all(np.isfinite(value.xy)):
        row = int(np.argwhere(~np.isfinite(value.xy))[0, 0])
        raise ValueError(f"{name}.xy must be finite, got {value.xy[row].tolist()} at node {row}")
    return value
