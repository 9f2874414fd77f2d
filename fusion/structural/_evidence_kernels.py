"""Compiled evidence of an alignment (numba, cached on disk after the first call): one-to-one
matches, conflicts, crossings, branch agreement, match likelihoods and path agreement
(:mod:`fusion.structural.evidence`).

Calls :func:`fusion.structural._prepare_kernels.bbox` and :func:`fusion._icp_kernels.spread`,
kernels of other files: after editing those, delete the numba caches (CONTRIBUTING).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from fusion._icp_kernels import spread
from fusion.structural._prepare_kernels import bbox


@njit(cache=True, nogil=True)
def _nearest_compatible(x, y, kind, P, p_kind, compat_row_first, compat, gate2):
    """The point of ``P`` of a kind compatible with ``kind`` nearest to ``(x, y)`` within
    ``gate2`` (squared): ``(index or -1, squared distance or gate2, whether any point of any
    kind is within gate2)``."""
    best = gate2
    arg = -1
    any_near = False
    for i in range(P.shape[0]):
        dd = (x - P[i, 0]) ** 2 + (y - P[i, 1]) ** 2
        if dd > gate2:
            continue
        any_near = True
        ok = compat[kind, p_kind[i]] if compat_row_first else compat[p_kind[i], kind]
        if ok and dd <= best:
            best = dd
            arg = i
    return arg, best, any_near


@njit(cache=True, nogil=True)
def _segment_boxes(P, edges, grow):
    """``(E, 4)`` bounding box ``(x0, x1, y0, y1)`` of each segment ``P[u]``–``P[v]``, grown by
    ``grow``: what :func:`_segment_distance2` tests first."""
    out = np.empty((edges.shape[0], 4))
    for e in range(edges.shape[0]):
        ux, uy = P[edges[e, 0], 0], P[edges[e, 0], 1]
        wx, wy = P[edges[e, 1], 0], P[edges[e, 1], 1]
        out[e, 0], out[e, 1] = min(ux, wx) - grow, max(ux, wx) + grow
        out[e, 2], out[e, 3] = min(uy, wy) - grow, max(uy, wy) + grow
    return out


@njit(cache=True, nogil=True)
def _segment_distance2(x, y, P, edges, limit2, boxes, hit):
    """Squared distance from ``(x, y)`` to the nearest segment, or ``limit2`` if none is nearer.
    ``boxes``: :func:`_segment_boxes` grown by ``√limit2`` (segments whose box misses the point
    are farther; tested first, in a vectorised pass: coordinates are finite, so ``>=`` is
    ``not <``); ``hit`` (one per segment) is scratch."""
    best = limit2
    for e in range(edges.shape[0]):
        hit[e] = ((x >= boxes[e, 0]) & (x <= boxes[e, 1]) & (y >= boxes[e, 2])
                  & (y <= boxes[e, 3]))
    for e in range(edges.shape[0]):
        if not hit[e]:
            continue
        ux, uy = P[edges[e, 0], 0], P[edges[e, 0], 1]
        wx, wy = P[edges[e, 1], 0], P[edges[e, 1], 1]
        vx, vy = wx - ux, wy - uy
        ll = vx * vx + vy * vy
        t = 0.0 if ll == 0.0 else ((x - ux) * vx + (y - uy) * vy) / ll
        t = min(1.0, max(0.0, t))
        dx, dy = ux + t * vx - x, uy + t * vy - y
        best = min(best, dx * dx + dy * dy)
    return best


@njit(cache=True, nogil=True)
def _far_from_box(x, y, box, reach):
    """Whether ``(x, y)`` is more than ``reach`` from the box (then it is more than ``reach``
    from every point and segment inside it)."""
    dx = max(box[0] - x, 0.0, x - box[1])
    dy = max(box[2] - y, 0.0, y - box[3])
    return dx * dx + dy * dy > reach * reach


@njit(cache=True, nogil=True)
def _crossings(P, p_edges, p_margin, Q, q_edges, q_margin, min_sin):
    """Pairs of paths (one of each map) that cross at a point at least ``margin`` (a fraction
    of each path) away from their ends, at an angle whose sine is at least ``min_sin`` (nearly
    parallel paths are the same corridor seen twice, not a crossing): corridors that cross
    without a junction."""
    n = 0
    if P.shape[0] == 0 or Q.shape[0] == 0:
        return n
    # only paths reaching into the other map's bounding box can cross one of its paths
    qx0, qx1, qy0, qy1 = bbox(Q)
    px0, px1, py0, py1 = bbox(P)
    q_in = np.empty(q_edges.shape[0], dtype=np.bool_)
    for f in range(q_edges.shape[0]):
        u, v = q_edges[f, 0], q_edges[f, 1]
        q_in[f] = not (max(Q[u, 0], Q[v, 0]) < px0 or min(Q[u, 0], Q[v, 0]) > px1
                       or max(Q[u, 1], Q[v, 1]) < py0 or min(Q[u, 1], Q[v, 1]) > py1)
    # each Q path's box (from its start and step, as the crossing test reads it)
    q_box = np.empty((q_edges.shape[0], 4))
    for f in range(q_edges.shape[0]):
        bx, by = Q[q_edges[f, 0], 0], Q[q_edges[f, 0], 1]
        sx, sy = Q[q_edges[f, 1], 0] - bx, Q[q_edges[f, 1], 1] - by
        q_box[f, 0], q_box[f, 1] = min(bx, bx + sx), max(bx, bx + sx)
        q_box[f, 2], q_box[f, 3] = min(by, by + sy), max(by, by + sy)
    overlap = np.empty(q_edges.shape[0], dtype=np.bool_)
    for e in range(p_edges.shape[0]):
        ax, ay = P[p_edges[e, 0], 0], P[p_edges[e, 0], 1]
        rx, ry = P[p_edges[e, 1], 0] - ax, P[p_edges[e, 1], 1] - ay
        if (max(ax, ax + rx) < qx0 or min(ax, ax + rx) > qx1 or max(ay, ay + ry) < qy0
                or min(ay, ay + ry) > qy1):
            continue
        ex0, ex1 = min(ax, ax + rx), max(ax, ax + rx)
        ey0, ey1 = min(ay, ay + ry), max(ay, ay + ry)
        for f in range(q_edges.shape[0]):  # the boxes overlap (vectorised)
            overlap[f] = (q_in[f] & (ex1 >= q_box[f, 0]) & (q_box[f, 1] >= ex0)
                          & (ey1 >= q_box[f, 2]) & (q_box[f, 3] >= ey0))
        for f in range(q_edges.shape[0]):
            if not overlap[f]:
                continue
            bx, by = Q[q_edges[f, 0], 0], Q[q_edges[f, 0], 1]
            sx, sy = Q[q_edges[f, 1], 0] - bx, Q[q_edges[f, 1], 1] - by
            den = rx * sy - ry * sx
            # zero-length paths (coincident end nodes) cross nothing
            if den == 0.0 or abs(den) < min_sin * math.sqrt((rx * rx + ry * ry)
                                                             * (sx * sx + sy * sy)):
                continue
            t = ((bx - ax) * sy - (by - ay) * sx) / den
            u = ((bx - ax) * ry - (by - ay) * rx) / den
            if p_margin[e] < t < 1.0 - p_margin[e] and q_margin[f] < u < 1.0 - q_margin[f]:
                n += 1
    return n


LIKELIHOOD_SIGMAS = (0.07, 0.14, 0.21)
"""Spreads (m, per axis) of the distance between matched nodes that :func:`evidence` scores
the matches' likelihood under: the distance between two copies of a node each off by node noise
σ = 0.05, 0.1 and 0.15 m spreads by σ√2."""


N_FEATURES = 9 + len(LIKELIHOOD_SIGMAS)
"""Columns of :func:`evidence`'s feature vector: closeness, inliers, matched paths, conflicts,
crossings, branches agreeing, branches disagreeing, sum of squared match distances, near
misses, then per spread ``s`` of :data:`LIKELIHOOD_SIGMAS` the log-likelihood ratio of the
match distances: ``Σ log(0.9 p_s(d) / u(d) + 0.1)``, ``p_s`` the distance between two noisy
copies of a node (Rayleigh, scale ``s``), ``u`` a chance match (uniform in the ``eps`` disk),
one match in ten allowed to be chance."""


@njit(cache=True, nogil=True)
def _angle_gap(a, b):
    return abs((a - b + math.pi) % (2.0 * math.pi) - math.pi)


@njit(cache=True, nogil=True)
def evidence(A, a_kind, a_edges, a_margin, a_near, a_branch, B, b_kind, b_edges, b_margin,
             b_branch, theta, tx, ty, eps, compat, loose_kind, branch_tol, min_sin, near_miss,
             match_b, d2_b):
    """The evidence for B moved by ``(theta, tx, ty)`` onto A (see ``MergeEvidence``).

    Fills ``match_b[b]`` (the A node mutually nearest to B node ``b`` among compatible kinds
    within ``eps``, or ``-1``) and ``d2_b`` (squared distance to it) and returns the
    :data:`N_FEATURES` features. A *conflict* is a node of either map (other than
    ``loose_kind``, the dead ends that frontier artefacts make) with no node of the other map
    within ``eps`` but lying within ``eps`` of one of its paths: the other robot went there and
    saw no such place; a *near miss* is such a node between ``eps`` and ``near_miss`` from the
    other map's nearest path (two corridors that close would be one). ``a_near[i, j]``: A nodes
    joined by a path or two. ``a_branch``,
    ``b_branch``: direction of each path leaving each node, NaN padded.
    """
    out = np.zeros(N_FEATURES)
    c, s = math.cos(theta), math.sin(theta)
    X = np.empty_like(B)
    for b in range(B.shape[0]):
        X[b, 0] = c * B[b, 0] - s * B[b, 1] + tx
        X[b, 1] = s * B[b, 0] + c * B[b, 1] + ty
    eps2 = eps * eps
    # a node farther than ``reach`` from the other map's bounding box has no match, conflict or
    # near miss there: skipped (about half the nodes of a half-overlapping pair)
    reach = max(eps, near_miss)
    box_a = np.array(bbox(A))
    box_x = np.array(bbox(X))
    far_b = np.empty(B.shape[0], dtype=np.bool_)
    near_b = np.zeros(B.shape[0], dtype=np.bool_)  # some A node within eps
    nn_b = np.empty(B.shape[0], dtype=np.int64)
    for b in range(B.shape[0]):
        far_b[b] = _far_from_box(X[b, 0], X[b, 1], box_a, reach)
        if far_b[b]:
            nn_b[b], d2_b[b] = -1, eps2
        else:
            nn_b[b], d2_b[b], near_b[b] = _nearest_compatible(
                X[b, 0], X[b, 1], b_kind[b], A, a_kind, False, compat, eps2)
    far_a = np.empty(A.shape[0], dtype=np.bool_)
    near_a = np.zeros(A.shape[0], dtype=np.bool_)
    nn_a = np.empty(A.shape[0], dtype=np.int64)
    for a in range(A.shape[0]):
        far_a[a] = _far_from_box(A[a, 0], A[a, 1], box_x, reach)
        if far_a[a]:
            nn_a[a] = -1
        else:
            nn_a[a], _, near_a[a] = _nearest_compatible(A[a, 0], A[a, 1], a_kind[a], X, b_kind,
                                                        True, compat, eps2)
    a_hit = np.zeros(a_branch.shape[1], dtype=np.bool_)  # a's branches met by one of b
    for b in range(B.shape[0]):
        a = nn_b[b]
        match_b[b] = -1
        if a >= 0 and nn_a[a] == b:
            match_b[b] = a
            out[0] += 1.0 - d2_b[b] / eps2
            out[1] += 1.0
            out[7] += d2_b[b]
            for j in range(len(LIKELIHOOD_SIGMAS)):
                s2 = 2.0 * LIKELIHOOD_SIGMAS[j] ** 2
                out[9 + j] += math.log(0.9 * eps2 / s2 * math.exp(-d2_b[b] / s2) + 0.1)
            a_hit[:] = False
            for i in range(b_branch.shape[1]):  # branches of b against those of a
                if math.isnan(b_branch[b, i]):
                    continue
                hit = False
                for j in range(a_branch.shape[1]):
                    if not math.isnan(a_branch[a, j]) and _angle_gap(
                            a_branch[a, j], b_branch[b, i] + theta) <= branch_tol:
                        hit = True
                        a_hit[j] = True
                out[5 if hit else 6] += 1.0
            for j in range(a_branch.shape[1]):  # branches of a without one of b
                if not math.isnan(a_branch[a, j]) and not a_hit[j]:
                    out[6] += 1.0
    for e in range(b_edges.shape[0]):
        u, v = match_b[b_edges[e, 0]], match_b[b_edges[e, 1]]
        if u >= 0 and v >= 0 and a_near[u, v]:
            out[2] += 1.0
    miss2 = near_miss * near_miss
    limit2 = max(eps2, miss2)  # farther paths make neither a conflict nor a near miss
    hit = np.empty(max(a_edges.shape[0], b_edges.shape[0]), dtype=np.bool_)
    boxes = _segment_boxes(A, a_edges, math.sqrt(limit2))
    for b in range(B.shape[0]):
        if not far_b[b] and b_kind[b] != loose_kind and not near_b[b]:
            d2 = _segment_distance2(X[b, 0], X[b, 1], A, a_edges, limit2, boxes, hit)
            if d2 <= eps2:
                out[3] += 1.0
            elif d2 < miss2:
                out[8] += 1.0
    boxes = _segment_boxes(X, b_edges, math.sqrt(limit2))
    for a in range(A.shape[0]):
        if not far_a[a] and a_kind[a] != loose_kind and not near_a[a]:
            d2 = _segment_distance2(A[a, 0], A[a, 1], X, b_edges, limit2, boxes, hit)
            if d2 <= eps2:
                out[3] += 1.0
            elif d2 < miss2:
                out[8] += 1.0
    out[4] = _crossings(A, a_edges, a_margin, X, b_edges, b_margin, min_sin)
    return out


@njit(cache=True, nogil=True)
def matched_pairs(match_b):
    """``(K, 2)`` pairs ``(match_b[b], b)`` of the B nodes ``b`` with a match (``match_b[b] >= 0``,
    :func:`evidence`), ``b`` ascending: ``np.column_stack`` of ``np.flatnonzero``'s rows."""
    n = 0
    for b in range(match_b.shape[0]):
        n += match_b[b] >= 0
    out = np.empty((n, 2), dtype=np.int64)
    k = 0
    for b in range(match_b.shape[0]):
        if match_b[b] >= 0:
            out[k, 0], out[k, 1] = match_b[b], b
            k += 1
    return out


