"""The env's observation space and its observations.

The manual (``env.py``, Observations) says what every key holds; this module builds the space,
each robot's observation from the env's live state (:class:`Observer`) and the three
``graph_*`` arrays: the ``max_nodes`` nodes of the robot's own topological map nearest to it,
in its odometry frame, their features and the paths between them (:class:`GraphEncoder`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from gymnasium import spaces

from envs.explore._kernels import nearest_nodes
from envs.explore.comm import TeamViews
from envs.explore.config import EnvConfig
from envs.explore.mapping import LocalMapSampler, RobotMap, compose_pose
from envs.explore.robot import Robot
from envs.explore.sonar import Sonar
from fusion.rigid import Rigid2D
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



def adjacency(order: np.ndarray, edges: np.ndarray, n_nodes: int, adj: np.ndarray) -> None:
    """``graph_adjacency``: 1 in ``adj`` (zeros) at ``(j, k)`` and ``(k, j)`` for every edge
    of ``edges`` (``(E, 2)`` node indices, ``n_nodes`` nodes) joining the listed nodes
    ``order[j]`` and ``order[k]``."""
    slot = np.full(n_nodes, -1, dtype=np.int64)
    slot[order] = np.arange(len(order))
    ends = slot[edges].reshape(-1, 2)
    ends = ends[(ends >= 0).all(axis=1)]
    adj[ends[:, 0], ends[:, 1]] = adj[ends[:, 1], ends[:, 0]] = 1.0

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


class Observer:
    """Builds the robots' observations (manual, Observations) from the env's live state.

    Holds what does not change within an env (the space's bounds, the ``local_map`` sampler)
    and, per episode, each robot's :class:`GraphEncoder` (:attr:`graphs`, refreshed by the
    env when it re-extracts a robot's topological map).

    Args:
        config: the env's config.
        frame_radius: as :func:`observation_space`.
        two_robot: the ``two_robot_explore_v0`` layout (as :func:`observation_space`).
    """

    def __init__(self, config: EnvConfig, frame_radius: float, two_robot: bool) -> None:
        self.config = config
        self.frame_radius = frame_radius
        self.two_robot = two_robot
        space = observation_space(config, frame_radius, two_robot)
        box = space["teammate" if two_robot else "teammates"]
        self._row_low = box.low if box.low.ndim == 1 else box.low[0]  # one teammate row's
        self._row_high = box.high if box.high.ndim == 1 else box.high[0]
        self._odo_bound = float(space["odometry"].high[0])  # R as a float32 value
        self._sampler = LocalMapSampler(config.mapping.local_map_size,
                                        config.mapping.local_map_resolution)
        self.graphs: list[GraphEncoder] = []

    def reset(self, n: int) -> None:
        """New graph encoders for an episode of ``n`` robots."""
        self.graphs = [GraphEncoder(self.config.mapping.max_nodes, self.frame_radius)
                       for _ in range(n)]

    def observe(self, i: int, robots: Sequence[Robot], sonars: Sequence[Sonar],
                maps: Sequence[RobotMap], frames: Sequence[dict[int, tuple[Rigid2D, Rigid2D]]],
                views: TeamViews, steps: int, max_cycles: int,
                live: Sequence[np.ndarray] | None = None) -> dict[str, np.ndarray]:
        """Robot ``i``'s observation: a dict of new arrays in its observation space.

        Args:
            i: the robot.
            robots, sonars, maps: every robot's, in index order (the env's live objects).
            frames: ``frames[i]``: ``{j: (to_i, from_i)}`` for each robot ``j`` in robot
                ``i``'s fused map (``TeamMerging.frames``).
            views: who is in contact and what each robot holds of the others' maps.
            steps, max_cycles: the step count now and the truncation step count (the
                teammates' contact age).
            live: every robot's odometry now (``None``: read from ``robots``).
        """
        if live is None:
            live = [r.odometry for r in robots]
        ox, oy, oth = robots[i].odometry.tolist()
        c, s = math.cos(oth), math.sin(oth)
        # clipped as floats, then rounded: the bounds are float32 values, so this is the
        # float32 clip, without np.clip's call overhead
        r = self._odo_bound
        odometry = np.array([min(max(ox, -r), r), min(max(oy, -r), r), c, s], dtype=np.float32)
        sonar = (sonars[i].last / self.config.sonar.max_range).astype(np.float32)
        nodes, mask, adj = self.graphs[i].encode(maps[i].topomap, ox, oy, c, s)
        obs = {
            "sonar": sonar,
            "odometry": odometry,
            "graph_nodes": nodes,
            "graph_mask": mask,
            "graph_adjacency": adj,
            "local_map": self._local_map(i, maps[i], robots[i].odometry, frames[i], views),
        }
        rows = [self._teammate(i, j, (ox, oy, oth, c, s), frames[i], views, steps, max_cycles,
                               live) for j in range(len(robots)) if j != i]
        if self.two_robot:
            obs["teammate"] = rows[0]
        else:
            obs["teammates"] = np.stack(rows)
        return obs

    def _teammate(self, i: int, j: int, pose: tuple[float, float, float, float, float],
                  fused: dict[int, tuple[Rigid2D, Rigid2D]], views: TeamViews, steps: int,
                  max_cycles: int, live: Sequence[np.ndarray]) -> np.ndarray:
        """Robot ``i``'s observation row of teammate ``j`` (manual, Observations, c and h);
        ``pose``: robot ``i``'s odometry ``x, y, θ, cos θ, sin θ``; ``fused``: robot ``i``'s
        fused-map frames; the rest as :meth:`observe`."""
        ox, oy, oth, c, s = pose
        row = np.zeros(len(self._row_low), dtype=np.float32)
        frame = fused.get(j)
        peer_odo = views.odometry(i, j, live)
        if frame is not None and peer_odo is not None:
            peer = compose_pose(frame[0], peer_odo)
            dx, dy = peer[0] - ox, peer[1] - oy
            dth = peer[2] - oth
            row[:5] = (c * dx + s * dy, -s * dx + c * dy, math.cos(dth), math.sin(dth), 1.0)
        if not self.two_robot:
            seen = int(views.seen[i, j])
            row[5] = float(views.in_contact(i, j))
            row[6] = 1.0 if seen < 0 else min((steps - seen) / max_cycles, 1.0)
        np.clip(row, self._row_low, self._row_high, out=row)
        return row

    def _local_map(self, i: int, own: RobotMap, odometry: np.ndarray,
                   fused: dict[int, tuple[Rigid2D, Rigid2D]], views: TeamViews) -> np.ndarray:
        """Robot ``i``'s ``local_map``: its own map ``own`` around its ``odometry``, with the
        maps it holds of the teammates in its fused map (``fused``: their frames)."""
        others = []
        for j, (_, from_i) in fused.items():
            if j != i:
                peer = views.view(i, j)
                others.append((peer.states, peer.geometry, compose_pose(from_i, odometry)))
        return self._sampler.image(own.states, own.geometry, odometry, others)
