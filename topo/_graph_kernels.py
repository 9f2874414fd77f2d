"""The clean-up of :func:`topo.extract.extract_topomap` (steps 4–7 and the output) compiled:
``topo.extract._Graph``'s passes on arrays, in two numba kernels around numpy's ``arctan2``
(:func:`graph_first`: the graph, spurs, degree-two nodes, short paths, and the corner step's
chord products; :func:`graph_second`: corner cuts and splits, again degree-two nodes and short
paths, loops, snapping, and :func:`topo._extract_kernels.topomap_arrays`). They give bit for bit
the map of the Python passes (``topo.extract._graph_topomap_reference``), which ``tests/topo``
compares on hypothesis masks and on every extraction of env episodes.

The passes' results depend on the order in which ``_Graph`` visits a node's paths (which of a
degree-two node's two paths comes first sets the joined polyline's direction, and so later
floats and choices), and ``_Graph`` keeps them in Python sets of path ids. So each node's paths
are kept here in a hash table that reproduces CPython's ``set`` of small non-negative ints
(``Objects/setobject.c``: an 8-slot table, linear probes of 9 then perturbed probing, dummies
left by removals and reused by the last one passed, resizing at 3/5 full to the smallest power
of two above 4 × the size); ``tests/topo`` checks its iteration order against ``set`` itself on
random add/remove sequences.

The kernels are pure: arrays have fixed capacities, and a pass that would overflow one sets a
flag and stops, so that the caller (:mod:`topo.extract`) runs the kernel again with larger ones.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from topo._extract_kernels import corner_arms, corner_cuts, polyline_length, topomap_arrays

NULL, DUMMY = -1, -2  # set slots: never used, removed
# columns of the node table ``ni``
ALIVE, MASS, CORNER, TOFF, TMASK, FILL, USED = range(7)
# columns of the edge table ``ei``
EALIVE, EU, EV, POFF, PLEN = range(5)
# the counters ``cnt``
N_NODES, N_EDGES, N_PTS, N_TAB, OVER = range(5)


@njit(cache=True, nogil=True)
def _new_table(tab, cnt, size):
    off = cnt[N_TAB]
    if off + size > len(tab):
        cnt[OVER] = 1
        return -1
    tab[off: off + size] = NULL
    cnt[N_TAB] = off + size
    return off


@njit(cache=True, nogil=True)
def _insert_clean(tab, off, mask, key):
    perturb = key
    i = key & mask
    while True:
        if tab[off + i] == NULL:
            break
        found = False
        if i + 9 <= mask:
            for j in range(1, 10):
                if tab[off + i + j] == NULL:
                    i += j
                    found = True
                    break
        if found:
            break
        perturb >>= 5
        i = (i * 5 + 1 + perturb) & mask
    tab[off + i] = key


@njit(cache=True, nogil=True)
def _resize(tab, ni, cnt, n, minused):
    size = 8
    while size <= minused:
        size <<= 1
    old, old_mask = ni[n, TOFF], ni[n, TMASK]
    if size == 8 and old_mask == 7 and ni[n, FILL] == ni[n, USED]:
        return
    off = _new_table(tab, cnt, size)
    if off < 0:
        return
    for s in range(old_mask + 1):
        key = tab[old + s]
        if key >= 0:
            _insert_clean(tab, off, size - 1, key)
    ni[n, TOFF], ni[n, TMASK], ni[n, FILL] = off, size - 1, ni[n, USED]


@njit(cache=True, nogil=True)
def _probe(tab, off, mask, key):
    """CPython's probe sequence for ``key`` up to its slot or the first never-used one: that
    slot and the last dummy passed on the way (-1 if none)."""
    i = key & mask
    perturb = key
    free = -1
    while True:
        probes = 9 if i + 9 <= mask else 0
        j = i
        while True:
            k = tab[off + j]
            if k == NULL or k == key:
                return j, free
            if k == DUMMY:
                free = j
            if probes == 0:
                break
            probes -= 1
            j += 1
        perturb >>= 5
        i = (i * 5 + 1 + perturb) & mask


@njit(cache=True, nogil=True)
def set_add(tab, ni, cnt, n, key):
    """``inc[n].add(key)`` as CPython's ``set_add_entry`` does it (nothing once a table could not
    grow: ``cnt[OVER]``)."""
    if cnt[OVER]:
        return
    off, mask = ni[n, TOFF], ni[n, TMASK]
    j, free = _probe(tab, off, mask, key)
    if tab[off + j] == key:
        return
    ni[n, USED] += 1
    if free >= 0:
        tab[off + free] = key
        return
    tab[off + j] = key
    ni[n, FILL] += 1
    if ni[n, FILL] * 5 >= mask * 3:
        used = ni[n, USED]
        _resize(tab, ni, cnt, n, used * 2 if used > 50000 else used * 4)


@njit(cache=True, nogil=True)
def set_discard(tab, ni, cnt, n, key):
    """``inc[n].discard(key)`` (the slot becomes a dummy; nothing after ``cnt[OVER]``)."""
    if cnt[OVER]:
        return
    off = ni[n, TOFF]
    j, _ = _probe(tab, off, ni[n, TMASK], key)
    if tab[off + j] == key:
        tab[off + j] = DUMMY
        ni[n, USED] -= 1


@njit(cache=True, nogil=True)
def set_items(tab, ni, n):
    """The keys of ``inc[n]`` in ``set`` iteration order (slot order)."""
    out = np.empty(ni[n, USED], dtype=np.int64)
    k = 0
    off = ni[n, TOFF]
    for s in range(ni[n, TMASK] + 1):
        key = tab[off + s]
        if key >= 0:
            out[k] = key
            k += 1
    return out


@njit(cache=True, nogil=True)
def new_set(tab, ni, cnt, n):
    """An empty ``set()`` for node ``n``."""
    off = _new_table(tab, cnt, 8)
    ni[n, TOFF], ni[n, TMASK], ni[n, FILL], ni[n, USED] = off, 7, 0, 0
    return off >= 0


@njit(cache=True, nogil=True)
def _add_node(ni, pos, tab, cnt, r, c):
    n = cnt[N_NODES]
    if n >= len(ni):
        cnt[OVER] = 1
        return -1
    if not new_set(tab, ni, cnt, n):
        return -1
    cnt[N_NODES] = n + 1
    ni[n, ALIVE], ni[n, MASS], ni[n, CORNER] = 1, 1, 0
    pos[n, 0], pos[n, 1] = r, c
    return n


@njit(cache=True, nogil=True)
def _add_edge(ni, ei, elen, pts, tab, cnt, u, v, off, size):
    e = cnt[N_EDGES]
    if e >= len(ei):
        cnt[OVER] = 1
        return -1
    cnt[N_EDGES] = e + 1
    ei[e, EALIVE], ei[e, EU], ei[e, EV], ei[e, POFF], ei[e, PLEN] = 1, u, v, off, size
    elen[e] = polyline_length(pts[off: off + size])
    set_add(tab, ni, cnt, u, e)
    set_add(tab, ni, cnt, v, e)
    return e


@njit(cache=True, nogil=True)
def _remove_edge(ni, ei, tab, cnt, e):
    ei[e, EALIVE] = 0
    set_discard(tab, ni, cnt, ei[e, EU], e)
    set_discard(tab, ni, cnt, ei[e, EV], e)


@njit(cache=True, nogil=True)
def _is_free(given, r, c):
    return given[math.floor(r + 0.5), math.floor(c + 0.5)]


@njit(cache=True, nogil=True)
def _dissolve(ni, ei, elen, pts, tab, cnt, n):
    """``_Graph.dissolve``: join the two paths of an alive, non-corner degree-two node."""
    if not ni[n, ALIVE] or ni[n, CORNER] or ni[n, USED] != 2:
        return
    pair = set_items(tab, ni, n)
    ea, eb = pair[0], pair[1]
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
    _remove_edge(ni, ei, tab, cnt, ea)
    _remove_edge(ni, ei, tab, cnt, eb)
    ni[n, ALIVE], ni[n, CORNER] = 0, 0
    _add_edge(ni, ei, elen, pts, tab, cnt, ua, vb, off, size)


@njit(cache=True, nogil=True)
def _dissolve_all(ni, ei, elen, pts, tab, cnt):
    for n in range(cnt[N_NODES]):
        _dissolve(ni, ei, elen, pts, tab, cnt, n)
        if cnt[OVER]:
            return


@njit(cache=True, nogil=True)
def _prune_spurs(ni, ei, elen, pts, tab, cnt, radius, min_protrusion):
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
            du, dv = ni[u, USED], ni[v, USED]
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
            for e in set_items(tab, ni, leaf):
                _remove_edge(ni, ei, tab, cnt, e)
            ni[leaf, ALIVE], ni[leaf, CORNER] = 0, 0
        for k in range(nd):
            _dissolve(ni, ei, elen, pts, tab, cnt, hubs[k])
            if cnt[OVER]:
                return


@njit(cache=True, nogil=True)
def _merge_short(ni, pos, ei, elen, pts, tab, cnt, given, radius):
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
        _remove_edge(ni, ei, tab, cnt, e)
        keep, drop = (u, v) if ni[u, USED] >= ni[v, USED] else (v, u)
        mk, md = ni[keep, MASS], ni[drop, MASS]
        r = (mk * pos[keep, 0] + md * pos[drop, 0]) / (mk + md)
        c = (mk * pos[keep, 1] + md * pos[drop, 1]) / (mk + md)
        if _is_free(given, r, c):
            pos[keep, 0], pos[keep, 1] = r, c
        for k in set_items(tab, ni, drop):
            ou, ov = ei[k, EU], ei[k, EV]
            _remove_edge(ni, ei, tab, cnt, k)
            _add_edge(ni, ei, elen, pts, tab, cnt, keep if ou == drop else ou,
                      keep if ov == drop else ov, ei[k, POFF], ei[k, PLEN])
            if cnt[OVER]:
                return
        ni[keep, MASS] = mk + md
        if ni[drop, CORNER]:
            ni[keep, CORNER] = 1
        ni[drop, ALIVE], ni[drop, CORNER] = 0, 0


@njit(cache=True, nogil=True)
def _split(ni, pos, ei, elen, pts, tab, cnt, e, cuts, at_start):
    """``_Graph._split``."""
    u, v, off, size = ei[e, EU], ei[e, EV], ei[e, POFF], ei[e, PLEN]
    _remove_edge(ni, ei, tab, cnt, e)
    if at_start:
        ni[u, CORNER] = 1
    prev, prev_cut = u, 0
    for c in cuts:
        node = _add_node(ni, pos, tab, cnt, pts[off + c, 0], pts[off + c, 1])
        if node < 0:
            return
        ni[node, CORNER] = 1
        _add_edge(ni, ei, elen, pts, tab, cnt, prev, node, off + prev_cut, c + 1 - prev_cut)
        prev, prev_cut = node, c
    _add_edge(ni, ei, elen, pts, tab, cnt, prev, v, off + prev_cut, size - prev_cut)


@njit(cache=True, nogil=True)
def _degree(ei, tab, ni, n):
    d = 0
    for e in set_items(tab, ni, n):
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
def _break_self_loops(ni, pos, ei, elen, pts, tab, cnt):
    """``_Graph.break_self_loops``."""
    m = cnt[N_EDGES]
    for e in range(m):
        if not ei[e, EALIVE] or ei[e, EU] != ei[e, EV]:
            continue
        off, size = ei[e, POFF], ei[e, PLEN]
        if size < 4:
            _remove_edge(ni, ei, tab, cnt, e)
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
        _split(ni, pos, ei, elen, pts, tab, cnt, e, cuts, False)
        if cnt[OVER]:
            return


@njit(cache=True, nogil=True)
def _snap_to_free(ni, pos, ei, pts, tab, cnt, given):
    """``_Graph.snap_to_free``."""
    for n in range(cnt[N_NODES]):
        if not ni[n, ALIVE]:
            continue
        r, c = pos[n, 0], pos[n, 1]
        if _is_free(given, r, c):
            continue
        best, best_d = -1, np.inf
        for e in set_items(tab, ni, n):
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
    points, set slots)."""
    ni = np.zeros((caps[0], 7), dtype=np.int64)
    pos = np.empty((caps[0], 2), dtype=np.float64)
    ei = np.zeros((caps[1], 5), dtype=np.int64)
    elen = np.empty(caps[1], dtype=np.float64)
    pts = np.empty((caps[2], 2), dtype=np.float64)
    tab = np.empty(caps[3], dtype=np.int64)
    cnt = np.zeros(5, dtype=np.int64)
    if len(node_rc) > caps[0] or len(ends) > caps[1] or len(points) > caps[2]:
        cnt[OVER] = 1
        return ni, pos, ei, elen, pts, tab, cnt
    pts[: len(points)] = points
    cnt[N_PTS] = len(points)
    for n in range(len(node_rc)):
        if _add_node(ni, pos, tab, cnt, node_rc[n, 0], node_rc[n, 1]) < 0:
            return ni, pos, ei, elen, pts, tab, cnt
    for k in range(len(ends)):
        u, v = ends[k, 0], ends[k, 1]
        ei[k, EALIVE], ei[k, EU], ei[k, EV] = 1, u, v
        ei[k, POFF], ei[k, PLEN] = bounds[k], bounds[k + 1] - bounds[k]
        elen[k] = lengths[k]
        set_add(tab, ni, cnt, u, k)
        set_add(tab, ni, cnt, v, k)
    cnt[N_EDGES] = len(ends)
    return ni, pos, ei, elen, pts, tab, cnt


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
    the graph's state (``ni, pos, ei, elen, pts, tab, cnt``; ``cnt[OVER]`` set if ``caps`` were
    too small), the open paths' ids, sizes, arc lengths, cross and dot products, and the loops'
    ids, sizes and concatenated polylines."""
    ni, pos, ei, elen, pts, tab, cnt = _state(node_rc, ends, points, bounds, lengths, caps)
    if not cnt[OVER]:
        _prune_spurs(ni, ei, elen, pts, tab, cnt, radius, min_protrusion)
    if not cnt[OVER]:
        _dissolve_all(ni, ei, elen, pts, tab, cnt)
    if not cnt[OVER]:
        _merge_short(ni, pos, ei, elen, pts, tab, cnt, given, merge_px)
    open_ids, open_lens, open_pts, loop_ids, loop_lens, loop_pts = _open_and_loops(ei, pts, cnt)
    if len(open_ids):
        arc, cross, dot = corner_arms(open_pts, open_lens, arm)
    else:
        arc = cross = dot = np.empty(0, dtype=np.float64)
    return ((ni, pos, ei, elen, pts, tab, cnt), open_ids, open_lens, arc, cross, dot, loop_ids,
            loop_lens, loop_pts)


@njit(cache=True, nogil=True)
def _grown(state, caps):
    ni0, pos0, ei0, elen0, pts0, tab0, cnt0 = state
    ni = np.zeros((max(caps[0], len(ni0)), 7), dtype=np.int64)
    pos = np.empty((len(ni), 2), dtype=np.float64)
    ei = np.zeros((max(caps[1], len(ei0)), 5), dtype=np.int64)
    elen = np.empty(len(ei), dtype=np.float64)
    pts = np.empty((max(caps[2], len(pts0)), 2), dtype=np.float64)
    tab = np.empty(max(caps[3], len(tab0)), dtype=np.int64)
    n, m, p, t = cnt0[N_NODES], cnt0[N_EDGES], cnt0[N_PTS], cnt0[N_TAB]
    ni[:n] = ni0[:n]
    pos[:n] = pos0[:n]
    ei[:m] = ei0[:m]
    elen[:m] = elen0[:m]
    pts[:p] = pts0[:p]
    tab[:t] = tab0[:t]
    return ni, pos, ei, elen, pts, tab, cnt0.copy()


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
    ni, pos, ei, elen, pts, tab, cnt = _grown(state, caps)
    if len(open_ids) and not cnt[OVER]:
        cuts, counts = corner_cuts(turn, arc, open_lens, min_turn, merge_px)
        start = 0
        for j in range(len(open_ids)):
            if counts[j]:
                _split(ni, pos, ei, elen, pts, tab, cnt, open_ids[j],
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
        if _degree(ei, tab, ni, u) > 2 or ni[u, CORNER]:
            cuts = anchored_cuts[a: a + anchored_counts[j]]
        else:
            cuts = free_cuts[f: f + free_counts[j]]
        a += anchored_counts[j]
        f += free_counts[j]
        if len(cuts):
            at_start = False
            for c in cuts:
                at_start |= c == 0
            _split(ni, pos, ei, elen, pts, tab, cnt, e, cuts[cuts > 0], at_start)
    if not cnt[OVER]:
        _dissolve_all(ni, ei, elen, pts, tab, cnt)
    if not cnt[OVER]:
        _merge_short(ni, pos, ei, elen, pts, tab, cnt, given, merge_px)
    if not cnt[OVER]:
        _break_self_loops(ni, pos, ei, elen, pts, tab, cnt)
    if not cnt[OVER]:
        _snap_to_free(ni, pos, ei, pts, tab, cnt, given)
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