@njit(cache=True, nogil=True)
def evaluation(A, a_kind, a_edges, a_margin, a_near, a_branch, B, b_kind, b_edges, b_margin,
               b_branch, theta, tx, ty, eps, compat, loose_kind, branch_tol, min_sin, near_miss,
               a_pts, a_w, a_field, a_x0, a_y0, b_pts, b_w, b_field, b_x0, b_y0, inv_cell, tol,
               off, cap):
    """One alignment's evidence in one call (``fusion.structural.evidence.evaluate``): ``(features,
    matches, (path_agree, path_off), moments)`` — :func:`evidence`'s features, its matches
    (:func:`matched_pairs`), :func:`path_agreement` both ways, and the
    :func:`fusion._icp_kernels.spread` of the matched A nodes (zeros with fewer than 3)."""
    match_b = np.empty(B.shape[0], dtype=np.int64)
    d2_b = np.empty(B.shape[0])
    f = evidence(A, a_kind, a_edges, a_margin, a_near, a_branch, B, b_kind, b_edges, b_margin,
                 b_branch, theta, tx, ty, eps, compat, loose_kind, branch_tol, min_sin,
                 near_miss, match_b, d2_b)
    matches = matched_pairs(match_b)
    paths = path_agreement(np.array([theta]), np.array([tx]), np.array([ty]), a_pts, a_w,
                           a_field, a_x0, a_y0, b_pts, b_w, b_field, b_x0, b_y0, inv_cell, tol,
                           off, cap, True)
    moments = (0.0, 0.0, 0.0, 0.0, 0.0)
    if matches.shape[0] >= 3:
        moments = spread(A[matches[:, 0]])
    return f, matches, (paths[0, 0], paths[0, 1]), moments


