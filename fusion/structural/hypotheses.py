"""``"auto"``'s global search (steps 1–4 of :mod:`fusion.structural`): 2-point hypotheses from node
pairs, their coarse score on a raster of A, distinct candidates re-ranked with path evidence,
refined and fully scored; and the best distinct alternative of an alignment (its runner-up)."""

from __future__ import annotations

import math

import numpy as np

from fusion.icp import degeneracy
from fusion.rigid import Rigid2D
from fusion.structural import _kernels as K
from fusion.structural.config import MergeConfig, config_of
from fusion.structural.evidence import (
    BRANCH_TOL,
    CONFIDENCE_WEIGHTS,
    MIN_CROSSING_SIN,
    PATH_WEIGHTS,
    Evaluated,
    evaluate,
    evidence_args,
    feature_matrix,
    path_evidence,
    score_rows,
    with_evidence,
)
from fusion.structural.prepare import Prepared, check_map, matchable, prepare_pair
from fusion.structural.refine import polish
from topo.graph import TopoMap


def _centroid_image(theta: np.ndarray, tx: np.ndarray, ty: np.ndarray,
                    centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where each motion ``(theta, tx, ty)`` puts the point ``centre``: ``(cx, cy)``."""
    c, s = np.cos(theta), np.sin(theta)
    return c * centre[0] - s * centre[1] + tx, s * centre[0] + c * centre[1] + ty


def runner_up(best: Evaluated, theta: np.ndarray, tx: np.ndarray, ty: np.ndarray,
              scores: np.ndarray, b_xy: np.ndarray, cfg: MergeConfig) -> float:
    """Best of ``scores`` among the alignments ``(theta, tx, ty)`` distinct from ``best``
    (``-inf`` if none).

    Distinct: rotated ``distinct_angle_deg`` or more apart, or moving the centre of B's matched
    nodes ``distinct_distance`` or more apart — where the evidence is, not at B's centroid,
    which may lie far outside the overlap (B's centroid when nothing matched).
    """
    centre = b_xy[best.matches[:, 1]].mean(axis=0) if len(best.matches) else b_xy.mean(axis=0)
    p = best.transform.apply(centre)
    cx, cy = _centroid_image(theta, tx, ty, centre)
    gap = np.abs(np.angle(np.exp(1j * (theta - best.theta))))
    distinct = ((gap >= math.radians(cfg.distinct_angle_deg))
                | (np.hypot(cx - p[0], cy - p[1]) >= cfg.distinct_distance))
    return float(scores[distinct].max(initial=-math.inf))


def runner_up_of(best: Evaluated, others: list[Evaluated], b_xy: np.ndarray,
                 cfg: MergeConfig) -> float:
    """:func:`runner_up` over evaluated alignments."""
    if not others:
        return -math.inf
    return runner_up(best, np.array([o.theta for o in others]),
                     np.array([o.t[0] for o in others]), np.array([o.t[1] for o in others]),
                     np.array([o.evidence.score for o in others]), b_xy, cfg)


def hit_grid(pa: Prepared, tol: float, path_tol: float
             ) -> tuple[np.ndarray, float, float, float]:
    """The raster of A that :func:`fusion.structural._kernels.refined_scores` reads, cells
    ``tol / 2`` wide: ``table[iy, ix, k]`` (``k`` < 3) the A node of a kind compatible with B
    kind ``k`` nearest to the cell within ~``tol`` (``-1`` if none); ``table[iy, ix, 3]`` the bits
    :data:`~fusion.structural._kernels.NEAR_ANY_NODE` (within ~``tol`` of an A node) and
    :data:`~fusion.structural._kernels.ON_PATH` (within ~``path_tol`` of an A path).
    Returns ``(table, x0, y0, 1 / cell)``."""
    # the smallest dtype that holds a node index keeps the table in cache
    n = len(pa.xy)
    dtype = np.int8 if n < 127 else np.int16 if n < 32767 else np.int32
    cell = tol / 2.0
    (x0, y0), (x1, y1) = pa.xy.min(axis=0).tolist(), pa.xy.max(axis=0).tolist()
    x0, y0 = x0 - tol - cell, y0 - tol - cell
    shape = (int(math.ceil((y1 - y0 + tol) / cell) + 2), int(math.ceil((x1 - x0 + tol) / cell) + 2))
    table = np.full((*shape, pa.compat.shape[1] + 1), -1, dtype=dtype)
    table[:, :, -1] = 0
    K.paint_nearest(table, x0, y0, cell, pa.xy, pa.kinds, tol, pa.compat)
    K.paint_segments(table[:, :, -1], x0, y0, cell, pa.xy, pa.edges, path_tol, 1 << K.ON_PATH)
    return table, x0, y0, 1.0 / cell


_COARSE_MIN_PAIRS = 4
"""The coarse ranking holds the hypotheses landing at least this many B nodes on A nodes; those
landing ``min_inliers`` to this − 1 are refitted and scored too, and pooled apart
(``MergeConfig.sparse_pool``), so that chance 3-node landings do not crowd the ranking."""


_SPARSE_MIN = 0.7
"""A hypothesis of the ``sparse_pool`` must land its few nodes tightly: a coarse score of at
least this per landed node (a mean distance of about 0.27 m at ``eps`` 0.5), which right
alignments of maps with node noise up to 0.15 m pass and loose chance landings do not."""


def _pair_candidates(pa: Prepared, pb: Prepared, tol: float
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """2-point consensus: every (A pair ``p``, B pair ``q``, B's pairs in both orientations by
    length) whose lengths agree within ``tol`` and whose end kinds are compatible, in the order
    ``p``, then ``q``: ``(p, q, weight)``, ``weight`` the shorter length (longer pairs fix the
    angle better)."""
    lo = np.searchsorted(pb.both_len, pa.pair_len - tol)
    count = np.searchsorted(pb.both_len, pa.pair_len + tol, side="right") - lo
    p = np.repeat(np.arange(len(lo)), count)
    q = lo[p] + np.arange(len(p)) - np.repeat(np.cumsum(count) - count, count)
    ok = (pa.compat[pa.kinds[pa.pair_i[p]], pb.kinds[pb.both_i[q]]]
          & pa.compat[pa.kinds[pa.pair_j[p]], pb.kinds[pb.both_j[q]]])
    p, q = p[ok], q[ok]
    return p, q, np.minimum(pa.pair_len[p], pb.both_len[q])


def search_candidates(pa: Prepared, pb: Prepared, cfg: MergeConfig) -> tuple | str:
    """Steps 1–4 of the module docstring: the ``scored`` candidates' motions, evidence
    features and path evidence, and how many hypotheses there were (or why there are none)."""
    b_i, b_j = pb.both_i, pb.both_j
    hyp_p, hyp_q, weight = _pair_candidates(pa, pb, cfg.pair_tolerance)
    n_hyp = len(hyp_p)
    if n_hyp == 0:
        return "no pair of nodes of B matches a pair of A in length and kinds"
    if n_hyp > cfg.max_hypotheses:  # the motions of the kept ones only
        keep = np.sort(np.argpartition(-weight, cfg.max_hypotheses - 1)[:cfg.max_hypotheses])
        hyp_p, hyp_q = hyp_p[keep], hyp_q[keep]
    theta, tx, ty, cos_t, sin_t = K.pair_motions(pa.xy, pa.pair_i, pa.pair_j, pb.xy, b_i, b_j,
                                                 hyp_p, hyp_q)
    table, x0, y0, inv_cell = hit_grid(pa, cfg.coarse_tolerance, cfg.eps)
    landed = np.zeros(len(theta), dtype=np.int64)
    min_pairs = max(cfg.min_inliers, _COARSE_MIN_PAIRS)
    reserve = cfg.sparse_pool if cfg.min_inliers < min_pairs else 0
    coarse = K.refined_scores(theta, tx, ty, cos_t, sin_t, pa.xy, pb.xy, pb.kinds, table, x0,
                              y0, inv_cell, cfg.eps, pa.loose,
                              cfg.min_inliers if reserve else min_pairs, landed)
    centre = pb.xy.mean(axis=0)
    cx, cy = _centroid_image(theta, tx, ty, centre)
    # those landing fewer than min_pairs are ranked with the unscored ones (0), and pooled apart
    few = landed < min_pairs
    ranked = np.argsort(np.where(few, 0.0, -coarse), kind="stable")
    small = np.flatnonzero(few & (coarse > _SPARSE_MIN * landed))
    small = small[np.argsort(-coarse[small], kind="stable")]
    chosen = K.select_distinct(ranked, theta, cx, cy, math.radians(cfg.distinct_angle_deg),
                               cfg.distinct_distance, max(cfg.path_pool, cfg.candidates))
    if reserve:  # the best distinct ones landing only min_inliers..3 nodes: sparse_pool
        chosen = K.select_distinct(np.concatenate([chosen, small]), theta, cx, cy,
                                   math.radians(cfg.distinct_angle_deg), cfg.distinct_distance,
                                   len(chosen) + reserve)
    if len(chosen) > cfg.candidates:  # re-ranked with the path evidence, in node units
        w = CONFIDENCE_WEIGHTS
        paths = path_evidence(pa, pb, theta[chosen], tx[chosen], ty[chosen], both=False)
        gain = coarse[chosen] + paths @ PATH_WEIGHTS / (w["closeness"] + w["inliers"])
        chosen = chosen[np.argsort(-gain, kind="stable")[:cfg.candidates]]  # best first
    th, txc, tyc = theta[chosen], tx[chosen], ty[chosen]  # refined; the most matched kept
    counts = K.refine_batch(th, txc, tyc, pa.xy, pa.kinds, pb.xy, pb.kinds, pa.compat,
                            np.array([cfg.coarse_tolerance, cfg.eps]))
    best = np.sort(np.argsort(-counts, kind="stable")[:cfg.scored])
    th, txc, tyc = th[best], txc[best], tyc[best]
    features = K.evidence_batch(*evidence_args(pa, pb), th, txc, tyc, cfg.eps, pa.compat,
                                pa.loose, BRANCH_TOL, MIN_CROSSING_SIN, cfg.near_miss)
    return th, txc, tyc, features, path_evidence(pa, pb, th, txc, tyc), n_hyp


def auto_merge(pa: Prepared, pb: Prepared, cfg: MergeConfig) -> Evaluated | str:
    found = search_candidates(pa, pb, cfg)
    if isinstance(found, str):
        return found
    th, txc, tyc, features, paths, n_hyp = found
    scores = score_rows(features, paths, len(pa.xy), len(pb.xy))
    k = int(np.argmax(scores))
    best = polish(pa, pb, evaluate(pa, pb, th[k], np.array([txc[k], tyc[k]]), cfg), cfg)
    runner = runner_up(best, th, txc, tyc, scores, pb.xy, cfg)
    return with_evidence(best, runner_up=runner, hypotheses=n_hyp)


def candidate_features(map_a: TopoMap, map_b: TopoMap,
                       config: MergeConfig | dict | None = None
                       ) -> tuple[list[Rigid2D], np.ndarray]:
    """The alignments ``"auto"`` scores last before refining the best (its search's candidates)
    and their :meth:`MergeEvidence.features` values, one row each (columns in the order of
    :data:`CONFIDENCE_WEIGHTS`): what ``python -m fusion.calibration fit --model ranking`` fits
    those weights on. Empty when ``merge_maps`` would not search (too few nodes, degenerate
    maps, no hypothesis).

    Raises:
        TypeError, ValueError: as :func:`merge_maps` for bad maps or config.
    """
    map_a, map_b = check_map(map_a, "map_a"), check_map(map_b, "map_b")
    cfg = config_of(config)
    (view_a, _), (view_b, _) = matchable(map_a), matchable(map_b)
    empty = ([], np.empty((0, len(CONFIDENCE_WEIGHTS))))
    if min(view_a.n_nodes, view_b.n_nodes) < 3 or degeneracy(view_a.xy, "map_a") or \
            degeneracy(view_b.xy, "map_b"):
        return empty
    pa, pb = prepare_pair(view_a, view_b, cfg)
    found = search_candidates(pa, pb, cfg)
    if isinstance(found, str):
        return empty
    th, txc, tyc, features, paths, _ = found
    transforms = [Rigid2D(float(a), (float(x), float(y))) for a, x, y in zip(th, txc, tyc,
                                                                             strict=True)]
    return transforms, feature_matrix(features, paths, len(pa.xy), len(pb.xy))
