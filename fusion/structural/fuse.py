"""Two maps made one: :func:`fuse_maps` moves B onto A and fuses nodes that are the same place."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from fusion.rigid import Rigid2D
from fusion.structural import _fuse_kernels as FK
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
    node, first = FK.components_by_first(n, rows, cols)
    fields = FK.fused_graph(node, first, xy, np.concatenate([map_a.kinds, map_b.kinds]),
                            np.concatenate([map_a.edges, map_b.edges + n_a]).astype(np.int64),
                            np.concatenate([map_a.lengths, map_b.lengths]).astype(np.float64),
                            _RANK_OF_KIND, _KIND_OF_RANK)
    # Built directly: every field is valid by construction (from_arrays re-parses each kind).
    for f in fields:
        f.setflags(write=False)
    return TopoMap(*fields)
