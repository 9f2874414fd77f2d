"""Compiled inner loop of :meth:`topo.OccupancyGrid.update` (numba, cached on disk)."""

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
