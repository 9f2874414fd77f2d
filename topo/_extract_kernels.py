"""Compiled kernels of :mod:`topo.extract`: the merge tree of a clearance field, routes inside
its basins, the cells where two basins touch, and cells counted in squares about the nodes.

No library computes the 0-dimensional persistence of an image's superlevel sets together with
the basins and the merge (saddle) events, so this one loop is compiled (numba, cached). It is
the textbook union-find algorithm (Edelsbrunner & Harer, *Computational Topology*, VII.1):
pixels are added in decreasing value; a pixel with no processed neighbour starts a component
(a maximum is born), one joining several components merges them and every component but the
oldest dies there (the elder rule). Tests check it against a brute-force flood fill.

The routes (:func:`basin_paths`, :func:`route`) are breadth-first trees inside the basins.
The last two kernels replace numpy passes over the whole grid that took much of the
extraction's time (``benchmarks/fusion.md``): :func:`touching` four shifted comparisons of the
basin labels, :func:`box_counts` two summed-area tables read at a few nodes. Tests check both
against those passes.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def _find(parent: np.ndarray, i: int) -> int:
    root = i
    while parent[root] != root:
        root = parent[root]
    while parent[i] != root:  # path compression
        nxt = parent[i]
        parent[i] = root
        i = nxt
    return root


@numba.njit(cache=True)
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


@numba.njit(cache=True)
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


@numba.njit(cache=True)
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


@numba.njit(cache=True)
def touching(basins: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every pair of 8-connected cells in two different basins (labels ``>= 0``), once:
    ``(a, b)`` flat indices, ``b`` the right, lower-left, lower or lower-right neighbour of
    ``a`` (row 0 first). One pass over the grid where four shifted comparisons and their
    ``np.nonzero`` took most of the time of finding the passes."""
    h, w = basins.shape
    lab = basins.ravel()
    a = np.empty(4 * h * w, np.int64)
    b = np.empty(4 * h * w, np.int64)
    n = 0
    for y in range(h):
        for x in range(w):
            p = y * w + x
            if lab[p] < 0:
                continue
            for dy, dx in ((0, 1), (1, -1), (1, 0), (1, 1)):
                yy, xx = y + dy, x + dx
                if yy >= h or xx < 0 or xx >= w:
                    continue
                q = yy * w + xx
                if lab[q] >= 0 and lab[q] != lab[p]:
                    a[n] = p
                    b[n] = q
                    n += 1
    return a[:n], b[:n]


@numba.njit(cache=True)
def box_counts(a: np.ndarray, b: np.ndarray, cells: np.ndarray, outer: np.ndarray,
               inner: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per node ``k``, in the square of half-side ``outer[k]`` about ``cells[k]`` (row, col),
    clipped to the grid: how many cells of the boolean masks ``a`` and ``b`` are set; and
    whether ``a`` has a cell set in the square of half-side ``inner[k]`` (none when
    negative). A node's squares are a few hundred cells: counting in them is cheaper than
    summed-area tables over the whole grid."""
    h, w = a.shape
    n = cells.shape[0]
    n_a = np.zeros(n, np.int64)
    n_b = np.zeros(n, np.int64)
    inside = np.zeros(n, np.bool_)
    for k in range(n):
        cy, cx = cells[k, 0], cells[k, 1]
        r, ri = outer[k], inner[k]
        for y in range(max(cy - r, 0), min(cy + r + 1, h)):
            for x in range(max(cx - r, 0), min(cx + r + 1, w)):
                if b[y, x]:
                    n_b[k] += 1
                if a[y, x]:
                    n_a[k] += 1
                    if ri >= 0 and abs(y - cy) <= ri and abs(x - cx) <= ri:
                        inside[k] = True
    return n_a, n_b, inside
