"""Compiled loops of :mod:`topo`: the sonar inverse model of :meth:`topo.OccupancyGrid.update`
and the merge tree, basins and routes of :mod:`topo.extract` (numba, cached on disk).

Each stays compiled because no numpy/scipy/scikit-image routine does what it does:

- :func:`sonar_update` visits, per reading, the cells of a cone sector and applies the
  log-odds update with first-known bookkeeping (a per-cell branchy loop over a small window).
- :func:`merge_tree` is the 0-dimensional persistence of an image's superlevel sets together
  with the basins and the merge (saddle) events: the textbook union-find algorithm
  (Edelsbrunner & Harer, *Computational Topology*, VII.1): pixels are added in decreasing
  value; a pixel with no processed neighbour starts a component (a maximum is born), one
  joining several merges them and every component but the oldest dies there (the elder rule).
  Tests check it against a brute-force flood fill.
- :func:`basin_paths` grows breadth-first trees inside the basins with a tie rule on the
  clearance (scipy's graph searches keep no such rule); :func:`route` follows them.

No kernel here calls one of another module, so numba's per-file cache stays valid.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

NO_MASK = np.zeros((0, 0), dtype=np.bool_)
"""The ``ever`` / ``union`` / ``reachable`` arguments of :func:`sonar_update` when no coverage
is tracked."""

NO_COUNTS = np.zeros(0, dtype=np.int64)
"""Its ``fresh`` argument then."""


@njit(cache=True, nogil=True)
def _bounds(lo_x, hi_x, lo_y, hi_y, x, y, reach, axis, beta):
    """Grow ``[lo, hi]`` boxes to hold the cone sector (robot, arc ends, axis, and any
    cardinal direction inside the cone)."""
    for a in (axis - beta, axis, axis + beta):
        px = x + reach * math.cos(a)
        py = y + reach * math.sin(a)
        lo_x, hi_x = min(lo_x, px), max(hi_x, px)
        lo_y, hi_y = min(lo_y, py), max(hi_y, py)
    for k in range(4):
        card = k * math.pi / 2.0
        off = abs(((card - axis + math.pi) % (2.0 * math.pi)) - math.pi)
        if off <= beta:
            px = x + reach * math.cos(card)
            py = y + reach * math.sin(card)
            lo_x, hi_x = min(lo_x, px), max(hi_x, px)
            lo_y, hi_y = min(lo_y, py), max(hi_y, py)
    return lo_x, hi_x, lo_y, hi_y


@njit(cache=True, nogil=True)
def _span(dy, e1x, e1y, e2x, e2y, reach):
    """``[lo, hi]`` of the offsets ``dx`` for which ``(dx, dy)`` lies in the cone sector of
    edges ``e1`` (clockwise) and ``e2`` within ``reach``: the two edge half-planes (a cone of
    half-width ≤ 90° is their intersection) and the disc. An edge nearly parallel to the row
    sets no bound (its bound would be ill-conditioned); ``lo > hi`` when the row misses."""
    rr = reach * reach - dy * dy
    if rr < 0.0:
        return 1.0, -1.0
    hi = math.sqrt(rr)
    lo = -hi
    # e1 × p ≥ 0: e1y · dx ≤ e1x · dy
    if e1y > 1e-3:
        hi = min(hi, e1x * dy / e1y)
    elif e1y < -1e-3:
        lo = max(lo, e1x * dy / e1y)
    # e2 × p ≤ 0: e2y · dx ≥ e2x · dy
    if e2y > 1e-3:
        lo = max(lo, e2x * dy / e2y)
    elif e2y < -1e-3:
        hi = min(hi, e2x * dy / e2y)
    return lo, hi


@njit(cache=True, nogil=True)
def _first_known(iy, ix, ever, union, reachable, fresh):
    """Cell ``(iy, ix)`` is known for the first time: set it in ``ever``, count it and grow
    the box in ``fresh``, and with a non-empty ``union`` fold it in (:func:`sonar_update`)."""
    ever[iy, ix] = True
    fresh[0] += 1
    fresh[1] = min(fresh[1], iy)
    fresh[2] = max(fresh[2], iy + 1)
    fresh[3] = min(fresh[3], ix)
    fresh[4] = max(fresh[4], ix + 1)
    if union.size > 0:
        if union[iy, ix]:
            fresh[5] += 1
        else:
            union[iy, ix] = True
            fresh[6] += 1
            if reachable[iy, ix]:
                fresh[7] += 1


@njit(cache=True, nogil=True)
def sonar_update(log_odds, states, ox, oy, res, x, y, theta, ranges, angles, max_range, beta,
                 half, l_free, l_occ, clamp, threshold, usable, ever, union, reachable, fresh):
    """Apply the sonar-cone inverse model of one scan in place; returns cells changed.

    A reading beyond ``usable`` (``inf`` for none) is taken as no echo within it: it frees the
    cone up to ``usable`` and marks nothing.

    Each row of a cone's bounding box is visited only over :func:`_span`'s columns, widened
    by one cell each side (the cone test below, unchanged, still decides every cell: the span
    only skips cells that cannot pass it).

    Coverage bookkeeping, for callers that track it (empty ``(0, 0)`` arrays otherwise):
    ``ever`` (bool, the grid's shape) holds the cells known at least once; a cell an update
    makes known that is not in it yet is added (:func:`_first_known`), with ``fresh``
    (int64, 8) ``= [count, r0, r1, c0, c1, both, new, covered]``: how many, their bounding
    box (all zero when none) and, with a non-empty ``union`` mask, how many were in it
    already, were added to it, and were added and ``reachable``. With an empty ``log_odds``
    (and ``states``) the scan only sweeps: every cell the model would update joins ``ever``
    — the same cells, for a model whose single update makes a cell known (``|l_free|`` and
    ``l_occ`` above ``threshold``) — and cells already in ``ever`` are skipped untested."""
    sweep = log_odds.size == 0
    track = ever.size > 0
    h, w = ever.shape if sweep else log_odds.shape
    if track:
        fresh[:] = 0
        fresh[1], fresh[3] = h, w
    cos_beta = math.cos(beta)
    sin_beta = math.sin(beta)
    changed = 0
    for k in range(ranges.shape[0]):
        r = ranges[k]
        axis = theta + angles[k]
        ux = math.cos(axis)
        uy = math.sin(axis)
        e1x, e1y = ux * cos_beta + uy * sin_beta, uy * cos_beta - ux * sin_beta
        e2x, e2y = ux * cos_beta - uy * sin_beta, uy * cos_beta + ux * sin_beta
        echo = r < max_range and r <= usable
        reach_free = r - half if echo else min(max_range, usable)
        reach = r + half if echo else reach_free
        lo_x, hi_x, lo_y, hi_y = _bounds(x, x, y, y, x, y, reach, axis, beta)
        c0 = max(int(math.floor((lo_x - ox) / res)), 0)
        c1 = min(int(math.floor((hi_x - ox) / res)), w - 1)
        r0 = max(int(math.floor((lo_y - oy) / res)), 0)
        r1 = min(int(math.floor((hi_y - oy) / res)), h - 1)
        for iy in range(r0, r1 + 1):
            dy = oy + (iy + 0.5) * res - y
            lo, hi = _span(dy, e1x, e1y, e2x, e2y, reach + res)
            if lo > hi:
                continue
            a = max(c0, int(math.floor((x + lo - ox) / res - 0.5)) - 1)
            b = min(c1, int(math.ceil((x + hi - ox) / res - 0.5)) + 1)
            for ix in range(a, b + 1):
                if sweep and ever[iy, ix]:
                    continue  # swept already: nothing to learn
                dx = ox + (ix + 0.5) * res - x
                d = math.sqrt(dx * dx + dy * dy)
                if ux * dx + uy * dy < cos_beta * d:
                    continue  # outside the cone
                if d < reach_free:
                    delta = l_free
                elif echo and abs(d - r) <= half:
                    delta = l_occ
                else:
                    continue
                if sweep:
                    _first_known(iy, ix, ever, union, reachable, fresh)
                    continue
                v = min(max(log_odds[iy, ix] + delta, -clamp), clamp)
                log_odds[iy, ix] = v
                s = 1 if v < -threshold else (2 if v > threshold else 0)
                if states[iy, ix] != s:
                    states[iy, ix] = s
                    changed += 1
                    if track and s != 0 and not ever[iy, ix]:
                        _first_known(iy, ix, ever, union, reachable, fresh)
    if track and fresh[0] == 0:
        fresh[1:5] = 0
    return changed


@njit(cache=True)
def _find(parent: np.ndarray, i: int) -> int:
    root = i
    while parent[root] != root:
        root = parent[root]
    while parent[i] != root:  # path compression
        nxt = parent[i]
        parent[i] = root
        i = nxt
    return root


@njit(cache=True)
def merge_tree(field: np.ndarray, domain: np.ndarray, order: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Superlevel-set merge tree of ``field`` over ``domain`` (8-connected).

    Args:
        field: ``(H, W)`` float64 values.
        domain: ``(H, W)`` bool, the pixels taking part.
        order: flat pixel indices in decreasing ``field`` (ties in any fixed order).

    Returns:
        ``(ascent, saddle, dying, survivor, into)``: ``ascent[p]`` is the maximum whose basin
        pixel ``p`` joins by steepest ascent (that of its highest neighbour processed before
        it; ``-1`` outside the domain); one merge event per component death, in
        the order they happen: the pixel where it happens, the maximum of the dying component
        (the younger one: lower maximum, ties to the larger index), that of the surviving one,
        and the basin (a maximum) on the surviving side of the pixel — the one the dying
        component's basin touches there.
    """
    h, w = field.shape
    n = h * w
    flat = field.ravel()
    dom = domain.ravel()
    parent = np.full(n, -1, np.int64)
    ascent = np.full(n, -1, np.int64)
    saddle = np.empty(n, np.int64)
    dying = np.empty(n, np.int64)
    survivor = np.empty(n, np.int64)
    into = np.empty(n, np.int64)
    n_events = 0
    roots = np.empty(8, np.int64)
    top = np.empty(8, np.int64)  # per root: its highest neighbour of p
    for t in range(order.shape[0]):
        p = order[t]
        if not dom[p]:
            continue
        y = p // w
        x = p - y * w
        k = 0
        steepest = -1
        for dy in range(-1, 2):
            yy = y + dy
            if yy < 0 or yy >= h:
                continue
            for dx in range(-1, 2):
                xx = x + dx
                if (dy == 0 and dx == 0) or xx < 0 or xx >= w:
                    continue
                q = yy * w + xx
                if parent[q] < 0:
                    continue
                if steepest < 0 or flat[q] > flat[steepest]:
                    steepest = q
                r = _find(parent, q)
                seen = False
                for j in range(k):
                    if roots[j] == r:
                        seen = True
                        if flat[q] > flat[top[j]]:
                            top[j] = q
                if not seen:
                    roots[k] = r
                    top[k] = q
                    k += 1
        if k == 0:  # a maximum is born
            parent[p] = p
            ascent[p] = p
            continue
        jb = 0
        for j in range(1, k):
            r = roots[j]
            if flat[r] > flat[roots[jb]] or (flat[r] == flat[roots[jb]] and r < roots[jb]):
                jb = j
        best = roots[jb]
        parent[p] = best
        ascent[p] = ascent[steepest]
        for j in range(k):
            r = roots[j]
            if r != best:
                saddle[n_events] = p
                dying[n_events] = r
                survivor[n_events] = best
                into[n_events] = ascent[top[jb]]
                n_events += 1
                parent[r] = best
    return (ascent, saddle[:n_events], dying[:n_events], survivor[:n_events],
            into[:n_events])


@njit(cache=True)
def basin_paths(basins: np.ndarray, field: np.ndarray, sources: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """Breadth-first trees grown inside each basin from its source.

    ``basins`` ``(H, W)`` int64 labels (``-1`` outside), ``sources[k]`` the flat pixel of basin
    ``k``'s root. Returns ``(parent, depth)`` (flat; ``-1`` where unreached; a source is its own
    parent, at depth 0): following ``parent`` from any pixel of basin ``k`` leads to
    ``sources[k]`` by a shortest 8-connected route of ``depth`` steps inside the basin; among
    equally short steps the one to the highest ``field`` is taken, so routes keep to the
    middle of the free space.
    """
    h, w = basins.shape
    n = h * w
    lab = basins.ravel()
    f = field.ravel()
    parent = np.full(n, -1, np.int64)
    depth = np.full(n, -1, np.int64)
    queue = np.empty(n, np.int64)
    head = 0
    tail = 0
    for k in range(sources.shape[0]):
        s = sources[k]
        parent[s] = s
        depth[s] = 0
        queue[tail] = s
        tail += 1
    while head < tail:
        p = queue[head]
        head += 1
        y = p // w
        x = p - y * w
        for dy in range(-1, 2):
            yy = y + dy
            if yy < 0 or yy >= h:
                continue
            for dx in range(-1, 2):
                xx = x + dx
                if (dy == 0 and dx == 0) or xx < 0 or xx >= w:
                    continue
                q = yy * w + xx
                if lab[q] != lab[p]:
                    continue
                if depth[q] < 0:
                    depth[q] = depth[p] + 1
                    parent[q] = p
                    queue[tail] = q
                    tail += 1
                elif depth[q] == depth[p] + 1 and f[p] > f[parent[q]]:
                    parent[q] = p
    return parent, depth


@njit(cache=True)
def route(parent: np.ndarray, width: int, start: int) -> np.ndarray:
    """``(K, 2)`` cells ``(row, col)`` from flat pixel ``start`` along ``parent``
    (:func:`basin_paths`, a grid ``width`` wide) to its source."""
    n = 1
    p = start
    while parent[p] != p:
        p = parent[p]
        n += 1
    out = np.empty((n, 2), np.int64)
    p = start
    for i in range(n):
        out[i, 0] = p // width
        out[i, 1] = p - out[i, 0] * width
        p = parent[p]
    return out

