"""Compiled per-step observation loops of :mod:`envs.explore` (numba, cached on disk), run for
every robot at every step, where a profile of the env step shows numpy's forms costing far more
than the loops:

- :func:`sample_image`: the ``local_map`` gather of
  :class:`envs.explore.mapping.LocalMapSampler`, nearest cells of one or more grids under a
  heading-up square (numpy's fancy-indexed form builds a dozen image-sized temporaries per grid).
- :func:`nearest_nodes`: the ``graph_nodes`` rows of :mod:`envs.explore.observations`, a few
  dozen nodes (a dozen small numpy calls, each costing more than the arithmetic).

No kernel here calls one of another module, so numba's per-file cache stays valid."""

from __future__ import annotations

import math

import numpy as np
from numba import njit, uint64

NO_STATES = np.zeros((0, 0), dtype=np.int8)
"""The ``states2`` argument of :func:`sample_image` when there is no second grid."""


@njit(cache=True, nogil=True)
def sample_image(image, values, fwd, left, states, ox, oy, res, x, y, theta,
                 states2, ox2, oy2, res2, x2, y2, theta2):
    """The ``local_map`` pixels in one pass: pixel ``(i, j)`` of ``image`` (``(1, n, n)``
    uint8) gets ``values[state]``, ``state`` the code of the cell of ``states`` (origin ``ox,
    oy``, cell size ``res``; unknown, 0, outside the grid) under the offset ``(fwd[i],
    left[j])`` (forward, left; metres) of the pose ``(x, y, theta)`` or, when ``states2`` is
    not empty, the larger of that and the code of ``states2`` under the same offset of ``(x2,
    y2, theta2)`` (each grid with its own origin and cell size). Each row's and column's share
    is computed once; indices are unsigned (the bounds are checked first)."""
    n = fwd.shape[0]
    h, w = states.shape
    inv = 1.0 / res
    c = math.cos(theta) * inv
    s = math.sin(theta) * inv
    u0 = (x - ox) * inv
    v0 = (y - oy) * inv
    both = states2.size > 0
    h2, w2 = states2.shape
    inv2 = 1.0 / res2
    c2 = math.cos(theta2) * inv2
    s2 = math.sin(theta2) * inv2
    u02 = (x2 - ox2) * inv2
    v02 = (y2 - oy2) * inv2
    flat, flat2 = states.ravel(), states2.ravel()
    sg, cg = s * left, c * left
    sg2, cg2 = s2 * left, c2 * left
    for i in range(n):
        f = fwd[i]
        a, b = u0 + c * f, v0 + s * f  # u = u0 + c f - s g, left to right
        a2, b2 = u02 + c2 * f, v02 + s2 * f
        for j in range(n):
            u = a - sg[j]
            v = b + cg[j]
            st = 0
            if 0.0 <= u < w and 0.0 <= v < h:
                st = flat[uint64(int(v)) * uint64(w) + uint64(int(u))]
            if both:
                u = a2 - sg2[j]
                v = b2 + cg2[j]
                if 0.0 <= u < w2 and 0.0 <= v < h2:
                    st2 = flat2[uint64(int(v)) * uint64(w2) + uint64(int(u))]
                    if st2 > st:
                        st = st2
            image[0, i, j] = values[uint64(st)]


@njit(cache=True, nogil=True)
def nearest_nodes(xy, x, y, c, s, static, lim, nodes, mask):
    """The ``graph_nodes`` rows: of the nodes ``xy``, seen from ``(x, y)`` at heading ``(cos,
    sin) = (c, s)`` — offsets ``(c dx + s dy, -s dx + c dy)`` — the ``len(nodes)`` nearest (by
    squared distance ``x² + y²`` of their offsets; stable order: ties by index) get their
    offsets clipped to ``[-lim, lim]`` and their ``static`` features, and a 1 in ``mask``;
    returns their indices."""
    n = xy.shape[0]
    rel = np.empty((n, 2))
    dist2 = np.empty(n)
    for q in range(n):
        dx = xy[q, 0] - x
        dy = xy[q, 1] - y
        rel[q, 0] = c * dx + s * dy
        rel[q, 1] = c * dy - s * dx
        dist2[q] = rel[q, 0] * rel[q, 0] + rel[q, 1] * rel[q, 1]
    order = np.argsort(dist2, kind="mergesort")[: nodes.shape[0]]
    for j in range(order.shape[0]):
        q = order[j]
        nodes[j, 0] = min(max(rel[q, 0], -lim), lim)
        nodes[j, 1] = min(max(rel[q, 1], -lim), lim)
        for f in range(static.shape[1]):
            nodes[j, 2 + f] = static[q, f]
        mask[j] = 1.0
    return order
