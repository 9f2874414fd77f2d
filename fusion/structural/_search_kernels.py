"""Compiled loops of ``"auto"``'s search (numba, cached on disk after the first call): 2-point
hypotheses, the raster of A and the refitted coarse score, distinct-candidate selection and
batched refinement (:mod:`fusion.structural.hypotheses`).

A merge of two 60-node maps tries thousands of rigid hypotheses; numpy's per-call overhead and
``(H, N_B, N_A)`` temporaries would cost more than the arithmetic, so these are loops.
Conventions: a transform is ``(theta, tx, ty)`` with ``p_A = R(theta) p_B + (tx, ty)``;
``compat`` is the node-code compatibility table indexed ``[code_a, code_b]``.

Calls :func:`fusion.structural._prepare_kernels.bbox`, a kernel of another file: after editing that
file, delete the numba caches (CONTRIBUTING).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from fusion.structural._prepare_kernels import bbox


@njit(cache=True, nogil=True)
def pair_candidates(a_kind, a_i, a_j, a_len, b_kind, b_i, b_j, b_len, tol, compat):
    """2-point consensus: every (A pair ``p``, B pair ``q``) whose lengths agree within ``tol``
    and whose end kinds are compatible, in the order ``p``, then ``q``.

    ``b_len`` must be sorted ascending and the B pairs listed in both orientations. Returns
    ``(p, q, weight)`` arrays; ``weight`` is the shorter pair length (longer pairs fix the angle
    better). :func:`pair_motions` gives the motions of the ones kept.
    """
    lo = np.searchsorted(b_len, a_len - tol)
    hi = np.searchsorted(b_len, a_len + tol, side="right")
    n_max = 0  # pairs of matching lengths: room for every compatible one
    for p in range(a_i.shape[0]):
        n_max += hi[p] - lo[p]
    out_p = np.empty(n_max, dtype=np.int64)
    out_q = np.empty(n_max, dtype=np.int64)
    weight = np.empty(n_max)
    k = 0
    for p in range(a_i.shape[0]):
        for q in range(lo[p], hi[p]):
            if compat[a_kind[a_i[p]], b_kind[b_i[q]]] and compat[a_kind[a_j[p]], b_kind[b_j[q]]]:
                out_p[k], out_q[k] = p, q
                weight[k] = min(a_len[p], b_len[q])
                k += 1
    return out_p[:k], out_q[:k], weight[:k]


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
def hit_table(points, p_kind, edges, tol, path_tol, compat, like):
    """The raster of ``fusion.structural.hypotheses.hit_grid`` (cells ``tol / 2`` wide, entries of
    ``like``'s dtype): ``(table, x0, y0, 1 / cell)``, ``table[iy, ix, :-1]`` painted by
    :func:`paint_nearest` (``-1`` elsewhere) and ``table[iy, ix, -1]`` its bits and
    :data:`ON_PATH` within ~``path_tol`` of the paths ``edges`` (:func:`paint_segments`). The
    extent as numpy computed it: ``lo = min − tol − cell``, ``ceil((max − lo + tol) / cell) + 2``
    cells."""
    cell = tol / 2.0
    x0, x1, y0, y1 = bbox(points)
    x0, y0 = x0 - tol - cell, y0 - tol - cell
    nx = int(math.ceil((x1 - x0 + tol) / cell) + 2)
    ny = int(math.ceil((y1 - y0 + tol) / cell) + 2)
    table = np.full((ny, nx, compat.shape[1] + 1), -1, dtype=like.dtype)
    table[:, :, -1] = 0
    paint_nearest(table, x0, y0, cell, points, p_kind, tol, compat)
    paint_segments(table[:, :, -1], x0, y0, cell, points, edges, path_tol, 1 << ON_PATH)
    return table, x0, y0, 1.0 / cell


@njit(cache=True, nogil=True)
def _moved_cells(c, s, ox, oy, bx, by, x_hi, y_hi, inv_cell, nx, depth, mx, my, cell):
    """The points ``(bx, by)`` moved by ``(c, s, ox, oy)`` into raster coordinates (``mx``,
    ``my``) and the flat index of their raster cell's first entry (``-1`` outside): a loop
    without branches or reductions, which the compiler vectorises (scoring a third faster
    than with the move inside the scoring loop)."""
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
        for b in range(n_b):  # the pairs listed without branches (20% faster than branching
            a = flat[max(cell[b], 0) + b_kind[b]]  # on each node), then summed in order
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
def centroid_image(cos_t, sin_t, tx, ty, px, py):
    """``(cx, cy)``: the point ``(px, py)`` moved by each motion ``(cos_t, sin_t, tx, ty)``
    (``c px − s py + tx``, ``s px + c py + ty``, evaluated as numpy does it elementwise)."""
    cx = np.empty(cos_t.shape[0])
    cy = np.empty(cos_t.shape[0])
    for h in range(cos_t.shape[0]):
        cx[h] = cos_t[h] * px - sin_t[h] * py + tx[h]
        cy[h] = sin_t[h] * px + cos_t[h] * py + ty[h]
    return cx, cy


@njit(cache=True, nogil=True)
def coarse_ranking(coarse, landed, min_pairs, sparse_min):
    """``(ranked, sparse)``: the hypotheses by coarse score, best first, those landing fewer
    than ``min_pairs`` B nodes ranked as scoring 0 (``np.argsort(np.where(few, 0.0, -coarse),
    kind="stable")``); and those few landing them tightly (``coarse > sparse_min × landed``),
    best first (stable). Stable sorts, so the same orders as numpy's."""
    n_h = coarse.shape[0]
    key = np.empty(n_h)
    n_sparse = n_neg = n_zero = 0
    for h in range(n_h):
        few = landed[h] < min_pairs
        key[h] = 0.0 if few else -coarse[h]
        n_sparse += few and coarse[h] > sparse_min * landed[h]
        n_neg += key[h] < 0.0
        n_zero += key[h] == 0.0
    sparse = np.empty(n_sparse, dtype=np.int64)
    k = 0
    for h in range(n_h):
        if landed[h] < min_pairs and coarse[h] > sparse_min * landed[h]:
            sparse[k] = h
            k += 1
    sparse = sparse[np.argsort(-coarse[sparse], kind="mergesort")]
    # the stable order by key: the negative keys sorted, the zeros (most hypotheses) in index
    # order as a stable sort leaves them, the positive keys sorted (two small sorts, not one)
    neg = np.empty(n_neg, dtype=np.int64)
    pos = np.empty(n_h - n_neg - n_zero, dtype=np.int64)
    ranked = np.empty(n_h, dtype=np.int64)
    i_neg = i_zero = i_pos = 0
    for h in range(n_h):
        if key[h] < 0.0:
            neg[i_neg] = h
            i_neg += 1
        elif key[h] == 0.0:
            ranked[n_neg + i_zero] = h
            i_zero += 1
        else:
            pos[i_pos] = h
            i_pos += 1
    ranked[:n_neg] = neg[np.argsort(key[neg], kind="mergesort")]
    ranked[n_neg + n_zero:] = pos[np.argsort(key[pos], kind="mergesort")]
    return ranked, sparse


@njit(cache=True, nogil=True)
def best_by_gain(chosen, coarse, path_score, scale, k):
    """The ``k`` of the hypotheses ``chosen`` with the highest ``coarse + path_score / scale``
    (``path_score`` one per chosen), best first (a stable sort: numpy's order)."""
    gain = np.empty(chosen.shape[0])
    for m in range(chosen.shape[0]):
        gain[m] = -(coarse[chosen[m]] + path_score[m] / scale)
    return chosen[np.argsort(gain, kind="mergesort")[:k]]


@njit(cache=True, nogil=True)
def best_distinct_score(scores, gap, cx, cy, px, py, min_angle, min_dist):
    """The best of ``scores`` whose alignment is distinct from one at ``(px, py)``: an angle
    ``gap`` of at least ``min_angle``, or an image ``(cx, cy)`` at least ``min_dist`` from it
    (``math.hypot`` is the C library's, as ``np.hypot``); ``-inf`` if none is."""
    best = -np.inf
    for h in range(scores.shape[0]):
        if gap[h] >= min_angle or math.hypot(cx[h] - px, cy[h] - py) >= min_dist:
            best = max(best, scores[h])
    return best


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


@njit(cache=True, nogil=True)
def refine_most_matched(theta, tx, ty, chosen, A, a_kind, B, b_kind, compat, gates, keep):
    """:func:`refine_batch` of the hypotheses ``chosen`` (copies), then the ``keep`` of them
    with the most pairs at the last gate (ties to the earlier in ``chosen``; a stable sort),
    in the order of ``chosen``: ``(theta, tx, ty)`` arrays."""
    th, txc, tyc = theta[chosen], tx[chosen], ty[chosen]
    counts = refine_batch(th, txc, tyc, A, a_kind, B, b_kind, compat, gates)
    best = np.sort(np.argsort(-counts, kind="mergesort")[:keep])
    return th[best], txc[best], tyc[best]
