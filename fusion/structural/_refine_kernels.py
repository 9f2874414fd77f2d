"""Compiled loops of the final fits (numba, cached on disk after the first call): mutually
nearest node pairs and B's path points paired with A's paths (:mod:`fusion.structural.refine`)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def mutual_pairs(A, B, theta, tx, ty, dist):
    """``(K, 2)`` pairs ``(a, b)``: A node and B node (moved by the motion) mutually nearest and
    within ``dist``, any kinds."""
    c, s = math.cos(theta), math.sin(theta)
    X = np.empty_like(B)
    for b in range(B.shape[0]):
        X[b, 0] = c * B[b, 0] - s * B[b, 1] + tx
        X[b, 1] = s * B[b, 0] + c * B[b, 1] + ty
    nn_b = np.empty(B.shape[0], dtype=np.int64)
    d_b = np.empty(B.shape[0])
    for b in range(B.shape[0]):
        best, arg = np.inf, -1
        for a in range(A.shape[0]):
            dd = (X[b, 0] - A[a, 0]) ** 2 + (X[b, 1] - A[a, 1]) ** 2
            if dd < best:
                best, arg = dd, a
        nn_b[b], d_b[b] = arg, best
    out = np.empty((B.shape[0], 2), dtype=np.int64)
    n = 0
    for b in range(B.shape[0]):
        a = nn_b[b]
        if d_b[b] > dist * dist:
            continue
        mutual = True
        for o in range(B.shape[0]):
            if o != b and (X[o, 0] - A[a, 0]) ** 2 + (X[o, 1] - A[a, 1]) ** 2 < d_b[b]:
                mutual = False
                break
        if mutual:
            out[n, 0], out[n, 1] = a, b
            n += 1
    return out[:n]


@njit(cache=True, nogil=True)
def nearest_on_paths(seg, pts, theta, tx, ty, gate, field, x0, y0, cell):
    """For the points ``pts`` moved by ``(theta, tx, ty)``, the nearest point of the segments
    ``seg[k] = (x1, y1, x2, y2)`` within ``gate``: ``(index of each point that has one (K,),
    its nearest segment point (K, 2))``. ``field`` (:func:`path_field` of the segments, cells
    ``cell`` wide from ``(x0, y0)``) skips the points that are surely farther."""
    c, s = math.cos(theta), math.sin(theta)
    idx = np.empty(pts.shape[0], dtype=np.int64)
    near = np.empty((pts.shape[0], 2))
    gate2 = gate * gate
    skip2 = (gate + cell) ** 2  # a cell centre is within cell / √2 of any point of the cell
    ny, nx = field.shape
    n = 0
    for k in range(pts.shape[0]):
        x = c * pts[k, 0] - s * pts[k, 1] + tx
        y = s * pts[k, 0] + c * pts[k, 1] + ty
        ix, iy = int(math.floor((x - x0) / cell)), int(math.floor((y - y0) / cell))
        if ix < 0 or iy < 0 or ix >= nx or iy >= ny or field[iy, ix] >= skip2:
            continue
        best, bx, by = gate2, 0.0, 0.0
        for e in range(seg.shape[0]):
            ux, uy, wx, wy = seg[e, 0], seg[e, 1], seg[e, 2], seg[e, 3]
            if (x < min(ux, wx) - gate or x > max(ux, wx) + gate or y < min(uy, wy) - gate
                    or y > max(uy, wy) + gate):
                continue
            vx, vy = wx - ux, wy - uy
            ll = vx * vx + vy * vy
            t = 0.0 if ll == 0.0 else min(1.0, max(0.0, ((x - ux) * vx + (y - uy) * vy) / ll))
            qx, qy = ux + t * vx, uy + t * vy
            dd = (qx - x) ** 2 + (qy - y) ** 2
            if dd < best:
                best, bx, by = dd, qx, qy
        if best < gate2:
            idx[n] = k
            near[n, 0], near[n, 1] = bx, by
            n += 1
    return idx[:n], near[:n]


@njit(cache=True, nogil=True)
def fit_points(a_xy, b_xy, matches, seg, pts, pts_w, path_weight, theta, tx, ty, gate, field,
               x0, y0, cell):
    """What the least-squares fit of ``fusion.structural.refine.least_squares`` pairs: ``(P, Q,
    w)``, the
    matched B nodes ``b_xy[matches[:, 1]]`` onto ``a_xy[matches[:, 0]]`` (weight 1 each), then,
    when ``path_weight > 0``, the points ``pts`` that :func:`nearest_on_paths` finds within
    ``gate`` of the segments ``seg`` (moved by ``(theta, tx, ty)``) onto their nearest segment
    points, ``path_weight × pts_w`` each: the rows ``np.vstack`` and ``np.concatenate`` gave."""
    n = matches.shape[0]
    idx = np.empty(0, dtype=np.int64)
    near = np.empty((0, 2))
    if path_weight > 0.0:
        idx, near = nearest_on_paths(seg, pts, theta, tx, ty, gate, field, x0, y0, cell)
    m = n + idx.shape[0]
    P = np.empty((m, 2))
    Q = np.empty((m, 2))
    w = np.ones(m)
    for k in range(n):
        P[k, 0], P[k, 1] = b_xy[matches[k, 1], 0], b_xy[matches[k, 1], 1]
        Q[k, 0], Q[k, 1] = a_xy[matches[k, 0], 0], a_xy[matches[k, 0], 1]
    for k in range(idx.shape[0]):
        P[n + k, 0], P[n + k, 1] = pts[idx[k], 0], pts[idx[k], 1]
        Q[n + k, 0], Q[n + k, 1] = near[k, 0], near[k, 1]
        w[n + k] = path_weight * pts_w[idx[k]]
    return P, Q, w
