"""The baseline methods of :func:`fusion.merge_maps`, sharing ``"auto"``'s refinement and
scoring so that they differ by their search alone: ``"paper_icp"`` (the paper's ICP-SVD from
its own start), ``"exhaustive"`` (the paper's search), ``"multistart_icp"`` and ``"ransac"`` (a
plain two-point RANSAC with kind-gated inliers: what a generic graph matcher does without the
maps' structure)."""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from fusion.icp import icp_svd, rigid_fit
from fusion.rigid import Rigid2D
from fusion.search import exhaustive_search
from fusion.structural import _kernels as K
from fusion.structural.config import MergeConfig
from fusion.structural.evidence import Evaluated, evaluate, with_evidence
from fusion.structural.hypotheses import _centroid_image, runner_up_of
from fusion.structural.prepare import Prepared
from fusion.structural.refine import polish
from topo.graph import TopoMap


def _points(m: TopoMap) -> np.ndarray:
    """The paper's point set (path endpoints), or all nodes when fewer than 2 end paths."""
    pts = m.endpoints()
    return pts if len(pts) >= 2 else m.xy


def paper_icp(map_a: TopoMap, map_b: TopoMap, pa: Prepared, pb: Prepared,
              cfg: MergeConfig) -> Evaluated:
    res = icp_svd(_points(map_a), _points(map_b), tau=0.1, max_iter=100)
    return with_evidence(evaluate(pa, pb, res.transform.theta, res.transform.T, cfg), hypotheses=1)


def best_polished(pa: Prepared, pb: Prepared, starts: list[Evaluated], cfg: MergeConfig,
                  top: int = 4) -> Evaluated:
    """Polish the ``top`` best-scoring ``starts`` (:func:`polish`); the best of them, with the
    runner-up among the other polished ones and the remaining starts."""
    ranked = sorted(starts, key=Evaluated.key, reverse=True)
    polished = [polish(pa, pb, e, cfg) for e in ranked[:top]]
    order = sorted(range(len(polished)), key=lambda i: polished[i].key(), reverse=True)
    best = polished[order[0]]
    others = [polished[i] for i in order[1:]] + ranked[top:]
    return with_evidence(best, runner_up=runner_up_of(best, others, pb.xy, cfg))


def exhaustive(map_a: TopoMap, map_b: TopoMap, pa: Prepared, pb: Prepared,
               cfg: MergeConfig) -> Evaluated:
    found = exhaustive_search(map_a if len(map_a.endpoints()) else map_a.xy,
                              map_b if len(map_b.endpoints()) else map_b.xy,
                              step_deg=cfg.exhaustive_step_deg, eps=cfg.eps)
    ties = [evaluate(pa, pb, p.transform.theta, p.transform.T, cfg) for p in found.ties]
    return with_evidence(best_polished(pa, pb, ties, cfg, top=8), hypotheses=found.evaluations)


def multistart_icp(map_a: TopoMap, map_b: TopoMap, pa: Prepared, pb: Prepared,
                   cfg: MergeConfig) -> Evaluated:
    M, D = _points(map_a), _points(map_b)
    evals = []
    for k in range(cfg.multistart_starts):
        theta = 2 * math.pi * k / cfg.multistart_starts
        c, s = math.cos(theta), math.sin(theta)
        start = Rigid2D(theta, M.mean(axis=0) - np.array([[c, -s], [s, c]]) @ D.mean(axis=0))
        res = icp_svd(M, D, tau=0.1, max_iter=100, init=start)
        evals.append(evaluate(pa, pb, res.transform.theta, res.transform.T, cfg))
    return with_evidence(best_polished(pa, pb, evals, cfg), hypotheses=cfg.multistart_starts)


RANSAC_NEIGHBOURS = 4
"""A moved B node is an inlier of a RANSAC hypothesis when one of its this many nearest A nodes
within ``eps`` has a compatible kind (the nearest of those counts)."""


