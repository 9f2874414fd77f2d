"""Merging N maps: pairwise merges assembled into one graph of frames, look-alikes rejected by
cycle consistency.

A pairwise merge of robots ``i < j`` gives ``T_ij`` (robot j's frame → robot i's, ``p_i = R p_j
+ T``) and a confidence. With three or more robots the pairwise merges over-determine the
frames: around any cycle the transforms must compose to the identity (A→B→C agrees with A→C).
A look-alike merge (a room row shifted onto its twin, a 180°-turned corridor) breaks every
cycle it is in, while right merges agree with each other, so :func:`consistent_edges` keeps
the edges that the cycles they close support:

1. **Votes.** Every triangle whose three edges are all merged is checked: its composed
   transform ``T_ab · T_bc · T_ca`` must move the third robot's map centre by at most
   ``tolerance_m`` and turn by at most ``tolerance_deg``. Each edge counts the consistent
   (``+``) and inconsistent (``−``) triangles it is in. The edges with the most ``−`` votes
   (of those, the fewest ``+``) are **disputed** and left out, all of them when several tie,
   and the votes are counted again without them, until no triangle is inconsistent. A
   look-alike among four robots breaks two triangles while its right neighbours break one
   each: it goes alone. In an inconsistent triangle of three robots any edge may be the
   wrong one: all three go, since a wrong merge costs more than a late one.
2. **Unconfirmed edges.** An edge no consistent triangle confirms (the bridge that first
   joins a robot to the others, say) is judged by its own confidence alone, and a team has
   many pairs, hence many chances of one confident look-alike: such an edge is kept only at
   ``min_unconfirmed`` confidence or more (the env's ``mapping.team_accept_threshold``,
   :meth:`fusion.decision.MergeRule.team_min_unconfirmed`).
3. **Spanning forest.** The remaining edges are added by decreasing confidence
   (Kruskal's order); an edge closing a longer cycle is kept only if the path through the
   forest already built agrees with it, so the forest is consistent by construction.

This is pairwise consistency maximisation (PCM, Mangelson et al. 2018) reduced to what frames
without odometry links allow: the group-k consistency of triangles, and a greedy maximum
consistent set. :func:`frames_from` then places each robot's frame in a root robot's: along
the fewest consistent edges where they form a tree (both directions composed from the edges'
own transforms and inverses, so a two-robot team gets exactly the pairwise transform and its
inverse), and where consistent edges close cycles by a least-squares pose graph over all of
them (:func:`adjust_frames`), so that no robot carries one pair's error alone.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import networkx as nx
import numpy as np
from scipy.optimize import least_squares

from fusion.decision import CYCLE_TOLERANCE_DEG, CYCLE_TOLERANCE_M
from fusion.rigid import Rigid2D


@dataclass(frozen=True, slots=True)
class Edge:
    """A pairwise merge in use between robots ``i < j``.

    Attributes:
        i, j: the robots (``i < j``).
        transform: ``T_ij``, robot j's frame → robot i's.
        confidence: its calibrated probability of being right.
        inverse: ``transform.inverse()``, computed once (``None``: computed here).
    """

    i: int
    j: int
    transform: Rigid2D
    confidence: float
    inverse: Rigid2D | None = None

    def __post_init__(self) -> None:
        if not (isinstance(self.i, int) and isinstance(self.j, int) and 0 <= self.i < self.j):
            raise ValueError(f"an edge needs robots 0 <= i < j, got i={self.i!r}, j={self.j!r}")
        if not isinstance(self.transform, Rigid2D):
            raise TypeError(f"transform must be a Rigid2D, got {type(self.transform).__name__}")
        if self.inverse is None:
            object.__setattr__(self, "inverse", self.transform.inverse())

    def towards(self, k: int) -> Rigid2D:
        """The transform into robot ``k``'s frame from the other end's (``k`` is i or j)."""
        return self.transform if k == self.i else self.inverse


@dataclass(frozen=True, slots=True)
class CycleCheck:
    """What :func:`consistent_edges` decided.

    Attributes:
        kept: the edges of the consistent spanning forest, keyed ``(i, j)``.
        consistent: those and the edges closing a cycle that the forest agrees with (what
            :func:`frames_from` composes along).
        disputed: edges left out by the triangle votes.
        rejected: edges left out because the forest's path disagreed with them.
        unconfirmed: edges no consistent triangle confirms, left out below
            ``min_unconfirmed`` confidence.
        votes: ``(i, j) → (consistent, inconsistent)`` triangle counts before any edge was
            left out.
    """

    kept: dict[tuple[int, int], Edge]
    disputed: tuple[tuple[int, int], ...]
    rejected: tuple[tuple[int, int], ...]
    votes: dict[tuple[int, int], tuple[int, int]]
    unconfirmed: tuple[tuple[int, int], ...] = ()
    consistent: dict[tuple[int, int], Edge] = field(default_factory=dict)


def _agrees(a: Rigid2D, b: Rigid2D, at: np.ndarray, tolerance_deg: float,
            tolerance_m: float) -> bool:
    """Whether two transforms between the same frames agree at point ``at`` (their source
    frame)."""
    return (math.degrees(a.rotation_error(b)) <= tolerance_deg
            and a.translation_error(b, at) <= tolerance_m)


def consistent_edges(edges: Sequence[Edge], centres: Mapping[int, np.ndarray] | None = None,
                     *, check: bool = True, tolerance_deg: float = CYCLE_TOLERANCE_DEG,
                     tolerance_m: float = CYCLE_TOLERANCE_M,
                     min_unconfirmed: float = 0.0) -> CycleCheck:
    """The consistent subset of pairwise merges (module docstring).

    Args:
        edges: the merges in use, at most one per pair.
        centres: a point per robot in its own frame where agreement is measured (its map's
            centre; missing robots: their frame origin).
        check: ``False`` keeps the pairwise decisions alone: a spanning forest by confidence,
            no votes, no rejection (for ablations).
        tolerance_deg, tolerance_m: what a consistent cycle may compose to
            (:data:`fusion.decision.CYCLE_TOLERANCE_DEG`, ``CYCLE_TOLERANCE_M``).
        min_unconfirmed: least confidence of an edge no consistent triangle confirms
            (with ``check``).

    Returns:
        a :class:`CycleCheck`.

    Raises:
        ValueError: two edges for the same pair, or a tolerance that is not positive.
    """
    if tolerance_deg <= 0 or tolerance_m <= 0:
        raise ValueError(f"tolerances must be > 0, got {tolerance_deg} deg, {tolerance_m} m")
    by_pair: dict[tuple[int, int], Edge] = {}
    for e in edges:
        if (e.i, e.j) in by_pair:
            raise ValueError(f"two edges for robots ({e.i}, {e.j})")
        by_pair[(e.i, e.j)] = e
    centres = centres or {}

    def centre(k: int) -> np.ndarray:
        return np.asarray(centres.get(k, (0.0, 0.0)), dtype=np.float64)

    consistent = {}
    for tri in _triangles(nx.Graph(list(by_pair))) if check else ():
        a, b, c = tri
        # c → a directly, and c → b → a: they must agree at c's map centre
        direct = by_pair[(a, c)].transform
        around = by_pair[(a, b)].transform @ by_pair[(b, c)].transform
        consistent[tri] = _agrees(direct, around, centre(c), tolerance_deg, tolerance_m)
    first_votes = None
    out: set[tuple[int, int]] = set()
    while True:
        votes = {p: [0, 0] for p in by_pair if p not in out}
        for (a, b, c), ok in consistent.items():
            sides = ((a, b), (b, c), (a, c))
            if all(p in votes for p in sides):
                for p in sides:
                    votes[p][0 if ok else 1] += 1
        if first_votes is None:
            first_votes = {p: (v[0], v[1]) for p, v in votes.items()}
        worst = max((v[1] for v in votes.values()), default=0)
        if worst == 0:
            break
        tied = [p for p, v in votes.items() if v[1] == worst]
        fewest = min(votes[p][0] for p in tied)
        out.update(p for p in tied if votes[p][0] == fewest)
    disputed = tuple(sorted(out))
    confirmed = {p for p, v in votes.items() if v[0]}
    unconfirmed = tuple(sorted(p for p, e in by_pair.items() if check and p not in out
                               and p not in confirmed and e.confidence < min_unconfirmed))
    order = sorted((e for p, e in by_pair.items() if p not in out and p not in unconfirmed),
                   key=lambda e: (-e.confidence, e.i, e.j))
    forest = nx.Graph()
    forest.add_nodes_from(range(1 + max((e.j for e in edges), default=0)))
    kept: dict[tuple[int, int], Edge] = {}
    agreeing: dict[tuple[int, int], Edge] = {}
    rejected = []
    for e in order:
        if nx.has_path(forest, e.i, e.j):
            if not check:
                continue  # the forest has this pair already: pairwise decisions alone
            path = nx.shortest_path(forest, e.i, e.j)
            along = _compose_path(path, kept)  # j → i along the forest
            if not _agrees(e.transform, along, centre(e.j), tolerance_deg, tolerance_m):
                rejected.append((e.i, e.j))
            else:
                agreeing[(e.i, e.j)] = e
            continue
        forest.add_edge(e.i, e.j)
        kept[(e.i, e.j)] = e
    return CycleCheck(kept, disputed, tuple(rejected), first_votes, unconfirmed,
                      {**kept, **agreeing})


def _triangles(graph: nx.Graph) -> list[tuple[int, int, int]]:
    """The graph's triangles as sorted robot triples ``a < b < c``."""
    out = set()
    for a, b in graph.edges:
        for c in set(graph[a]) & set(graph[b]):
            out.add(tuple(sorted((a, b, c))))
    return sorted(out)


