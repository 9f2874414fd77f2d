"""Compiled inner loops of :func:`fusion.merge_grids` (numba, cached on disk after the first call).

The env's grids are ~500 × 500 cells of which a few thousand are known: numpy's whole-grid
passes (``!=``, ``nonzero``, block reductions over a reshaped crop) and the fancy-indexed
rasters of the rotated points cost more than the FFT correlation they feed, so they are loops
here. They compute exactly what the numpy forms did (same cells, same flags)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def known_box(states, unknown):
    """``(r0, r1, c0, c1)``: the first and last rows and columns holding a cell other than
    ``unknown`` (``r0 = -1`` if there is none)."""
    r0 = r1 = c0 = c1 = -1
    for r in range(states.shape[0]):
        for c in range(states.shape[1]):
            if states[r, c] != unknown:
                if r0 < 0:
                    r0, c0, c1 = r, c, c
                r1 = r
                c0, c1 = min(c0, c), max(c1, c)
    return r0, r1, c0, c1


@njit(cache=True, nogil=True)
def _per_block(n_blocks, ratio):
    """How many fine cells fall in each of ``n_blocks`` blocks (cell ``n`` in block
    ``int((n + 0.5) * ratio)``), counting cells past the grid's edge."""
    counts = np.zeros(n_blocks, dtype=np.int64)
    n = 0
    while True:
        i = int((n + 0.5) * ratio)
        if i >= n_blocks:
            break
        counts[i] += 1
        n += 1
    return counts


@njit(cache=True, nogil=True)
def pool(states, r0, c0, h, w, ratio, free, occupied):
    """The ``(h, w)`` wall and free masks of blocks ``1 / ratio`` fine cells wide from
    ``(r0, c0)`` (``ratio`` = fine cell / block cell; fine cell ``(r, c)`` falls in block
    ``(int((r - r0 + 0.5) · ratio), int((c - c0 + 0.5) · ratio))``, so a block covers a whole
    or fractional number of cells and the blocks keep their true size; cells past the grid's
    edge count as unknown): a wall where any cell is ``occupied``, free where more than half
    are ``free`` and none is ``occupied``."""
    wall = np.zeros((h, w), dtype=np.bool_)
    n_free = np.zeros((h, w), dtype=np.int64)
    rows_in = _per_block(h, ratio)
    cols_in = _per_block(w, ratio)
    for r in range(r0, states.shape[0]):
        i = int((r - r0 + 0.5) * ratio)
        if i >= h:
            break
        for c in range(c0, states.shape[1]):
            j = int((c - c0 + 0.5) * ratio)
            if j >= w:
                break
            v = states[r, c]
            if v == occupied:
                wall[i, j] = True
            elif v == free:
                n_free[i, j] += 1
    is_free = np.empty((h, w), dtype=np.bool_)
    for i in range(h):
        for j in range(w):
            is_free[i, j] = n_free[i, j] * 2 > rows_in[i] * cols_in[j] and not wall[i, j]
    return wall, is_free


@njit(cache=True, nogil=True)
def raster_rotated(k, pts, centre_x, centre_y, cos_t, sin_t, res, half):
    """Set ``k[l, side - 1 - iy, side - 1 - ix] = 1`` for each point of ``pts`` rotated by the
    angle of ``(cos_t[l], sin_t[l])`` about the centre (``ix = floor(x' / res) + half``, the
    same for ``y``): the flipped kernels of the FFT correlation, one per rotation ``l``."""
    side = k.shape[1]
    for layer in range(cos_t.shape[0]):
        c, s = cos_t[layer], sin_t[layer]
        for p in range(pts.shape[0]):
            dx, dy = pts[p, 0] - centre_x, pts[p, 1] - centre_y
            ix = int(math.floor((c * dx - s * dy) / res)) + half
            iy = int(math.floor((s * dx + c * dy) / res)) + half
            k[layer, side - 1 - iy, side - 1 - ix] = 1.0