def _all_pairs(xy: np.ndarray, min_distance: float, both: bool
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every node pair ``(i, j)`` at least ``min_distance`` apart, by length (stable); with
    ``both``, in both orientations (what :func:`fusion.structural.hypotheses._pair_candidates`
    reads)."""
    i, j = np.triu_indices(len(xy), 1)
    if both:
        i, j = np.concatenate([i, j]), np.concatenate([j, i])
    length = np.linalg.norm(xy[i] - xy[j], axis=1)
    keep = length >= min_distance
    order = np.argsort(length[keep], kind="stable")
    return (i[keep][order].astype(np.int64), j[keep][order].astype(np.int64),
            length[keep][order])


def _inliers(tree: cKDTree, pa: Prepared, pb: Prepared, theta: np.ndarray, tx: np.ndarray,
             ty: np.ndarray, eps: float) -> tuple[np.ndarray, np.ndarray]:
    """Per hypothesis ``(theta, tx, ty)``: how many B nodes land within ``eps`` of an A node of
    a compatible kind, and the A node each B node lands on (``-1`` if none), ``(H, n_B)``."""
    c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
    x = c * pb.xy[:, 0] - s * pb.xy[:, 1] + tx[:, None]
    y = s * pb.xy[:, 0] + c * pb.xy[:, 1] + ty[:, None]
    k = min(RANSAC_NEIGHBOURS, len(pa.xy))
    _, idx = tree.query(np.stack([x.ravel(), y.ravel()], axis=1), k=k,
                        distance_upper_bound=eps)
    idx = idx.reshape(len(theta), len(pb.xy), k)
    found = idx < len(pa.xy)
    a_kind = np.append(pa.kinds, 0)[np.where(found, idx, len(pa.xy))]
    ok = found & pa.compat[a_kind, pb.kinds[None, :, None]]
    first = np.where(ok.any(axis=2), np.take_along_axis(idx, ok.argmax(axis=2)[..., None],
                                                        axis=2)[..., 0], -1)
    return (first >= 0).sum(axis=1), first


def ransac(pa: Prepared, pb: Prepared, cfg: MergeConfig) -> Evaluated | str:
    """A plain two-point RANSAC: minimal sets drawn (``ransac_seed``) as a random pair of B
    nodes and a random pair of A nodes whose length agrees within ``pair_tolerance``, kept when
    their end kinds are compatible (the first ``ransac_iterations`` of up to four times as many
    draws), each scored by its kind-gated inliers (:data:`RANSAC_NEIGHBOURS`); the ``8`` best
    distinct by inliers refitted on their inliers (SVD, twice), polished and scored like the
    other methods (:func:`best_polished`)."""
    a_i, a_j, a_len = _all_pairs(pa.xy, cfg.min_pair_distance, both=False)
    b_i, b_j, b_len = _all_pairs(pb.xy, cfg.min_pair_distance, both=True)
    if len(a_len) == 0 or len(b_len) == 0:
        return "no pair of nodes is min_pair_distance apart"
    rng = np.random.default_rng(cfg.ransac_seed)
    draws = 4 * cfg.ransac_iterations
    hyp_q = rng.integers(len(b_len), size=draws)
    lo = np.searchsorted(a_len, b_len[hyp_q] - cfg.pair_tolerance)
    hi = np.searchsorted(a_len, b_len[hyp_q] + cfg.pair_tolerance, side="right")
    hyp_p = np.minimum(lo + (rng.random(draws) * (hi - lo)).astype(np.int64), len(a_len) - 1)
    ok = (hi > lo) & pa.compat[pa.kinds[a_i[hyp_p]], pb.kinds[b_i[hyp_q]]] & \
        pa.compat[pa.kinds[a_j[hyp_p]], pb.kinds[b_j[hyp_q]]]
    keep = np.flatnonzero(ok)[:cfg.ransac_iterations]
    if len(keep) == 0:
        return "no pair of nodes of B matches a pair of A in length and kinds"
    hyp_p, hyp_q = hyp_p[keep], hyp_q[keep]
    theta, tx, ty, _, _ = K.pair_motions(pa.xy, a_i, a_j, pb.xy, b_i, b_j, hyp_p, hyp_q)
    tree = cKDTree(pa.xy)
    counts, _ = _inliers(tree, pa, pb, theta, tx, ty, cfg.eps)
    centre = pb.xy.mean(axis=0)
    cx, cy = _centroid_image(theta, tx, ty, centre)
    order = np.argsort(-counts, kind="stable")
    chosen = K.select_distinct(order, theta, cx, cy, math.radians(cfg.distinct_angle_deg),
                               cfg.distinct_distance, 8)
    starts = []
    for h in chosen:
        th, t = float(theta[h]), np.array([tx[h], ty[h]])
        for _ in range(2):  # refit on the inliers
            _, first = _inliers(tree, pa, pb, np.array([th]), t[:1], t[1:], cfg.eps)
            b = np.flatnonzero(first[0] >= 0)
            if len(b) < 2:
                break
            th, t = rigid_fit(pb.xy[b], pa.xy[first[0, b]])
        starts.append(evaluate(pa, pb, th, t, cfg))
    return with_evidence(best_polished(pa, pb, starts, cfg), hypotheses=len(theta))