@njit(cache=True, nogil=True)
def evidence_batch(A, a_kind, a_edges, a_margin, a_near, a_branch, B, b_kind, b_edges,
                   b_margin, b_branch, theta, tx, ty, eps, compat, loose_kind, branch_tol,
                   min_sin, near_miss):
    """:func:`evidence` for every hypothesis: an ``(H, N_FEATURES)`` array."""
    out = np.empty((theta.shape[0], N_FEATURES))
    match_b = np.empty(B.shape[0], dtype=np.int64)
    d2_b = np.empty(B.shape[0])
    for h in range(theta.shape[0]):
        out[h] = evidence(A, a_kind, a_edges, a_margin, a_near, a_branch, B, b_kind, b_edges,
                          b_margin, b_branch, theta[h], tx[h], ty[h], eps, compat, loose_kind,
                          branch_tol, min_sin, near_miss, match_b, d2_b)
    return out


@njit(cache=True, nogil=True)
def _field_cells(c, s, tx, ty, pts, x0, y0, inv_cell, ny, nx, cell):
    """Flat index into a ``(ny, nx)`` raster (cells ``1 / inv_cell`` wide from ``(x0, y0)``)
    of each point of ``pts`` moved by ``p' = R p + t`` (``-1`` outside): branch-free, so
    vectorised (see :func:`_moved_cells`)."""
    for k in range(pts.shape[0]):
        x = c * pts[k, 0] - s * pts[k, 1] + tx
        y = s * pts[k, 0] + c * pts[k, 1] + ty
        ix = int(math.floor((x - x0) * inv_cell))
        iy = int(math.floor((y - y0) * inv_cell))
        inside = (ix >= 0) & (iy >= 0) & (ix < nx) & (iy < ny)
        cell[k] = iy * nx + ix if inside else -1


