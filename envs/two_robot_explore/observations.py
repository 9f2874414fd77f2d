"""The env's observation space, and each robot's topological-graph observations.

The manual (``env.py``, Observations) says what every key holds; this module builds the space
and the three ``graph_*`` arrays: the ``max_nodes`` nodes of the robot's own topological map
nearest to it, in its odometry frame, their features and the paths between them.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from envs.two_robot_explore._map_kernels import adjacency, nearest_nodes
from envs.two_robot_explore.config import EnvConfig
from topo.graph import NodeKind, TopoMap

MAX_DEGREE = 16
"""Upper bound of the ``graph_nodes`` degree feature (larger degrees are clipped)."""

MAX_CLEARANCE = 10.0
"""Upper bound of the ``graph_nodes`` clearance feature, metres (larger values are clipped)."""

N_NODE_FEATURES = 2 + len(NodeKind) + 3
"""Per node: ``x, y``, the kind one-hot, degree, clearance, frontier flag (the manual)."""


TEAMMATE_FEATURES = 7
"""Per teammate in ``teammates``: ``x, y``, ``cos, sin`` of the relative heading, valid flag,
in-contact flag, age of the last contact (the manual)."""


def observation_space(config: EnvConfig, frame_radius: float,
                      two_robot: bool = False) -> spaces.Dict:
    """One robot's observation space (manual, Observations); ``frame_radius`` bounds the
    odometry (metres from the robot's start) and twice it the relative positions.
    ``two_robot``: the ``two_robot_explore_v0`` layout, one ``teammate`` (5,) instead of
    ``teammates`` (N − 1, 7)."""
    r = frame_radius
    n = config.mapping.max_nodes
    size = config.mapping.local_map_size
    f32 = np.float32
    node_lo = np.zeros((n, N_NODE_FEATURES), dtype=f32)
    node_hi = np.ones((n, N_NODE_FEATURES), dtype=f32)
    node_lo[:, :2] = -2 * r
    node_hi[:, :2] = 2 * r
    node_hi[:, -3] = MAX_DEGREE
    node_hi[:, -2] = MAX_CLEARANCE
    obs = {
        "sonar": spaces.Box(0.0, 1.0, (len(config.sonar.angles),), f32),
        "odometry": spaces.Box(np.array([-r, -r, -1, -1], f32), np.array([r, r, 1, 1], f32)),
        "graph_nodes": spaces.Box(node_lo, node_hi, dtype=f32),
        "graph_mask": spaces.Box(0.0, 1.0, (n,), f32),
        "graph_adjacency": spaces.Box(0.0, 1.0, (n, n), f32),
        "local_map": spaces.Box(0, 255, (1, size, size), np.uint8),
    }
    lo = np.array([-2 * r, -2 * r, -1, -1, 0, 0, 0], f32)
    hi = np.array([2 * r, 2 * r, 1, 1, 1, 1, 1], f32)
    if two_robot:
        obs["teammate"] = spaces.Box(lo[:5], hi[:5])
    else:
        n = config.n_robots - 1
        obs["teammates"] = spaces.Box(np.tile(lo, (n, 1)), np.tile(hi, (n, 1)))
    return spaces.Dict(obs)


class GraphEncoder:
    """One robot's ``graph_nodes``, ``graph_mask`` and ``graph_adjacency``.

    The per-node features that only change when the map is extracted again (kind one-hot,
    degree, clearance, frontier flag) are kept from :meth:`refresh` to the next; the adjacency
    is kept while the nearest nodes stay the same ones in the same order (most steps: the
    robot moves a few centimetres).

    Args:
        max_nodes: nodes in the observation (``mapping.max_nodes``).
        frame_radius: as :func:`observation_space` (bounds the relative positions).
    """

    def __init__(self, max_nodes: int, frame_radius: float) -> None:
        self.max_nodes = max_nodes
        self.frame_radius = frame_radius
        self._static: np.ndarray | None = None
        self._order: np.ndarray | None = None
        self._adj: np.ndarray | None = None

    def refresh(self, topo: TopoMap) -> None:
        """Take the static features of a newly extracted ``topo``."""
        static = np.zeros((topo.n_nodes, N_NODE_FEATURES - 2), dtype=np.float32)
        static[np.arange(topo.n_nodes), topo.kinds] = 1.0
        static[:, -3] = np.minimum(topo.degree(), MAX_DEGREE)
        static[:, -2] = np.minimum(topo.clearance, MAX_CLEARANCE)
        static[:, -1] = topo.frontier
        self._static, self._order, self._adj = static, None, None

    def encode(self, topo: TopoMap, x: float, y: float, c: float, s: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(nodes, mask, adjacency)`` of ``topo`` (the map last :meth:`refresh`-ed) seen from
        the odometry pose ``(x, y)`` with heading cosine ``c`` and sine ``s``: new arrays
        the caller may keep."""
        n_max = self.max_nodes
        nodes = np.zeros((n_max, N_NODE_FEATURES), dtype=np.float32)
        mask = np.zeros(n_max, dtype=np.float32)
        n = topo.n_nodes
        if n == 0:
            return nodes, mask, np.zeros((n_max, n_max), dtype=np.float32)
        order = nearest_nodes(topo.xy, x, y, c, s, self._static, 2 * self.frame_radius,
                              nodes, mask)
        if self._order is not None and order.tobytes() == self._order.tobytes():
            return nodes, mask, self._adj.copy()
        adj = np.zeros((n_max, n_max), dtype=np.float32)
        if topo.n_edges:
            adjacency(order, topo.edges, n, adj)
        self._order, self._adj = order, adj
        return nodes, mask, adj.copy()
