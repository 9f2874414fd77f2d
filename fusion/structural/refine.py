"""Refinement of a found alignment: trimmed, gated ICP-SVD, then least-squares fits on matched
nodes and on B's paths lying on A's (point to point for straight node-to-node paths, point to
line for polylines)."""

from __future__ import annotations

import math

import numpy as np

from fusion.icp import icp_checked, rigid_fit
from fusion.structural import _kernels as K
from fusion.structural.config import MergeConfig
from fusion.structural.evidence import Evaluated, evaluate
from fusion.structural.prepare import PATH_CELL, PATH_FIT_WEIGHT, PATH_TOL, Prepared

LINE_FIT_WEIGHT = 0.2
"""Weight of a metre of B's polylines lying on A's in the point-to-line fit of maps with
polylines (:func:`line_fit`), against up to 1 per matched node pair."""

LINE_FIT_GATE = 0.3
"""B's polyline points farther than this (m) from A's polylines are left out of
:func:`line_fit`: two robots' routes along one corridor run this close."""


def least_squares(pa: Prepared, pb: Prepared, matches: np.ndarray, theta: float,
                  t: np.ndarray, eps: float) -> tuple[float, np.ndarray]:
    """The weighted SVD fit of B's matched nodes onto A's, each pair weighing
    ``1 − d²/eps²`` for its distance ``d`` under ``(theta, t)`` (the kernel of the soft count
    the score is made of: a pair near the gate, as likely a neighbour as the same place, pulls
    little), with — when neither map's paths are polylines — B's path points that lie within
    :data:`PATH_TOL` of A's paths under ``(theta, t)`` paired with their nearest A path point,
    :data:`PATH_FIT_WEIGHT` per metre of path. Two robots' polylines between the same places
    are routes through each one's own free space and run apart by a few decimetres: paired
    point by point they pull the rotation off."""
    weight = 0.0 if pa.polylines or pb.polylines else PATH_FIT_WEIGHT
    n = len(matches)
    P, Q, w = pb.xy[matches[:, 1]], pa.xy[matches[:, 0]], np.ones(n)
    if weight > 0.0:  # and B's path points on A's paths, onto their nearest A path points
        idx, near = K.nearest_on_paths(pa.segments, pb.path_pts, theta, t[0], t[1], PATH_TOL,
                                       pa.field, *pa.field_origin, PATH_CELL)
        P, Q = np.vstack((P, pb.path_pts[idx])), np.vstack((Q, near))
        w = np.concatenate((w, weight * pb.path_w[idx]))
    c, s = np.cos(theta), np.sin(theta)
    moved = P[:n] @ np.array([[c, s], [-s, c]]) + t
    # (a pair right at the gate keeps a little weight, so that the weights never all vanish)
    w[:n] = np.maximum(1.0 - np.sum((moved - Q[:n]) ** 2, axis=1) / (eps * eps), 1e-3)
    return rigid_fit(P, Q, w)


