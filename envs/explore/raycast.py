"""The world's ray caster: sonar rays against the shapes the robots collide with.

The shapes are those :func:`~envs.explore.robot.build_space` gives pymunk: the world's
wall segments (zero radius) and one disc per robot. A ray from ``a`` to ``b`` reports the hit of
smallest fraction ``alpha`` of its length below 1 and the surface normal there, computed with
the formulas of chipmunk's segment queries (``cpSegmentShapeSegmentQuery``,
``CircleSegmentQuery``, ``cpSpaceSegmentQueryFirst``), so that a scan reads what pymunk's
``Space.segment_query_first`` reads; ``tests/envs/test_sonar.py`` checks them against each
other. Why not pymunk's query itself: its Python wrapper's overhead is paid per ray, this
caster's per scan, and the env casts every ray of every sonar every step.

Segments are binned in square cells :data:`CELL` wide; a scan tests only the segments of the
cells its rays can reach, each once, so a scan costs about the same in a small and a large
world.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

CELL = 2.0
"""Side (m) of the cells the wall segments are binned in."""

_TINY = np.finfo(np.float64).tiny
"""``CPFLOAT_MIN``: chipmunk adds it to a length before dividing by it."""


@njit(cache=True, nogil=True)
def _normalised(x, y):
    """chipmunk's ``cpvnormalize``: ``v / (|v| + CPFLOAT_MIN)``."""
    inv = 1.0 / (math.sqrt(x * x + y * y) + 2.2250738585072014e-308)
    return x * inv, y * inv


@njit(cache=True, nogil=True)
def _box_cells(seg, j, x0, y0, inv_cell, nx, ny):
    """Cells ``(c0, c1, r0, r1)`` (inclusive) that segment ``j``'s bounding box overlaps."""
    c0 = max(int(math.floor((min(seg[j, 0], seg[j, 2]) - x0) * inv_cell)), 0)
    c1 = min(int(math.floor((max(seg[j, 0], seg[j, 2]) - x0) * inv_cell)), nx - 1)
    r0 = max(int(math.floor((min(seg[j, 1], seg[j, 3]) - y0) * inv_cell)), 0)
    r1 = min(int(math.floor((max(seg[j, 1], seg[j, 3]) - y0) * inv_cell)), ny - 1)
    return c0, c1, r0, r1


@njit(cache=True, nogil=True)
def _bin_segments(seg, x0, y0, inv_cell, nx, ny):
    """CSR of the cells each segment's bounding box overlaps: ``(start, ids)``, the segments
    of cell ``k = iy * nx + ix`` at ``ids[start[k]:start[k + 1]]``."""
    start = np.zeros(nx * ny + 1, dtype=np.int64)
    for j in range(seg.shape[0]):
        c0, c1, r0, r1 = _box_cells(seg, j, x0, y0, inv_cell, nx, ny)
        for r in range(r0, r1 + 1):
            for c in range(c0, c1 + 1):
                start[r * nx + c + 1] += 1
    for k in range(nx * ny):
        start[k + 1] += start[k]
    ids = np.empty(start[-1], dtype=np.int64)
    fill = start[:-1].copy()
    for j in range(seg.shape[0]):
        c0, c1, r0, r1 = _box_cells(seg, j, x0, y0, inv_cell, nx, ny)
        for r in range(r0, r1 + 1):
            for c in range(c0, c1 + 1):
                ids[fill[r * nx + c]] = j
                fill[r * nx + c] += 1
    return start, ids


