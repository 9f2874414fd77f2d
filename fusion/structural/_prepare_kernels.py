"""Compiled preparation of one map for a merge (numba, cached on disk after the first call):
node pairs for the 2-point hypotheses, path chords and sample points, the distance-to-path
raster, and the paths leaving each node (:func:`fusion.structural.prepare.prepare_pair`)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def node_pairs(xy, edges, knn, min_dist):
    """The node pairs 2-point consensus uses, and which nodes are near in the graph.

    Returns ``(near, i, j, length)``: ``near[a, b]`` when ``a`` and ``b`` are joined by a path or
    by two; pairs ``i < j`` that are near or among each other's ``knn`` nearest nodes, at least
    ``min_dist`` apart, and their distances.
    """
    n = xy.shape[0]
    adj = np.zeros((n, n), dtype=np.bool_)
    for e in range(edges.shape[0]):
        adj[edges[e, 0], edges[e, 1]] = True
        adj[edges[e, 1], edges[e, 0]] = True
    near = adj.copy()
    degree = np.zeros(n, dtype=np.int64)
    for e in range(edges.shape[0]):
        degree[edges[e, 0]] += 1
        degree[edges[e, 1]] += 1
    start = np.zeros(n + 1, dtype=np.int64)
    for k in range(n):
        start[k + 1] = start[k] + degree[k]
    nbr = np.empty(start[n], dtype=np.int64)
    fill = start[:n].copy()
    for e in range(edges.shape[0]):
        u, v = edges[e, 0], edges[e, 1]
        nbr[fill[u]] = v
        fill[u] += 1
        nbr[fill[v]] = u
        fill[v] += 1
    for k in range(n):  # two paths through k
        for p in range(start[k], start[k + 1]):
            for q in range(start[k], start[k + 1]):
                near[nbr[p], nbr[q]] = True
    for a in range(n):
        near[a, a] = False
    dist = np.zeros((n, n))
    for a in range(n):  # hypot(-u, -v) == hypot(u, v): each pair once
        for b in range(a + 1, n):
            dist[a, b] = dist[b, a] = math.hypot(xy[a, 0] - xy[b, 0], xy[a, 1] - xy[b, 1])
    cand = near.copy()
    k = min(knn, n - 1)
    taken = np.zeros(n, dtype=np.bool_)
    for a in range(n):  # the k nearest by k selection passes (k is small)
        taken[:] = False
        taken[a] = True
        for _ in range(k):
            best, arg = np.inf, -1
            for b in range(n):
                if not taken[b] and dist[a, b] < best:
                    best, arg = dist[a, b], b
            taken[arg] = True
            cand[a, arg] = True
            cand[arg, a] = True
    count = 0
    for a in range(n):
        for b in range(a + 1, n):
            if cand[a, b] and dist[a, b] >= min_dist:
                count += 1
    pi = np.empty(count, dtype=np.int64)
    pj = np.empty(count, dtype=np.int64)
    plen = np.empty(count)
    c = 0
    for a in range(n):
        for b in range(a + 1, n):
            if cand[a, b] and dist[a, b] >= min_dist:
                pi[c], pj[c], plen[c] = a, b, dist[a, b]
                c += 1
    return near, pi, pj, plen


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
    values do not depend on each other, so their divisions overlap), then walked: 40% faster
    than one row after the other, the same arithmetic."""
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
def map_numbers(xy, edges, ends, eps, pad, pad2):
    """What :func:`fusion.structural.prepare.prepare_pair` needs besides the kernels' outputs: each
    path's ``margin`` (``min(0.5, eps / length)``, its length as ``np.linalg.norm`` computes
    it) and the box ``(x0, y0, x1, y1)`` of the nodes and the points ``ends``, grown by ``pad``
    and then by ``pad2`` (two roundings, as numpy's ``lo - pad - pad2``)."""
    margin = np.empty(edges.shape[0])
    for e in range(edges.shape[0]):
        dx = xy[edges[e, 0], 0] - xy[edges[e, 1], 0]
        dy = xy[edges[e, 0], 1] - xy[edges[e, 1], 1]
        margin[e] = min(0.5, eps / max(math.sqrt(dx * dx + dy * dy), 1e-12))
    x0, x1, y0, y1 = bbox(xy)
    if ends.shape[0]:
        ex0, ex1, ey0, ey1 = bbox(ends)
        x0, x1, y0, y1 = min(x0, ex0), max(x1, ex1), min(y0, ey0), max(y1, ey1)
    return margin, x0 - pad - pad2, y0 - pad - pad2, x1 + pad + pad2, y1 + pad + pad2


