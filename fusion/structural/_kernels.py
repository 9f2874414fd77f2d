"""Compiled loops of the structural merge (numba, cached on disk); the once-per-merge steps are
numpy in their modules. Each kernel here, and why no numpy/scipy call does it as is:

- :func:`path_field` (:mod:`~fusion.structural.prepare`): each segment's band of raster cells,
  row by row; a dense points × segments distance would cost far more.
- :func:`pair_motions`, :func:`refined_scores`, :func:`select_distinct`, :func:`refine_batch`
  (:mod:`~fusion.structural.hypotheses`): per hypothesis (thousands a merge) a motion, a raster
  lookup with one closed-form refit, a greedy suppression (sequential by nature), a nearest
  compatible node per gate; numpy's ``(H, N_B, N_A)`` forms are slower and sum in another order.
- :func:`paint_nearest`, :func:`paint_segments`: A's raster, the nearest compatible node per cell
  (ties to the earlier node) and the cells near A's paths.
- :func:`evidence`, :func:`evidence_batch`, :func:`path_agreement`
  (:mod:`~fusion.structural.evidence`): per hypothesis, mutual nearest nodes of compatible kinds,
  conflicts, crossings and branches; path samples read off the other map's raster.
- :func:`nearest_on_paths` (:mod:`~fusion.structural.refine`): each path sample's nearest
  segment point within a gate, skipping samples by the raster.

Conventions: a transform is ``(theta, tx, ty)`` with ``p_A = R(theta) p_B + (tx, ty)``;
``compat`` is the node-code compatibility table indexed ``[code_a, code_b]``. Kernels call only
kernels of this module, so numba's per-file cache stays valid.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def bbox(P):
    """``(x0, x1, y0, y1)`` of the points ``P``."""
    x0 = x1 = P[0, 0]
    y0 = y1 = P[0, 1]
    for i in range(1, P.shape[0]):
        x0, x1 = min(x0, P[i, 0]), max(x1, P[i, 0])
        y0, y1 = min(y0, P[i, 1]), max(y1, P[i, 1])
    return x0, x1, y0, y1

@njit(cache=True, nogil=True)
def path_field(seg, x0, y0, cell, ny, nx, reach):
    """``(ny, nx)`` raster (cells ``cell`` wide, cell (0, 0) at ``(x0, y0)``) of the squared
    distance from each cell centre to the nearest segment ``seg[k] = (x1, y1, x2, y2)``, capped
    at ``reach²``.
    Each segment visits only the cells of its bounding box (grown by ``reach``) that lie within
    ``reach`` of its line. A segment's rows are laid out first (their extents and starting
    values do not depend on each other, so their divisions overlap), then walked: the same
    arithmetic as one row after the other, in less time."""
    d2 = np.full((ny, nx), reach * reach, dtype=np.float32)
    row_ix0 = np.empty(ny, dtype=np.int64)  # each row's cells [ix0, ix1), first x and t
    row_ix1 = np.empty(ny, dtype=np.int64)
    row_px = np.empty(ny)
    row_t = np.empty(ny)
    for k in range(seg.shape[0]):
        ux, uy, wx, wy = seg[k, 0], seg[k, 1], seg[k, 2], seg[k, 3]
        vx, vy = wx - ux, wy - uy
        ll = vx * vx + vy * vy
        inv_ll = 0.0 if ll == 0.0 else 1.0 / ll
        band = reach * math.sqrt(ll)  # |cross((p - u), v)| <= band: within reach of the line
        bx0, bx1 = min(ux, wx) - reach, max(ux, wx) + reach
        iy0 = max(0, int(math.floor((min(uy, wy) - reach - y0) / cell)))
        iy1 = min(ny, int(math.ceil((max(uy, wy) + reach - y0) / cell)) + 1)
        for iy in range(iy0, iy1):
            py = y0 + (iy + 0.5) * cell
            lo, hi = bx0, bx1
            if vy != 0.0:  # (x - ux) vy - (py - uy) vx within ±band
                e1 = ux + ((py - uy) * vx - band) / vy
                e2 = ux + ((py - uy) * vx + band) / vy
                lo, hi = max(lo, min(e1, e2)), min(hi, max(e1, e2))
            ix0 = max(0, int(math.floor((lo - x0) / cell - 0.5)))
            ix1 = min(nx, int(math.ceil((hi - x0) / cell - 0.5)) + 1)
            if vy == 0.0 and abs(py - uy) > reach:  # a horizontal segment's far rows: none
                ix1 = ix0
            px = x0 + (ix0 + 0.5) * cell
            row_ix0[iy], row_ix1[iy], row_px[iy] = ix0, ix1, px
            row_t[iy] = ((px - ux) * vx + (py - uy) * vy) * inv_ll
        # along a row, the projection t and the offsets change linearly with x
        dt = cell * vx * inv_ll
        for iy in range(iy0, iy1):
            py = y0 + (iy + 0.5) * cell
            px, t = row_px[iy], row_t[iy]
            for ix in range(row_ix0[iy], row_ix1[iy]):
                tc = min(1.0, max(0.0, t))
                dx, dy = ux + tc * vx - px, uy + tc * vy - py
                dd = dx * dx + dy * dy
                if dd < d2[iy, ix]:
                    d2[iy, ix] = dd
                px += cell
                t += dt
    return d2

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
    # near miss there: skipped
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
    for k in range(pts.shape[0]):  # without branches: a sample adds 0.0 where it adds
        inside = cell[k] >= 0      # nothing, and sums of w >= 0 from +0.0 never meet −0.0
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

@njit(cache=True, nogil=True)
def pair_motions(A, a_i, a_j, B, b_i, b_j, pairs_p, pairs_q):
    """The rigid motion putting B pair ``pairs_q[k]`` onto A pair ``pairs_p[k]`` (ends on ends,
    midpoint on midpoint): ``(theta, tx, ty, cos theta, sin theta)`` arrays."""
    n = pairs_p.shape[0]
    theta = np.empty(n)
    tx = np.empty(n)
    ty = np.empty(n)
    cos_t = np.empty(n)
    sin_t = np.empty(n)
    ang_a = np.empty(a_i.shape[0])  # each pair's direction once (pairs recur in hypotheses)
    for p in range(a_i.shape[0]):
        ang_a[p] = math.atan2(A[a_j[p], 1] - A[a_i[p], 1], A[a_j[p], 0] - A[a_i[p], 0])
    ang_b = np.empty(b_i.shape[0])
    for q in range(b_i.shape[0]):
        ang_b[q] = math.atan2(B[b_j[q], 1] - B[b_i[q], 1], B[b_j[q], 0] - B[b_i[q], 0])
    for k in range(n):
        ai, aj = a_i[pairs_p[k]], a_j[pairs_p[k]]
        bi, bj = b_i[pairs_q[k]], b_j[pairs_q[k]]
        ang = ang_a[pairs_p[k]] - ang_b[pairs_q[k]]
        c, s = math.cos(ang), math.sin(ang)
        mxb = 0.5 * (B[bi, 0] + B[bj, 0])
        myb = 0.5 * (B[bi, 1] + B[bj, 1])
        theta[k] = ang
        tx[k] = 0.5 * (A[ai, 0] + A[aj, 0]) - (c * mxb - s * myb)
        ty[k] = 0.5 * (A[ai, 1] + A[aj, 1]) - (s * mxb + c * myb)
        cos_t[k], sin_t[k] = c, s
    return theta, tx, ty, cos_t, sin_t

NEAR_ANY_NODE = 3
"""Bit of a :func:`refined_scores` raster cell: within the coarse tolerance of an A node."""

ON_PATH = 4
"""Bit of a :func:`refined_scores` raster cell: on one of A's paths."""

