"""Compiled inner loop of :meth:`topo.OccupancyGrid.update` (numba, cached on disk)."""

from __future__ import annotations

import math

from numba import njit


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
def sonar_update(log_odds, states, ox, oy, res, x, y, theta, ranges, angles, max_range, beta,
                 half, l_free, l_occ, clamp, threshold):
    """Apply the sonar-cone inverse model of one scan in place; returns cells changed."""
    h, w = log_odds.shape
    cos_beta = math.cos(beta)
    changed = 0
    for k in range(ranges.shape[0]):
        r = ranges[k]
        axis = theta + angles[k]
        ux = math.cos(axis)
        uy = math.sin(axis)
        echo = r < max_range
        reach_free = r - half if echo else max_range
        reach = r + half if echo else max_range
        lo_x, hi_x, lo_y, hi_y = _bounds(x, x, y, y, x, y, reach, axis, beta)
        c0 = max(int(math.floor((lo_x - ox) / res)), 0)
        c1 = min(int(math.floor((hi_x - ox) / res)), w - 1)
        r0 = max(int(math.floor((lo_y - oy) / res)), 0)
        r1 = min(int(math.floor((hi_y - oy) / res)), h - 1)
        for iy in range(r0, r1 + 1):
            dy = oy + (iy + 0.5) * res - y
            for ix in range(c0, c1 + 1):
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
                v = min(max(log_odds[iy, ix] + delta, -clamp), clamp)
                log_odds[iy, ix] = v
                s = 1 if v < -threshold else (2 if v > threshold else 0)
                if states[iy, ix] != s:
                    states[iy, ix] = s
                    changed += 1
    return changed
