"""Compiled loops of :mod:`fusion` (numba, cached on disk), each for a loop no numpy/scipy
call does without whole-array temporaries:

- :func:`match_brute`: ICP's all-pairs nearest neighbours of small sets, with the objective
  and the repeat test in the same pass (a KD-tree pays off only for large sets).
- :func:`pool`: the grid merge's block pooling with blocks of a fractional number of cells,
  over the known box of a large, mostly unknown grid.
- :func:`raster_rotated`: the rotated points scattered into one FFT kernel per rotation.
- :func:`box_correlation`: the correlation of a sparse kernel at a small box of translations
  (an FFT scores every translation; a local search needs a few hundred of them).

Tests check the last three against the numpy forms. No kernel here calls one of another
module, so numba's per-file cache stays valid.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


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


@njit(cache=True, nogil=True)
def box_correlation(layer, pts, centre_x, centre_y, cos_t, sin_t, res, side, r0, c0, out):
    """Add ``layer[r0 + iy + dr, c0 + ix + dc]`` into ``out[dr, dc]`` for each kernel cell
    ``(iy, ix)`` that :func:`raster_rotated` sets for the rotation ``(cos_t, sin_t)`` (each
    cell once, unflipped; ``side`` the kernel's side; cells outside ``layer`` count 0): the
    correlation score of that kernel at the ``out.shape`` box of translations, without the
    whole-array FFT."""
    half = side // 2
    h, w = out.shape
    n_rows, n_cols = layer.shape
    seen = np.zeros((side, side), dtype=np.bool_)
    for p in range(pts.shape[0]):
        dx, dy = pts[p, 0] - centre_x, pts[p, 1] - centre_y
        ix = int(math.floor((cos_t * dx - sin_t * dy) / res)) + half
        iy = int(math.floor((sin_t * dx + cos_t * dy) / res)) + half
        if seen[iy, ix]:
            continue
        seen[iy, ix] = True
        for dr in range(h):
            r = r0 + iy + dr
            if r < 0 or r >= n_rows:
                continue
            for dc in range(w):
                c = c0 + ix + dc
                if 0 <= c < n_cols:
                    out[dr, dc] += layer[r, c]