@njit(cache=True, nogil=True)
def _disk_cells(px, py, x0, y0, cell, radius, ny, nx):
    """Cells ``grid[iy, ix]`` (``cell`` wide, cell (0, 0) at ``(x0, y0)``) whose centre may lie
    within ``radius + cell / 2`` of ``(px, py)``: ``(iy0, iy1, ix0, ix1)``, end exclusive."""
    r = int(math.ceil(radius / cell))
    cx = int(math.floor((px - x0) / cell))
    cy = int(math.floor((py - y0) / cell))
    return max(0, cy - r), min(ny, cy + r + 1), max(0, cx - r), min(nx, cx + r + 1)

@njit(cache=True, nogil=True)
def _cell_d2(ix, iy, px, py, x0, y0, cell):
    """Squared distance from the centre of cell ``(ix, iy)`` to ``(px, py)``."""
    dx = x0 + (ix + 0.5) * cell - px
    dy = y0 + (iy + 0.5) * cell - py
    return dx * dx + dy * dy

@njit(cache=True, nogil=True)
def paint_disk(grid, x0, y0, cell, px, py, radius, bit):
    """OR ``bit`` into every cell of ``grid[iy, ix]`` (cells ``cell`` wide, cell (0, 0) at
    ``(x0, y0)``) whose centre is within ``radius + cell / 2`` of ``(px, py)``."""
    reach2 = (radius + 0.5 * cell) ** 2
    iy0, iy1, ix0, ix1 = _disk_cells(px, py, x0, y0, cell, radius, grid.shape[0], grid.shape[1])
    for iy in range(iy0, iy1):
        for ix in range(ix0, ix1):
            if _cell_d2(ix, iy, px, py, x0, y0, cell) <= reach2:
                grid[iy, ix] |= bit