def line_fit(pa: Prepared, pb: Prepared, pairs: np.ndarray, theta: float, t: np.ndarray,
             eps: float, iterations: int = 3) -> tuple[float, np.ndarray]:
    """Gauss-Newton steps of a weighted fit of the node pairs ``pairs`` (``1 − d²/eps²`` each,
    as :func:`least_squares`) together with the *normal* distances of B's polyline points
    lying within :data:`LINE_FIT_GATE` of A's polylines to them (:data:`LINE_FIT_WEIGHT` per
    metre). Point to point, two robots' polylines of one corridor pull the rotation off (they
    run apart by a few decimetres, each through its own robot's free space); point to line,
    only their direction counts, and a long corridor fixes the rotation better than a few
    noisy nodes."""
    P, Q = pb.xy[pairs[:, 1]], pa.xy[pairs[:, 0]]
    for _ in range(iterations):
        c, s = np.cos(theta), np.sin(theta)
        rot = np.array([[c, -s], [s, c]])
        dp = P @ rot.T
        res = Q - dp - t
        w = np.maximum(1.0 - np.sum(res * res, axis=1) / (eps * eps), 1e-3)
        idx, near = K.nearest_on_paths(pa.segments, pb.path_pts, theta, t[0], t[1],
                                       LINE_FIT_GATE, pa.field, *pa.field_origin, PATH_CELL)
        dq = pb.path_pts[idx] @ rot.T
        off = dq + t - near
        dist = np.hypot(off[:, 0], off[:, 1])
        on = dist > 1e-12  # a point on the line has no normal here (and no residual)
        n = off[on] / dist[on, None]
        J = np.concatenate([np.column_stack([-dp[:, 1], np.ones(len(P)), np.zeros(len(P))]),
                            np.column_stack([dp[:, 0], np.zeros(len(P)), np.ones(len(P))]),
                            np.column_stack([n[:, 1] * dq[on, 0] - n[:, 0] * dq[on, 1], n])])
        r = np.concatenate([res[:, 0], res[:, 1], -dist[on]])
        weights = np.concatenate([w, w, LINE_FIT_WEIGHT * pb.path_w[idx][on]])
        step = np.linalg.solve((J * weights[:, None]).T @ J + 1e-12 * np.eye(3),
                               (J * weights[:, None]).T @ r)
        theta, t = theta + float(step[0]), t + step[1:]
    return theta, t


def _mutual_pairs(A: np.ndarray, B: np.ndarray, theta: float, t: np.ndarray,
                  dist: float) -> np.ndarray:
    """``(K, 2)`` pairs ``(a, b)``, ``b`` ascending: A node and B node (moved by ``(theta,
    t)``) mutually nearest (no other B node strictly nearer to ``a``; ties to the lower A
    node) and within ``dist``, any kinds."""
    c, s = math.cos(theta), math.sin(theta)
    x, y = c * B[:, 0] - s * B[:, 1] + t[0], s * B[:, 0] + c * B[:, 1] + t[1]
    d2 = (x[:, None] - A[None, :, 0]) ** 2 + (y[:, None] - A[None, :, 1]) ** 2
    if not d2.size:
        return np.zeros((0, 2), dtype=np.int64)
    a = d2.argmin(axis=1)
    best = d2[np.arange(len(B)), a]
    b = np.flatnonzero((best <= dist * dist) & ~(d2[:, a] < best).any(axis=0))
    return np.column_stack((a[b], b)).astype(np.int64)


def polish(pa: Prepared, pb: Prepared, start: Evaluated, cfg: MergeConfig) -> Evaluated:
    """Trimmed, gated ICP-SVD from ``start`` (kept if it scores better), then three weighted
    least-squares fits on mutually nearest nodes of any kinds within ``fit_eps`` (a node at
    the edge of explored space may have another kind in each map) and, for maps without
    polylines, on B's path points lying on A's paths (:func:`least_squares`: long corridors fix
    the rotation better than the few nodes a small overlap shares); for maps with
    polylines, then a point-to-line fit of the node pairs and B's polyline points on A's
    polylines (:func:`line_fit`)."""
    best = start
    if start.evidence.inliers >= 2:
        trim = min(1.0, max(start.evidence.inliers / len(pb.xy), 2.0 / len(pb.xy)))
        icp = icp_checked(pa.xy, pb.xy, None, cfg.icp_max_iter, start.transform, 1e-9,
                          cfg.eps, trim)  # the maps' nodes were checked by merge_maps
        ev = evaluate(pa, pb, icp.transform.theta, icp.transform.T, cfg)
        best = max((best, ev), key=Evaluated.key)
    theta, t, moved = best.theta, best.t, False
    for _ in range(3):
        pairs = _mutual_pairs(pa.xy, pb.xy, theta, t, cfg.fit_eps)
        if len(pairs) < 3:
            break
        theta, t, moved = *least_squares(pa, pb, pairs, theta, t, cfg.fit_eps), True
    if moved and pa.polylines and pb.polylines:
        pairs = _mutual_pairs(pa.xy, pb.xy, theta, t, cfg.fit_eps)
        if len(pairs) >= 3:
            theta, t = line_fit(pa, pb, pairs, theta, t, cfg.fit_eps)
    return evaluate(pa, pb, theta, t, cfg) if moved else best
