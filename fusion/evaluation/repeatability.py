"""Node repeatability: do two robots that know the same place put the same nodes there?

A topological merge can only work if the two maps' nodes of a shared place coincide. This
module measures that on a map pair with its true transform, the way keypoint repeatability is
measured in vision (Mikolajczyk et al. 2005), against the level chance alone would reach:

1. **Shared region** — the cells of A's grid that A knows and that B's known cells, moved into
   A's frame by the truth, also cover, eroded by ``erode`` metres (so that a node on the edge
   of one robot's knowledge is not counted).
2. **Repeatability at r** — of A's nodes inside the region, the share that has a B node (moved
   by the truth) within ``r``, wherever that B node lies (a node just outside the eroded region
   is still a node B placed there); the same from B's side (B's nodes moved into A's frame,
   inside the region, against all of A's nodes); the pair's figure is the mean of the two sides
   (of the one side that has region nodes, when only one has).
3. **Chance level at r** — the repeatability of nodes placed at random in the same region at
   the other map's node density ``ρ``: ``1 − exp(−ρ π r²)``, the same mean of two sides. A map
   denser in nodes scores higher by chance alone, so the two are read together.
4. **Mutual matches** — pairs of nodes, at least one of them in the region, that are each
   other's nearest neighbour within the first radius: a rigid fit on nodes needs at least 3.

Only the nodes a merge matches take part: with ``include_frontier=False`` (the default) nodes
flagged :attr:`topo.TopoMap.frontier` (they touch the unknown and move as the map grows) are
left out, as the structural merge leaves them out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from fusion.rigid import Rigid2D
from topo.graph import TopoMap
from topo.grid import CellState
from topo.validation import check_real

RADII = (0.5, 1.0)
"""Default radii (metres) of :func:`node_repeatability`."""


@dataclass(frozen=True, slots=True)
class Repeatability:
    """Node repeatability of one map pair (:func:`node_repeatability`).

    Attributes:
        radii: the radii (metres) the figures below are given at, in order.
        repeatability: ``(len(radii),)`` mean of A's and B's share of region nodes with a node
            of the other map within each radius (one side's share when the other has no region
            node); NaN when neither map has a node in the region.
        chance: ``(len(radii),)`` the same for nodes placed at random at the same densities.
        nodes_a, nodes_b: matchable nodes of each map inside the shared region.
        mutual: node pairs, at least one node in the region, that are mutually nearest
            within ``radii[0]``.
        region_m2: area of the shared region (m²).
        hits: ``(len(radii), 2)`` int, how many of A's and of B's region nodes have a node of
            the other map within each radius (for figures pooled over many pairs).
    """

    radii: tuple[float, ...]
    repeatability: np.ndarray
    chance: np.ndarray
    nodes_a: int
    nodes_b: int
    mutual: int
    region_m2: float
    hits: np.ndarray

    @property
    def nodes(self) -> float:
        """Mean node count of the two maps in the shared region."""
        return 0.5 * (self.nodes_a + self.nodes_b)


def _states_of(grid: Any, name: str) -> tuple[np.ndarray, float, np.ndarray]:
    states = grid.states() if callable(getattr(grid, "states", None)) else getattr(
        grid, "states", None)
    if states is None or not hasattr(grid, "resolution") or not hasattr(grid, "origin"):
        raise TypeError(f"{name} must be an OccupancyGrid or a grid snapshot (states, "
                        f"resolution, origin), got {type(grid).__name__}")
    states = np.asarray(states)
    if states.ndim != 2:
        raise ValueError(f"{name}.states must be 2-D, got shape {states.shape}")
    res = check_real(grid.resolution, f"{name}.resolution", low=0.0)
    return states, res, np.asarray(grid.origin, dtype=np.float64)


def _cells(xy: np.ndarray, origin: np.ndarray, res: float) -> np.ndarray:
    return np.floor((xy - origin) / res).astype(np.int64)[:, ::-1]  # (row, col)


def shared_region(grid_a: Any, grid_b: Any, truth: Rigid2D, erode: float = 0.3
                  ) -> np.ndarray:
    """The shared region on A's grid: bool ``(H, W)`` of the cells A knows whose centres, moved
    into B's frame by ``truth.inverse()``, fall on cells B knows, eroded by ``erode`` metres."""
    sa, res_a, org_a = _states_of(grid_a, "grid_a")
    sb, res_b, org_b = _states_of(grid_b, "grid_b")
    if not isinstance(truth, Rigid2D):
        raise TypeError(f"truth must be a Rigid2D, got {type(truth).__name__}")
    check_real(erode, "erode", low=0.0, low_inclusive=True)
    known_a = sa != CellState.UNKNOWN
    rows, cols = np.nonzero(known_a)
    region = np.zeros_like(known_a)
    if len(rows):
        centres = np.stack([org_a[0] + (cols + 0.5) * res_a, org_a[1] + (rows + 0.5) * res_a], 1)
        ij = _cells(truth.inverse().apply(centres), org_b, res_b)
        inside = ((ij[:, 0] >= 0) & (ij[:, 0] < sb.shape[0])
                  & (ij[:, 1] >= 0) & (ij[:, 1] < sb.shape[1]))
        hit = np.zeros(len(rows), dtype=bool)
        hit[inside] = sb[ij[inside, 0], ij[inside, 1]] != CellState.UNKNOWN
        region[rows[hit], cols[hit]] = True
    k = int(round(erode / res_a))
    if k > 0 and region.any():
        yy, xx = np.mgrid[-k:k + 1, -k:k + 1]
        region = ndimage.binary_erosion(region, structure=yy * yy + xx * xx <= k * k,
                                        border_value=0)
    return region