@njit(cache=True, nogil=True)
def paint_segments(grid, x0, y0, cell, P, edges, radius, bit):
    """OR ``bit`` into the cells within ~``radius`` of each segment ``P[u]``–``P[v]``
    (disks painted every half cell along it)."""
    for e in range(edges.shape[0]):
        ux, uy = P[edges[e, 0], 0], P[edges[e, 0], 1]
        vx, vy = P[edges[e, 1], 0], P[edges[e, 1], 1]
        steps = max(1, int(math.ceil(math.hypot(vx - ux, vy - uy) / (0.5 * cell))))
        for k in range(steps + 1):
            f = k / steps
            paint_disk(grid, x0, y0, cell, ux + f * (vx - ux), uy + f * (vy - uy), radius, bit)

@njit(cache=True, nogil=True)
def paint_nearest(table, x0, y0, cell, points, p_kind, radius, compat):
    """For each B kind ``k`` and cell, ``table[iy, ix, k]`` becomes the index of the point of a
    kind compatible with ``k`` (``compat[p_kind, k]``) nearest to the cell centre within
    ``radius + cell / 2`` (cells holding ``-1`` where none stay so), and the cells within that
    reach of any point get bit :data:`NEAR_ANY_NODE` in ``table[iy, ix, -1]``. The distance
    of a cell's current point is computed again when another point competes for the cell."""
    ny, nx = table.shape[0], table.shape[1]
    reach2 = (radius + 0.5 * cell) ** 2
    for p in range(points.shape[0]):
        px, py = points[p, 0], points[p, 1]
        iy0, iy1, ix0, ix1 = _disk_cells(px, py, x0, y0, cell, radius, ny, nx)
        for iy in range(iy0, iy1):
            for ix in range(ix0, ix1):
                d2 = _cell_d2(ix, iy, px, py, x0, y0, cell)
                if d2 > reach2:
                    continue
                table[iy, ix, -1] |= 1 << NEAR_ANY_NODE
                for k in range(compat.shape[1]):
                    if not compat[p_kind[p], k]:
                        continue
                    q = table[iy, ix, k]
                    if q < 0 or d2 < _cell_d2(ix, iy, points[q, 0], points[q, 1], x0, y0, cell):
                        table[iy, ix, k] = p

