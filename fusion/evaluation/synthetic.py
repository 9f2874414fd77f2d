"""Synthetic map pairs with ground truth, for tests and ``python -m fusion.evaluation --synthetic``.

A **world** is a random corridor graph: a jittered lattice with irregular spacing (a building's
corridors meet at right angles but are not evenly spaced), thinned to a random spanning tree plus a
fraction of loop-closing corridors, with straight-through lattice points removed so that nodes are
junctions, corners and dead ends — the node kinds of :class:`topo.NodeKind`.

Each robot of a pair **explores** a geodesic ball of the world (the nodes closest along the
corridors to its start) and its map is made the way extraction from a partial occupancy grid
makes one:

* corridors leaving the explored region end in a **frontier dead end** part-way along them
  (``frontier_stub_rate``) — spurious nodes that the other robot will not have;
* a junction whose side branch was not explored becomes a corner, or disappears when the two
  remaining corridors are straight;
* ``drop_rate`` of the nodes are **dropped** (a corridor through a dropped corner is kept);
* ``spurious_rate`` × nodes **spurious** short dead-end spurs are added;
* every node moves by Gaussian **noise** of ``noise`` metres per axis;
* the map is expressed in the robot's own frame: a random rotation (any angle) and translation.

The ground truth kept with each pair is the B → A transform (``p_A = R p_B + T``) and the node
correspondences (nodes of both maps that are the same world node). **Overlap** is the fraction of
the smaller explored region's world nodes that the other robot explored too (before drops);
``n_shared`` counts the correspondences that survive drops. No-overlap pairs come in two kinds:
``"disjoint"`` (same world, regions sharing no world node) and ``"other_world"`` (two worlds).

Randomness: every pair is drawn from ``numpy.random.default_rng([seed, index])``, so a pair can be
regenerated on its own and the set does not depend on how many pairs are asked for.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import networkx as nx
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import shortest_path

from fusion.rigid import Rigid2D
from topo.graph import TopoMap, kinds_from_degree
from topo.validation import check_int, check_real, config_from

PAIR_KINDS = ("overlap", "disjoint", "other_world")
"""The kinds of :class:`SyntheticPair`: partly overlapping, or one of the two no-overlap cases."""


@dataclass(frozen=True, slots=True)
class SyntheticConfig:
    """How worlds and map pairs are drawn (all lengths in metres).

    Attributes:
        spacing: ``(low, high)`` of the uniform gap between neighbouring lattice lines.
        keep_fraction: fraction of lattice points that exist (holes make the world irregular).
        loop_fraction: fraction of the lattice corridors outside the spanning tree kept (loops).
        jitter: std of the world nodes' offsets from the lattice (junctions of a real building
            are not on a perfect grid: rooms and corridor widths vary). The smaller it is, the
            more chance alignments a lattice-like world offers.
        straight_deg: a degree-2 node turning by less than this is not a node (it is contracted).
        map_nodes: ``(low, high)`` inclusive range of explored world nodes per robot.
        noise: std of the per-axis Gaussian noise on every map node.
        drop_rate: probability that a map node is missed.
        spurious_rate: expected spurious dead-end spurs per map node.
        frontier_stub_rate: probability that a corridor leaving the explored region shows as a
            frontier dead end.
        no_overlap_fraction: share of :func:`generate_pairs` pairs with no overlap (half
            ``"disjoint"``, half ``"other_world"``).
        overlap_range: ``(low, high)`` of the uniform target overlap of overlapping pairs.
        frame_translation: robot frames are translated uniformly within ``±`` this per axis.
    """

    spacing: tuple[float, float] = (2.5, 6.0)
    keep_fraction: float = 0.85
    loop_fraction: float = 0.3
    jitter: float = 0.3
    straight_deg: float = 20.0
    map_nodes: tuple[int, int] = (15, 60)
    noise: float = 0.15
    drop_rate: float = 0.1
    spurious_rate: float = 0.05
    frontier_stub_rate: float = 0.7
    no_overlap_fraction: float = 0.2
    overlap_range: tuple[float, float] = (0.05, 1.0)
    frame_translation: float = 30.0

    def __post_init__(self) -> None:
        lo, hi = _pair(self.spacing, "spacing", check_real)
        if not 0.0 < lo <= hi:
            raise ValueError(f"spacing must satisfy 0 < low <= high, got {self.spacing}")
        n_lo, n_hi = _pair(self.map_nodes, "map_nodes", check_int)
        if not 3 <= n_lo <= n_hi:
            raise ValueError(f"map_nodes must satisfy 3 <= low <= high, got {self.map_nodes}")
        o_lo, o_hi = _pair(self.overlap_range, "overlap_range", check_real)
        if not 0.0 <= o_lo <= o_hi <= 1.0:
            raise ValueError(
                f"overlap_range must satisfy 0 <= low <= high <= 1, got {self.overlap_range}"
            )
        check_real(self.keep_fraction, "keep_fraction", low=0.0, high=1.0)
        for name in ("loop_fraction", "drop_rate", "spurious_rate", "frontier_stub_rate",
                     "no_overlap_fraction"):
            check_real(getattr(self, name), name, low=0.0, low_inclusive=True, high=1.0)
        check_real(self.drop_rate, "drop_rate", high=0.9)
        for name in ("jitter", "noise", "frame_translation"):
            check_real(getattr(self, name), name, low=0.0, low_inclusive=True)
        check_real(self.straight_deg, "straight_deg", low=0.0, low_inclusive=True, high=90.0)

    @classmethod
    def from_dict(cls, data: dict) -> SyntheticConfig:
        """From a dict of field values; unknown keys are a ``ValueError`` listing the allowed."""
        return config_from(cls, data, "SyntheticConfig")


def _pair(value, name, check) -> tuple:
    if not isinstance(value, (tuple, list)) or len(value) != 2:
        raise TypeError(f"{name} must be a (low, high) pair, got {value!r}")
    return check(value[0], f"{name}[0]"), check(value[1], f"{name}[1]")


@dataclass(frozen=True, slots=True, eq=False)
class World:
    """A corridor graph in world coordinates: node positions, edges, and all-pairs corridor
    distances (``dist[i, j]``, metres along the corridors)."""

    xy: np.ndarray
    edges: np.ndarray
    dist: np.ndarray

    @property
    def n_nodes(self) -> int:
        return len(self.xy)

    def topomap(self) -> TopoMap:
        """The world's own topological map (kinds from degree)."""
        return TopoMap.from_arrays(self.xy, self.edges)