def _compose_path(path: Sequence[int], edges: Mapping[tuple[int, int], Edge]) -> Rigid2D:
    """The transform from ``path[-1]``'s frame into ``path[0]``'s along the path's edges."""
    out = None
    for a, b in zip(path, path[1:], strict=False):
        step = edges[(min(a, b), max(a, b))].towards(a)  # b's frame → a's
        out = step if out is None else out @ step
    return out if out is not None else Rigid2D.identity()


def frames_from(root: int, kept: Mapping[tuple[int, int], Edge],
                centres: Mapping[int, np.ndarray] | None = None
                ) -> dict[int, tuple[Rigid2D, Rigid2D]]:
    """Every robot of ``root``'s component of the consistent edges ``kept``
    (:attr:`CycleCheck.consistent`, or a forest), with ``(to_root, from_root)``: its frame →
    root's and root's → its.

    Where the component is a tree, each frame is composed along its path from the edges'
    transforms (breadth first, the more confident edge first; not inverted afterwards), so a
    single edge gives exactly ``(T, T.inverse())`` as stored. Where consistent edges close
    cycles they over-determine the frames, and each pair's error would otherwise land whole on
    whichever robot it reaches: the frames are then the least-squares fit to all of them
    (:func:`adjust_frames`, a pose graph over the robots' frames), started from the composed
    ones. ``centres`` (each robot's map centre in its own frame, where errors are weighed;
    missing: its origin) as for :func:`consistent_edges`. ``root`` maps to the identity both
    ways."""
    ident = Rigid2D.identity()
    out = {root: (ident, ident)}
    graph = nx.Graph()
    graph.add_node(root)
    # added most confident first: each robot's neighbours are listed (and searched) so
    for e in sorted(kept.values(), key=lambda e: (-e.confidence, e.i, e.j)):
        graph.add_edge(e.i, e.j, edge=e)
    for a, b in nx.bfs_edges(graph, root):
        e = graph.edges[a, b]["edge"]
        to_a, from_a = out[a]
        b_to_a, a_to_b = e.towards(a), e.towards(b)
        out[b] = (b_to_a if a == root else to_a @ b_to_a,
                  a_to_b if a == root else a_to_b @ from_a)
    component = graph.subgraph(out)
    if component.number_of_edges() < len(out):  # a tree: nothing over-determined
        return out
    edges = [d["edge"] for _, _, d in component.edges(data=True)]
    to_root = adjust_frames(root, {k: f[0] for k, f in out.items()}, edges, centres)
    return {k: (t, t.inverse()) if k != root else out[root] for k, t in to_root.items()}


