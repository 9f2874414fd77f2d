"""Compiled per-step bookkeeping of :mod:`envs.explore.mapping` (numba, cached on
disk): the shared map's patches, the ``local_map`` crop, the ``graph_nodes`` observation and the
state's block maps. Each replaces a dozen small numpy calls whose overhead, not arithmetic, was
the cost (they run every env step)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit, uint64


@njit(cache=True, nogil=True)
def cell_box(lo_x, lo_y, hi_x, hi_y, ox, oy, res, h, w, margin):
    """``[r0, r1, c0, c1]`` cells of an ``h × w`` grid (origin ``ox, oy``, cell size ``res``)
    covering the box ``[lo_x, hi_x] × [lo_y, hi_y]`` plus ``margin`` cells, clipped to the
    grid; all zero when that is empty."""
    inv = 1.0 / res
    out = np.empty(4, dtype=np.int64)
    out[0] = max(int(math.floor((lo_y - oy) * inv)) - margin, 0)
    out[1] = min(int(math.floor((hi_y - oy) * inv)) + margin + 1, h)
    out[2] = max(int(math.floor((lo_x - ox) * inv)) - margin, 0)
    out[3] = min(int(math.floor((hi_x - ox) * inv)) + margin + 1, w)
    if out[0] >= out[1] or out[2] >= out[3]:
        out[:] = 0
    return out


@njit(cache=True, nogil=True)
def or_patch(dst, patch, r0, c0):
    """``dst[r0:r0+h, c0:c0+w] |= patch`` (bool, ``patch`` ``h × w``); returns how many cells
    of ``dst`` became true."""
    n = 0
    for a in range(patch.shape[0]):
        for b in range(patch.shape[1]):
            if patch[a, b] and not dst[r0 + a, c0 + b]:
                dst[r0 + a, c0 + b] = True
                n += 1
    return n


@njit(cache=True, nogil=True)
def warp_patch(out, src, r0, c0, h, w, ox, oy, res, d_r0, d_c0, x0, y0, src_res,
               r00, r01, r10, r11, t0, t1):
    """The resampling loop of :func:`mapping.warp_window`: ``out[a, b]`` (zeros) gets the cell
    of ``src[r0:r0+h, c0:c0+w]`` (window corner ``x0, y0``, cell size ``src_res``) under the
    centre of destination cell ``(d_r0 + a, d_c0 + b)`` (grid origin ``ox, oy``, cell size
    ``res``) moved by the inverse motion ``p -> R p + t``; cells outside the window stay."""
    du = t0 - x0
    dv = t1 - y0
    for a in range(out.shape[0]):
        y = oy + ((d_r0 + a) + 0.5) * res
        for b in range(out.shape[1]):
            x = ox + ((d_c0 + b) + 0.5) * res
            iu = int(math.floor((r00 * x + r01 * y + du) / src_res))
            iv = int(math.floor((r10 * x + r11 * y + dv) / src_res))
            if 0 <= iu < w and 0 <= iv < h:
                out[a, b] = src[r0 + iv, c0 + iu]


NO_STATES = np.zeros((0, 0), dtype=np.int8)
"""The ``states2`` argument of :func:`sample_image` when there is no second grid."""


@njit(cache=True, nogil=True)
def sample_states(out, states, offsets, ox, oy, res, x, y, theta):
    """``out[k] = max(out[k], state)`` of the cell of ``states`` (origin ``ox, oy``, cell size
    ``res``) under each offset ``(forward, left)`` (``offsets``, ``(2, K)`` metres) of the pose
    ``(x, y, theta)``; cells outside the grid are unknown (0)."""
    h, w = states.shape
    inv = 1.0 / res
    c = math.cos(theta) * inv
    s = math.sin(theta) * inv
    u0 = (x - ox) * inv
    v0 = (y - oy) * inv
    for k in range(offsets.shape[1]):
        f = offsets[0, k]
        g = offsets[1, k]
        u = u0 + c * f - s * g
        v = v0 + s * f + c * g
        if 0.0 <= u < w and 0.0 <= v < h:
            val = states[int(v), int(u)]
            if val > out[k]:
                out[k] = val


@njit(cache=True, nogil=True)
def sample_image(image, values, fwd, left, states, ox, oy, res, x, y, theta,
                 states2, ox2, oy2, res2, x2, y2, theta2):
    """The ``local_map`` pixels in one pass: pixel ``(i, j)`` of ``image`` (``(1, n, n)``
    uint8) gets ``values[state]`` of :func:`sample_states`' state at the offset ``(fwd[i],
    left[j])`` of ``states`` around ``(x, y, theta)`` or, when ``states2`` is not empty, of
    the larger of that and the state of ``states2`` around ``(x2, y2, theta2)`` (each grid
    with its own origin and cell size). The same arithmetic as :func:`sample_states`, in the
    same order, with each row's and column's share computed once (and unsigned indices: the
    bounds are checked first)."""
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
        a, b = u0 + c * f, v0 + s * f  # u = u0 + c f - s g, left to right as sample_states
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


@njit(cache=True, nogil=True)
def adjacency(order, edges, n_nodes, adj):
    """``graph_adjacency``: 1 in ``adj`` (zeros) at ``(j, k)`` and ``(k, j)`` for every edge
    of ``edges`` (``(E, 2)`` node indices, ``n_nodes`` nodes) joining the listed nodes
    ``order[j]`` and ``order[k]``."""
    slot = np.full(n_nodes, -1, dtype=np.int64)
    for j in range(order.shape[0]):
        slot[order[j]] = j
    for e in range(edges.shape[0]):
        a = slot[edges[e, 0]]
        b = slot[edges[e, 1]]
        if a >= 0 and b >= 0:
            adj[a, b] = 1.0
            adj[b, a] = 1.0


@njit(cache=True, nogil=True)
def block_fractions(mask, cells, out):
    """Per block ``b`` of ``out``, the fraction of its samples ``cells[b·k : (b+1)·k]`` (flat
    indices into the C-contiguous ``mask``; ``-1``: outside, counted False) that are True,
    ``k = len(cells) / len(out)``."""
    flat = mask.ravel()
    k = cells.shape[0] // out.shape[0]
    for b in range(out.shape[0]):
        hits = 0
        for j in range(b * k, (b + 1) * k):
            c = cells[j]
            if c >= 0 and flat[c]:
                hits += 1
        out[b] = hits / k
