"""``TopoMap``: a topological map — places (junctions, dead ends, corners) and the paths between.

A map is immutable: arrays are read-only and every operation returns a new map. Coordinates are
metres in the frame of the robot that built the map. Node kinds are small integers from one
encoding table, :class:`NodeKind` (MiniGrid-style ``OBJECT_TO_IDX``), with names used at the edges
(dicts, networkx, plots).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import networkx as nx
import numpy as np

from topo.validation import as_points

FORMAT_VERSION = 2
"""Version of the :meth:`TopoMap.to_dict` layout (2 added ``clearance`` and ``frontier``);
:meth:`TopoMap.from_dict` reads versions 1 and 2."""


class NodeKind(enum.IntEnum):
    """The one encoding table of node kinds (the int stored in :attr:`TopoMap.kinds`)."""

    JUNCTION = 0
    DEAD_END = 1
    CORNER = 2
    GATEWAY = 3
    """A doorway or narrow passage between two places, or from a place into a room seen too
    little to be a place of its own (:func:`topo.extract_topomap`)."""

    @property
    def label(self) -> str:
        """The kind's name in dicts and networkx attributes: ``"junction"`` etc."""
        return self.name.lower()

    @classmethod
    def parse(cls, value: object, field: str = "kinds") -> NodeKind:
        """A kind from its label (``"dead_end"``), its code (``1``) or a ``NodeKind``."""
        if isinstance(value, str):
            for kind in cls:
                if kind.label == value:
                    return kind
        elif isinstance(value, (int, np.integer)) and not isinstance(value, bool):
            if int(value) in cls._value2member_map_:
                return cls(int(value))
        allowed = ", ".join(f"{k.label!r} ({k.value})" for k in cls)
        raise ValueError(f"{field} has unknown node kind {value!r}; allowed: {allowed}")


KIND_LABELS: tuple[str, ...] = tuple(k.label for k in NodeKind)


class PointTransform(Protocol):
    """Anything that maps an ``(N, 2)`` array of points, e.g. :class:`fusion.Rigid2D`."""

    def apply(self, points: np.ndarray) -> np.ndarray: ...


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


def kinds_from_degree(degree: np.ndarray) -> np.ndarray:
    """Default kinds from node degree: 1 (or 0) → dead end, 2 → corner, ≥ 3 → junction."""
    degree = np.asarray(degree)
    kinds = np.full(degree.shape, NodeKind.CORNER, dtype=np.int8)
    kinds[degree <= 1] = NodeKind.DEAD_END
    kinds[degree >= 3] = NodeKind.JUNCTION
    return kinds


_KIND_OF_DEGREE = np.array([NodeKind.DEAD_END, NodeKind.DEAD_END, NodeKind.CORNER,
                            NodeKind.JUNCTION], dtype=np.int8)
"""``kinds_from_degree`` of degrees 0, 1, 2 and ≥ 3, as a table."""