@njit(cache=True, nogil=True)
def _moved_cells(c, s, ox, oy, bx, by, x_hi, y_hi, inv_cell, nx, depth, mx, my, cell):
    """The points ``(bx, by)`` moved by ``(c, s, ox, oy)`` into raster coordinates (``mx``,
    ``my``) and the flat index of their raster cell's first entry (``-1`` outside): a loop
    without branches or reductions, which the compiler vectorises (unlike the move inside the
    scoring loop)."""
    for b in range(bx.shape[0]):
        x = c * bx[b] - s * by[b] + ox
        y = s * bx[b] + c * by[b] + oy
        mx[b], my[b] = x, y
        inside = (0.0 <= x) & (x < x_hi) & (0.0 <= y) & (y < y_hi)
        cell[b] = (int(y * inv_cell) * nx + int(x * inv_cell)) * depth if inside else -1

@njit(cache=True, nogil=True)
def refined_scores(theta, tx, ty, cos_t, sin_t, A, B, b_kind, table, x0, y0, inv_cell, tol,
                   loose_kind, min_pairs, landed):
    """Score each hypothesis after one closed-form fit step, updating it in place (``cos_t``,
    ``sin_t``: the cosine and sine of ``theta``, as :func:`pair_motions` gives them).

    ``table[iy, ix]`` is a cell of A's raster: entries ``0..2``, the A node of a kind compatible
    with B kind ``0..2`` nearest to the cell (``-1`` if none, :func:`paint_nearest`); the last,
    bits :data:`NEAR_ANY_NODE` and :data:`ON_PATH`. Each moved B node is paired with its cell's
    nearest compatible A node; with at least ``min_pairs`` pairs (else the hypothesis is left
    as is and scored 0: it cannot gather enough matches to be accepted) the motion is refitted
    to them, then scored: ``Σ max(0, 1 − d²/tol²)`` over B nodes at distance ``d`` from their
    cell's nearest compatible A node, −1 per B node (not of ``loose_kind``) with none, landing
    on an A path far from any A node (A went there and saw no such place). A soft, refitted
    count: the right hypothesis of a pair sharing few nodes lands them tightly, chance
    alignments of corridor lattices land more nodes loosely. ``landed[h]`` becomes the number of
    B nodes hypothesis ``h`` paired before its refit.
    """
    n_h = theta.shape[0]
    n_b = B.shape[0]
    ny, nx, depth = table.shape
    flat = table.ravel()
    x_hi, y_hi = nx / inv_cell, ny / inv_cell
    tol2 = tol * tol
    bx, by = B[:, 0].copy(), B[:, 1].copy()
    ax, ay = A[:, 0].copy(), A[:, 1].copy()
    mx, my = np.empty(n_b), np.empty(n_b)
    cell = np.empty(n_b, dtype=np.int64)
    pair_b = np.empty(n_b, dtype=np.int64)
    pair_a = np.empty(n_b, dtype=np.int64)
    out = np.zeros(n_h)
    for h in range(n_h):
        c, s = cos_t[h], sin_t[h]
        _moved_cells(c, s, tx[h] - x0, ty[h] - y0, bx, by, x_hi, y_hi, inv_cell, nx, depth, mx,
                     my, cell)
        n = 0
        for b in range(n_b):  # the pairs listed without branches, then summed in order
            a = flat[max(cell[b], 0) + b_kind[b]]
            pair_b[n], pair_a[n] = b, a
            n += (cell[b] >= 0) & (a >= 0)
        spx = spy = sqx = sqy = sc = ss = 0.0
        for m in range(n):
            b, a = pair_b[m], pair_a[m]
            spx += bx[b]
            spy += by[b]
            sqx += ax[a]
            sqy += ay[a]
            sc += bx[b] * ax[a] + by[b] * ay[a]
            ss += bx[b] * ay[a] - by[b] * ax[a]
        landed[h] = n
        if n < min_pairs:
            continue  # scored 0, not refitted
        # centred cross sums from the raw ones
        sc -= (spx * sqx + spy * sqy) / n
        ss -= (spx * sqy - spy * sqx) / n
        ang = math.atan2(ss, sc)
        c, s = math.cos(ang), math.sin(ang)
        theta[h] = ang
        tx[h] = (sqx - (c * spx - s * spy)) / n
        ty[h] = (sqy - (s * spx + c * spy)) / n
        _moved_cells(c, s, tx[h] - x0, ty[h] - y0, bx, by, x_hi, y_hi, inv_cell, nx, depth, mx,
                     my, cell)
        score = 0.0
        for b in range(n_b):
            if cell[b] < 0:
                continue
            a = flat[cell[b] + b_kind[b]]
            if a >= 0:
                d2 = (mx[b] + x0 - ax[a]) ** 2 + (my[b] + y0 - ay[a]) ** 2
                if d2 < tol2:
                    score += 1.0 - d2 / tol2
            elif b_kind[b] != loose_kind:
                bits = flat[cell[b] + depth - 1]
                if not (bits >> NEAR_ANY_NODE) & 1 and (bits >> ON_PATH) & 1:
                    score -= 1.0
        out[h] = score
    return out

