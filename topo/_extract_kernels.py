"""Compiled pieces of :func:`topo.extract.extract_topomap` (numba, cached on disk), each giving
bit for bit what the library or numpy code it replaces gives, and each tested against it
(``tests/topo/test_extract.py`` on hypothesis inputs, ``tests/envs/test_mapping.py`` on every
extraction of an env episode). On the env's 100–200-cell sonar grids the replaced calls' cost
was their fixed per-call overhead (scipy sparse matrices, small numpy calls), not the work.

* :func:`free_crop` — step 1's crop to the free cells' bounding box and its border of
  non-free cells (``np.pad`` of a slice: :func:`free_crop_reference`).
* :func:`clean_free` — step 1's morphology (skimage ``remove_small_holes``, scipy
  ``binary_erosion`` by a disk, dropping small ``ndimage.label`` components) on horizontal runs
  of pixels; :func:`clean_free_reference` is the library path.
* :func:`skeletonize` — ``skimage.morphology.skeletonize`` (Zhang–Suen, skimage's lookup
  table, BSD-3-Clause), examining only pixels beside removed ones.
* :func:`skeleton_paths` — what skan's ``Skeleton`` traces (``pixel_graph`` with
  8-connectivity, each junction cluster reduced to scipy's ``minimum_spanning_tree``,
  ``PathGraph``'s tracing): the same paths in the same order; :func:`skan_paths` is skan itself.
  :func:`path_nodes` numbers their end pixels as the clean-up expects.
* :func:`wall_distances` — the distance from pixels to the nearest non-free pixel bordering free
  space (a search in square rings), what a ``cKDTree`` of those pixels answers
  (:func:`wall_distances_reference`).
* :func:`polyline_length` / :func:`path_lengths` — ``np.sqrt((d * d).sum(axis=1)).sum()`` of
  the steps ``d``, with numpy's pairwise summation (so the same float).
* :func:`peaks` — the corner step's choice of one sharpest point per run of candidates.
* :func:`corner_arms` / :func:`corner_cuts` — the corner step on open paths around numpy's
  ``arctan2``: arc lengths and chord products, then candidates, peaks and cut indices
  (``topo.extract._open_corners_numpy``).
* :func:`metre_paths` — the output's polylines in metres, ends on their nodes, turned to run
  from the lower-numbered node, and their lengths (``topo.extract._to_topomap_loop``'s numpy
  arithmetic, edge by edge).
* :func:`topomap_arrays` — the whole output step around :func:`metre_paths`: nodes in metres
  and their order (``np.lexsort``), paths sorted by their ends (``sorted``), turned and
  measured (``topo.extract._to_topomap_loop`` with ``_node_order``).
* :func:`graph_first` / :func:`graph_second` — the clean-up (steps 4–7 and the output):
  ``topo.extract._Graph``'s passes on arrays, around numpy's ``arctan2``; the same map as the
  Python passes (``topo.extract._graph_topomap_reference``). See "The clean-up" below.

All kernels live in this one file: numba's disk cache notices changes to a cached function's
own file only, so a kernel calling kernels of another file could keep running their old code.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# 8-neighbour offsets (row, col) in increasing raveled order: skan's CSR rows list neighbours by
# increasing pixel index, and its tracing visits them in that order
_DR = np.array([-1, -1, -1, 0, 0, 1, 1, 1], dtype=np.int64)
_DC = np.array([-1, 0, 1, -1, 1, -1, 0, 1], dtype=np.int64)


@njit(cache=True, nogil=True)
def _block_sum(a, lo, n):
    """numpy's pairwise summation of a block ``a[lo:lo + n]``, ``n <= 128``: a plain loop under
    8 items, else 8 running sums combined as a tree, then the remainder."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r = a[lo: lo + 8].copy()
    i = 8
    stop = n - n % 8
    while i < stop:
        for j in range(8):
            r[j] += a[lo + i + j]
        i += 8
    res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@njit(cache=True, nogil=True)
def _pairwise_sum(a, n):
    """numpy's ``add.reduce`` of a contiguous float64 ``a[:n]``: blocks of up to 128 summed by
    :func:`_block_sum`, longer runs split in halves (a multiple of 8 first) and the halves'
    sums added. numpy recurses; this walks the same tree with an explicit stack (numba's disk
    cache does not support recursion)."""
    if n <= 128:
        return _block_sum(a, 0, n)
    los = np.empty(64, dtype=np.int64)
    ns = np.empty(64, dtype=np.int64)
    stage = np.zeros(64, dtype=np.int64)
    left = np.empty(64, dtype=np.float64)
    sp = 0
    los[0], ns[0] = 0, n
    ret = 0.0
    while sp >= 0:
        lo, m = los[sp], ns[sp]
        half = m // 2
        half -= half % 8
        if m <= 128:
            ret = _block_sum(a, lo, m)
            sp -= 1
        elif stage[sp] == 0:  # first the left half
            stage[sp] = 1
            sp += 1
            los[sp], ns[sp], stage[sp] = lo, half, 0
        elif stage[sp] == 1:  # left done (in ret): now the right half
            left[sp] = ret
            stage[sp] = 2
            sp += 1
            los[sp], ns[sp], stage[sp] = lo + half, m - half, 0
        else:
            ret = left[sp] + ret
            sp -= 1
    return ret


@njit(cache=True, nogil=True)
def polyline_length(poly):
    """Length of the ``(K, 2)`` float64 polyline ``poly`` (0 for fewer than two points)."""
    n = max(poly.shape[0] - 1, 0)
    steps = np.empty(n, dtype=np.float64)
    for i in range(n):
        dx = poly[i + 1, 0] - poly[i, 0]
        dy = poly[i + 1, 1] - poly[i, 1]
        steps[i] = math.sqrt(dx * dx + dy * dy)
    return 0.0 + _pairwise_sum(steps, n)


