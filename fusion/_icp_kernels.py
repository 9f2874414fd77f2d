"""Compiled inner loops of :func:`fusion.icp_svd` (numba, cached on disk after the first call).

At the paper's sizes (tens of points) numpy's per-call overhead (some 30 calls an iteration)
costs more than the arithmetic, so the nearest-neighbour pass and the closed-form
Step 2 fit each run as one compiled call.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _block_sum(a, lo, n):
    """numpy's pairwise summation of a block ``a[lo:lo + n]``, ``n <= 128``: a plain loop under
    8 items, else 8 running sums combined as a tree, then the remainder."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r = a[lo: lo + 8].copy()
    i = 8
    stop = n - n % 8
    while i < stop:
        for j in range(8):
            r[j] += a[lo + i + j]
        i += 8
    res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@njit(cache=True, nogil=True)
def _pairwise_sum(a, n):
    """numpy's ``add.reduce`` of a contiguous float64 ``a[:n]``: blocks of up to 128 summed by
    :func:`_block_sum`, longer runs split in halves (a multiple of 8 first) and the halves'
    sums added. numpy recurses; this walks the same tree with an explicit stack (numba's disk
    cache does not support recursion)."""
    if n <= 128:
        return _block_sum(a, 0, n)
    los = np.empty(64, dtype=np.int64)
    ns = np.empty(64, dtype=np.int64)
    stage = np.zeros(64, dtype=np.int64)
    left = np.empty(64, dtype=np.float64)
    sp = 0
    los[0], ns[0] = 0, n
    ret = 0.0
    while sp >= 0:
        lo, m = los[sp], ns[sp]
        half = m // 2
        half -= half % 8
        if m <= 128:
            ret = _block_sum(a, lo, m)
            sp -= 1
        elif stage[sp] == 0:  # first the left half
            stage[sp] = 1
            sp += 1
            los[sp], ns[sp], stage[sp] = lo, half, 0
        elif stage[sp] == 1:  # left done (in ret): now the right half
            left[sp] = ret
            stage[sp] = 2
            sp += 1
            los[sp], ns[sp], stage[sp] = lo + half, m - half, 0
        else:
            ret = left[sp] + ret
            sp -= 1
    return ret


@njit(cache=True, nogil=True)
def match_brute(D, M, theta, tx, ty, max_d2, prev_idx, prev_keep, idx, d2, keep):
    """Move ``D`` by ``(theta, tx, ty)`` and pair each point with its nearest point of ``M``.

    Fills ``idx``, ``d2`` (squared distance) and ``keep`` (``d2 <= max_d2``). Returns the
    objective over the kept pairs and whether the pairing (``idx`` and ``keep``) equals the
    previous one.
    """
    c = math.cos(theta)
    s = math.sin(theta)
    f = 0.0
    same = prev_idx.shape[0] == D.shape[0]
    for i in range(D.shape[0]):
        x = c * D[i, 0] - s * D[i, 1] + tx
        y = s * D[i, 0] + c * D[i, 1] + ty
        best = np.inf
        arg = 0
        for j in range(M.shape[0]):
            dx = x - M[j, 0]
            dy = y - M[j, 1]
            dd = dx * dx + dy * dy
            if dd < best:
                best = dd
                arg = j
        idx[i] = arg
        d2[i] = best
        keep[i] = best <= max_d2
        if keep[i]:
            f += best
        if same and (prev_idx[i] != arg or prev_keep[i] != keep[i]):
            same = False
    return f, same


@njit(cache=True, nogil=True)
def fit_rigid(D, M, idx, keep):
    """Closed-form Step 2 on the kept pairs ``(D[i], M[idx[i]])``: the proper rotation and
    translation minimising ``Σ ‖M[idx[i]] − (R D[i] + T)‖²``. Returns ``(theta, tx, ty, n)``;
    ``n < 2`` means there was nothing to fit (identity returned)."""
    n = 0
    dx = dy = mx = my = 0.0
    for i in range(D.shape[0]):
        if keep[i]:
            n += 1
            dx += D[i, 0]
            dy += D[i, 1]
            mx += M[idx[i], 0]
            my += M[idx[i], 1]
    if n < 2:
        return 0.0, 0.0, 0.0, n
    dx /= n
    dy /= n
    mx /= n
    my /= n
    sin_sum = 0.0
    cos_sum = 0.0
    for i in range(D.shape[0]):
        if keep[i]:
            px = D[i, 0] - dx
            py = D[i, 1] - dy
            qx = M[idx[i], 0] - mx
            qy = M[idx[i], 1] - my
            sin_sum += px * qy - py * qx
            cos_sum += px * qx + py * qy
    theta = math.atan2(sin_sum, cos_sum)
    c = math.cos(theta)
    s = math.sin(theta)
    return theta, mx - (c * dx - s * dy), my - (s * dx + c * dy), n


