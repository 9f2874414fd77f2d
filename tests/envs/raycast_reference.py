"""Slow, obvious numpy ray caster: the reference the pymunk-based sonar is tested against."""

from __future__ import annotations

import numpy as np


def cast_rays(starts: np.ndarray, ends: np.ndarray, segments: np.ndarray,
              circles: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Distance to the first hit of each ray ``starts[i] -> ends[i]`` among wall ``segments``
    ``(M, 4)`` and ``circles`` ``(C, 3)`` ``(x, y, r)``; ``inf`` if none. Also the unit normal
    of the surface hit, ``(N, 2)`` (zeros where nothing is hit)."""
    n = len(starts)
    best = np.full(n, np.inf)
    normal = np.zeros((n, 2))
    for i in range(n):
        o = starts[i]
        d = ends[i] - o
        length = np.hypot(*d)
        u = d / length
        for x0, y0, x1, y1 in segments:
            p = np.array([x0, y0])
            e = np.array([x1 - x0, y1 - y0])
            den = u[0] * (-e[1]) - u[1] * (-e[0])
            if abs(den) < 1e-12:
                continue
            rhs = p - o
            t = (rhs[0] * (-e[1]) - rhs[1] * (-e[0])) / den
            s = (u[0] * rhs[1] - u[1] * rhs[0]) / den
            if 0.0 <= t <= length and 0.0 <= s <= 1.0 and t < best[i]:
                best[i] = t
                nrm = np.array([-e[1], e[0]]) / np.hypot(*e)
                normal[i] = nrm if nrm @ u < 0 else -nrm
        for cx, cy, r in ([] if circles is None else circles):
            oc = o - np.array([cx, cy])
            b = oc @ u
            c = oc @ oc - r * r
            disc = b * b - c
            if disc < 0:
                continue
            t = -b - np.sqrt(disc)
            if 0.0 <= t <= length and t < best[i]:
                best[i] = t
                hit = o + t * u
                normal[i] = (hit - np.array([cx, cy])) / r
    return best, normal
