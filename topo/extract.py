"""``extract_topomap``: an occupancy map → a topological map of **places** and **gateways**.

Two robots that know the same rooms must put the same nodes there, whatever each has seen
beyond them, however each is rotated, and with the wall fragments a sonar leaves. So nodes are
critical points of one smooth field that depends on what is *seen*, and a node whose field
depends on the unknown is flagged:

1. **Working grid** — the map is cropped to its known cells and pooled to ``resolution``
   (a cell is occupied if any fine cell is, free if at least half are).
2. **Free space** — known free, holes smaller than ``min_hole_area`` filled (sonar speckle),
   optionally opened by a disc of ``open_radius`` within ``open_near_unknown`` of the unknown
   (the thin wedges a sonar cone leaves beyond a wall it missed; off by default: the env's
   usable sonar range leaves few, and opening cost repeatability), components smaller than
   ``min_component_area`` dropped (``skimage.morphology``, ``scipy.ndimage``).
3. **Clearance** — the distance from each free cell to the nearest *occupied* cell
   (``scipy.ndimage.distance_transform_edt``), smoothed by a Gaussian of ``smoothing``. The
   unknown is not an obstacle here: where a robot has not looked yet the clearance is not cut
   short, so it does not depend on how far the exploration has got. Walls seen only in
   fragments still bound the field.
4. **Places** — the maxima of the clearance whose persistence is at least ``persistence``
   (the clearance must fall by that much on every way to a higher maximum) and whose
   clearance is at least ``min_clearance``: room centres, corridor crossings and bends, the
   middle of wide spots. The merge tree of the field's superlevel sets (a compiled union-find,
   :func:`topo._kernels.merge_tree`) finds them, with each pixel's basin by steepest
   ascent; the basins of the other maxima join the place they drain into. A place sits at the
   middle of its summit (the cells within ``summit_tolerance`` of its maximum): a room's
   clearance peaks on a nearly flat ridge. Persistence is what
   makes them stable: a maximum that stands out by more than twice a perturbation of the field
   survives it (the stability of persistence diagrams, Cohen-Steiner et al. 2007).
5. **Gateways and paths** — two places whose basins touch are joined by a path through
   their **pass** (the highest point of the common boundary). A pass narrower than
   ``gateway_clearance`` and lower than ``gateway_ratio`` of the lower place is a doorway or a
   narrow passage (a critical point in the sense of Thrun 1998) and becomes a **gateway**
   node; the path runs place → gateway → place. The same rule makes a gateway of the saddle
   where a maximum at least ``min_clearance`` wide that does not persist joined a place's
   basin: the doorway to a room seen too little to be a place of its own is a node all the
   same, so that a robot that saw the room and one that only looked in put a gateway at the
   same door (the path runs place → gateway). A gateway within ``merge_radius`` of its place
   (or of another gateway) is not a node of its own. Polylines follow the shortest route
   inside each basin from the pass to the place (a breadth-first tree per basin, compiled with
   the merge tree; ties go to the higher clearance, so routes keep to the middle of the free
   space).
6. **Dead ends** — an end of the free space's skeleton (``skimage.morphology.skeletonize``)
   at least ``dead_end_clearance`` wide from which the route to its place runs on for
   ``dead_end_length`` without widening by more than ``dead_end_clearance``, at least
   ``dead_end_length`` beyond the place's clearance: the closed end of a corridor. (The spurs a
   skeleton sends into a room's corners widen at once.)
7. **Frontier flags** — a node bounded by the unknown rather than by walls moves as the map
   grows, so :attr:`TopoMap.frontier` flags it and merges leave it out: one whose surroundings
   (a square of half-side its clearance + ``frontier_margin``) have more open unknown than
   ``frontier_fraction`` of the edge of their free space (unknown farther than
   ``frontier_margin`` from any wall: not a gap in a wall seen in fragments), or with open
   unknown inside its own free disc.
8. **Kinds and descriptors** — gateways are :attr:`NodeKind.GATEWAY`; places and dead ends are
   named by their number of paths (:func:`topo.graph.kinds_from_degree`: dead end, corner,
   junction); every node keeps its clearance (:attr:`TopoMap.clearance`, metres) as a size
   descriptor.

Input: an :class:`~topo.grid.OccupancyGrid`, a :class:`~topo.maps.FloorPlan`, an int8 array of
:class:`~topo.grid.CellState` codes, or a boolean free mask (everything else, the outside
included, counts as occupied, nothing as unknown). A map with no occupied cell has no places
(nothing bounds its free space yet). Coordinates are metres in the map's frame: cell
``(iy, ix)`` has its centre at ``origin + (ix + 0.5, iy + 0.5) · resolution`` (row 0 at the
bottom, CONTRIBUTING.md). Nodes are numbered by ``y``, then ``x``; the same input gives the
same map.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage
from skimage.morphology import remove_small_holes, skeletonize

from topo._kernels import basin_paths, merge_tree, route
from topo.graph import NodeKind, TopoMap, kinds_from_degree
from topo.grid import CellState
from topo.validation import check_real, config_from

_UNKNOWN, _FREE, _OCCUPIED = int(CellState.UNKNOWN), int(CellState.FREE), int(CellState.OCCUPIED)


@dataclass(frozen=True, slots=True)
class ExtractConfig:
    """Settings of :func:`extract_topomap` (metres, m²; validated; module docstring, steps 1–7).

    Attributes:
        resolution: cell size the map is pooled to before extraction (never finer than the
            map's own cells). 0.2 m keeps doors (≈ 1 m) several cells wide and an extraction
            cheap enough to repeat during an episode.
        min_hole_area: holes in free space smaller than this are filled.
        open_radius: free space within ``open_near_unknown`` of the unknown is opened by a disc
            of this radius (about the robot's); 0 (the default) turns the opening off.
        open_near_unknown: see ``open_radius`` (a square of this half-side).
        min_component_area: free components smaller than this are dropped.
        smoothing: standard deviation of the Gaussian applied to the clearance; 0 = none.
        persistence: a clearance maximum is a place if it stands out by at least this much.
        min_clearance: ... and if its clearance is at least this (narrower spots are passages).
        summit_tolerance: a place sits at the middle of the cells of its basin whose smoothed
            clearance is within this of its maximum (the top of a room's ridge).
        gateway_clearance: a pass between two places narrower than this ...
        gateway_ratio: ... and lower than this fraction of the lower place is a gateway node.
        dead_end_clearance: a dead end is an end of the skeleton at least this wide ...
        dead_end_length: ... from which the route to its place runs on this far without
            widening by more than ``dead_end_clearance`` (a corridor; module docstring, step 6).
        frontier_margin: the square tested for the unknown reaches this far beyond the
            clearance.
        frontier_fraction: a node is flagged frontier when more than this fraction of the
            non-free cells in its square are unknown.
        merge_radius: a gateway this close to one of its places is not a node of its own.
    """

    resolution: float = 0.2
    min_hole_area: float = 0.5
    open_radius: float = 0.0
    open_near_unknown: float = 0.6
    min_component_area: float = 1.0
    smoothing: float = 0.25
    persistence: float = 0.3
    summit_tolerance: float = 0.05
    min_clearance: float = 0.5
    gateway_clearance: float = 0.65
    gateway_ratio: float = 0.75
    dead_end_clearance: float = 0.4
    dead_end_length: float = 2.0
    frontier_margin: float = 0.3
    frontier_fraction: float = 0.45
    merge_radius: float = 0.5

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            name = f"ExtractConfig.{f.name}"
            value = getattr(self, f.name)
            if f.name == "resolution":
                check_real(value, name, low=0.0)
            elif f.name in ("gateway_ratio", "frontier_fraction"):
                check_real(value, name, low=0.0, high=1.0)
            else:
                check_real(value, name, low=0.0, low_inclusive=True)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ExtractConfig:
        """A config from a plain dict; unknown keys are an error naming the allowed ones."""
        if not isinstance(data, dict):
            raise TypeError(f"data must be a dict, got {type(data).__name__}")
        return config_from(cls, data, "ExtractConfig")


_DEFAULT = ExtractConfig()


# ------------------------------------------------------------------------------ input
def _origin(origin: Any) -> tuple[float, float]:
    if origin is None or isinstance(origin, (str, bytes)):
        raise ValueError(f"origin must be (x, y), got {origin!r}")
    try:
        ox, oy = (float(v) for v in origin)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"origin must be (x, y), got {origin!r}") from exc
    if not (math.isfinite(ox) and math.isfinite(oy)):
        raise ValueError(f"origin must be finite, got {(ox, oy)}")
    return ox, oy


def as_states(grid: Any, resolution: float | None = None, origin: Any = (0.0, 0.0)
              ) -> tuple[np.ndarray, float, tuple[float, float]]:
    """``(states, resolution, origin)`` of any input :func:`extract_topomap` takes:
    ``states`` an int8 ``(H, W)`` array of :class:`~topo.grid.CellState` codes (a free mask
    gains a ring of occupied cells, its origin one cell lower and further left).

    Raises:
        TypeError: an input of another type, an array that is neither bool nor int8.
        ValueError: not 2-D, unknown cell codes, a missing or conflicting resolution, a bad
            origin.
    """
    from topo.grid import OccupancyGrid
    from topo.maps import FloorPlan

    if isinstance(grid, OccupancyGrid):
        if resolution is not None and resolution != grid.resolution:
            raise ValueError(f"resolution {resolution} differs from the grid's "
                             f"{grid.resolution}")
        return grid.states(), float(grid.resolution), (float(grid.origin[0]),
                                                       float(grid.origin[1]))
    if isinstance(grid, FloorPlan):
        if resolution is not None and resolution != grid.resolution:
            raise ValueError(f"resolution {resolution} differs from the floor plan's "
                             f"{grid.resolution}")
        states = np.zeros(grid.free.shape, dtype=np.int8)
        states[grid.free] = _FREE
        states[grid.occupied] = _OCCUPIED
        return states, float(grid.resolution), _origin(grid.origin)
    if not isinstance(grid, np.ndarray):
        raise TypeError("grid must be an OccupancyGrid, a FloorPlan, a 2-D array of CellState "
                        f"codes or a 2-D boolean free mask, got {type(grid).__name__}")
    if grid.ndim != 2 or min(grid.shape) < 1:
        raise ValueError(f"grid must be a 2-D array, got shape {grid.shape}")
    if grid.dtype == bool:
        pass
    elif grid.dtype == np.int8:
        bad = (grid < 0) | (grid > _OCCUPIED)
        if bad.any():
            raise ValueError(f"grid holds cell codes other than CellState "
                             f"{[int(c) for c in CellState]}: {np.unique(grid[bad])[:5].tolist()}")
    else:
        raise TypeError(f"grid must have dtype bool (a free mask) or int8 (CellState codes, as "
                        f"OccupancyGrid.states() gives), got {grid.dtype}")
    if resolution is None:
        raise ValueError("resolution is required with an array (metres per cell), got None")
    res = check_real(resolution, "resolution", low=0.0)
    ox, oy = _origin(origin)
    if grid.dtype == np.int8:
        return grid, res, (ox, oy)
    # a free mask: everything else is occupied, the outside too (a ring of occupied cells)
    states = np.full((grid.shape[0] + 2, grid.shape[1] + 2), _OCCUPIED, dtype=np.int8)
    states[1:-1, 1:-1][grid] = _FREE
    return states, res, (ox - res, oy - res)


def _pool(states: np.ndarray, f: int) -> np.ndarray:
    """``states`` pooled ``f × f``: occupied if any cell is, free if at least half are."""
    if f == 1:
        return states
    h, w = -(-states.shape[0] // f), -(-states.shape[1] // f)
    padded = np.zeros((h * f, w * f), dtype=np.int8)
    padded[:states.shape[0], :states.shape[1]] = states
    n_free = np.zeros((h, w), dtype=np.int16)
    occupied = np.zeros((h, w), dtype=bool)
    for dy in range(f):  # f² strided views: far cheaper than reducing a (h, f, w, f) array
        for dx in range(f):
            cells = padded[dy::f, dx::f]
            n_free += cells == _FREE
            occupied |= cells == _OCCUPIED
    out = np.where(2 * n_free >= f * f, np.int8(_FREE), np.int8(_UNKNOWN))
    out[occupied] = _OCCUPIED
    return out


def _disk(radius_cells: float) -> np.ndarray:
    k = int(math.ceil(radius_cells))
    yy, xx = np.mgrid[-k:k + 1, -k:k + 1]
    return yy * yy + xx * xx <= radius_cells * radius_cells + 1e-9


def _free_space(states: np.ndarray, res: float, cfg: ExtractConfig) -> np.ndarray:
    free = states == _FREE
    hole = int(cfg.min_hole_area / res ** 2)
    if hole > 0:
        free = remove_small_holes(free, max_size=hole)
    r = cfg.open_radius / res
    unknown = states == _UNKNOWN
    if r >= 0.5 and unknown.any():
        opened = ndimage.binary_opening(free, structure=_disk(max(r, 1.0)))
        reach = int(math.ceil(cfg.open_near_unknown / res))  # a square of that half-side
        near = ndimage.maximum_filter(unknown, size=2 * reach + 1, mode="constant")
        free = np.where(near, opened, free)
    labels, n = ndimage.label(free)
    if n:
        keep = np.bincount(labels.ravel()) >= cfg.min_component_area / res ** 2
        keep[0] = False
        free = keep[labels]
    return free


# ------------------------------------------------------------------------------ graph
def _touching(basins: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every pair of 8-connected cells in two different basins (labels ``>= 0``), once:
    ``(a, b)`` flat indices, ``b`` the right, lower-left, lower or lower-right neighbour."""
    flat = np.arange(basins.size).reshape(basins.shape)
    ia, ib = [], []
    for a, b in ((np.s_[:, :-1], np.s_[:, 1:]), (np.s_[:-1, 1:], np.s_[1:, :-1]),
                 (np.s_[:-1, :], np.s_[1:, :]), (np.s_[:-1, :-1], np.s_[1:, 1:])):
        across = (basins[a] >= 0) & (basins[b] >= 0) & (basins[a] != basins[b])
        ia.append(flat[a][across])
        ib.append(flat[b][across])
    return np.concatenate(ia), np.concatenate(ib)


def _passes(basins: np.ndarray, field: np.ndarray
            ) -> dict[tuple[int, int], tuple[tuple[int, int], tuple[int, int]]]:
    """For every pair ``(p, q)``, ``p < q``, of touching basins (labels ≥ 0, 8-connected): the
    two touching cells of their common boundary whose lower value is the highest, the lower
    cell (the pass) first."""
    h, w = basins.shape
    ia, ib = _touching(basins)
    if not len(ia):
        return {}
    fa, fb = field.flat[ia], field.flat[ib]
    lower_a = fa <= fb
    la, lb = basins.flat[ia], basins.flat[ib]
    key = np.minimum(la, lb) * (h * w) + np.maximum(la, lb)
    value = np.where(lower_a, fa, fb)
    low, high = np.where(lower_a, ia, ib), np.where(lower_a, ib, ia)
    order = np.lexsort((high, low, -value, key))  # per pair: highest value, then lowest cells
    key, low, high = key[order], low[order], high[order]
    first = np.concatenate(([True], key[1:] != key[:-1]))
    return {divmod(int(k), h * w): (divmod(int(lo), w), divmod(int(hi), w))
            for k, lo, hi in zip(key[first], low[first], high[first], strict=True)}


def _route(parent: np.ndarray, width: int, start: tuple[int, int]) -> np.ndarray:
    """``(K, 2)`` cells ``(row, col)`` from ``start`` along ``parent``
    (:func:`topo._kernels.basin_paths`) to its basin's place."""
    return route(parent, width, start[0] * width + start[1])


def _summits(field: np.ndarray, basins: np.ndarray, places: np.ndarray, tolerance: float
             ) -> np.ndarray:
    """``(P, 2)`` centroid ``(row, col)`` of each place's summit: the cells of its basin within
    ``tolerance`` of its maximum and connected to it. A room's clearance peaks on a ridge whose
    top is nearly flat; its middle, unlike the first cell reaching the maximum, does not depend
    on how the map is turned."""
    if not len(places):
        return np.empty((0, 2))
    peak = np.full(len(places) + 1, np.inf)
    peak[:-1] = field.ravel()[places]
    top = (basins >= 0) & (field >= peak[basins] - tolerance)
    lab, n = ndimage.label(top, structure=np.ones((3, 3)))
    rows, cols = np.nonzero(top)
    which = lab[rows, cols]
    count = np.bincount(which, minlength=n + 1)
    own = lab.ravel()[places]
    return np.stack([np.bincount(which, rows, n + 1)[own], np.bincount(which, cols, n + 1)[own]],
                    axis=1) / count[own, None]


def _ends(domain: np.ndarray, basins: np.ndarray, parent: np.ndarray, depth: np.ndarray,
          clearance: np.ndarray, places: np.ndarray, res: float, cfg: ExtractConfig
          ) -> list[tuple[int, tuple[int, int]]]:
    """Dead ends: ends of the free space's skeleton (``skimage.morphology.skeletonize``) at
    least ``dead_end_clearance`` wide from which the route to their basin's place runs on for
    ``dead_end_length`` no wider than ``dead_end_clearance`` plus the end's clearance — a
    corridor (the spurs a skeleton sends into a room's corners widen at once) — and ends at
    least ``dead_end_length`` beyond the place's clearance (out of the place's room). The widest
    first, one per ``2 · clearance + dead_end_length`` (the two spurs of a corridor's square
    end are one end). Returns ``(place, cell)`` pairs."""
    skeleton = skeletonize(domain)
    neighbours = ndimage.convolve(skeleton.astype(np.uint8), np.ones((3, 3), np.uint8),
                                  mode="constant")
    ys, xs = np.nonzero(skeleton & (neighbours == 2) & (clearance >= cfg.dead_end_clearance)
                        & (basins >= 0))
    w = basins.shape[1]
    flat_c = clearance.ravel()
    steps = int(math.ceil(cfg.dead_end_length / res))
    # routes in steps (a diagonal one counted as 1: a lower bound in cells)
    length = depth[ys * w + xs]
    far = length * res >= flat_c[places[basins[ys, xs]]] + cfg.dead_end_length
    found = []
    for y, x in zip(ys[far].tolist(), xs[far].tolist(), strict=True):
        p, c = y * w + x, float(clearance[y, x])
        widest = c
        for _ in range(steps):
            p = int(parent[p])
            widest = max(widest, float(flat_c[p]))
        if widest <= c + cfg.dead_end_clearance:
            found.append((c, y, x))
    kept: list[tuple[int, tuple[int, int]]] = []
    for c, y, x in sorted(found, key=lambda f: (-f[0], f[1], f[2])):
        if all(math.dist((y, x), cell) * res > 2 * max(c, float(clearance[cell]))
               + cfg.dead_end_length for _, cell in kept):
            kept.append((int(basins[y, x]), (y, x)))
    return kept


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


def _box_sums(mask: np.ndarray, cells: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Per node ``k``, the cells of ``mask`` set in the square of half-side ``half[k]`` about
    ``cells[k]`` (row, col), clipped to the grid: read off a summed-area table."""
    table = np.zeros((mask.shape[0] + 1, mask.shape[1] + 1), dtype=np.int64)
    np.cumsum(np.cumsum(mask, axis=0, dtype=np.int64), axis=1, out=table[1:, 1:])
    r0, r1 = (np.clip(cells[:, 0] + d, 0, mask.shape[0]) for d in (-half, half + 1))
    c0, c1 = (np.clip(cells[:, 1] + d, 0, mask.shape[1]) for d in (-half, half + 1))
    return table[r1, c1] - table[r0, c1] - table[r1, c0] + table[r0, c0]


def _frontier(cells: np.ndarray, clearance: np.ndarray, states: np.ndarray,
              wall_distance: np.ndarray, res: float, cfg: ExtractConfig) -> np.ndarray:
    """Whether the edge of the free space around each node (its non-free cells that touch a
    free cell, in a square of half-side ``clearance + frontier_margin``) is more than
    ``frontier_fraction`` open unknown rather than occupied. Counted on the edge, so that thick
    walls (a floor plan) and thin ones (a sonar map) weigh alike; unknown within
    ``frontier_margin`` of an occupied cell (``wall_distance``) is a gap in a wall seen in
    fragments, not open unknown, and is not counted (:func:`_box_sums`).
    Also flagged: a node with open unknown within its clearance less ``frontier_margin`` (a
    square of that half-side: inside its own free disc, which a wall bounds)."""
    free = states == _FREE
    edge = ~free & ndimage.maximum_filter(free, size=3, mode="constant")
    open_unknown = edge & (states == _UNKNOWN) & (wall_distance > cfg.frontier_margin)
    outer = np.ceil((clearance + cfg.frontier_margin) / res).astype(np.int64)
    inner = np.floor((clearance - cfg.frontier_margin) / res).astype(np.int64)
    n_unknown = _box_sums(open_unknown, cells, outer)
    n_occupied = _box_sums(edge & (states == _OCCUPIED), cells, outer)
    inside = (inner >= 0) & (_box_sums(open_unknown, cells, np.maximum(inner, 0)) > 0)
    return (n_unknown > cfg.frontier_fraction * (n_unknown + n_occupied)) | inside


def extract_topomap(grid: Any, resolution: float | None = None,
                    origin: Any = (0.0, 0.0), config: ExtractConfig | None = None) -> TopoMap:
    """The topological map of an occupancy map: places, gateways and dead ends (module
    docstring).

    Args:
        grid: an :class:`~topo.grid.OccupancyGrid`, a :class:`~topo.maps.FloorPlan`, a 2-D
            int8 array of :class:`~topo.grid.CellState` codes, or a 2-D boolean free mask.
        resolution: metres per cell of an array (taken from grids and floor plans).
        origin: ``(x, y)`` of the lower-left corner of cell ``(0, 0)`` of an array.
        config: :class:`ExtractConfig`, a dict of its fields, or ``None`` for the defaults.

    Returns:
        A :class:`~topo.graph.TopoMap` with places and gateways, their paths (with polylines),
        clearances and frontier flags; empty if nothing is known.

    Raises:
        TypeError: a grid of another type or dtype, a config that is not an ``ExtractConfig``.
        ValueError: a grid that is not 2-D or holds other codes, a missing or conflicting
            resolution, a bad origin.
    """
    if config is None:
        config = _DEFAULT
    elif isinstance(config, dict):
        config = ExtractConfig.from_dict(config)
    elif not isinstance(config, ExtractConfig):
        raise TypeError(f"config must be an ExtractConfig, a dict of its fields or None, got "
                        f"{type(config).__name__}")
    states, res, (ox, oy) = as_states(grid, resolution, origin)
    known = states != _UNKNOWN
    rows, cols = np.flatnonzero(known.any(axis=1)), np.flatnonzero(known.any(axis=0))
    if not len(rows):
        return TopoMap.empty()
    r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    f = max(1, int(round(config.resolution / res)))
    # one working cell of unknown around the known cells: what lies beyond them is unknown
    work = np.pad(_pool(states[r0:r1, c0:c1], f), 1, constant_values=_UNKNOWN)
    wres = res * f
    worigin = np.array([ox + c0 * res - wres, oy + r0 * res - wres])
    return _extract(work, wres, worigin, config)


def _places(field: np.ndarray, clearance: np.ndarray, domain: np.ndarray, cfg: ExtractConfig
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Step 4: ``(places, basins, saddles, weak)`` — the flat cells of the places (maxima of
    ``field`` that persist by ``persistence`` and are ``min_clearance`` wide), each cell's
    place (``basins``, ``-1`` outside the domain), and the saddle where each maximum that is
    not a place joined its neighbour's component with that maximum (``weak``), for the
    doorways of step 5."""
    inside = np.flatnonzero(domain)
    order = inside[np.argsort(-field.ravel()[inside], kind="stable")]
    ascent, saddle, dying, _, into = merge_tree(field, domain, order)
    flat_f, flat_c = field.ravel(), clearance.ravel()
    # a maximum is a place if it persists and is wide enough; the basin of any other drains
    # into the basin it touches where its component merged (so every place's basin stays
    # connected; chains end at a place or at a component's highest maximum)
    maxima = np.flatnonzero(ascent == np.arange(field.size))
    index = np.full(field.size, -1, dtype=np.int64)
    index[maxima] = np.arange(len(maxima))
    host = np.arange(len(maxima))
    weak = ((flat_f[dying] - flat_f[saddle] < cfg.persistence)
            | (flat_c[dying] < cfg.min_clearance))
    host[index[dying[weak]]] = index[into[weak]]
    for _ in range(64):  # pointer jumping along the (acyclic) drain chains
        nxt = host[host]
        if np.array_equal(nxt, host):
            break
        host = nxt
    resolved = maxima[host]
    places = np.unique(resolved[flat_c[resolved] >= cfg.min_clearance])
    place_of = np.full(field.size, -1, dtype=np.int64)
    place_of[places] = np.arange(len(places))
    lut = np.full(field.size, -1, dtype=np.int64)
    lut[maxima] = place_of[resolved]
    basins = np.where(ascent >= 0, lut[np.maximum(ascent, 0)], -1).reshape(field.shape)
    return places, basins, saddle[weak], dying[weak]


def _extract(states: np.ndarray, res: float, origin: np.ndarray, cfg: ExtractConfig
             ) -> TopoMap:
    occupied = states == _OCCUPIED
    if not occupied.any():  # no wall seen: nothing bounds the free space yet
        return TopoMap.empty()
    free = _free_space(states, res, cfg)
    wall_distance = ndimage.distance_transform_edt(~occupied) * res
    clearance = np.where(free, wall_distance, 0.0)
    field = ndimage.gaussian_filter(clearance, cfg.smoothing / res) if cfg.smoothing else \
        clearance.copy()
    field[~free] = 0.0
    domain = free & (field > 0.0)
    if not domain.any():
        return TopoMap.empty()
    places, basins, saddles, weak = _places(field, clearance, domain, cfg)
    flat_f, flat_c = field.ravel(), clearance.ravel()
    h, w = field.shape
    cells = [divmod(int(m), w) for m in places.tolist()]
    kinds = [-1] * len(cells)  # places' kinds come from their degree below

    def narrow(y: int, x: int, top: float) -> bool:
        """The gateway rule (step 5): a saddle narrower than ``gateway_clearance`` and lower
        than ``gateway_ratio`` of the lower side's maximum ``top``."""
        return bool(clearance[y, x] <= cfg.gateway_clearance
                    and field[y, x] <= cfg.gateway_ratio * top)

    links: list[tuple[int, int, int | None, tuple[int, int]]] = []  # (p, q, gateway, pass)
    for (p, q), ((y, x), other) in sorted(_passes(basins, field).items()):
        gate = None
        if narrow(y, x, min(flat_f[places[p]], flat_f[places[q]])):
            near = min(math.dist((y, x), cells[p]), math.dist((y, x), cells[q])) * res
            if near > cfg.merge_radius:
                gate = len(cells)
                cells.append((y, x))
                kinds.append(int(NodeKind.GATEWAY))
        links.append((p, q, gate, ((y, x), other)))
    # doorways to rooms seen too little to be places of their own: where a wide maximum that
    # does not persist joined a place's basin, the same rule as for a pass between two places
    doors: list[tuple[int, int]] = []  # (place, gateway)
    for s, m in zip(saddles.tolist(), weak.tolist(), strict=True):
        y, x = divmod(s, w)
        p = int(basins[y, x])
        if p < 0 or flat_c[m] < cfg.min_clearance \
                or not narrow(y, x, min(flat_f[m], flat_f[places[p]])):
            continue
        if any(math.dist((y, x), cells[k]) * res <= cfg.merge_radius
               for k in (p, *range(len(places), len(cells)))):
            continue  # at its place, or a gateway already there
        doors.append((p, len(cells)))
        cells.append((y, x))
        kinds.append(int(NodeKind.GATEWAY))
    # polylines: from each side of the pass along the basin's routes to its place
    parent, depth = basin_paths(basins, field, places)
    edges: list[tuple[int, int]] = []
    polys: list[np.ndarray] = []
    for p, q, gate, (cell, other) in links:
        side = {int(basins[cell]): cell, int(basins[other]): other}
        a = _route(parent, w, side[p])[::-1]   # p ... pass side
        b = _route(parent, w, side[q])         # pass side ... q
        if gate is None:
            edges.append((p, q))
            polys.append(np.concatenate([a, b]))
        else:
            g = np.array([cells[gate]], dtype=np.int64)
            edges += [(p, gate), (gate, q)]
            polys += [np.concatenate([a, g]) if tuple(a[-1]) != cells[gate] else a,
                      np.concatenate([g, b]) if tuple(b[0]) != cells[gate] else b]
    for p, gate in doors:
        edges.append((p, gate))
        polys.append(_route(parent, w, cells[gate])[::-1])
    for p, (y, x) in _ends(domain, basins, parent, depth, clearance, places, res, cfg):
        edges.append((p, len(cells)))
        polys.append(_route(parent, w, (y, x))[::-1])
        cells.append((y, x))
        kinds.append(-1)
    centres = _summits(field, basins, places, cfg.summit_tolerance)
    return _assemble(np.array(cells, dtype=np.int64).reshape(-1, 2), centres,
                     np.array(kinds, dtype=np.int8), np.array(edges, dtype=np.int64).reshape(-1, 2),
                     polys, clearance, states, wall_distance, origin, res, cfg)


def _assemble(rc: np.ndarray, centres: np.ndarray, kinds: np.ndarray, edges: np.ndarray,
              polys: list[np.ndarray], clearance: np.ndarray, states: np.ndarray,
              wall_distance: np.ndarray, origin: np.ndarray, res: float, cfg: ExtractConfig
              ) -> TopoMap:
    """Steps 7–8: the :class:`TopoMap` of nodes at cells ``rc`` (the places first, placed at
    their summits' ``centres``), ``kinds`` (``-1``: from the degree), ``edges`` and their cell
    polylines ``polys``, in metres, with clearances and frontier flags, numbered by ``y``, then
    ``x``."""
    node_clear = clearance[rc[:, 0], rc[:, 1]]
    frontier = _frontier(rc, node_clear, states, wall_distance, res, cfg)
    xy = origin + (rc[:, ::-1] + 0.5) * res
    xy[: len(centres)] = origin + (centres[:, ::-1] + 0.5) * res
    degree_kinds = kinds_from_degree(np.bincount(edges.ravel(), minlength=len(rc)))
    kinds = np.where(kinds < 0, degree_kinds, kinds).astype(np.int8)
    # number nodes by y, then x (then kind, for two nodes on one cell)
    order = np.lexsort((kinds, xy[:, 0], xy[:, 1]))
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    sizes = np.array([len(poly) for poly in polys], dtype=np.int64)
    points = origin + (np.concatenate(polys)[:, ::-1] + 0.5) * res if polys else np.empty((0, 2))
    ends = np.cumsum(sizes)
    points[ends - sizes] = xy[edges[:, 0]]  # from node to node (places' centres)
    points[ends - 1] = xy[edges[:, 1]]
    steps = np.append(np.hypot(*np.diff(points, axis=0).T), 0.0)
    steps[ends - 1] = 0.0  # the step from one polyline's last point to the next one's first
    lengths = np.add.reduceat(steps, ends - sizes) if polys else np.empty(0)
    paths = np.split(points, ends[:-1]) if polys else []
    # valid by construction (indices in range, no self-loops, polylines from node to node)
    return TopoMap(_frozen(xy[order]), _frozen(kinds[order]), _frozen(rank[edges]),
                   _frozen(lengths), tuple(_frozen(q) for q in paths), node_clear[order],
                   frontier[order])