@njit(cache=True, nogil=True)
def map_fields(xy, edges, pieces, knn, min_dist, step, eps, reach, cell):
    """Everything ``fusion.structural.prepare.prepare_pair`` computes of a map in compiled code, in
    one
    call:
    :func:`node_pairs` (``near, i, j, length``; then the pairs in both orientations sorted
    by length, stably, as :func:`pair_candidates` reads B's), :func:`path_samples` of the
    path pieces ``pieces`` (``pts, w``), :func:`map_numbers`' ``margin`` and the raster's origin
    ``(x0, y0)``, the :func:`path_field` raster (``ceil(extent / cell) + 1`` cells a side, as
    ``math.ceil``) and :func:`branch_slots` (``node, slot, d, degree``)."""
    near, i, j, length = node_pairs(xy, edges, knn, min_dist)
    pts, w = path_samples(pieces, step)
    margin, x0, y0, x1, y1 = map_numbers(xy, edges, pieces.reshape(-1, 2), eps, reach, cell)
    nx = math.ceil((x1 - x0) / cell) + 1
    ny = math.ceil((y1 - y0) / cell) + 1
    field = path_field(pieces, x0, y0, cell, ny, nx, reach)
    node, slot, d, degree = branch_slots(xy, edges, xy.shape[0])
    # both orientations of the pairs, by length (stable): what a merge reads of its map B
    both_i = np.concatenate((i, j))
    both_j = np.concatenate((j, i))
    both_len = np.concatenate((length, length))
    order = np.argsort(both_len, kind="mergesort")
    return (near, i, j, length, both_i[order], both_j[order], both_len[order], pts, w, margin,
            x0, y0, field, node, slot, d, degree)


@njit(cache=True, nogil=True)
def branch_slots(xy, edges, n):
    """The paths leaving each of the ``n`` nodes, in order of node (stable): ``(node, slot, d)``
    — the node, its path's place among its node's, and the vector to the path's other end
    (``(2E, 2)``, for ``np.arctan2``) — and the largest degree."""
    m = 2 * edges.shape[0]
    ends = np.empty((m, 2), dtype=np.int64)
    ends[: edges.shape[0]] = edges
    ends[edges.shape[0]:, 0] = edges[:, 1]
    ends[edges.shape[0]:, 1] = edges[:, 0]
    order = np.argsort(ends[:, 0], kind="mergesort")
    degree = np.zeros(n, dtype=np.int64)
    node = np.empty(m, dtype=np.int64)
    slot = np.empty(m, dtype=np.int64)
    d = np.empty((m, 2))
    for k in range(m):
        u, v = ends[order[k], 0], ends[order[k], 1]
        node[k] = u
        slot[k] = degree[u]
        degree[u] += 1
        d[k, 0] = xy[v, 0] - xy[u, 0]
        d[k, 1] = xy[v, 1] - xy[u, 1]
    return node, slot, d, degree.max() if n else 0


@njit(cache=True, nogil=True)
def polyline_chords(pts, sizes, chord):
    """``(S, 4)`` chords ``(x1, y1, x2, y2)`` of the polylines stacked in ``pts`` (``sizes[k]``
    points each): the first and last point of each, and the first point past each multiple of
    ``chord`` of arc length along it, joined in order (``math.hypot`` is the C library's, as
    ``np.hypot``; the arc length sums in order, as ``np.cumsum``)."""
    n = pts.shape[0]
    arc = np.empty(n)
    run = 0.0
    i = 0
    for k in range(sizes.shape[0]):  # the running sum over every point, no step between lines
        for m in range(sizes[k]):
            if m:
                run += math.hypot(pts[i, 0] - pts[i - 1, 0], pts[i, 1] - pts[i - 1, 1])
            else:
                run += 0.0
            arc[i] = run
            i += 1
    keep = np.zeros(n, dtype=np.bool_)
    count = 0
    i = 0
    for k in range(sizes.shape[0]):
        start = arc[i]
        prev = 0.0
        for m in range(sizes[k]):
            bucket = math.floor((arc[i] - start) / chord)
            keep[i] = m == 0 or m == sizes[k] - 1 or bucket != prev
            prev = bucket
            count += keep[i] and m > 0
            i += 1
    out = np.empty((count, 4))
    c = 0
    i = 0
    for k in range(sizes.shape[0]):
        last = -1
        for _ in range(sizes[k]):
            if keep[i]:
                if last >= 0:
                    out[c, 0], out[c, 1] = pts[last, 0], pts[last, 1]
                    out[c, 2], out[c, 3] = pts[i, 0], pts[i, 1]
                    c += 1
                last = i
            i += 1
    return out


@njit(cache=True, nogil=True)
def path_samples(seg, step):
    """Points along the segments ``seg[k] = (x1, y1, x2, y2)``: each cut into
    ``max(1, ceil(length / step))`` equal pieces, a point at each piece's middle. Returns
    ``(points (S, 2), metres of path each stands for (S,))``."""
    count = np.empty(seg.shape[0], dtype=np.int64)
    for k in range(seg.shape[0]):
        length = math.hypot(seg[k, 2] - seg[k, 0], seg[k, 3] - seg[k, 1])
        count[k] = max(1, int(math.ceil(length / step)))
    pts = np.empty((count.sum(), 2))
    w = np.empty(count.sum())
    i = 0
    for k in range(seg.shape[0]):
        length = math.hypot(seg[k, 2] - seg[k, 0], seg[k, 3] - seg[k, 1])
        for m in range(count[k]):
            f = (m + 0.5) / count[k]
            pts[i, 0] = seg[k, 0] + f * (seg[k, 2] - seg[k, 0])
            pts[i, 1] = seg[k, 1] + f * (seg[k, 3] - seg[k, 1])
            w[i] = length / count[k]
            i += 1
    return pts, w