def in_region(xy: Any, region: Any, grid: Any) -> np.ndarray:
    """Whether each point lies on a ``True`` cell of ``region``, a mask over ``grid``'s cells
    (as :func:`shared_region` gives on grid A): ``(N,)`` bool for ``(N, 2)`` points in metres
    in the grid's frame; points off the grid are outside. Counts nodes in a region.

    Raises:
        TypeError: ``grid`` has no states, resolution or origin.
        ValueError: ``xy`` is not ``(N, 2)``; ``region`` is not a 2-D mask of the grid's shape.
    """
    states, res, origin = _states_of(grid, "grid")
    xy = np.asarray(xy, dtype=np.float64)
    if xy.ndim != 2 or xy.shape[1] != 2:
        raise ValueError(f"xy must be (N, 2) points, got shape {xy.shape}")
    region = np.asarray(region)
    if region.shape != states.shape:
        raise ValueError(f"region must be a mask of the grid's shape {states.shape}, got shape "
                         f"{region.shape}")
    return _in_region(xy, region.astype(bool, copy=False), origin, res)


def _in_region(xy: np.ndarray, region: np.ndarray, origin: np.ndarray, res: float
               ) -> np.ndarray:
    ij = _cells(xy, origin, res)
    ok = ((ij[:, 0] >= 0) & (ij[:, 0] < region.shape[0])
          & (ij[:, 1] >= 0) & (ij[:, 1] < region.shape[1]))
    out = np.zeros(len(xy), dtype=bool)
    out[ok] = region[ij[ok, 0], ij[ok, 1]]
    return out


def _matchable(m: TopoMap, include_frontier: bool) -> np.ndarray:
    if include_frontier:
        return m.xy
    return m.xy[~m.frontier]


def node_repeatability(map_a: TopoMap, map_b: TopoMap, grid_a: Any, grid_b: Any,
                       truth: Rigid2D, *, radii: tuple[float, ...] = RADII,
                       erode: float = 0.3, include_frontier: bool = False) -> Repeatability:
    """Node repeatability of a map pair against its true B → A transform (module docstring).

    Args:
        map_a, map_b: the two robots' topological maps, each in its own frame.
        grid_a, grid_b: their occupancy grids (``topo.OccupancyGrid`` or
            ``fusion.evaluation.pairs.GridSnapshot``), which define what each robot knows.
        truth: the true transform ``p_A = R p_B + T``.
        radii: distances (metres, increasing) at which a node counts as repeated.
        erode: the shared region is eroded by this (metres).
        include_frontier: count frontier-flagged nodes too (the merge leaves them out).

    Returns:
        A :class:`Repeatability`.

    Raises:
        TypeError: a map that is not a ``TopoMap``, a grid without states/resolution/origin, a
            truth that is not a ``Rigid2D``.
        ValueError: radii empty, not positive or not increasing; a negative ``erode``.
    """
    for name, m in (("map_a", map_a), ("map_b", map_b)):
        if not isinstance(m, TopoMap):
            raise TypeError(f"{name} must be a TopoMap, got {type(m).__name__}")
    radii = tuple(float(check_real(r, "radii", low=0.0)) for r in radii)
    if not radii or any(b <= a for a, b in zip(radii, radii[1:], strict=False)):
        raise ValueError(f"radii must be a non-empty increasing sequence, got {radii}")
    region = shared_region(grid_a, grid_b, truth, erode)
    _, res_a, org_a = _states_of(grid_a, "grid_a")
    area = float(region.sum()) * res_a * res_a
    xa = _matchable(map_a, include_frontier)
    xb = truth.apply(_matchable(map_b, include_frontier)) if len(map_b.xy) else np.empty((0, 2))
    in_a = _in_region(xa, region, org_a, res_a)
    in_b = _in_region(xb, region, org_a, res_a)
    na, nb = int(in_a.sum()), int(in_b.sum())
    rep = np.full(len(radii), np.nan)
    chance = np.full(len(radii), np.nan)
    mutual = 0
    hits = np.zeros((len(radii), 2), dtype=np.int64)
    if na or nb:
        # every node's nearest in the other map (inf when that map has none)
        da, ia = cKDTree(xb).query(xa) if len(xb) else (np.full(len(xa), np.inf), None)
        db, ib = cKDTree(xa).query(xb) if len(xa) else (np.full(len(xb), np.inf), None)
        if ia is not None and ib is not None:
            mutual = int(np.sum((ib[ia] == np.arange(len(xa))) & (da <= radii[0])
                                & (in_a | in_b[ia])))
        sides = [(n, other) for n, other in ((na, nb), (nb, na)) if n]
        for k, r in enumerate(radii):
            hits[k] = np.sum(da[in_a] <= r), np.sum(db[in_b] <= r)
            rep[k] = np.mean([h / n for h, n in zip(hits[k], (na, nb), strict=True) if n])
            chance[k] = np.mean([1 - math.exp(-other / area * math.pi * r * r)
                                 for _, other in sides])
    return Repeatability(radii, rep, chance, na, nb, mutual, area, hits)