@dataclass(frozen=True, slots=True, eq=False)
class SyntheticPair:
    """Two maps in their robots' own frames, with the ground truth.

    Attributes:
        map_a, map_b: the two robots' maps.
        transform: true B → A motion (``p_A = R p_B + T``).
        correspondences: ``(K, 2)`` int node index pairs ``(a, b)`` of the same world node.
        overlap: shared fraction of the smaller explored region (0 for no-overlap pairs).
        kind: one of :data:`PAIR_KINDS`.
        noise: the node noise std the pair was drawn with.
        seed, index: the pair is ``make_pair(default_rng([seed, index]), ...)``.
        world_a: the world map A was drawn from, in A's frame (for pictures).
    """

    map_a: TopoMap
    map_b: TopoMap
    transform: Rigid2D
    correspondences: np.ndarray
    overlap: float
    kind: str
    noise: float
    seed: int
    index: int
    world_a: TopoMap

    @property
    def n_shared(self) -> int:
        return int(len(self.correspondences))

    @property
    def true_rotation_deg(self) -> float:
        """The true rotation between the frames, degrees in ``(-180, 180]``."""
        return self.transform.degrees


GENERIC_CONFIG = SyntheticConfig(spacing=(2.5, 5.0), jitter=0.15, map_nodes=(12, 50),
                                 overlap_range=(0.2, 1.0), spurious_rate=0.08)
"""Generic corridor-lattice pairs (``benchmarks/generic_graphs.py``): a more regular lattice
than the defaults' (jitter 0.15 m, spacing 2.5–5 m, so more chance alignments), smaller maps
(12–50 explored world nodes), overlap 0.2–1, 10 % dropped nodes and more spurious spurs; the
noise is set per level. Not what ``python -m fusion.calibration fit`` fits on by default
(``fusion.evaluation.evaluate.synthetic_pairs`` uses :class:`SyntheticConfig`'s defaults): a graph
source
the structural merge was not made on."""


