"""Compiled fusion of two maps' graphs (numba, cached on disk after the first call): nodes to
fuse as connected components, and the fused graph (:func:`fusion.structural.fuse.fuse_maps`)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def components_by_first(n, rows, cols):
    """Connected components of the ``n``-node graph with edges ``rows[k]``–``cols[k]``
    (union-find). Returns ``(label, first)``: components numbered in order of their lowest
    node, ``first[c]`` that node."""
    parent = np.arange(n)
    for k in range(rows.shape[0]):
        u, v = rows[k], cols[k]
        while parent[u] != u:
            parent[u] = parent[parent[u]]
            u = parent[u]
        while parent[v] != v:
            parent[v] = parent[parent[v]]
            v = parent[v]
        if u < v:
            parent[v] = u
        elif v < u:
            parent[u] = v
    label = np.empty(n, dtype=np.int64)
    first = np.empty(n, dtype=np.int64)
    c = 0
    for i in range(n):  # a root is the lowest node of its component (unions keep the lower)
        r = i
        while parent[r] != r:
            r = parent[r]
        if r == i:
            label[i] = c
            first[c] = i
            c += 1
        else:
            label[i] = label[r]
    return label, first[:c]


@njit(cache=True, nogil=True)
def fused_graph(node, first, xy, kinds, edges, lengths, rank_of_kind, kind_of_rank):
    """The map ``fusion.structural.fuse.fuse_maps`` builds once its nodes are grouped (``node[i]``:
    the
    fused node of input node ``i``; ``first[c]``: the lowest input node of fused node ``c``,
    :func:`components_by_first`): ``(xy, kinds, edges, lengths)`` — each fused node at
    ``xy[first[c]]``, of the kind of lowest ``rank_of_kind`` among its nodes (``kind_of_rank``
    back to a kind, int8); each path joining two fused nodes once (its first listing; none
    within one node), ends in ascending order, its length at least the new straight line
    (``sqrt(dx² + dy²)``, as ``np.linalg.norm``). What ``np.minimum.at``, ``np.sort`` by row
    and ``np.unique(..., return_index=True)`` gave."""
    n_out = first.shape[0]
    best = np.full(n_out, 99, dtype=np.int64)
    for i in range(node.shape[0]):
        best[node[i]] = min(best[node[i]], rank_of_kind[kinds[i]])
    out_xy = np.empty((n_out, 2))
    out_kinds = np.empty(n_out, dtype=np.int8)
    for c in range(n_out):
        out_xy[c, 0], out_xy[c, 1] = xy[first[c], 0], xy[first[c], 1]
        out_kinds[c] = kind_of_rank[best[c]]
    m = edges.shape[0]
    u = np.empty(m, dtype=np.int64)
    v = np.empty(m, dtype=np.int64)
    key = np.empty(m, dtype=np.int64)
    width = max(n_out, 1)
    for k in range(m):
        a, b = node[edges[k, 0]], node[edges[k, 1]]
        u[k], v[k] = min(a, b), max(a, b)
        key[k] = u[k] * width + v[k]
    order = np.argsort(key, kind="mergesort")  # stable: each key's first listing leads its run
    take = np.zeros(m, dtype=np.bool_)
    for r in range(m):
        k = order[r]
        take[k] = u[k] != v[k] and (r == 0 or key[order[r - 1]] != key[k])
    out_edges = np.empty((take.sum(), 2), dtype=np.int64)
    out_lengths = np.empty(take.sum())
    j = 0
    for k in range(m):
        if take[k]:
            out_edges[j, 0], out_edges[j, 1] = u[k], v[k]
            dx = out_xy[u[k], 0] - out_xy[v[k], 0]
            dy = out_xy[u[k], 1] - out_xy[v[k], 1]
            out_lengths[j] = max(lengths[k], math.sqrt(dx * dx + dy * dy))
            j += 1
    return out_xy, out_kinds, out_edges, out_lengths
