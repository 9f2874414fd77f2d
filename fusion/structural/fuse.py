"""Two maps made one: :func:`fuse_maps` moves B onto A and fuses nodes that are the same place."""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from fusion.rigid import Rigid2D
from topo.graph import NodeKind, TopoMap

_KIND_PRIORITY = {NodeKind.JUNCTION: 0, NodeKind.CORNER: 1, NodeKind.DEAD_END: 2,
                  NodeKind.GATEWAY: 3}


_RANK_OF_KIND = np.array([_KIND_PRIORITY[NodeKind(k)] for k in range(len(NodeKind))])


_KIND_OF_RANK = np.array(sorted(_KIND_PRIORITY, key=_KIND_PRIORITY.get), dtype=np.int64)


def fuse_maps(map_a: TopoMap, map_b: TopoMap, transform: Rigid2D, matches: np.ndarray,
              eps: float) -> TopoMap:
    """A in its frame with B moved by ``transform`` onto it.

    Matched pairs ``(a, b)`` are fused at their mean position; any other node (of B, or of A)
    within ``eps`` of a node is fused into it, so the result has no two nodes within ``eps``.
    A fused node keeps the most connected kind (junction > corner > dead end); paths are united
    (a path joining two fused nodes once), lengths kept (at least the new straight line).
    """
    n_a = map_a.n_nodes
    moved = transform.apply(map_b.xy)
    xy = np.vstack([map_a.xy, moved])
    matches = np.asarray(matches, dtype=np.int64).reshape(-1, 2)
    xy[matches[:, 0]] = 0.5 * (map_a.xy[matches[:, 0]] + moved[matches[:, 1]])
    n = len(xy)
    close = cKDTree(xy).query_pairs(eps, output_type="ndarray").reshape(-1, 2)
    rows = np.concatenate([matches[:, 0], close[:, 0]])
    cols = np.concatenate([matches[:, 1] + n_a, close[:, 1]])
    node, first = _components_by_first(n, rows, cols)
    fields = _fused_graph(node, first, xy, np.concatenate([map_a.kinds, map_b.kinds]),
                          np.concatenate([map_a.edges, map_b.edges + n_a]).astype(np.int64),
                          np.concatenate([map_a.lengths, map_b.lengths]).astype(np.float64))
    # Built directly: every field is valid by construction (from_arrays re-parses each kind).
    for f in fields:
        f.setflags(write=False)
    return TopoMap(*fields)


def _components_by_first(n: int, rows: np.ndarray, cols: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Connected components of the ``n``-node graph with edges ``rows[k]``–``cols[k]``:
    ``(label, first)``, components numbered in order of their lowest node, ``first[c]`` that
    node (scipy's labels renumbered so: the fused nodes keep A's order)."""
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    first = np.full(label.max(initial=-1) + 1, n, dtype=np.int64)
    np.minimum.at(first, label, np.arange(n))
    order = np.argsort(first, kind="stable")
    rename = np.empty_like(order)
    rename[order] = np.arange(len(order))
    return rename[label].astype(np.int64), first[order]


def _fused_graph(node: np.ndarray, first: np.ndarray, xy: np.ndarray, kinds: np.ndarray,
                 edges: np.ndarray, lengths: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The fused map's ``(xy, kinds, edges, lengths)`` once its nodes are grouped (``node[i]``:
    the fused node of input node ``i``; ``first[c]``: the lowest input node of fused node
    ``c``): each fused node at ``xy[first[c]]``, of its nodes' kind of highest priority; each
    path joining two fused nodes once (its first listing; none within one node), ends in
    ascending order, its length at least the new straight line."""
    best = np.full(len(first), len(_KIND_OF_RANK), dtype=np.int64)
    np.minimum.at(best, node, _RANK_OF_KIND[kinds])
    out_xy = xy[first]
    e = np.sort(node[edges], axis=1).reshape(-1, 2)
    keep = e[:, 0] != e[:, 1]
    e, lengths = e[keep], lengths[keep]
    _, uniq = np.unique(e[:, 0] * max(len(first), 1) + e[:, 1], return_index=True)
    e, lengths = e[np.sort(uniq)], lengths[np.sort(uniq)]
    straight = np.linalg.norm(out_xy[e[:, 0]] - out_xy[e[:, 1]], axis=1)
    return (out_xy, _KIND_OF_RANK[best].astype(np.int8), np.ascontiguousarray(e, np.int64),
            np.maximum(lengths, straight).astype(np.float64))