def generic_pairs(n: int, seed: int, noise: float) -> Iterator[SyntheticPair]:
    """``n`` pairs of :data:`GENERIC_CONFIG` at node noise ``noise`` (:func:`generate_pairs`:
    the last ``round(0.2 n)`` have no overlap; the same worlds at every noise level)."""
    noise = check_real(noise, "noise", low=0.0, low_inclusive=True)
    fields = {f: getattr(GENERIC_CONFIG, f) for f in SyntheticConfig.__dataclass_fields__}
    return generate_pairs(n, seed, {**fields, "noise": noise})


# ------------------------------------------------------------------------------------ worlds
def random_world(rng: np.random.Generator, shape: tuple[int, int],
                 config: SyntheticConfig | None = None) -> World:
    """A random corridor world on a ``shape = (rows, cols)`` lattice (see the module doc)."""
    cfg = config_from(SyntheticConfig, config)
    rows, cols = check_int(shape[0], "shape[0]", low=2), check_int(shape[1], "shape[1]", low=2)
    xs = np.concatenate([[0.0], np.cumsum(rng.uniform(*cfg.spacing, cols - 1))])
    ys = np.concatenate([[0.0], np.cumsum(rng.uniform(*cfg.spacing, rows - 1))])
    lattice = nx.grid_2d_graph(rows, cols)
    kept = rng.random(rows * cols) < cfg.keep_fraction
    lattice.remove_nodes_from(
        [n for n, k in zip(sorted(lattice.nodes), kept, strict=True) if not k])
    if lattice.number_of_nodes() < 2:
        lattice = nx.grid_2d_graph(rows, cols)
    biggest = max(nx.connected_components(lattice), key=lambda c: (len(c), min(c)))
    lattice = lattice.subgraph(sorted(biggest)).copy()
    edges = sorted(tuple(sorted(e)) for e in lattice.edges)
    for (u, v), w in zip(edges, rng.random(len(edges)), strict=True):
        lattice.edges[u, v]["w"] = w
    tree = nx.minimum_spanning_tree(lattice, weight="w")
    extra = [e for e in edges if not tree.has_edge(*e)]
    tree.add_edges_from(e for e, k in zip(extra, rng.random(len(extra)), strict=True)
                        if k < cfg.loop_fraction)
    graph = nx.Graph()
    nodes = sorted(tree.nodes)
    jitter = rng.normal(0.0, cfg.jitter, (len(nodes), 2))
    index = {n: i for i, n in enumerate(nodes)}
    for n, dxy in zip(nodes, jitter, strict=True):
        graph.add_node(index[n], xy=np.array([xs[n[1]], ys[n[0]]]) + dxy, wid=index[n])
    graph.add_edges_from((index[u], index[v]) for u, v in sorted(tuple(sorted(e))
                                                                    for e in tree.edges))
    _contract_straight(graph, math.radians(cfg.straight_deg))
    xy, edge_arr, _ = _arrays(graph)
    return World(xy, edge_arr, _corridor_distances(xy, edge_arr))


def _corridor_distances(xy: np.ndarray, edges: np.ndarray) -> np.ndarray:
    n = len(xy)
    w = np.linalg.norm(xy[edges[:, 0]] - xy[edges[:, 1]], axis=1)
    graph = coo_matrix((w, (edges[:, 0], edges[:, 1])), shape=(n, n))
    return shortest_path(graph, directed=False)


def _contract_straight(graph: nx.Graph, min_turn: float) -> None:
    """Remove degree-2 nodes whose corridors continue straight (they are not places)."""
    for node in sorted(graph.nodes):
        if graph.degree[node] != 2:
            continue
        u, v = sorted(graph[node])
        if graph.has_edge(u, v):
            continue
        p = graph.nodes[node]["xy"]
        d1, d2 = p - graph.nodes[u]["xy"], graph.nodes[v]["xy"] - p
        turn = abs(math.atan2(d1[0] * d2[1] - d1[1] * d2[0], float(d1 @ d2)))
        if turn < min_turn:
            graph.remove_node(node)
            graph.add_edge(u, v)


def _arrays(graph: nx.Graph) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    nodes = sorted(graph.nodes)
    index = {n: i for i, n in enumerate(nodes)}
    xy = np.array([graph.nodes[n]["xy"] for n in nodes], dtype=np.float64).reshape(-1, 2)
    wid = np.array([graph.nodes[n]["wid"] for n in nodes], dtype=np.int64)
    edges = np.array(sorted((index[u], index[v]) if index[u] < index[v] else (index[v], index[u])
                            for u, v in graph.edges), dtype=np.int64).reshape(-1, 2)
    return xy, edges, wid


