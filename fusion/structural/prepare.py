"""What a merge reads of two maps, computed once per pair: node descriptors and which may match
(:data:`MATCH_COMPATIBLE`), node pairs for the hypotheses, path points and distance-to-path
rasters for the path evidence (:class:`Prepared`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusion.structural import _prepare_kernels as PK
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
    field: np.ndarray  # squared distance to the nearest path (PK.path_field), PATH_CELL cells
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
    near, i, j, length, both_i, both_j, both_len, pts, w, margin, x0, y0, field, *slots = (
        PK.map_fields(xy, edges, pieces, cfg.knn, max(cfg.min_pair_distance, 1e-9), PATH_STEP,
                      cfg.eps, PATH_REACH, PATH_CELL))
    return Prepared(xy, codes.astype(np.int64), edges, near, i, j, length, both_i, both_j,
                    both_len, margin, _branches(len(xy), *slots), pieces, pts, w, field,
                    (x0, y0), compat, loose, m.paths is not None and len(m.paths) > 0)


def path_segments(m: TopoMap) -> np.ndarray:
    """``(S, 4)`` straight pieces ``(x1, y1, x2, y2)`` of the map's paths: chords of its
    polylines about :data:`PATH_CHORD` long, or the straight node-to-node segments of a map
    without polylines."""
    if m.paths is None or not len(m.paths):
        return np.hstack([m.xy[m.edges[:, 0]], m.xy[m.edges[:, 1]]]).reshape(-1, 4).astype(
            np.float64)
    pts = np.ascontiguousarray(np.concatenate(m.paths), dtype=np.float64)
    sizes = np.fromiter((len(q) for q in m.paths), dtype=np.int64, count=len(m.paths))
    return PK.polyline_chords(pts, sizes, PATH_CHORD)


def _branches(n: int, node: np.ndarray, slot: np.ndarray, d: np.ndarray,
              degree: int) -> np.ndarray:
    """``(n, max degree)`` angle of each path leaving each node (toward its other end), from
    :func:`fusion.structural._prepare_kernels.branch_slots`."""
    out = np.full((n, max(1, degree)), np.nan)
    if len(node):  # numpy's arctan2 (numba's differs in the last bit), on the same layout
        out[node, slot] = np.arctan2(d[:, 1], d[:, 0])
    return out


_LOOSE_KIND = int(NodeKind.DEAD_END)  # the kind that makes no conflicts (frontier artefacts)


def check_map(value: object, name: str) -> TopoMap:
    if not isinstance(value, TopoMap):
        raise TypeError(f"{name} must be a topo.TopoMap, got {type(value).__name__}")
    if not np.all(np.isfinite(value.xy)):
        row = int(np.argwhere(~np.isfinite(value.xy))[0, 0])
        raise ValueError(f"{name}.xy must be finite, got {value.xy[row].tolist()} at node {row}")
    return value