@njit(cache=True, nogil=True)
def select_distinct(order, theta, cx, cy, min_angle, min_dist, k):
    """Greedy non-maximum suppression: walk ``order`` (best first) and keep up to ``k``
    hypotheses whose angle differs by ``>= min_angle`` or whose image of B's centroid
    ``(cx, cy)`` is ``>= min_dist`` away from every hypothesis kept before."""
    kept = np.empty(k, dtype=np.int64)
    n = 0
    min_dist2 = min_dist * min_dist
    for h in order:
        ok = True
        for m in range(n):
            g = kept[m]
            dx, dy = cx[h] - cx[g], cy[h] - cy[g]
            if dx * dx + dy * dy >= min_dist2:  # the cheap test first
                continue
            if abs((theta[h] - theta[g] + math.pi) % (2 * math.pi) - math.pi) < min_angle:
                ok = False
                break
        if ok:
            kept[n] = h
            n += 1
            if n == k:
                break
    return kept[:n]

@njit(cache=True, nogil=True)
def refine_batch(theta, tx, ty, A, a_kind, B, b_kind, compat, gates):
    """Refine each hypothesis in place: per gate in ``gates``, pair every B node with its nearest
    compatible A node within the gate and refit the rigid motion to those pairs (closed-form 2-D
    SVD step). A hypothesis with fewer than 2 pairs keeps its motion. Returns the number of pairs
    each hypothesis had at the last gate."""
    counts = np.zeros(theta.shape[0], dtype=np.int64)
    for h in range(theta.shape[0]):
        for g in range(gates.shape[0]):
            gate2 = gates[g] * gates[g]
            c, s = math.cos(theta[h]), math.sin(theta[h])
            n = 0
            spx = spy = sqx = sqy = 0.0
            pairs_b = np.empty(B.shape[0], dtype=np.int64)
            pairs_a = np.empty(B.shape[0], dtype=np.int64)
            for b in range(B.shape[0]):
                x = c * B[b, 0] - s * B[b, 1] + tx[h]
                y = s * B[b, 0] + c * B[b, 1] + ty[h]
                best = gate2
                arg = -1
                for a in range(A.shape[0]):
                    if not compat[a_kind[a], b_kind[b]]:
                        continue
                    dd = (x - A[a, 0]) ** 2 + (y - A[a, 1]) ** 2
                    if dd <= best:
                        best = dd
                        arg = a
                if arg >= 0:
                    pairs_b[n] = b
                    pairs_a[n] = arg
                    spx += B[b, 0]
                    spy += B[b, 1]
                    sqx += A[arg, 0]
                    sqy += A[arg, 1]
                    n += 1
            counts[h] = n
            if n < 2:
                continue
            spx /= n
            spy /= n
            sqx /= n
            sqy /= n
            sc = ss = 0.0
            for m in range(n):
                px = B[pairs_b[m], 0] - spx
                py = B[pairs_b[m], 1] - spy
                qx = A[pairs_a[m], 0] - sqx
                qy = A[pairs_a[m], 1] - sqy
                sc += px * qx + py * qy
                ss += px * qy - py * qx
            ang = math.atan2(ss, sc)
            c, s = math.cos(ang), math.sin(ang)
            theta[h] = ang
            tx[h] = sqx - (c * spx - s * spy)
            ty[h] = sqy - (s * spx + c * spy)
    return counts