@njit(cache=True, nogil=True)
def cast_rays(ax, ay, ends, seg, normal, start, ids, x0, y0, inv_cell, nx, ny, discs, radius,
              own, seen, stamp, work, alpha, hit_nx, hit_ny):
    """Cast a ray from ``(ax, ay)`` to each row of ``ends``: per ray the hit fraction ``alpha``
    (``inf``: none below 1) and the surface normal ``(hit_nx, hit_ny)`` (0 without a hit).

    Shapes: the segments ``seg`` ``(M, 4)`` with chipmunk's normals ``normal`` ``(M, 2)``,
    binned by :func:`_bin_segments` (``start``, ``ids``; ``nx × ny`` cells, corner ``x0, y0``),
    and the discs ``discs`` ``(D, 2)`` of ``radius``, except disc ``own``. ``seen`` ``(M,)``
    int64 and the scan's ``stamp`` (not used by an earlier scan) mark the segments already
    taken; ``work`` ``(M, 9)`` holds the taken segments' terms for this ray start."""
    reach = 0.0
    for i in range(ends.shape[0]):
        reach = max(reach, abs(ends[i, 0] - ax), abs(ends[i, 1] - ay))
    c0 = max(int(math.floor((ax - reach - x0) * inv_cell)), 0)
    c1 = min(int(math.floor((ax + reach - x0) * inv_cell)), nx - 1)
    r0 = max(int(math.floor((ay - reach - y0) * inv_cell)), 0)
    r1 = min(int(math.floor((ay + reach - y0) * inv_cell)), ny - 1)
    # cpSegmentShapeSegmentQuery's terms that depend on the segment and the ray start only
    m = 0
    for r in range(r0, r1 + 1):
        for c in range(c0, c1 + 1):
            k = r * nx + c
            for q in range(start[k], start[k + 1]):
                j = ids[q]
                if seen[j] == stamp:
                    continue
                seen[j] = stamp
                n_x, n_y = normal[j, 0], normal[j, 1]
                d = (seg[j, 0] - ax) * n_x + (seg[j, 1] - ay) * n_y
                f_x, f_y = (-n_x, -n_y) if d > 0.0 else (n_x, n_y)
                off_x, off_y = f_x * 0.0 - ax, f_y * 0.0 - ay  # cpvmult(fn, r) - a, r = 0
                work[m, 0] = seg[j, 0] + off_x
                work[m, 1] = seg[j, 1] + off_y
                work[m, 2] = seg[j, 2] + off_x
                work[m, 3] = seg[j, 3] + off_y
                work[m, 4] = d + (-0.0 if d > 0.0 else 0.0)  # d + (d > 0 ? -r : r)
                work[m, 5], work[m, 6], work[m, 7], work[m, 8] = n_x, n_y, f_x, f_y
                m += 1
    for i in range(ends.shape[0]):
        dx, dy = ends[i, 0] - ax, ends[i, 1] - ay
        best = 1.0  # cpSpaceSegmentQueryFirst counts hits below alpha 1
        bx = by = 0.0
        found = False
        for q in range(m):
            if ((dx * work[q, 1] - dy * work[q, 0]) * (dx * work[q, 3] - dy * work[q, 2])
                    > 0.0):
                continue  # the ray passes beside the segment
            ad = -work[q, 4]
            bd = (dx * work[q, 5] + dy * work[q, 6]) - work[q, 4]
            if ad * bd < 0.0:
                t = ad / (ad - bd)
                if t < best:
                    best, found = t, True
                    bx, by = work[q, 7], work[q, 8]
        for k in range(discs.shape[0]):
            if k == own:
                continue
            da_x, da_y = ax - discs[k, 0], ay - discs[k, 1]
            db_x, db_y = ends[i, 0] - discs[k, 0], ends[i, 1] - discs[k, 1]
            aa = da_x * da_x + da_y * da_y
            dist = math.sqrt(aa)
            if dist - radius <= 0.0:  # cpShapeSegmentQuery: a ray starting inside hits at 0
                if best > 0.0:
                    scale = radius / dist if dist > 0.0 else radius
                    best, found = 0.0, True
                    bx, by = _normalised(ax - (discs[k, 0] + da_x * scale),
                                         ay - (discs[k, 1] + da_y * scale))
                continue
            ab = da_x * db_x + da_y * db_y
            qa = aa - 2.0 * ab + (db_x * db_x + db_y * db_y)
            qb = ab - aa
            det = qb * qb - qa * (aa - radius * radius)
            if det >= 0.0:
                t = (-qb - math.sqrt(det)) / qa
                if 0.0 <= t <= 1.0 and t < best:
                    best, found = t, True
                    bx, by = _normalised(da_x * (1.0 - t) + db_x * t,
                                         da_y * (1.0 - t) + db_y * t)
        if found:
            alpha[i], hit_nx[i], hit_ny[i] = best, bx, by
        else:
            alpha[i], hit_nx[i], hit_ny[i] = math.inf, 0.0, 0.0


class RayCaster:
    """Ray casts against one world's walls and the robots' discs (module docstring).

    Args:
        segments: ``(M, 4)`` wall segments ``(x0, y0, x1, y1)``, metres (``World.segments``).
        disc_radius: the robots' radius, metres.
        robots: how many robot discs.

    Attributes:
        discs: ``(robots, 2)`` the discs' centres; the env sets them to the robots' positions
            before the robots sense.
    """

    __slots__ = ("discs", "radius", "_seg", "_normal", "_start", "_ids", "_grid", "_seen",
                 "_stamp", "_work")

    def __init__(self, segments: np.ndarray, disc_radius: float, robots: int = 2) -> None:
        seg = np.ascontiguousarray(segments, dtype=np.float64).reshape(-1, 4)
        self._seg = seg
        # chipmunk's segment normal: cpvrperp(cpvnormalize(b - a))
        d = seg[:, 2:] - seg[:, :2]
        inv = 1.0 / (np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]) + _TINY)
        self._normal = np.ascontiguousarray(np.stack([d[:, 1] * inv, -(d[:, 0] * inv)], 1))
        lo = seg.reshape(-1, 2).min(axis=0) if len(seg) else np.zeros(2)
        hi = seg.reshape(-1, 2).max(axis=0) if len(seg) else np.zeros(2)
        nx, ny = (int(v) for v in np.floor((hi - lo) / CELL) + 1)
        self._start, self._ids = _bin_segments(seg, float(lo[0]), float(lo[1]), 1.0 / CELL,
                                               nx, ny)
        self._grid = (float(lo[0]), float(lo[1]), 1.0 / CELL, nx, ny)
        self._seen = np.zeros(len(seg), dtype=np.int64)
        self._stamp = 0
        self._work = np.empty((len(seg), 9))
        self.discs = np.zeros((robots, 2))
        self.radius = float(disc_radius)

    def cast(self, x: float, y: float, ends: np.ndarray, own: int, alpha: np.ndarray,
             nx: np.ndarray, ny: np.ndarray) -> None:
        """Rays from ``(x, y)`` to each row of ``ends`` ``(N, 2)``, not seeing disc ``own``:
        into ``alpha`` ``(N,)`` the hit fraction of each ray's length (``inf``: no hit) and
        into ``nx``, ``ny`` the surface normal (0 without a hit)."""
        self._stamp += 1
        cast_rays(x, y, ends, self._seg, self._normal, self._start, self._ids, *self._grid,
                  self.discs, self.radius, own, self._seen, self._stamp, self._work, alpha, nx,
                  ny)