@njit(cache=True, nogil=True)
def _row_runs(mask, value):
    """The horizontal runs of pixels of ``mask`` equal to ``value``: ``(R, 3)`` rows ``row,
    start, stop`` in raster order, and ``first`` (``H + 1``): row ``r``'s runs are
    ``first[r]:first[r + 1]``."""
    h, w = mask.shape
    runs = np.empty((h * ((w + 1) // 2) + 1, 3), dtype=np.int64)
    first = np.zeros(h + 1, dtype=np.int64)
    n = 0
    for r in range(h):
        first[r] = n
        c = 0
        while c < w:
            if mask[r, c] != value:
                c += 1
                continue
            start = c
            while c < w and mask[r, c] == value:
                c += 1
            runs[n, 0], runs[n, 1], runs[n, 2] = r, start, c
            n += 1
    first[h] = n
    return runs[:n], first


@njit(cache=True, nogil=True)
def _join_runs(runs, first, h):
    """4-connected components of a mask's pixels given as horizontal runs (``runs`` ``(R, 3)``
    as ``row, start, stop`` in raster order, row ``r``'s runs ``first[r]:first[r + 1]``):
    ``ndimage.label``'s default structure. Returns each run's component ``root`` (a run index)
    and ``size``, the pixel count of each root's component (runs of adjacent rows that share a
    column are joined)."""
    n = len(runs)
    root = np.arange(n)
    for r in range(1, h):
        a, b = first[r - 1], first[r]
        while a < first[r] and b < first[r + 1]:
            if runs[a, 2] > runs[b, 1] and runs[b, 2] > runs[a, 1]:  # columns overlap
                x, y = _find(root, a), _find(root, b)
                if x != y:
                    root[max(x, y)] = min(x, y)
            if runs[a, 2] < runs[b, 2]:
                a += 1
            else:
                b += 1
    size = np.zeros(n, dtype=np.int64)
    for k in range(n):
        root[k] = _find(root, k)
        size[root[k]] += runs[k, 2] - runs[k, 1]
    return root, size


@njit(cache=True, nogil=True)
def _gaps(runs, first, keep, h, w):
    """The runs of the pixels of each row of width ``w`` outside its ``keep`` runs (the complement
    of those runs; the other runs count as outside too), laid out as :func:`_row_runs`'."""
    out = np.empty((len(runs) + h, 3), dtype=np.int64)
    out_first = np.zeros(h + 1, dtype=np.int64)
    n = 0
    for r in range(h):
        out_first[r] = n
        c = 0
        for k in range(first[r], first[r + 1]):
            if not keep[k]:
                continue
            if runs[k, 1] > c:
                out[n, 0], out[n, 1], out[n, 2] = r, c, runs[k, 1]
                n += 1
            c = runs[k, 2]
        if c < w:
            out[n, 0], out[n, 1], out[n, 2] = r, c, w
            n += 1
    out_first[h] = n
    return out[:n], out_first


@njit(cache=True, nogil=True)
def _erode_runs(runs, first, h, w, footprint):
    """Binary erosion by ``footprint`` (centred; outside the array counts as non-free) of the
    ``h × w`` mask whose set pixels are the runs ``runs``/``first`` (:func:`_row_runs`), as
    runs; for footprints whose rows are each one centred run (a disk): pixel ``(r, c)`` stays
    iff in every footprint row ``i`` (half width ``a``) the ``2a + 1`` pixels of row
    ``r + i - centre`` around ``c`` are set, i.e. ``c`` lies in a run ``[s, e)`` of that row
    shrunk to ``[s + a, e - a)``; the shrunk runs of each row are counted per column."""
    fh = footprint.shape[0]
    centre = fh // 2
    half = np.full(fh, -1, dtype=np.int64)
    for i in range(fh):
        for j in range(footprint.shape[1]):
            if footprint[i, j]:
                half[i] = max(half[i], j - footprint.shape[1] // 2)
    need = 0
    for i in range(fh):
        if half[i] >= 0:
            need += 1
    out = np.empty((h * ((w + 1) // 2) + 1, 3), dtype=np.int64)
    out_first = np.zeros(h + 1, dtype=np.int64)
    n = 0
    count = np.zeros(w + 1, dtype=np.int64)
    for r in range(h):
        out_first[r] = n
        count[:] = 0
        inside = True
        for i in range(fh):
            a = half[i]
            if a < 0:
                continue
            rr = r + i - centre
            if rr < 0 or rr >= h:
                inside = False
                break
            for k in range(first[rr], first[rr + 1]):
                s, e = runs[k, 1] + a, runs[k, 2] - a
                if s < e:
                    count[s] += 1
                    count[e] -= 1
        if not inside:
            continue
        acc = 0
        start = -1
        for c in range(w):
            acc += count[c]
            if acc == need:
                if start < 0:
                    start = c
            elif start >= 0:
                out[n, 0], out[n, 1], out[n, 2] = r, start, c
                n += 1
                start = -1
        if start >= 0:
            out[n, 0], out[n, 1], out[n, 2] = r, start, w
            n += 1
    out_first[h] = n
    return out[:n], out_first


@njit(cache=True, nogil=True)
def _clean_free(given, max_hole, footprint, min_cells):
    """On horizontal runs: the non-free runs of ``given`` and their components (holes), the
    free runs of the filled mask as the gaps between the holes kept, eroded run by run, their
    components, and the mask painted from the runs kept (one scan of the image in all)."""
    h, w = given.shape
    if max_hole > 0:
        holes, holes_first = _row_runs(given, False)
        root, size = _join_runs(holes, holes_first, h)
        keep = np.empty(len(holes), dtype=np.bool_)
        for k in range(len(holes)):
            keep[k] = size[root[k]] > max_hole
        runs, first = _gaps(holes, holes_first, keep, h, w)
    else:
        runs, first = _row_runs(given, True)
    if footprint.size:
        runs, first = _erode_runs(runs, first, h, w, footprint)
    root = np.zeros(len(runs), dtype=np.int64)
    size = np.zeros(len(runs), dtype=np.int64)
    if min_cells > 0:
        root, size = _join_runs(runs, first, h)
    out = np.zeros((h, w), dtype=np.bool_)
    flat = out.ravel()
    for k in range(len(runs)):
        if min_cells > 0 and size[root[k]] < min_cells:
            continue
        base = runs[k, 0] * w
        for c in range(runs[k, 1], runs[k, 2]):
            flat[base + c] = True
    return out


_NO_FOOTPRINT = np.zeros((0, 0), dtype=np.bool_)


def clean_free(given: np.ndarray, max_hole: int, footprint: np.ndarray | None,
               min_cells: float) -> np.ndarray:
    """Free space cleaned as in :func:`clean_free_reference`, in a new array."""
    fp = _NO_FOOTPRINT if footprint is None else np.ascontiguousarray(footprint, dtype=np.bool_)
    return _clean_free(given, int(max_hole), fp, float(min_cells))


def clean_free_reference(given: np.ndarray, max_hole: int, footprint: np.ndarray | None,
                         min_cells: float) -> np.ndarray:
    """The library path of :func:`clean_free`: holes of ``given`` (4-connected non-free
    components) of at most ``max_hole`` cells filled (skimage ``remove_small_holes``; 0 = none),
    eroded by ``footprint`` (scipy ``binary_erosion``, outside the array non-free; ``None`` =
    none), 4-connected components of fewer than ``min_cells`` cells dropped (0 = none)."""
    from scipy import ndimage
    from skimage.morphology import remove_small_holes

    free = given
    if max_hole > 0:
        free = remove_small_holes(free, max_size=max_hole)
    if footprint is not None:
        free = ndimage.binary_erosion(free, structure=footprint)
    if min_cells > 0:
        labels, n = ndimage.label(free)
        if n:
            sizes = np.bincount(labels.ravel(), minlength=n + 1)
            small = sizes < min_cells
            small[0] = False
            free = free & ~small[labels]
    return free


@njit(cache=True, nogil=True)
def _free_box(mask):
    """Rows ``r0:r1`` and columns ``c0:c1`` of the free cells' bounding box grown by one cell
    (within the mask); ``r1 == 0`` when nothing is free. Each row is scanned from both ends to
    its first and last free cell."""
    h, w = mask.shape
    r_lo, r_hi, c_lo, c_hi = h, -1, w, -1
    for r in range(h):
        lo = 0
        while lo < w and not mask[r, lo]:
            lo += 1
        if lo == w:
            continue
        hi = w - 1
        while not mask[r, hi]:
            hi -= 1
        r_lo = min(r_lo, r)
        r_hi = r
        c_lo = min(c_lo, lo)
        c_hi = max(c_hi, hi)
    if r_hi < 0:
        return 0, 0, 0, 0
    return max(r_lo - 1, 0), min(r_hi + 2, h), max(c_lo - 1, 0), min(c_hi + 2, w)


def free_crop(mask: np.ndarray) -> tuple[np.ndarray, int, int]:
    """The 2-D boolean ``mask`` cropped to its free cells' bounding box grown by one cell (within
    the mask), padded with a border of non-free cells, and the crop's first row and column in
    ``mask``; an empty ``(0, 0)`` array when nothing is free (:func:`free_crop_reference`). The
    box by a compiled scan, the copy by numpy."""
    mask = np.ascontiguousarray(mask, dtype=np.bool_)
    r0, r1, c0, c1 = _free_box(mask)
    if r1 == 0:
        return np.zeros((0, 0), dtype=bool), 0, 0
    out = np.zeros((r1 - r0 + 2, c1 - c0 + 2), dtype=bool)
    out[1:-1, 1:-1] = mask[r0:r1, c0:c1]
    return out, int(r0), int(c0)


def free_crop_reference(mask: np.ndarray) -> tuple[np.ndarray, int, int]:
    """The numpy form of :func:`free_crop`."""
    rows = np.flatnonzero(mask.any(axis=1))
    if len(rows) == 0:
        return np.zeros((0, 0), dtype=bool), 0, 0
    cols = np.flatnonzero(mask.any(axis=0))
    r0, c0 = max(rows[0] - 1, 0), max(cols[0] - 1, 0)
    return np.pad(mask[r0: rows[-1] + 2, c0: cols[-1] + 2], 1), int(r0), int(c0)


@njit(cache=True, nogil=True)
def _is_wall(free, r, c):
    h, w = free.shape
    if r < 0 or r >= h or c < 0 or c >= w or free[r, c]:
        return False
    return ((r > 0 and free[r - 1, c]) or (r + 1 < h and free[r + 1, c])
            or (c > 0 and free[r, c - 1]) or (c + 1 < w and free[r, c + 1]))


@njit(cache=True, nogil=True)
def _ring_min(free, pr, pc, ir, ic, d, best):
    """``best`` lowered by the squared distances from ``(pr, pc)`` to the wall pixels at
    Chebyshev distance ``d`` from pixel ``(ir, ic)``."""
    for c in range(ic - d, ic + d + 1):
        for r in (ir - d, ir + d):
            if _is_wall(free, r, c):
                best = min(best, (r - pr) * (r - pr) + (c - pc) * (c - pc))
            if d == 0:
                break
    for r in range(ir - d + 1, ir + d):
        for c in (ic - d, ic + d):
            if _is_wall(free, r, c):
                best = min(best, (r - pr) * (r - pr) + (c - pc) * (c - pc))
    return best


@njit(cache=True, nogil=True)
def _wall_distances(free, points):
    h, w = free.shape
    out = np.empty(points.shape[0])
    for k in range(points.shape[0]):
        pr, pc = points[k, 0], points[k, 1]
        ir, ic = int(round(pr)), int(round(pc))
        best = np.inf
        d = 0
        # square rings around the point's pixel (at most half a pixel from the point): a wall
        # in ring d or beyond is at least d - 0.5 away
        while best > (d - 0.5) * (d - 0.5) and d <= h + w + abs(ir) + abs(ic):
            best = _ring_min(free, pr, pc, ir, ic, d, best)
            d += 1
        out[k] = math.sqrt(best)
    return out


def wall_distances(free: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Distance (pixels) from each ``(row, col)`` of ``points`` ``(K, 2)`` to the nearest
    non-free pixel 4-adjacent to a free one: the radius of the largest free disc there (``inf``
    without such pixels)."""
    return _wall_distances(free, np.ascontiguousarray(points, dtype=np.float64))


def wall_distances_reference(free: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The library path of :func:`wall_distances`: a scipy ``cKDTree`` of the wall pixels."""
    from scipy.spatial import cKDTree

    near = np.zeros_like(free)
    near[1:] |= free[:-1]
    near[:-1] |= free[1:]
    near[:, 1:] |= free[:, :-1]
    near[:, :-1] |= free[:, 1:]
    return cKDTree(np.argwhere(near & ~free)).query(points)[0]


@njit(cache=True, nogil=True)
def path_lengths(points, bounds):
    """:func:`polyline_length` of each ``points[bounds[k]:bounds[k + 1]]``."""
    out = np.empty(len(bounds) - 1, dtype=np.float64)
    for k in range(len(bounds) - 1):
        out[k] = polyline_length(points[bounds[k]: bounds[k + 1]])
    return out


@njit(cache=True, nogil=True)
def _find(parent, v):
    root = v
    while parent[root] != root:
        root = parent[root]
    while parent[v] != root:
        up = parent[v]
        parent[v] = root
        v = up
    return root


@njit(cache=True, nogil=True)
def _pixel_graph(skel, dr, dc):
    """Pixel ids (raveled order), coordinates ``(N, 2)`` and the CSR neighbour lists
    (``indptr``, ``indices``; neighbours by increasing id; ``diag``: the step is diagonal) of
    the 8-connected pixel graph of ``skel``."""
    h, w = skel.shape
    flat = skel.ravel()
    where = np.empty(h * w, dtype=np.int64)
    n = 0
    for i in range(h * w):
        if flat[i]:
            where[n] = i
            n += 1
    ids = np.empty(h * w, dtype=np.int64)  # set (and read) at skeleton pixels only
    for p in range(n):
        ids[where[p]] = p
    coords = np.empty((n, 2), dtype=np.float64)
    indptr = np.zeros(n + 1, dtype=np.int64)
    indices = np.empty(8 * n, dtype=np.int64)
    diag = np.empty(8 * n, dtype=np.bool_)
    k = 0
    for p in range(n):
        r, c = where[p] // w, where[p] % w
        coords[p, 0] = r
        coords[p, 1] = c
        for j in range(8):
            rr, cc = r + dr[j], c + dc[j]
            if 0 <= rr < h and 0 <= cc < w and flat[rr * w + cc]:
                indices[k] = ids[rr * w + cc]
                diag[k] = dr[j] != 0 and dc[j] != 0
                k += 1
        indptr[p + 1] = k
    return coords, indptr, indices[:k], diag[:k]


@njit(cache=True, nogil=True)
def _junction_trees(indptr, indices, diag):
    """Which CSR entries survive when every cluster of junction pixels (degree ≥ 3) keeps only
    its minimum spanning tree: scipy's Kruskal (edges by weight, stable in CSR order, so the
    straight steps of weight 1 before the diagonal ones of weight √2)."""
    n = len(indptr) - 1
    m = len(indices)
    deg = indptr[1:] - indptr[:-1]
    keep = np.ones(m, dtype=np.bool_)
    inner = np.zeros(m, dtype=np.bool_)
    for p in range(n):
        if deg[p] >= 3:
            for k in range(indptr[p], indptr[p + 1]):
                inner[k] = deg[indices[k]] >= 3
    parent = np.arange(n)
    tree = np.zeros(m, dtype=np.bool_)
    for want_diag in (False, True):
        for p in range(n):
            for k in range(indptr[p], indptr[p + 1]):
                if inner[k] and diag[k] == want_diag:
                    a, b = _find(parent, p), _find(parent, indices[k])
                    if a != b:
                        parent[b] = a
                        tree[k] = True
    for p in range(n):
        for k in range(indptr[p], indptr[p + 1]):
            if inner[k] and not tree[k]:
                q = indices[k]
                # kept if the tree holds the edge in either direction
                found = False
                for kk in range(indptr[q], indptr[q + 1]):
                    if indices[kk] == p and tree[kk]:
                        found = True
                keep[k] = found
    return keep


@njit(cache=True, nogil=True)
def _trace(indptr, indices, keep):
    """skan's ``_build_paths`` on the kept entries: paths from every end or junction pixel along
    each unvisited neighbour, then the isolated cycles; returns ``(bounds, pixels)``."""
    n = len(indptr) - 1
    m = len(indices)
    # compact the kept entries
    kptr = np.zeros(n + 1, dtype=np.int64)
    kidx = np.empty(m, dtype=np.int64)
    j = 0
    for p in range(n):
        for k in range(indptr[p], indptr[p + 1]):
            if keep[k]:
                kidx[j] = indices[k]
                j += 1
        kptr[p + 1] = j
    kidx = kidx[:j]
    deg = kptr[1:] - kptr[:-1]
    visited = np.zeros(j, dtype=np.bool_)
    out = np.empty(j + n + 1, dtype=np.int64)
    bounds = np.zeros(j + 2, dtype=np.int64)
    n_paths = 0
    pos = 0
    for phase in range(2):
        for p in range(n):
            if phase == 0 and not (deg[p] > 2 or deg[p] == 1):
                continue
            if phase == 1 and deg[p] == 0:
                continue
            last = kptr[p + 1] if phase == 0 else kptr[p] + 1
            for e in range(kptr[p], last):
                if visited[e]:
                    continue
                start = p
                node = p
                nb = kidx[e]
                ee = e
                out[pos] = node
                pos += 1
                while not visited[ee]:
                    visited[ee] = True
                    for back in range(kptr[nb], kptr[nb + 1]):
                        if kidx[back] == node:
                            visited[back] = True
                    out[pos] = nb
                    pos += 1
                    if deg[nb] != 2 or nb == start:
                        break
                    a0 = kidx[kptr[nb]]
                    nxt = a0 if a0 != node else kidx[kptr[nb] + 1]
                    node = nb
                    nb = nxt
                    for cand in range(kptr[node], kptr[node + 1]):
                        if kidx[cand] == nb:
                            ee = cand
                n_paths += 1
                bounds[n_paths] = pos
    return bounds[: n_paths + 1], out[:pos]


@njit(cache=True, nogil=True)
def _skeleton_paths(skel, dr, dc):
    coords, indptr, indices, diag = _pixel_graph(skel, dr, dc)
    keep = _junction_trees(indptr, indices, diag)
    bounds, pixels = _trace(indptr, indices, keep)
    return coords, bounds, pixels


def skeleton_paths(skel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixel coordinates ``(N, 2)`` (float, raveled order) of the 2-D boolean skeleton ``skel``
    and its paths as ``bounds`` (``P + 1``) and ``pixels``: path ``k`` is
    ``pixels[bounds[k]:bounds[k + 1]]``, pixel indices into the coordinates, exactly skan's
    ``PathGraph`` paths of the junction-tree pixel graph (no paths when no pixel has a
    neighbour)."""
    return _skeleton_paths(skel, _DR, _DC)


@njit(cache=True, nogil=True)
def peaks(turn, candidate, group):
    """Corner step 6 of ``extract_topomap``: one index per run of consecutive ``candidate``
    points within one ``group`` (polyline), its sharpest point by ``turn``, the middle one if
    several are as sharp (within 1e-9)."""
    out = np.empty(len(turn), dtype=np.int64)
    n = 0
    i = 0
    size = len(turn)
    while i < size:
        if not candidate[i]:
            i += 1
            continue
        j = i + 1
        while j < size and candidate[j] and group[j] == group[i]:
            j += 1
        top = turn[i]
        for k in range(i + 1, j):
            top = max(top, turn[k])
        sharp = 0
        for k in range(i, j):
            if turn[k] >= top - 1e-9:
                sharp += 1
        want = sharp // 2
        for k in range(i, j):
            if turn[k] >= top - 1e-9:
                if want == 0:
                    out[n] = k
                    n += 1
                    break
                want -= 1
        i = j
    return out[:n]


@njit(cache=True, nogil=True)
def path_nodes(n_pixels, bounds, pixels):
    """The graph of traced paths: node pixels in order of first appearance as a path end
    (start, end, next path...), then the pixels on no path in increasing order (a tiny blob's
    single pixel); each path's ``(start, end)`` node numbers ``(P, 2)``."""
    node_of = np.full(n_pixels, -1, dtype=np.int64)
    order = np.empty(n_pixels, dtype=np.int64)
    n = 0
    n_paths = len(bounds) - 1
    ends = np.empty((n_paths, 2), dtype=np.int64)
    for k in range(n_paths):
        for j, p in enumerate((pixels[bounds[k]], pixels[bounds[k + 1] - 1])):
            if node_of[p] < 0:
                node_of[p] = n
                order[n] = p
                n += 1
            ends[k, j] = node_of[p]
    on_path = np.zeros(n_pixels, dtype=np.bool_)
    for p in pixels:
        on_path[p] = True
    for p in range(n_pixels):
        if not on_path[p]:
            order[n] = p
            n += 1
    return order[:n], ends


def skan_paths(skel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The reference of :func:`skeleton_paths`: the same ``(coords, bounds, pixels)`` from
    ``skan.csr.Skeleton`` itself (slow: skan walks every pixel in Python). Tests only."""
    from skan.csr import Skeleton

    coords = np.argwhere(skel).astype(np.float64)
    if len(coords) == 0:
        return coords, np.zeros(1, dtype=np.int64), np.zeros(0, dtype=np.int64)
    h, w = skel.shape
    padded = np.pad(skel, 1).astype(np.int64)
    around = sum(padded[1 + dr: 1 + dr + h, 1 + dc: 1 + dc + w]
                 for dr in (-1, 0, 1) for dc in (-1, 0, 1)) - padded[1:-1, 1:-1]
    if not around[skel].any():  # isolated pixels only: skan raises, there are no paths
        return coords, np.zeros(1, dtype=np.int64), np.zeros(0, dtype=np.int64)
    ref = Skeleton(skel, keep_images=False)
    paths = [np.asarray(p, dtype=np.int64) for p in ref.paths_list()]
    bounds = np.concatenate([[0], np.cumsum([len(p) for p in paths])]).astype(np.int64)
    return np.asarray(ref.coordinates, dtype=np.float64), bounds, np.concatenate(paths)


@njit(cache=True, nogil=True)
def metre_paths(cells, sizes, ends, xy, res, ox, oy):
    """The output polylines of ``extract_topomap``: the concatenated pixel polylines ``cells``
    (``sizes`` points each, ``(row, col)``) in metres (``o + (col|row + 0.5) · res``), each
    with its first and last point moved onto its end nodes ``xy[ends[k]]`` and, when
    ``ends[k, 0] > ends[k, 1]``, turned round; returns them concatenated and
    :func:`polyline_length` of each (what ``topo.extract._to_topomap_loop`` computes edge by
    edge)."""
    out = np.empty_like(cells)
    lengths = np.empty(len(sizes), dtype=np.float64)
    start = 0
    for k in range(len(sizes)):
        n = sizes[k]
        stop = start + n
        flip = ends[k, 0] > ends[k, 1]
        for i in range(n):
            j = stop - 1 - i if flip else start + i
            out[j, 0] = ox + (cells[start + i, 1] + 0.5) * res
            out[j, 1] = oy + (cells[start + i, 0] + 0.5) * res
        a, b = (stop - 1, start) if flip else (start, stop - 1)
        out[a, 0], out[a, 1] = xy[ends[k, 0], 0], xy[ends[k, 0], 1]
        out[b, 0], out[b, 1] = xy[ends[k, 1], 0], xy[ends[k, 1], 1]
        lengths[k] = polyline_length(out[start:stop])
        start = stop
    return out, lengths


@njit(cache=True, nogil=True)
def _lex_order(primary, secondary):
    """``np.lexsort((secondary, primary))``: indices by ``primary``, then ``secondary``, then
    index (two stable sorts)."""
    first = np.argsort(secondary, kind="mergesort")
    return first[np.argsort(primary[first], kind="mergesort")]


@njit(cache=True, nogil=True)
def topomap_arrays(rc, ids, ends, cells, sizes, res, ox, oy):
    """The arrays of ``extract_topomap``'s output from the cleaned-up graph: nodes ``ids`` at
    pixel positions ``rc`` ``(N, 2)``, paths from node ``ends[k, 0]`` to ``ends[k, 1]`` (ids)
    along the concatenated pixel polylines ``cells`` (``sizes`` points each). Returns the
    node positions in metres sorted by ``y``, then ``x`` (``topo.extract._node_order``); the
    paths sorted by their ends' new indices (stable), as sorted index pairs ``(E, 2)``; their
    :func:`metre_paths` polylines and lengths, their sizes; and ``near``: the paths whose
    length does not clearly exceed their chord, the only ones where the chord's ulps (numpy's
    ``dot``, which the caller takes) can be the path's length."""
    n = len(rc)
    x = np.empty(n, dtype=np.float64)
    y = np.empty(n, dtype=np.float64)
    for i in range(n):
        x[i] = ox + (rc[i, 1] + 0.5) * res
        y[i] = oy + (rc[i, 0] + 0.5) * res
    order = _lex_order(y, x)
    xy = np.empty((n, 2), dtype=np.float64)
    slot = np.full(ids.max() + 1, -1, dtype=np.int64)
    for i in range(n):
        xy[i, 0], xy[i, 1] = x[order[i]], y[order[i]]
        slot[ids[order[i]]] = i
    m = len(sizes)
    iu = np.empty(m, dtype=np.int64)
    iv = np.empty(m, dtype=np.int64)
    first = np.empty(m, dtype=np.int64)
    start = 0
    for k in range(m):
        iu[k], iv[k] = slot[ends[k, 0]], slot[ends[k, 1]]
        first[k] = start
        start += sizes[k]
    by = _lex_order(iu, iv)
    moved = np.empty_like(cells)
    new_ends = np.empty((m, 2), dtype=np.int64)
    new_sizes = np.empty(m, dtype=np.int64)
    pos = 0
    for j in range(m):
        k = by[j]
        new_ends[j, 0], new_ends[j, 1] = iu[k], iv[k]
        new_sizes[j] = sizes[k]
        moved[pos: pos + sizes[k]] = cells[first[k]: first[k] + sizes[k]]
        pos += sizes[k]
    metres, lengths = metre_paths(moved, new_sizes, new_ends, xy, res, ox, oy)
    pairs = np.empty((m, 2), dtype=np.int64)
    near = np.empty(m, dtype=np.bool_)
    for j in range(m):
        a, b = min(new_ends[j, 0], new_ends[j, 1]), max(new_ends[j, 0], new_ends[j, 1])
        pairs[j, 0], pairs[j, 1] = a, b
        d0, d1 = xy[a, 0] - xy[b, 0], xy[a, 1] - xy[b, 1]
        # a chord computed in any order is within a few ulps of this one
        near[j] = not lengths[j] > math.sqrt(d0 * d0 + d1 * d1) * (1.0 + 1e-12)
    return xy, pairs, metres, lengths, near, new_sizes


# Zhang–Suen thinning as ``skimage.morphology.skeletonize`` (2-D, method "zhang") does it.
# Lookup table from scikit-image, BSD-3-Clause (Copyright (C) 2011, the scikit-image team):
# entry ``n`` is a pixel's value for the 8-neighbour code ``n`` (bits 1 NW, 2 N, 4 NE, 8 E,
# 16 SE, 32 S, 64 SW, 128 W, row 0 on top); value 1 is removed in the first subpass of an
# iteration, 2 in the second, 3 in both, 0 never. skimage keeps this table only in its compiled
# module, so it was derived from skimage's own outputs (``tests/topo/zhang_lut_derivation.py``:
# every image up to 4×4 and random images around each remaining pattern, each entry fixed only
# when every assignment of the unknown entries consistent with skimage's output agrees on it;
# entry 10 is not fixed that way, and that script shows the output is the same for each of its
# removable values 1, 2 and 3; 3 is its rotations' value).
_ZHANG_LUT = np.array([
    0, 0, 0, 1, 0, 0, 1, 3, 0, 0, 3, 1, 1, 0, 1, 3, 0, 0, 0, 0, 0, 0, 0, 0, 2, 0, 2, 0, 3, 0, 3, 3,
    0, 0, 0, 0, 0, 0, 0, 0, 3, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 2, 0, 0, 0, 3, 0, 2, 2,
    0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
    2, 0, 0, 0, 0, 0, 0, 0, 2, 0, 0, 0, 2, 0, 0, 0, 3, 0, 0, 0, 0, 0, 0, 0, 3, 0, 0, 0, 3, 0, 2, 0,
    0, 0, 3, 1, 0, 0, 1, 3, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1,
    3, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 2, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
    2, 3, 1, 3, 0, 0, 1, 3, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
    2, 3, 0, 1, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 3, 3, 0, 1, 0, 0, 0, 0, 2, 2, 0, 0, 2, 0, 0, 0,
], dtype=np.uint8)


@njit(cache=True, nogil=True)
def _code(sk, k, wp):
    """The 8-neighbour code of flat pixel ``k`` of the padded image ``sk`` (row length ``wp``)."""
    return (sk[k - wp - 1] + 2 * sk[k - wp] + 4 * sk[k - wp + 1] + 8 * sk[k + 1]
            + 16 * sk[k + wp + 1] + 32 * sk[k + wp] + 64 * sk[k + wp - 1] + 128 * sk[k - 1])


@njit(cache=True, nogil=True)
def _zhang(image, lut):
    h, w = image.shape
    wp = w + 2
    total = (h + 2) * wp
    sk = np.zeros(total, dtype=np.uint8)
    for r in range(h):
        base = (r + 1) * wp + 1
        for c in range(w):
            if image[r, c]:
                sk[base + c] = 1
    # the candidates: pixels that may be removed in a coming subpass, with bit p + 1 of ``due``
    # set while subpass p has yet to examine them. A pixel is listed for a subpass only if its
    # table value removes it there or a neighbour went since it was examined (at first: every
    # pixel whose table value is not 0; an interior pixel, code 255, has value 0)
    cand = np.empty(total, dtype=np.int64)
    due = np.zeros(total, dtype=np.uint8)
    code = np.zeros(total, dtype=np.uint8)  # each pixel's 8-neighbour code, kept up to date
    n = 0
    for k in range(wp, total - wp):
        if sk[k]:
            code[k] = _code(sk, k, wp)
            if lut[code[k]]:
                cand[n] = k
                n += 1
                due[k] = 3
    gone = np.empty(total, dtype=np.int64)
    # neighbour k + offsets[t] sees pixel k in the direction whose code bit ``keep[t]`` clears
    offsets = np.array([-wp - 1, -wp, -wp + 1, 1, wp + 1, wp, wp - 1, -1], dtype=np.int64)
    keep = np.array([255 - 16, 255 - 32, 255 - 64, 255 - 128, 255 - 1, 255 - 2, 255 - 4,
                     255 - 8], dtype=np.uint8)
    removed_any = False
    p = 0
    while True:
        bit = p + 1
        other = 2 - p
        ngone = 0
        kept = 0
        for i in range(n):  # decisions on the state at the subpass's start
            k = cand[i]
            d = due[k]
            if d & bit:
                v = lut[code[k]]
                if v & bit:
                    gone[ngone] = k
                    ngone += 1
                    d = 0
                elif v & other:  # the other subpass removes it unless a neighbour goes first
                    d = other
                else:  # kept by both unless a neighbour goes (which lists it again)
                    d = 0
                due[k] = d
            if d:
                cand[kept] = k
                kept += 1
        n = kept
        for i in range(ngone):
            sk[gone[i]] = 0
        for i in range(ngone):  # only pixels beside a removed one can change their decision
            g = gone[i]
            for t in range(8):
                j = g + offsets[t]
                code[j] &= keep[t]
                if sk[j]:
                    if due[j] == 0:
                        cand[n] = j
                        n += 1
                    due[j] = 3
        removed_any |= ngone > 0
        if p == 1:
            if not removed_any:
                break
            removed_any = False
        p = 1 - p
    out = np.empty((h, w), dtype=np.bool_)
    for r in range(h):
        base = (r + 1) * wp + 1
        for c in range(w):
            out[r, c] = sk[base + c] != 0
    return out


def skeletonize(mask: np.ndarray) -> np.ndarray:
    """``skimage.morphology.skeletonize(mask)`` of a 2-D boolean mask (Zhang–Suen thinning,
    skimage's default for 2-D), bit for bit, with the lookup table from scikit-image
    (BSD-3-Clause; see ``_ZHANG_LUT``). skimage rescans the whole image in every subpass; this
    re-examines only pixels beside one removed in the previous subpasses (a kept pixel whose
    neighbourhood did not change keeps its decision; one that the table keeps in both subpasses
    waits for a neighbour to go), so thin free space costs about its border, not its area times
    the iterations. Tested against skimage itself in ``tests/topo``
    (hypothesis masks, every image up to 4×4) and ``tests/envs`` (every extraction of an env
    episode)."""
    return _zhang(np.ascontiguousarray(mask, dtype=np.bool_), _ZHANG_LUT)


@njit(cache=True, nogil=True)
def corner_arms(points, lens, arm):
    """Corner step 6 of ``extract_topomap`` on the open polylines ``points`` (concatenated,
    ``lens`` points each), up to the turn's ``arctan2`` (numpy's, applied by the caller):
    the arc length ``arc`` (a gap of ``2·arm + 1`` between polylines) and at each point the
    cross and dot products of the chords from the point ``arm`` before it to it and from it
    to the point ``arm`` after it (clipped to its polyline): the arithmetic of
    ``topo.extract._open_corners_numpy``."""
    n = len(points)
    arc = np.empty(n, dtype=np.float64)
    lo = np.empty(n, dtype=np.int64)
    hi = np.empty(n, dtype=np.int64)
    start = 0
    total = 0.0
    for k in range(len(lens)):
        for i in range(start, start + lens[k]):
            if i == 0:
                step = 0.0
            elif i == start:
                step = 2.0 * arm + 1.0
            else:
                dx = points[i, 0] - points[i - 1, 0]
                dy = points[i, 1] - points[i - 1, 1]
                step = math.sqrt(dx * dx + dy * dy)
            total += step
            arc[i] = total
            lo[i], hi[i] = start, start + lens[k] - 1
        start += lens[k]
    cross = np.empty(n, dtype=np.float64)
    dot = np.empty(n, dtype=np.float64)
    # np.searchsorted of arc[i] -/+ arm, which grow with i: two pointers that only move on
    le = lt = 0  # how many arc values are <= arc[i] - arm, and < arc[i] + arm
    for i in range(n):
        v, u = arc[i] - arm, arc[i] + arm
        while le < n and arc[le] <= v:
            le += 1
        while lt < n and arc[lt] < u:
            lt += 1
        back = max(le - 1, lo[i])
        ahead = min(lt, hi[i])
        a0 = points[i, 0] - points[back, 0]
        a1 = points[i, 1] - points[back, 1]
        b0 = points[ahead, 0] - points[i, 0]
        b1 = points[ahead, 1] - points[i, 1]
        cross[i] = a0 * b1 - a1 * b0
        dot[i] = (0.0 + a0 * b0) + a1 * b1  # numpy's sum over a row starts from +0.0
    return arc, cross, dot


@njit(cache=True, nogil=True)
def corner_cuts(turn, arc, lens, min_turn, margin):
    """The corner pixels of each open polyline from :func:`corner_arms`' ``arc`` and the turns:
    :func:`peaks` of the points turning by more than ``min_turn`` at least ``margin`` from
    their polyline's ends, as indices into their own polyline (ascending) and the count per
    polyline."""
    n = len(turn)
    group = np.empty(n, dtype=np.int64)
    candidate = np.empty(n, dtype=np.bool_)
    start = 0
    for k in range(len(lens)):
        stop = start + lens[k]
        for i in range(start, stop):
            group[i] = k
            candidate[i] = (turn[i] > min_turn and arc[i] - arc[start] >= margin
                            and arc[stop - 1] - arc[i] >= margin)
        start = stop
    at = peaks(turn, candidate, group)
    first = np.empty(len(lens), dtype=np.int64)
    start = 0
    for k in range(len(lens)):
        first[k] = start
        start += lens[k]
    counts = np.zeros(len(lens), dtype=np.int64)
    cuts = np.empty(len(at), dtype=np.int64)
    for j in range(len(at)):
        g = group[at[j]]
        cuts[j] = at[j] - first[g]
        counts[g] += 1
    return cuts, counts


# ---------------------------------------------------------------- the clean-up
# The clean-up of :func:`topo.extract.extract_topomap` (steps 4–7 and the output) compiled:
# ``topo.extract._Graph``'s passes on arrays, in two numba kernels around numpy's ``arctan2``
# (:func:`graph_first`: the graph, spurs, degree-two nodes, short paths, and the corner step's
# chord products; :func:`graph_second`: corner cuts and splits, again degree-two nodes and short
# paths, loops, snapping, and :func:`topo._extract_kernels.topomap_arrays`). They give bit for bit
# the map of the Python passes (``topo.extract._graph_topomap_reference``), which ``tests/topo``
# compares on hypothesis masks and on every extraction of env episodes.
#
# The passes' results depend on the order in which they visit a node's paths (which of a
# degree-two node's two paths comes first sets the joined polyline's direction, and so later
# floats and choices). ``_Graph`` makes that order explicit: ascending path id (``paths_of``), as
# for the nodes and paths themselves (``range`` over the tables here, its dicts there). So
# each node's paths are kept here in ascending id in its row of ``inc`` (the first ``DEG`` entries
# of a fixed-width row): a new path always has the highest id yet, so adding appends it (once for
# a loop), and removing one shifts the later ones down.
#
# The kernels are pure: arrays have fixed capacities (nodes, paths, points, and the width of the
# ``inc`` rows), and a pass that would overflow one sets a flag and stops, so that the caller
# (:mod:`topo.extract`) runs the kernel again with larger ones.

# columns of the node table ``ni``
ALIVE, MASS, CORNER, DEG = range(4)
# columns of the edge table ``ei``
EALIVE, EU, EV, POFF, PLEN = range(5)
# the counters ``cnt``
N_NODES, N_EDGES, N_PTS, OVER = range(4)


@njit(cache=True, nogil=True)
def _attach(ni, inc, cnt, n, e):
    """Path ``e``, the highest id yet, joins node ``n``'s row (once: a loop is attached twice);
    a full row sets ``cnt[OVER]`` instead."""
    d = ni[n, DEG]
    if d and inc[n, d - 1] == e:
        return
    if d == inc.shape[1]:
        cnt[OVER] = 1
        return
    inc[n, d] = e
    ni[n, DEG] = d + 1


@njit(cache=True, nogil=True)
def _detach(ni, inc, n, e):
    """Path ``e`` leaves node ``n``'s row (if there), the later ones move down."""
    d = ni[n, DEG]
    for i in range(d):
        if inc[n, i] == e:
            for j in range(i + 1, d):
                inc[n, j - 1] = inc[n, j]
            ni[n, DEG] = d - 1
            return


@njit(cache=True, nogil=True)
def _add_node(ni, pos, cnt, r, c):
    n = cnt[N_NODES]
    if n >= len(ni):
        cnt[OVER] = 1
        return -1
    cnt[N_NODES] = n + 1
    ni[n, ALIVE], ni[n, MASS], ni[n, CORNER], ni[n, DEG] = 1, 1, 0, 0
    pos[n, 0], pos[n, 1] = r, c
    return n


@njit(cache=True, nogil=True)
def _add_edge(ni, ei, elen, pts, inc, cnt, u, v, off, size):
    e = cnt[N_EDGES]
    if e >= len(ei):
        cnt[OVER] = 1
        return -1
    cnt[N_EDGES] = e + 1
    ei[e, EALIVE], ei[e, EU], ei[e, EV], ei[e, POFF], ei[e, PLEN] = 1, u, v, off, size
    elen[e] = polyline_length(pts[off: off + size])
    _attach(ni, inc, cnt, u, e)
    _attach(ni, inc, cnt, v, e)
    return e


@njit(cache=True, nogil=True)
def _remove_edge(ni, ei, inc, e):
    ei[e, EALIVE] = 0
    _detach(ni, inc, ei[e, EU], e)
    _detach(ni, inc, ei[e, EV], e)


@njit(cache=True, nogil=True)
def _is_free(given, r, c):
    return given[math.floor(r + 0.5), math.floor(c + 0.5)]


@njit(cache=True, nogil=True)
def _dissolve(ni, ei, elen, pts, inc, cnt, n):
    """``_Graph.dissolve``: join the two paths of an alive, non-corner degree-two node."""
    if not ni[n, ALIVE] or ni[n, CORNER] or ni[n, DEG] != 2:
        return
    ea, eb = inc[n, 0], inc[n, 1]  # ascending id
    if ei[ea, EU] == ei[ea, EV] or ei[eb, EU] == ei[eb, EV]:
        return
    ua = ei[ea, EV] if ei[ea, EU] == n else ei[ea, EU]
    vb = ei[eb, EV] if ei[eb, EU] == n else ei[eb, EU]
    la, lb = ei[ea, PLEN], ei[eb, PLEN]
    off = cnt[N_PTS]
    size = la + lb - 1
    if off + size > len(pts) or cnt[N_EDGES] >= len(ei):
        cnt[OVER] = 1
        return
    cnt[N_PTS] = off + size
    a0, b0 = ei[ea, POFF], ei[eb, POFF]
    turn_a, turn_b = ei[ea, EU] == n, ei[eb, EU] != n
    for i in range(la):  # path a, ending at n
        j = a0 + (la - 1 - i if turn_a else i)
        pts[off + i, 0], pts[off + i, 1] = pts[j, 0], pts[j, 1]
    for i in range(1, lb):  # path b from n, without n
        j = b0 + (lb - 1 - i if turn_b else i)
        pts[off + la - 1 + i, 0], pts[off + la - 1 + i, 1] = pts[j, 0], pts[j, 1]
    _remove_edge(ni, ei, inc, ea)
    _remove_edge(ni, ei, inc, eb)
    ni[n, ALIVE], ni[n, CORNER] = 0, 0
    _add_edge(ni, ei, elen, pts, inc, cnt, ua, vb, off, size)


@njit(cache=True, nogil=True)
def _dissolve_all(ni, ei, elen, pts, inc, cnt):
    for n in range(cnt[N_NODES]):
        _dissolve(ni, ei, elen, pts, inc, cnt, n)
        if cnt[OVER]:
            return


@njit(cache=True, nogil=True)
def _prune_spurs(ni, ei, elen, pts, inc, cnt, radius, min_protrusion):
    """``_Graph.prune_spurs``."""
    leaves = np.empty(len(ei), dtype=np.int64)
    hubs = np.empty(len(ei), dtype=np.int64)
    while True:
        nd = 0
        for e in range(cnt[N_EDGES]):
            if not ei[e, EALIVE]:
                continue
            u, v = ei[e, EU], ei[e, EV]
            if u == v:
                continue
            du, dv = ni[u, DEG], ni[v, DEG]
            if du == 1 and dv >= 3:
                leaf, hub = u, v
            elif dv == 1 and du >= 3:
                leaf, hub = v, u
            else:
                continue
            inside = radius[hub] - radius[leaf]
            if 0.0 > inside:  # Python's max(inside, 0.0), nan included
                inside = 0.0
            if elen[e] - inside < min_protrusion:
                leaves[nd], hubs[nd] = leaf, hub
                nd += 1
        if nd == 0:
            return
        for k in range(nd):
            leaf = leaves[k]
            while ni[leaf, DEG]:  # its paths in ascending id
                _remove_edge(ni, ei, inc, inc[leaf, 0])
            ni[leaf, ALIVE], ni[leaf, CORNER] = 0, 0
        for k in range(nd):
            _dissolve(ni, ei, elen, pts, inc, cnt, hubs[k])
            if cnt[OVER]:
                return


@njit(cache=True, nogil=True)
def _merge_short(ni, pos, ei, elen, pts, inc, cnt, given, radius):
    """``_Graph.merge_short``."""
    m = cnt[N_EDGES]
    ids = np.empty(m, dtype=np.int64)
    k = 0
    for e in range(m):
        if ei[e, EALIVE]:
            ids[k] = e
            k += 1
    ids = ids[:k]
    ids = ids[np.argsort(elen[ids], kind="mergesort")]
    for e in ids:
        u, v = ei[e, EU], ei[e, EV]
        if not ei[e, EALIVE] or u == v or elen[e] >= radius:
            continue
        _remove_edge(ni, ei, inc, e)
        keep, drop = (u, v) if ni[u, DEG] >= ni[v, DEG] else (v, u)
        mk, md = ni[keep, MASS], ni[drop, MASS]
        r = (mk * pos[keep, 0] + md * pos[drop, 0]) / (mk + md)
        c = (mk * pos[keep, 1] + md * pos[drop, 1]) / (mk + md)
        if _is_free(given, r, c):
            pos[keep, 0], pos[keep, 1] = r, c
        while ni[drop, DEG]:  # its paths in ascending id; the new ones do not end at drop
            k = inc[drop, 0]
            ou, ov = ei[k, EU], ei[k, EV]
            _remove_edge(ni, ei, inc, k)
            _add_edge(ni, ei, elen, pts, inc, cnt, keep if ou == drop else ou,
                      keep if ov == drop else ov, ei[k, POFF], ei[k, PLEN])
            if cnt[OVER]:
                return
        ni[keep, MASS] = mk + md
        if ni[drop, CORNER]:
            ni[keep, CORNER] = 1
        ni[drop, ALIVE], ni[drop, CORNER] = 0, 0


@njit(cache=True, nogil=True)
def _split(ni, pos, ei, elen, pts, inc, cnt, e, cuts, at_start):
    """``_Graph._split``."""
    u, v, off, size = ei[e, EU], ei[e, EV], ei[e, POFF], ei[e, PLEN]
    _remove_edge(ni, ei, inc, e)
    if at_start:
        ni[u, CORNER] = 1
    prev, prev_cut = u, 0
    for c in cuts:
        node = _add_node(ni, pos, cnt, pts[off + c, 0], pts[off + c, 1])
        if node < 0:
            return
        ni[node, CORNER] = 1
        _add_edge(ni, ei, elen, pts, inc, cnt, prev, node, off + prev_cut, c + 1 - prev_cut)
        prev, prev_cut = node, c
    _add_edge(ni, ei, elen, pts, inc, cnt, prev, v, off + prev_cut, size - prev_cut)


@njit(cache=True, nogil=True)
def _degree(ei, inc, ni, n):
    d = 0
    for i in range(ni[n, DEG]):
        e = inc[n, i]
        d += 2 if ei[e, EU] == ei[e, EV] else 1
    return d


@njit(cache=True, nogil=True)
def _search_left(a, v):
    lo, hi = 0, len(a)
    while lo < hi:
        mid = (lo + hi) // 2
        if a[mid] < v:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True, nogil=True)
def _break_self_loops(ni, pos, ei, elen, pts, inc, cnt):
    """``_Graph.break_self_loops``."""
    m = cnt[N_EDGES]
    for e in range(m):
        if not ei[e, EALIVE] or ei[e, EU] != ei[e, EV]:
            continue
        off, size = ei[e, POFF], ei[e, PLEN]
        if size < 4:
            _remove_edge(ni, ei, inc, e)
            continue
        arc = np.empty(size, dtype=np.float64)
        arc[0] = 0.0
        for i in range(1, size):
            d0 = pts[off + i, 0] - pts[off + i - 1, 0]
            d1 = pts[off + i, 1] - pts[off + i - 1, 1]
            arc[i] = arc[i - 1] + math.sqrt(d0 * d0 + d1 * d1)
        c1 = min(max(_search_left(arc, arc[-1] * 1.0 / 3.0), 1), size - 2)
        c2 = min(max(_search_left(arc, arc[-1] * 2.0 / 3.0), 1), size - 2)
        cuts = np.array([c1]) if c1 == c2 else np.array([min(c1, c2), max(c1, c2)])
        _split(ni, pos, ei, elen, pts, inc, cnt, e, cuts, False)
        if cnt[OVER]:
            return


@njit(cache=True, nogil=True)
def _snap_to_free(ni, pos, ei, pts, inc, cnt, given):
    """``_Graph.snap_to_free``."""
    for n in range(cnt[N_NODES]):
        if not ni[n, ALIVE]:
            continue
        r, c = pos[n, 0], pos[n, 1]
        if _is_free(given, r, c):
            continue
        best, best_d = -1, np.inf
        for i in range(ni[n, DEG]):  # ascending id: ties go to the lowest-numbered path
            e = inc[n, i]
            off = ei[e, POFF]
            arg, d_min = -1, np.inf
            for i in range(off, off + ei[e, PLEN]):
                if _is_free(given, pts[i, 0], pts[i, 1]):
                    dr, dc = pts[i, 0] - r, pts[i, 1] - c
                    d = math.sqrt(dr * dr + dc * dc)
                    if arg < 0 or d < d_min:
                        arg, d_min = i, d
            if arg >= 0 and d_min < best_d:
                best, best_d = arg, d_min
        if best >= 0:
            pos[n, 0], pos[n, 1] = pts[best, 0], pts[best, 1]


@njit(cache=True, nogil=True)
def _state(node_rc, ends, points, bounds, lengths, caps):
    """``_Graph.start``: nodes ``0..N-1``, path ``k`` from ``ends[k, 0]`` to ``ends[k, 1]``
    along ``points[bounds[k]:bounds[k + 1]]``, in arrays of capacities ``caps`` (nodes, edges,
    points, ``inc`` row width)."""
    ni = np.zeros((caps[0], 4), dtype=np.int64)
    pos = np.empty((caps[0], 2), dtype=np.float64)
    ei = np.zeros((caps[1], 5), dtype=np.int64)
    elen = np.empty(caps[1], dtype=np.float64)
    pts = np.empty((caps[2], 2), dtype=np.float64)
    inc = np.empty((caps[0], caps[3]), dtype=np.int64)
    cnt = np.zeros(4, dtype=np.int64)
    if len(node_rc) > caps[0] or len(ends) > caps[1] or len(points) > caps[2]:
        cnt[OVER] = 1
        return ni, pos, ei, elen, pts, inc, cnt
    pts[: len(points)] = points
    cnt[N_PTS] = len(points)
    for n in range(len(node_rc)):
        if _add_node(ni, pos, cnt, node_rc[n, 0], node_rc[n, 1]) < 0:
            return ni, pos, ei, elen, pts, inc, cnt
    for k in range(len(ends)):
        u, v = ends[k, 0], ends[k, 1]
        ei[k, EALIVE], ei[k, EU], ei[k, EV] = 1, u, v
        ei[k, POFF], ei[k, PLEN] = bounds[k], bounds[k + 1] - bounds[k]
        elen[k] = lengths[k]
        _attach(ni, inc, cnt, u, k)
        _attach(ni, inc, cnt, v, k)
    cnt[N_EDGES] = len(ends)
    return ni, pos, ei, elen, pts, inc, cnt


@njit(cache=True, nogil=True)
def _open_and_loops(ei, pts, cnt):
    """The alive paths in id order split into open ones and loops: ids, and polylines
    concatenated with their sizes."""
    m = cnt[N_EDGES]
    n_open = n_loop = p_open = p_loop = 0
    for e in range(m):
        if ei[e, EALIVE]:
            if ei[e, EU] != ei[e, EV]:
                n_open += 1
                p_open += ei[e, PLEN]
            else:
                n_loop += 1
                p_loop += ei[e, PLEN]
    open_ids = np.empty(n_open, dtype=np.int64)
    open_lens = np.empty(n_open, dtype=np.int64)
    open_pts = np.empty((p_open, 2), dtype=np.float64)
    loop_ids = np.empty(n_loop, dtype=np.int64)
    loop_lens = np.empty(n_loop, dtype=np.int64)
    loop_pts = np.empty((p_loop, 2), dtype=np.float64)
    a = b = pa = pb = 0
    for e in range(m):
        if not ei[e, EALIVE]:
            continue
        off, size = ei[e, POFF], ei[e, PLEN]
        if ei[e, EU] != ei[e, EV]:
            open_ids[a], open_lens[a] = e, size
            open_pts[pa: pa + size] = pts[off: off + size]
            a += 1
            pa += size
        else:
            loop_ids[b], loop_lens[b] = e, size
            loop_pts[pb: pb + size] = pts[off: off + size]
            b += 1
            pb += size
    return open_ids, open_lens, open_pts, loop_ids, loop_lens, loop_pts


@njit(cache=True, nogil=True)
def graph_first(node_rc, ends, points, bounds, lengths, radius, given, min_protrusion,
                merge_px, arm, caps):
    """The clean-up up to numpy's ``arctan2`` of the corner step (``extract_topomap``'s
    ``_Graph.start``, ``prune_spurs``, ``dissolve_degree_two``, ``merge_short``, and
    :func:`topo._extract_kernels.corner_arms` of the open paths, as ``split_corners`` calls it):
    the graph's state (``ni, pos, ei, elen, pts, inc, cnt``; ``cnt[OVER]`` set if ``caps`` were
    too small), the open paths' ids, sizes, arc lengths, cross and dot products, and the loops'
    ids, sizes and concatenated polylines."""
    ni, pos, ei, elen, pts, inc, cnt = _state(node_rc, ends, points, bounds, lengths, caps)
    if not cnt[OVER]:
        _prune_spurs(ni, ei, elen, pts, inc, cnt, radius, min_protrusion)
    if not cnt[OVER]:
        _dissolve_all(ni, ei, elen, pts, inc, cnt)
    if not cnt[OVER]:
        _merge_short(ni, pos, ei, elen, pts, inc, cnt, given, merge_px)
    open_ids, open_lens, open_pts, loop_ids, loop_lens, loop_pts = _open_and_loops(ei, pts, cnt)
    if len(open_ids):
        arc, cross, dot = corner_arms(open_pts, open_lens, arm)
    else:
        arc = cross = dot = np.empty(0, dtype=np.float64)
    return ((ni, pos, ei, elen, pts, inc, cnt), open_ids, open_lens, arc, cross, dot, loop_ids,
            loop_lens, loop_pts)


@njit(cache=True, nogil=True)
def _grown(state, caps):
    ni0, pos0, ei0, elen0, pts0, inc0, cnt0 = state
    ni = np.zeros((max(caps[0], len(ni0)), 4), dtype=np.int64)
    pos = np.empty((len(ni), 2), dtype=np.float64)
    ei = np.zeros((max(caps[1], len(ei0)), 5), dtype=np.int64)
    elen = np.empty(len(ei), dtype=np.float64)
    pts = np.empty((max(caps[2], len(pts0)), 2), dtype=np.float64)
    inc = np.empty((len(ni), max(caps[3], inc0.shape[1])), dtype=np.int64)
    n, m, p = cnt0[N_NODES], cnt0[N_EDGES], cnt0[N_PTS]
    ni[:n] = ni0[:n]
    pos[:n] = pos0[:n]
    ei[:m] = ei0[:m]
    elen[:m] = elen0[:m]
    pts[:p] = pts0[:p]
    inc[:n, : inc0.shape[1]] = inc0[:n]
    return ni, pos, ei, elen, pts, inc, cnt0.copy()


@njit(cache=True, nogil=True)
def graph_second(state, open_ids, open_lens, arc, turn, loop_ids, anchored_cuts, anchored_counts,
                 free_cuts, free_counts, given, min_turn, merge_px, res, ox, oy, caps):
    """The rest of the clean-up on a copy of :func:`graph_first`'s state (grown to ``caps``):
    the corner step's cuts of the open paths from their ``turn`` (numpy's), splitting them, and
    the loops' corners (``_loop_corners`` with the margin and without, ``*_cuts`` concatenated,
    ``*_counts`` per loop; which applies is decided when the loop is split), then
    ``dissolve_degree_two``, ``merge_short``, ``break_self_loops`` and ``snap_to_free``; returns
    ``cnt`` (``cnt[OVER]``: run again with larger ``caps``) and
    :func:`topo._extract_kernels.topomap_arrays` of the result (an empty graph: no nodes)."""
    ni, pos, ei, elen, pts, inc, cnt = _grown(state, caps)
    if len(open_ids) and not cnt[OVER]:
        cuts, counts = corner_cuts(turn, arc, open_lens, min_turn, merge_px)
        start = 0
        for j in range(len(open_ids)):
            if counts[j]:
                _split(ni, pos, ei, elen, pts, inc, cnt, open_ids[j],
                       cuts[start: start + counts[j]], False)
                start += counts[j]
            if cnt[OVER]:
                break
    a = f = 0
    for j in range(len(loop_ids)):
        if cnt[OVER]:
            break
        e = loop_ids[j]
        u = ei[e, EU]
        if _degree(ei, inc, ni, u) > 2 or ni[u, CORNER]:
            cuts = anchored_cuts[a: a + anchored_counts[j]]
        else:
            cuts = free_cuts[f: f + free_counts[j]]
        a += anchored_counts[j]
        f += free_counts[j]
        if len(cuts):
            at_start = False
            for c in cuts:
                at_start |= c == 0
            _split(ni, pos, ei, elen, pts, inc, cnt, e, cuts[cuts > 0], at_start)
    if not cnt[OVER]:
        _dissolve_all(ni, ei, elen, pts, inc, cnt)
    if not cnt[OVER]:
        _merge_short(ni, pos, ei, elen, pts, inc, cnt, given, merge_px)
    if not cnt[OVER]:
        _break_self_loops(ni, pos, ei, elen, pts, inc, cnt)
    if not cnt[OVER]:
        _snap_to_free(ni, pos, ei, pts, inc, cnt, given)
    n_nodes = m = p = 0
    if not cnt[OVER]:
        for n in range(cnt[N_NODES]):
            n_nodes += ni[n, ALIVE]
        for e in range(cnt[N_EDGES]):
            if ei[e, EALIVE]:
                m += 1
                p += ei[e, PLEN]
    rc = np.empty((n_nodes, 2), dtype=np.float64)
    ids = np.empty(n_nodes, dtype=np.int64)
    ends = np.empty((m, 2), dtype=np.int64)
    cells = np.empty((p, 2), dtype=np.float64)
    sizes = np.empty(m, dtype=np.int64)
    if n_nodes == 0:
        return cnt, (np.empty((0, 2), dtype=np.float64), ends, cells,
                     np.empty(0, dtype=np.float64), np.empty(0, dtype=np.bool_), sizes)
    k = 0
    for n in range(cnt[N_NODES]):
        if ni[n, ALIVE]:
            rc[k, 0], rc[k, 1], ids[k] = pos[n, 0], pos[n, 1], n
            k += 1
    k = q = 0
    for e in range(cnt[N_EDGES]):
        if ei[e, EALIVE]:
            off, size = ei[e, POFF], ei[e, PLEN]
            ends[k, 0], ends[k, 1], sizes[k] = ei[e, EU], ei[e, EV], size
            cells[q: q + size] = pts[off: off + size]
            k += 1
            q += size
    return cnt, topomap_arrays(rc, ids, ends, cells, sizes, res, ox, oy)
