"""``merge_maps``: align two robots' topological maps from any relative pose, and know when not to.

The paper's ICP-SVD is local (it starts from ``R = I``), plain ICP is biased when maps overlap only
in part, and the paper's exhaustive search is slow and ambiguous. ``method="auto"`` is a global
merge built from the maps' structure:

1. **Node pairs** of each map: ends of a path, nodes two paths apart, and each node's ``knn``
   nearest nodes, at least ``min_pair_distance`` apart.
2. **2-point consensus**: every A pair and B pair whose lengths agree within ``pair_tolerance``
   and whose end kinds are compatible (:data:`KIND_COMPATIBLE`) gives one rigid hypothesis.
3. **Coarse score** of every hypothesis from a raster of A (each cell holds the nearest A node
   of each compatible kind within ``coarse_tolerance``, and whether it lies on an A path): one
   closed-form fit of the hypothesis to the B nodes that land on such a node, then a soft
   count ``Σ (1 − d²/eps²)`` of the B nodes landing within ``eps`` of their cell's node, −1 per
   B junction/corner landing on an A path far from any A node. Refitting before counting is
   what finds pairs sharing few nodes: the right hypothesis lands its 3–5 shared nodes tightly,
   where a hard count within the loose coarse tolerance prefers chance alignments of a
   corridor lattice landing more nodes loosely.
4. **Candidates**: the ``path_pool`` best *distinct* hypotheses (non-maximum suppression on angle
   and on where B's centroid lands), and the ``sparse_pool`` best of those landing only 3 B nodes
   tightly (pairs sharing 3 nodes, kept apart so that the many chance 3-node landings do not
   crowd the coarse ranking), are re-ranked with their **path evidence** (how many metres of
   each map's paths lie on the other's, and how many run beside them: rasters of the distance to
   each map's paths), the ``candidates`` best refined by gated nearest-compatible-node SVD fits,
   and the ``scored`` most matched fully scored (:class:`MergeEvidence`): soft one-to-one matches
   within ``eps`` (the paper's ω with a tolerance), matched paths, **conflicts** (a junction or
   corner of one map on a path of the other with no node there: the other robot passed and saw
   no such place), **crossings** (paths crossing without a junction), the agreement of the
   paths leaving matched nodes, and the path evidence.
   The score is the calibrated log-odds that the alignment is right (:data:`CONFIDENCE_WEIGHTS`).
5. **Refinement** of the best candidate with the paper's ICP-SVD (:func:`fusion.icp_svd`), gated
   at ``eps`` and trimmed (TrICP) to the estimated overlap, then weighted least-squares SVD fits
   on mutually nearest nodes within ``fit_eps`` (each pair weighing ``1 − d²/fit_eps²``: one
   that may be a neighbour rather than the same place pulls little) and,
   for maps whose paths are straight node-to-node segments, on B's path points lying on A's
   paths (long corridors fix the rotation better than the few nodes of a small overlap); for
   maps with polylines (two robots' polylines of the same corridor run apart and would pull a
   point-to-point fit off), a point-to-line fit of the node pairs and B's polyline points on
   A's polylines, where only the corridors' directions count.
6. **Accept/reject** (:func:`decide`): enough matches, not collinear, log-odds at least
   ``min_score``, and a margin of ``min_margin`` over the best *distinct* runner-up (a symmetric
   map has several equally good alignments: rejected as ambiguous).

The baselines share steps 4–6 so that their difference is the search alone: ``"paper_icp"`` is the
paper's ICP-SVD from its own initialisation (no refinement), ``"exhaustive"`` the paper's search
(:func:`fusion.exhaustive_search`, ``exhaustive_step_deg``; its tied optima all refined, the best
by score kept, the others its runner-up), and ``"multistart_icp"`` the paper's ICP from
``multistart_starts`` rotations about the centroids, the 4 best refined, and ``"ransac"`` a plain
two-point RANSAC (``ransac_iterations`` minimal sets from *all* node pairs, kind-gated inlier
counts; :func:`fusion.structural.baselines.ransac`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from fusion.icp import degeneracy
from fusion.inputs import check_map_sizes
from fusion.rigid import Rigid2D
from fusion.structural.baselines import exhaustive, multistart_icp, paper_icp, ransac
from fusion.structural.config import DEFAULT_ACCEPT_THRESHOLD, METHODS, MergeConfig, config_of
from fusion.structural.evidence import (
    CALIBRATION_FEATURES,
    CONFIDENCE_WEIGHTS,
    MergeEvidence,
    decide,
    with_evidence,
)
from fusion.structural.fuse import fuse_maps
from fusion.structural.hypotheses import auto_merge, candidate_features
from fusion.structural.prepare import check_map, matchable, prepare_pair
from topo.graph import TopoMap

__all__ = [
    "CALIBRATION_FEATURES",
    "CONFIDENCE_WEIGHTS",
    "DEFAULT_ACCEPT_THRESHOLD",
    "METHODS",
    "MergeConfig",
    "MergeEvidence",
    "MergeResult",
    "candidate_features",
    "decide",
    "fuse_maps",
    "merge_maps",
]


@dataclass(frozen=True, slots=True, eq=False)
class MergeResult:
    """What :func:`merge_maps` found.

    Attributes:
        transform: B → A motion (``p_A = R p_B + T``); the best estimate even when rejected.
        accepted: whether the merge passed :func:`decide` (``confidence >= accept_threshold``
            and the hard gates).
        score: :attr:`MergeEvidence.score` of ``transform``.
        matches: ``(K, 2)`` int node index pairs ``(a, b)`` matched at ``transform``.
        merged: if accepted, A with B moved onto it (matched nodes fused at their mean, other
            B nodes within ``eps`` of a node fused into it, paths united, polylines dropped);
            if rejected, ``map_a`` unchanged.
        method: the method used.
        time_s: wall time of the call in seconds.
        reason: why the merge was rejected (``None`` when accepted).
        evidence: the numbers behind the decision (``None`` for maps too small to try).
        confidence: calibrated probability that ``transform`` is right (< 2°, < 0.3 m at B's
            centroid; :attr:`MergeEvidence.confidence`); 0 when nothing was tried.
    """

    transform: Rigid2D
    accepted: bool
    score: float
    matches: np.ndarray
    merged: TopoMap
    method: str
    time_s: float
    reason: str | None = None
    evidence: MergeEvidence | None = None
    confidence: float = 0.0


def _not_tried(map_a: TopoMap, method: str, start: float, reason: str) -> MergeResult:
    """The result when no alignment could be tried (too small, degenerate, no hypothesis)."""
    return MergeResult(Rigid2D.identity(), False, 0.0, np.empty((0, 2), dtype=np.int64), map_a,
                       method, time.perf_counter() - start, reason)


def merge_maps(map_a: TopoMap, map_b: TopoMap, method: str = "auto",
               config: MergeConfig | dict | None = None) -> MergeResult:
    """Align ``map_b`` onto ``map_a`` and merge them, or say why not.

    Args:
        map_a: the fixed map (its frame is the result's frame).
        map_b: the map moved onto A.
        method: ``"auto"`` (the global structural merge of the module doc), ``"paper_icp"``,
            ``"exhaustive"``, ``"multistart_icp"`` or ``"ransac"`` (:data:`METHODS`).
        config: :class:`MergeConfig`, a dict of its fields, or ``None`` for the defaults.

    Returns:
        :class:`MergeResult`. Maps with fewer than 3 nodes, degenerate geometry (coincident or
        collinear nodes) and maps that do not overlap give ``accepted=False`` with a ``reason``,
        never an exception.

    Raises:
        TypeError: a map that is not a :class:`topo.TopoMap`, a config of the wrong type.
        ValueError: NaN/inf node positions, more than :data:`fusion.inputs.MAX_NODES` nodes, an
            unknown ``method``, invalid config values or unknown config keys.

    Example:
        >>> from fusion.evaluation.synthetic import make_pair
        >>> pair = make_pair(np.random.default_rng(3), overlap=0.8, nodes=(30, 30))
        >>> result = merge_maps(pair.map_a, pair.map_b)
        >>> result.accepted, result.transform.rotation_error(pair.transform) < 0.035
        (True, True)
    """
    start = time.perf_counter()
    map_a = check_map(map_a, "map_a")
    map_b = check_map(map_b, "map_b")
    check_map_sizes(map_a, map_b)
    if method not in METHODS:
        raise ValueError(f"method must be one of {list(METHODS)}, got {method!r}")
    cfg = config_of(config)

    (view_a, index_a), (view_b, index_b) = matchable(map_a), matchable(map_b)
    small = [f"{name} has {v.n_nodes} node(s) off the frontier (of {m.n_nodes}); at least 3 "
             f"are needed" for name, m, v in (("map_a", map_a, view_a), ("map_b", map_b, view_b))
             if v.n_nodes < 3]
    if small:
        return _not_tried(map_a, method, start, "; ".join(small))
    flat = [d for name, v in (("map_a", view_a), ("map_b", view_b))
            if (d := degeneracy(v.xy, name)) is not None]
    if flat:
        return _not_tried(map_a, method, start, "; ".join(flat))
    pa, pb = prepare_pair(view_a, view_b, cfg)
    if method == "auto":
        found = auto_merge(pa, pb, cfg)
    elif method == "paper_icp":
        found = paper_icp(view_a, view_b, pa, pb, cfg)
    elif method == "exhaustive":
        found = exhaustive(view_a, view_b, pa, pb, cfg)
    elif method == "ransac":
        found = ransac(pa, pb, cfg)
    else:
        found = multistart_icp(view_a, view_b, pa, pb, cfg)
    if isinstance(found, str):
        return _not_tried(map_a, method, start, found)
    described = float(np.mean(np.concatenate([view_a.clearance, view_b.clearance]) > 0))
    found = with_evidence(found, described=described)
    reason = decide(found.evidence, cfg)
    transform = found.transform
    matches = np.stack([index_a[found.matches[:, 0]], index_b[found.matches[:, 1]]], axis=1)
    merged = map_a if reason else fuse_maps(map_a, map_b, transform, matches, cfg.eps)
    return MergeResult(transform, reason is None, found.evidence.score, matches, merged,
                       method, time.perf_counter() - start, reason, found.evidence,
                       found.evidence.confidence)