@njit(cache=True, nogil=True)
def _field_sums(c, s, tx, ty, pts, w, field, x0, y0, inv_cell, tol, off, cap, cell):
    """Moved by ``p' = R p + t``, the path samples ``pts`` (weights ``w``, metres of path each)
    read ``field`` (squared distances, :func:`path_field`): ``(Σ w (1 − d²/tol²) over d < tol,
    Σ w over off <= d < cap)``; ``cell`` (one per sample) is scratch."""
    ny, nx = field.shape
    flat = field.ravel()
    agree = away = 0.0
    tol2, off2, cap2 = tol * tol, off * off, cap * cap
    _field_cells(c, s, tx, ty, pts, x0, y0, inv_cell, ny, nx, cell)
    for k in range(pts.shape[0]):  # without branches (11% faster): a sample adds 0.0 where it
        inside = cell[k] >= 0      # adds nothing, and sums of w >= 0 from +0.0 never meet −0.0
        d2 = flat[max(cell[k], 0)]
        agree += w[k] * (1.0 - d2 / tol2) if inside & (d2 < tol2) else 0.0
        away += w[k] if inside & (d2 >= tol2) & (off2 <= d2) & (d2 < cap2) else 0.0
    return agree, away


@njit(cache=True, nogil=True)
def path_agreement(theta, tx, ty, a_pts, a_w, a_field, a_x0, a_y0, b_pts, b_w, b_field, b_x0,
                   b_y0, inv_cell, tol, off, cap, both):
    """Path evidence of each hypothesis ``(theta, tx, ty)`` (B → A): ``(H, 2)`` — metres of path
    of either map lying on a path of the other (soft, within ``tol``), and metres lying near one
    (``off`` up to ``cap``, the fields' cap) but not on it. B's samples read A's field moved
    forward, A's read B's moved back (:func:`path_field`); without ``both``, B's samples alone
    (twice their sums: the same scale, half the work)."""
    out = np.zeros((theta.shape[0], 2))
    cell = np.empty(max(a_pts.shape[0], b_pts.shape[0]), dtype=np.int64)
    for h in range(theta.shape[0]):
        c, s = math.cos(theta[h]), math.sin(theta[h])
        g1, w1 = _field_sums(c, s, tx[h], ty[h], b_pts, b_w, a_field, a_x0, a_y0, inv_cell, tol,
                             off, cap, cell)
        g2, w2 = g1, w1
        if both:  # the inverse motion: p_B = R^T (p_A - t)
            ix, iy = -(c * tx[h] + s * ty[h]), -(-s * tx[h] + c * ty[h])
            g2, w2 = _field_sums(c, -s, ix, iy, a_pts, a_w, b_field, b_x0, b_y0, inv_cell, tol,
                                 off, cap, cell)
        out[h, 0] = g1 + g2
        out[h, 1] = w1 + w2
    return out