# ------------------------------------------------------------------------------ exploration
def explored_map(world: World, region: np.ndarray, rng: np.random.Generator,
                 config: SyntheticConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The map a robot that explored the world nodes ``region`` (bool mask) builds, in world
    coordinates: ``(xy, edges, world_ids)``; ``world_ids`` is ``-1`` for frontier and spurious
    nodes. Applies frontier stubs, contraction, drops, spurs and noise (module doc)."""
    graph = nx.Graph()
    for i in np.flatnonzero(region):
        graph.add_node(int(i), xy=world.xy[i], wid=int(i))
    next_id = world.n_nodes
    for u, v in world.edges:
        if region[u] and region[v]:
            graph.add_edge(int(u), int(v))
        elif region[u] or region[v]:
            inside, outside = (u, v) if region[u] else (v, u)
            if rng.random() < config.frontier_stub_rate:
                f = rng.uniform(0.25, 0.75)
                xy = world.xy[inside] + f * (world.xy[outside] - world.xy[inside])
                graph.add_node(next_id, xy=xy, wid=-1)
                graph.add_edge(int(inside), next_id)
                next_id += 1
    _contract_straight(graph, math.radians(config.straight_deg))
    for node in sorted(graph.nodes):
        if rng.random() < config.drop_rate:
            nbrs = sorted(graph[node])
            graph.remove_node(node)
            if len(nbrs) == 2 and not graph.has_edge(*nbrs):
                graph.add_edge(*nbrs)
    graph.remove_nodes_from([n for n in sorted(graph.nodes) if graph.degree[n] == 0])
    hosts = sorted(graph.nodes)
    n_spurs = int(rng.binomial(len(hosts), config.spurious_rate)) if hosts else 0
    for _ in range(n_spurs):
        host = hosts[int(rng.integers(len(hosts)))]
        angle, reach = rng.uniform(0.0, 2 * math.pi), rng.uniform(0.6, 1.5)
        xy = graph.nodes[host]["xy"] + reach * np.array([math.cos(angle), math.sin(angle)])
        graph.add_node(next_id, xy=xy, wid=-1)
        graph.add_edge(host, next_id)
        next_id += 1
    xy, edges, wid = _arrays(graph)
    xy = xy + rng.normal(0.0, config.noise, xy.shape)
    return xy, edges, wid


def _region(world: World, start: int, n: int) -> np.ndarray:
    mask = np.zeros(world.n_nodes, dtype=bool)
    mask[np.argsort(world.dist[start], kind="stable")[:n]] = True
    return mask


def _random_frame(rng: np.random.Generator, config: SyntheticConfig) -> Rigid2D:
    """A robot frame → world motion: any rotation, translation within ``±frame_translation``."""
    return Rigid2D(rng.uniform(-math.pi, math.pi),
                   rng.uniform(-config.frame_translation, config.frame_translation, 2))


def make_pair(rng: np.random.Generator, config: SyntheticConfig | dict | None = None, *,
              kind: str = "overlap", overlap: float | None = None,
              nodes: tuple[int, int] | None = None, seed: int = 0, index: int = 0
              ) -> SyntheticPair:
    """Draw one pair.

    Args:
        rng: the generator everything is drawn from.
        config: :class:`SyntheticConfig`, a dict of its fields, or ``None`` (defaults).
        kind: ``"overlap"``, ``"disjoint"`` or ``"other_world"`` (:data:`PAIR_KINDS`).
        overlap: target overlap in ``[0, 1]`` for ``"overlap"`` pairs (the closest the world
            allows is used); ``None`` draws it from ``config.overlap_range``.
        nodes: explored world nodes ``(n_a, n_b)``; ``None`` draws each from ``config.map_nodes``.
        seed, index: recorded in the pair.
    """
    cfg = config_from(SyntheticConfig, config)
    if kind not in PAIR_KINDS:
        raise ValueError(f"kind must be one of {list(PAIR_KINDS)}, got {kind!r}")
    if overlap is not None:
        overlap = check_real(overlap, "overlap", low=0.0, low_inclusive=True, high=1.0)
    if nodes is None:
        n_a, n_b = (int(n) for n in rng.integers(cfg.map_nodes[0], cfg.map_nodes[1] + 1, 2))
    else:
        n_a, n_b = (check_int(n, f"nodes[{i}]", low=3) for i, n in enumerate(nodes))
    target = overlap if overlap is not None else rng.uniform(*cfg.overlap_range)

    side = math.ceil(math.sqrt(2.4 * (n_a + n_b) / max(cfg.keep_fraction, 0.1))) + 1
    for _attempt in range(20):
        world = random_world(rng, (side, side), cfg)
        if world.n_nodes < n_a + n_b + 4:
            side += 1
            continue
        region_a = _region(world, int(rng.integers(world.n_nodes)), n_a)
        if kind == "other_world":
            world_b = random_world(rng, (side, side), cfg)
            if world_b.n_nodes < n_b:
                side += 1
                continue
            region_b = _region(world_b, int(rng.integers(world_b.n_nodes)), n_b)
            shared = 0.0
            break
        world_b = world
        ranks = np.argsort(np.argsort(world.dist, axis=1, kind="stable"), axis=1, kind="stable")
        members = ranks < n_b
        shares = (members.astype(np.int64) @ region_a.astype(np.int64)) / min(n_a, n_b)
        if kind == "disjoint":
            candidates = np.flatnonzero(shares == 0)
        else:
            gap = np.abs(shares - target)
            candidates = np.flatnonzero(gap <= gap.min() + 0.02)
        if len(candidates) == 0:
            side += 1
            continue
        start_b = int(candidates[rng.integers(len(candidates))])
        region_b, shared = members[start_b], float(shares[start_b])
        break
    else:
        raise RuntimeError(f"could not place two regions of {n_a} and {n_b} nodes in a world")

    xy_a, edges_a, wid_a = explored_map(world, region_a, rng, cfg)
    xy_b, edges_b, wid_b = explored_map(world_b, region_b, rng, cfg)
    frame_a, frame_b = _random_frame(rng, cfg), _random_frame(rng, cfg)
    to_a = frame_a.inverse()
    map_a = TopoMap.from_arrays(to_a.apply(xy_a), edges_a)
    map_b = TopoMap.from_arrays(frame_b.inverse().apply(xy_b), edges_b)
    if kind == "other_world":
        corr = np.empty((0, 2), dtype=np.int64)
    else:
        pos_b = {int(w): j for j, w in enumerate(wid_b) if w >= 0}
        corr = np.array([(i, pos_b[int(w)]) for i, w in enumerate(wid_a) if int(w) in pos_b],
                        dtype=np.int64).reshape(-1, 2)
    world_map = TopoMap.from_arrays(to_a.apply(world.xy), world.edges,
                                    kinds_from_degree(np.bincount(world.edges.ravel(),
                                                                  minlength=world.n_nodes)))
    return SyntheticPair(map_a, map_b, to_a @ frame_b, corr, shared, kind, cfg.noise,
                         seed, index, world_map)


def pair_kind(index: int, n: int, no_overlap_fraction: float) -> str:
    """Which kind pair ``index`` of ``n`` is: the last ``round(n * fraction)`` pairs have no
    overlap, alternating ``"disjoint"`` and ``"other_world"``."""
    n_none = round(n * no_overlap_fraction)
    if index < n - n_none:
        return "overlap"
    return "disjoint" if (index - (n - n_none)) % 2 == 0 else "other_world"


def generate_pairs(n: int, seed: int = 0, config: SyntheticConfig | dict | None = None
                   ) -> Iterator[SyntheticPair]:
    """``n`` pairs, pair ``i`` drawn from ``default_rng([seed, i])`` (reproducible one by one).

    Overlapping pairs come first with target overlaps spread evenly over
    ``config.overlap_range`` (stratified, so every overlap bin gets pairs), then
    ``round(n * no_overlap_fraction)`` no-overlap pairs (:func:`pair_kind`).
    """
    n = check_int(n, "n", low=0)
    seed = check_int(seed, "seed", low=0)
    cfg = config_from(SyntheticConfig, config)
    n_overlap = n - round(n * cfg.no_overlap_fraction)
    lo, hi = cfg.overlap_range
    for i in range(n):
        rng = np.random.default_rng([seed, i])
        kind = pair_kind(i, n, cfg.no_overlap_fraction)
        target = None
        if kind == "overlap":
            target = lo + (hi - lo) * (i + rng.random()) / max(n_overlap, 1)
        yield make_pair(rng, cfg, kind=kind, overlap=target, seed=seed, index=i)