ROTATION_SCALE_M = 0.3 / math.radians(2.0)
"""Metres one radian of a pair's rotation error weighs in :func:`adjust_frames`: a merge's
"right" bounds (2°, 0.3 m; ``fusion.calibration``) count alike."""


def adjust_frames(root: int, to_root: Mapping[int, Rigid2D], edges: Sequence[Edge],
                  centres: Mapping[int, np.ndarray] | None = None) -> dict[int, Rigid2D]:
    """The least-squares frames of a connected set of robots given their pairwise merges.

    Each edge ``(i, j)`` asks that robot j's frame, seen through ``T_ij`` and robot i's frame,
    land where robot j's own frame puts it: the residuals are the two placements' distance at
    robot j's map centre (metres) and their rotation difference (× :data:`ROTATION_SCALE_M`).
    Solved with ``scipy.optimize.least_squares`` from ``to_root``, ``root`` held at the
    identity — the pose-graph optimisation that follows a consistent-set selection (as in
    PCM): with every edge consistent, a plain (non-robust) fit.

    Args:
        root: the robot whose frame is the reference.
        to_root: a first guess per robot (its frame → root's), ``root`` included.
        edges: merges between robots of ``to_root``.
        centres: each robot's map centre in its own frame (missing: its origin).

    Returns:
        ``{robot: its frame → root's}`` for the robots of ``to_root``.

    Raises:
        ValueError: ``root`` not in ``to_root``, or an edge to a robot outside it.
    """
    if root not in to_root:
        raise ValueError(f"root {root!r} is not among the robots {sorted(to_root)}")
    for e in edges:
        if e.i not in to_root or e.j not in to_root:
            raise ValueError(f"edge ({e.i}, {e.j}) leaves the robots {sorted(to_root)}")
    free = sorted(k for k in to_root if k != root)
    if not free or not edges:
        return dict(to_root)
    slot = {k: n for n, k in enumerate(free)}
    centres = centres or {}
    at = {k: np.asarray(centres.get(k, (0.0, 0.0)), dtype=np.float64) for k in to_root}
    # per edge: robot j's centre in robot i's frame through T_ij, and in its own frame
    via = np.array([e.transform.R @ at[e.j] + e.transform.T for e in edges])
    own = np.array([at[e.j] for e in edges])
    theta_ij = np.array([e.transform.theta for e in edges])
    # rows of the poses vector [0 (root), x...] each edge's ends read
    ii = np.array([0 if e.i == root else 1 + slot[e.i] for e in edges])
    jj = np.array([0 if e.j == root else 1 + slot[e.j] for e in edges])

    m = len(edges)
    rows = np.arange(m)

    def rotated(x: np.ndarray) -> tuple[np.ndarray, ...]:
        poses = np.vstack([np.zeros(3), x.reshape(-1, 3)])  # theta, tx, ty per robot
        ci, si = np.cos(poses[ii, 0]), np.sin(poses[ii, 0])
        cj, sj = np.cos(poses[jj, 0]), np.sin(poses[jj, 0])
        return (poses, ci * via[:, 0] - si * via[:, 1], si * via[:, 0] + ci * via[:, 1],
                cj * own[:, 0] - sj * own[:, 1], sj * own[:, 0] + cj * own[:, 1])

    def residuals(x: np.ndarray) -> np.ndarray:
        poses, vx, vy, ox, oy = rotated(x)
        turn = np.remainder(poses[ii, 0] + theta_ij - poses[jj, 0] + math.pi,
                            2 * math.pi) - math.pi
        return np.concatenate([vx + poses[ii, 1] - ox - poses[jj, 1],
                               vy + poses[ii, 2] - oy - poses[jj, 2], turn * ROTATION_SCALE_M])

    def jacobian(x: np.ndarray) -> np.ndarray:
        _, vx, vy, ox, oy = rotated(x)
        jac = np.zeros((3 * m, 3 * (len(free) + 1)))
        for r, (di, dj) in enumerate((((-vy, 1, 0), (oy, -1, 0)), ((vx, 0, 1), (-ox, 0, -1)),
                                      ((ROTATION_SCALE_M, 0, 0), (-ROTATION_SCALE_M, 0, 0)))):
            for col in range(3):  # d/d theta, d/d tx, d/d ty of each end's pose
                jac[r * m + rows, 3 * ii + col] += di[col]
                jac[r * m + rows, 3 * jj + col] += dj[col]
        return jac[:, 3:]  # the root's pose is fixed

    x0 = np.concatenate([[to_root[k].theta, *to_root[k].T] for k in free])
    x = least_squares(residuals, x0, jac=jacobian, method="lm").x
    return {root: to_root[root], **{k: Rigid2D(x[3 * slot[k]], x[3 * slot[k] + 1:3 * slot[k] + 3])
                                    for k in free}}