@njit(cache=True, nogil=True)
def spread(P):
    """Centroid and principal second moments of ``P``: ``(cx, cy, big, small, scale)`` with
    ``big >= small`` the eigenvalues of the centred scatter matrix and ``scale = n · max|P|²``."""
    n = P.shape[0]
    cx = cy = 0.0
    top = 0.0
    for i in range(n):
        cx += P[i, 0]
        cy += P[i, 1]
        top = max(top, abs(P[i, 0]), abs(P[i, 1]))
    cx /= n
    cy /= n
    a = b = c = 0.0
    for i in range(n):
        x = P[i, 0] - cx
        y = P[i, 1] - cy
        a += x * x
        b += x * y
        c += y * y
    half_gap = math.hypot((a - c) / 2.0, b)
    return cx, cy, (a + c) / 2.0 + half_gap, (a + c) / 2.0 - half_gap, n * top * top


@njit(cache=True, nogil=True)
def stops(prev, f, same, tau, rel_tol):
    """ICP's stopping rules after an update: the pairs repeat, or the objective changed from
    ``prev`` to ``f`` by less than ``tau`` or by at most ``rel_tol × prev`` (each rule off when
    negative)."""
    change = abs(prev - f)
    return same or (tau >= 0.0 and change < tau) or (rel_tol >= 0.0 and change <= rel_tol * prev)


@njit(cache=True, nogil=True)
def icp_brute(D, M, theta, tx, ty, max_d2, n_trim, tau, rel_tol, max_iter):
    """The loop of :func:`fusion.icp_svd` with all-pairs nearest neighbours, in one call (the
    Python loop cost more than the arithmetic at the merges' sizes); ``tau`` / ``rel_tol``
    negative when unused. The same steps in the same order: :func:`match_brute`, the TrICP trim
    (stable sort, the kept distances summed as numpy sums them), :func:`stops`,
    :func:`fit_rigid`.

    Returns ``(theta, tx, ty, iterations, errors, converged, idx, keep, short)``: ``short`` the
    number of pairs of a fit that had fewer than 2 (the loop stopped there), else ``-1``."""
    n = D.shape[0]
    idx, prev_idx = np.empty(n, dtype=np.int64), np.full(n, -1, dtype=np.int64)
    keep, prev_keep = np.empty(n, dtype=np.bool_), np.zeros(n, dtype=np.bool_)
    d2 = np.empty(n)
    kept = np.empty(n)
    errors = np.empty(max_iter + 1)
    converged = False
    iterations = 0
    short = -1
    while True:
        f, same = match_brute(D, M, theta, tx, ty, max_d2, prev_idx, prev_keep, idx, d2, keep)
        if n_trim < n:  # TrICP: only the n_trim closest pairs take part
            order = np.argsort(d2, kind="mergesort")
            for i in range(n_trim, n):
                keep[order[i]] = False
            m = 0
            for i in range(n):
                if keep[i]:
                    kept[m] = d2[i]
                    m += 1
            f = _pairwise_sum(kept, m)
            same = True
            for i in range(n):
                if idx[i] != prev_idx[i] or keep[i] != prev_keep[i]:
                    same = False
                    break
        errors[iterations] = f
        if iterations and stops(errors[iterations - 1], f, same, tau, rel_tol):
            converged = True
            break
        if iterations == max_iter:
            break
        new_theta, new_tx, new_ty, n_fit = fit_rigid(D, M, idx, keep)
        if n_fit < 2:
            short = n_fit
            break
        theta, tx, ty = new_theta, new_tx, new_ty
        iterations += 1
        idx, prev_idx = prev_idx, idx
        keep, prev_keep = prev_keep, keep
    return (theta, tx, ty, iterations, errors[: iterations + 1].copy(), converged, idx, keep,
            short)