@dataclass(frozen=True, slots=True, eq=False)
class TopoMap:
    """A topological map: nodes with positions and kinds, and undirected paths between them.

    Build one with :meth:`from_arrays` (validated), :meth:`from_networkx` or :meth:`from_dict`.

    Attributes:
        xy: ``(N, 2)`` float64 node positions in metres.
        kinds: ``(N,)`` int8 codes from :class:`NodeKind`.
        edges: ``(E, 2)`` int64 node indices, one row per path. Parallel paths between the same
            two nodes are allowed (two corridors joining the same junctions); self-loops are not
            (a loop must pass through at least one more node).
        lengths: ``(E,)`` float64 path lengths in metres (at least the straight-line distance).
        paths: ``None`` or one ``(K, 2)`` polyline per edge, from its first node to its second,
            kept for plotting.
        clearance: ``(N,)`` float64 distance (metres) from each node to the nearest obstacle or
            unknown cell, the node's size descriptor for matching; 0 where not known (maps not
            made by :func:`topo.extract_topomap`).
        frontier: ``(N,)`` bool, ``True`` for a node that touches the unknown (the edge of the
            explored area): such a node moves as the map grows, so merges leave it out.
    """

    xy: np.ndarray
    kinds: np.ndarray
    edges: np.ndarray
    lengths: np.ndarray
    paths: tuple[np.ndarray, ...] | None = None
    clearance: np.ndarray | None = None
    frontier: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = self.xy.shape[0]
        clearance = np.zeros(n) if self.clearance is None else self.clearance
        frontier = np.zeros(n, dtype=bool) if self.frontier is None else self.frontier
        object.__setattr__(self, "clearance", _frozen(np.asarray(clearance, dtype=np.float64)))
        object.__setattr__(self, "frontier", _frozen(np.asarray(frontier, dtype=bool)))

    # ---------------------------------------------------------------- construction
    @classmethod
    def from_arrays(
        cls,
        xy: Any,
        edges: Any = (),
        kinds: Any = None,
        lengths: Any = None,
        paths: Sequence[Any] | None = None,
        clearance: Any = None,
        frontier: Any = None,
    ) -> TopoMap:
        """Validate arrays and build a map.

        Args:
            xy: ``(N, 2)`` node positions in metres; finite.
            edges: ``(E, 2)`` node index pairs; in ``[0, N)``; no self-loops.
            kinds: ``(N,)`` labels (``"junction"``, ``"dead_end"``, ``"corner"``), codes or
                :class:`NodeKind`; ``None`` derives them from degree (:func:`kinds_from_degree`).
            lengths: ``(E,)`` path lengths; ``None`` uses straight-line distances. Must be finite
                and not shorter than the straight line (1 mm slack).
            paths: optional polylines, one ``(K >= 2, 2)`` array per edge.
            clearance: ``(N,)`` finite, non-negative node clearances (m); ``None`` = zeros.
            frontier: ``(N,)`` booleans; ``None`` = no node is on the frontier.

        Raises:
            ValueError: naming the field and the offending value.
            TypeError: when a field is not array-like.
        """
        xy = as_points(xy, "xy")
        n = len(xy)
        edges = _as_edges(edges, n)
        if kinds is None:
            degree = np.bincount(edges.ravel(), minlength=n)
            codes = kinds_from_degree(degree)
        else:
            codes = _as_kinds(kinds, n)
        straight = np.linalg.norm(xy[edges[:, 0]] - xy[edges[:, 1]], axis=1)
        if lengths is None:
            lens = straight
        else:
            lens = _as_lengths(lengths, straight)
        polys = None if paths is None else _as_paths(paths, len(edges))
        return cls(_frozen(xy), _frozen(codes), _frozen(edges), _frozen(lens), polys,
                   _as_clearance(clearance, n), _as_flags(frontier, n))

    @classmethod
    def empty(cls) -> TopoMap:
        """A map with no nodes (what a robot that has seen nothing yet has)."""
        return cls.from_arrays(np.empty((0, 2)))

    # ---------------------------------------------------------------- views
    @property
    def n_nodes(self) -> int:
        return int(self.xy.shape[0])

    @property
    def n_edges(self) -> int:
        return int(self.edges.shape[0])

    def __len__(self) -> int:
        return self.n_nodes

    def __repr__(self) -> str:
        counts = np.bincount(self.kinds, minlength=len(NodeKind))
        parts = ", ".join(f"{k.label}={counts[k]}" for k in NodeKind)
        return f"TopoMap(nodes={self.n_nodes} [{parts}], edges={self.n_edges})"

    def kind_labels(self) -> list[str]:
        """Node kinds as labels, in node order."""
        return [KIND_LABELS[k] for k in self.kinds]

    def degree(self) -> np.ndarray:
        """``(N,)`` number of paths at each node (a parallel path counts again)."""
        return np.bincount(self.edges.ravel(), minlength=self.n_nodes)

    def path_directions(self, reach: float = 1.0) -> list[np.ndarray]:
        """Per node, the directions (radians, CCW from +x) of the paths leaving it, measured
        to the point ``reach`` metres along each path (its polyline when known, else the
        straight segment; the far end if the path is shorter): with :attr:`clearance` and
        :meth:`degree`, a node's descriptor — the same place seen by two robots has its paths
        leaving the same ways, turned by the robots' relative heading.

        Raises:
            ValueError: ``reach`` not a positive number.
        """
        if not (isinstance(reach, (int, float)) and math.isfinite(reach) and reach > 0):
            raise ValueError(f"reach must be a positive number of metres, got {reach!r}")
        out: list[list[float]] = [[] for _ in range(self.n_nodes)]
        for e, (u, v) in enumerate(self.edges.tolist()):
            line = self.paths[e] if self.paths is not None else self.xy[[u, v]]
            for node, pts in ((u, line), (v, line[::-1])):
                steps = np.hypot(*np.diff(pts, axis=0).T)
                k = min(int(np.searchsorted(np.cumsum(steps), reach)) + 1, len(pts) - 1)
                d = pts[k] - pts[0]
                out[node].append(math.atan2(d[1], d[0]))
        return [np.array(a, dtype=np.float64) for a in out]

    def endpoints(self) -> np.ndarray:
        """The paper's point set: coordinates of the path endpoints (``E_A``/``E_B`` of eq. 2).

        Every node that ends at least one path, once, in node order. A map without paths
        returns an empty ``(0, 2)`` array.
        """
        used = np.zeros(self.n_nodes, dtype=bool)
        used[self.edges.ravel()] = True
        return self.xy[used]

    def transformed(self, transform: PointTransform) -> TopoMap:
        """The same map with every position (nodes and polylines) mapped by ``transform``.

        ``transform`` is anything with ``apply((N, 2)) -> (N, 2)``, such as
        :class:`fusion.Rigid2D`; lengths are kept (a rigid motion preserves them).
        """
        xy = np.asarray(transform.apply(self.xy), dtype=np.float64).reshape(-1, 2)
        paths = None
        if self.paths is not None:
            paths = tuple(
                _frozen(np.asarray(transform.apply(p), dtype=np.float64)) for p in self.paths
            )
        return TopoMap(_frozen(xy), self.kinds, self.edges, self.lengths, paths, self.clearance,
                       self.frontier)

    # ---------------------------------------------------------------- conversions
    def to_networkx(self) -> nx.MultiGraph:
        """A ``networkx.MultiGraph``: node ``i`` has ``xy`` (tuple), ``kind`` (label),
        ``clearance`` and ``frontier``; each
        edge has ``length`` and, if known, ``path`` (list of ``(x, y)``). A multigraph because
        two paths may join the same pair of nodes."""
        g = nx.MultiGraph()
        for i, ((x, y), k, c, f) in enumerate(zip(self.xy.tolist(), self.kinds.tolist(),
                                                  self.clearance.tolist(),
                                                  self.frontier.tolist(), strict=True)):
            g.add_node(i, xy=(x, y), kind=KIND_LABELS[k], clearance=c, frontier=f)
        for e, (u, v) in enumerate(self.edges.tolist()):
            attrs: dict[str, Any] = {"length": float(self.lengths[e])}
            if self.paths is not None:
                attrs["path"] = [tuple(p) for p in self.paths[e].tolist()]
            g.add_edge(u, v, **attrs)
        return g

    @classmethod
    def from_networkx(cls, graph: nx.Graph) -> TopoMap:
        """Build from a ``Graph`` or ``MultiGraph`` whose nodes carry ``xy`` (and optionally
        ``kind``, ``clearance``, ``frontier``) and whose edges may carry ``length`` and
        ``path``. Nodes are numbered in the graph's iteration order."""
        if not isinstance(graph, nx.Graph):
            raise TypeError(f"graph must be a networkx Graph, got {type(graph).__name__}")
        if graph.is_directed():
            raise ValueError("graph must be undirected, got a directed graph")
        index = {node: i for i, node in enumerate(graph.nodes)}
        try:
            xy = [graph.nodes[node]["xy"] for node in graph.nodes]
        except KeyError as exc:
            raise ValueError("graph nodes must each have an 'xy' attribute") from exc
        node_kinds = [graph.nodes[node].get("kind") for node in graph.nodes]
        kinds = None if any(k is None for k in node_kinds) else node_kinds
        clearance = [graph.nodes[node].get("clearance", 0.0) for node in graph.nodes]
        frontier = [bool(graph.nodes[node].get("frontier", False)) for node in graph.nodes]
        edge_rows = list(graph.edges(data=True))
        edges = [(index[u], index[v]) for u, v, _ in edge_rows]
        lengths = None
        if edge_rows and all("length" in d for _, _, d in edge_rows):
            lengths = [d["length"] for _, _, d in edge_rows]
        paths = None
        if edge_rows and all("path" in d for _, _, d in edge_rows):
            # networkx may report an edge as (v, u): orient polylines from the first node.
            paths = []
            for (u, _v, d) in edge_rows:
                p = np.asarray(d["path"], dtype=np.float64)
                start = np.asarray(graph.nodes[u]["xy"], dtype=np.float64)
                if len(p) and np.linalg.norm(p[-1] - start) < np.linalg.norm(p[0] - start):
                    p = p[::-1]
                paths.append(p)
        return cls.from_arrays(np.asarray(xy, dtype=np.float64).reshape(-1, 2),
                               np.asarray(edges, dtype=np.int64).reshape(-1, 2),
                               kinds, lengths, paths, clearance, frontier)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-safe dict (plain lists and strings) that :meth:`from_dict` reads back exactly."""
        out: dict[str, Any] = {
            "format": "topomerge.TopoMap",
            "version": FORMAT_VERSION,
            "xy": self.xy.tolist(),
            "kinds": self.kind_labels(),
            "edges": self.edges.tolist(),
            "lengths": self.lengths.tolist(),
        }
        if self.paths is not None:
            out["paths"] = [p.tolist() for p in self.paths]
        out["clearance"] = self.clearance.tolist()
        out["frontier"] = self.frontier.tolist()
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TopoMap:
        """Read a dict made by :meth:`to_dict` (validated like :meth:`from_arrays`)."""
        if not isinstance(data, dict):
            raise TypeError(f"data must be a dict, got {type(data).__name__}")
        version = data.get("version")
        if data.get("format") != "topomerge.TopoMap" or version not in (1, FORMAT_VERSION):
            raise ValueError(
                f"data is not a topomerge.TopoMap version 1 or {FORMAT_VERSION} dict "
                f"(format={data.get('format')!r}, version={version!r})"
            )
        known = {"format", "version", "xy", "kinds", "edges", "lengths", "paths", "clearance",
                 "frontier"}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"data has unknown keys {unknown}; allowed: {sorted(known)}")
        missing = sorted({"xy", "kinds", "edges", "lengths"} - set(data))
        if missing:
            raise ValueError(f"data is missing keys {missing}")
        return cls.from_arrays(
            np.asarray(data["xy"], dtype=np.float64).reshape(-1, 2),
            np.asarray(data["edges"], dtype=np.int64).reshape(-1, 2),
            data["kinds"], data["lengths"], data.get("paths"), data.get("clearance"),
            data.get("frontier"),
        )

    def equals(self, other: TopoMap, atol: float = 0.0) -> bool:
        """Same nodes, kinds, frontier flags, edges and lengths (positions, clearances and
        lengths within ``atol``)."""
        return (
            self.xy.shape == other.xy.shape
            and self.edges.shape == other.edges.shape
            and np.array_equal(self.kinds, other.kinds)
            and np.array_equal(self.frontier, other.frontier)
            and np.allclose(self.clearance, other.clearance, rtol=0.0, atol=atol)
            and np.array_equal(self.edges, other.edges)
            and np.allclose(self.xy, other.xy, rtol=0.0, atol=atol)
            and np.allclose(self.lengths, other.lengths, rtol=0.0, atol=atol)
        )


# -------------------------------------------------------------------- field validation
def _as_edges(edges: Any, n: int) -> np.ndarray:
    if edges is None or isinstance(edges, (str, bytes, dict)):
        raise TypeError(f"edges must be an (E, 2) integer array, got {type(edges).__name__}")
    arr = np.asarray(edges)
    if arr.size == 0:
        return np.empty((0, 2), dtype=np.int64)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(f"edges must have shape (E, 2), got shape {arr.shape}")
    if not np.issubdtype(arr.dtype, np.integer):
        if not np.issubdtype(arr.dtype, np.floating) or not np.all(np.mod(arr, 1) == 0):
            raise TypeError(f"edges must hold integer node indices, got dtype {arr.dtype}")
    arr = arr.astype(np.int64)
    out_of_range = (arr < 0) | (arr >= n)
    if out_of_range.any():
        row = int(np.argwhere(out_of_range)[0, 0])
        raise ValueError(
            f"edges[{row}] = {arr[row].tolist()} has a node index out of range [0, {n})"
        )
    loops = arr[:, 0] == arr[:, 1]
    if loops.any():
        row = int(np.flatnonzero(loops)[0])
        raise ValueError(f"edges[{row}] = {arr[row].tolist()} is a self-loop; not allowed")
    return arr


def _as_kinds(kinds: Any, n: int) -> np.ndarray:
    if isinstance(kinds, (str, bytes)):
        raise TypeError(f"kinds must be a sequence of {n} node kinds, got a string")
    seq = list(np.asarray(kinds, dtype=object).ravel()) if not isinstance(kinds, list) else kinds
    if len(seq) != n:
        raise ValueError(f"kinds must have one entry per node ({n}), got {len(seq)}")
    return np.fromiter((NodeKind.parse(k) for k in seq), dtype=np.int8, count=n)


def _as_lengths(lengths: Any, straight: np.ndarray) -> np.ndarray:
    try:
        arr = np.asarray(lengths, dtype=np.float64).ravel()
    except (TypeError, ValueError) as exc:
        raise TypeError(f"lengths must be numeric, got {type(lengths).__name__}") from exc
    if arr.shape != straight.shape:
        raise ValueError(f"lengths must have one entry per edge ({len(straight)}), got {arr.size}")
    bad = ~np.isfinite(arr) | (arr < straight - 1e-3)
    if bad.any():
        e = int(np.flatnonzero(bad)[0])
        raise ValueError(
            f"lengths[{e}] = {arr[e]} must be finite and >= the straight-line distance "
            f"{straight[e]:.4f} between its nodes"
        )
    return arr


def _as_clearance(clearance: Any, n: int) -> np.ndarray | None:
    if clearance is None:
        return None
    if isinstance(clearance, (str, bytes, dict)):
        raise TypeError(f"clearance must be a sequence of {n} numbers, got "
                        f"{type(clearance).__name__}")
    try:
        arr = np.asarray(clearance, dtype=np.float64).ravel()
    except (TypeError, ValueError) as exc:
        raise TypeError(f"clearance must be numeric, got {type(clearance).__name__}") from exc
    if arr.size != n:
        raise ValueError(f"clearance must have one entry per node ({n}), got {arr.size}")
    bad = ~np.isfinite(arr) | (arr < 0)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"clearance[{i}] = {arr[i]} must be finite and >= 0")
    return arr


def _as_flags(frontier: Any, n: int) -> np.ndarray | None:
    if frontier is None:
        return None
    arr = np.asarray(frontier)
    if arr.dtype != bool and not (np.issubdtype(arr.dtype, np.integer)
                                  and np.isin(arr, (0, 1)).all()):
        raise TypeError(f"frontier must hold booleans, got dtype {arr.dtype}")
    if arr.size != n:
        raise ValueError(f"frontier must have one entry per node ({n}), got {arr.size}")
    return arr.astype(bool).ravel()


def _as_paths(paths: Sequence[Any], n_edges: int) -> tuple[np.ndarray, ...]:
    if len(paths) != n_edges:
        raise ValueError(f"paths must have one polyline per edge ({n_edges}), got {len(paths)}")
    return tuple(_frozen(as_points(p, f"paths[{e}]", min_points=2)) for e, p in enumerate(paths))
