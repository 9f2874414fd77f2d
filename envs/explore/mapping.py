"""Mapping in the loop: per-robot grids and topological maps, the shared map, and the
bookkeeping of covered area.

Frames: robot ``i`` maps in its own start frame (its odometry frame). The **shared map** lives
in robot 0's frame ("A"); robot 1's map ("B") enters it through the latest accepted
``fusion.merge_maps`` transform (``p_A = R p_B + T``). Ground truth is the world frame.

Per step only a window around each robot is touched: the grid update visits the cones' cells
(``topo.OccupancyGrid``) and adds those it makes known to the "ever known" mask, and the shared
map only receives the bounding box of the cells that became known this step — so a step's cost
does not grow with the world's size. The shared map is re-warped whole only when a merge
changes the transform. "Ever known" makes coverage monotone: a cell whose log-odds later drift
back to unknown still counts as covered. The true coverage sweeps the cones without a grid
(:class:`OracleCoverage`).

Cell states are :class:`topo.grid.CellState` codes (``UNKNOWN = 0``, ``FREE = 1``,
``OCCUPIED = 2``); ``topo.grid.IMAGE_VALUES`` is the one table turning them into ``local_map``
pixels (unknown 128, free 255, occupied 0). Where two maps overlap, the shared state is the
larger code (occupied wins over free, known over unknown).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from envs.explore._kernels import NO_STATES, sample_image
from fusion.rigid import Rigid2D
from topo.extract import ExtractConfig, extract_topomap
from topo.graph import TopoMap
from topo.grid import IMAGE_VALUES, CellState, OccupancyGrid, SensorModel, sweep_scan

LOCAL_MAP_VALUES = IMAGE_VALUES
"""``local_map`` pixel value of each cell state: ``topo.grid.IMAGE_VALUES`` (unknown 128, free
255, occupied 0)."""

@dataclass(frozen=True, slots=True)
class Geometry:
    """Where a grid lies: ``origin`` (lower-left corner of cell (0, 0)), ``resolution`` and
    ``shape`` ``(H, W)``, CONTRIBUTING.md conventions."""

    origin: tuple[float, float]
    resolution: float
    shape: tuple[int, int]

    def window(self, xy: np.ndarray, margin: int) -> tuple[slice, slice] | None:
        """Row and column slices of the cells covering points ``xy`` (``(N, 2)``) plus
        ``margin`` cells, clipped to the grid; ``None`` if that is empty."""
        (lo_x, lo_y), (hi_x, hi_y) = xy.min(axis=0).tolist(), xy.max(axis=0).tolist()
        inv = 1.0 / self.resolution
        r0 = max(math.floor((lo_y - self.origin[1]) * inv) - margin, 0)
        r1 = min(math.floor((hi_y - self.origin[1]) * inv) + margin + 1, self.shape[0])
        c0 = max(math.floor((lo_x - self.origin[0]) * inv) - margin, 0)
        c1 = min(math.floor((hi_x - self.origin[0]) * inv) + margin + 1, self.shape[1])
        if r0 >= r1 or c0 >= c1:
            return None
        return slice(r0, r1), slice(c0, c1)


def geometry_of(grid: OccupancyGrid) -> Geometry:
    """The :class:`Geometry` of an ``OccupancyGrid``."""
    return Geometry((float(grid.origin[0]), float(grid.origin[1])), float(grid.resolution),
                    tuple(int(n) for n in grid.shape))


def cell_indices(xy: np.ndarray, geometry: Geometry) -> np.ndarray:
    """Flat (row-major) indices of the cells of ``geometry`` holding points ``xy`` (``(N, 2)``
    metres); ``-1`` for points outside the grid."""
    ix = np.floor((xy[:, 0] - geometry.origin[0]) / geometry.resolution).astype(np.int64)
    iy = np.floor((xy[:, 1] - geometry.origin[1]) / geometry.resolution).astype(np.int64)
    h, w = geometry.shape
    inside = (ix >= 0) & (ix < w) & (iy >= 0) & (iy < h)
    return np.where(inside, iy * w + ix, -1)


def warp_window(dst: Geometry, src: Geometry, src_mask: np.ndarray,
                window: tuple[slice, slice], transform: Rigid2D,
                inverse: Rigid2D | None = None
                ) -> tuple[tuple[slice, slice], np.ndarray] | None:
    """Nearest-cell resampling of ``src_mask[window]`` into ``dst`` through ``transform``
    (src frame → dst frame; ``inverse``: ``transform.inverse()`` if the caller has it).

    Returns ``(dst_window, values)``: the slices of ``dst`` covered by the moved window and the
    resampled values there (``False``/0 outside the source window); ``None`` if the window
    lands outside ``dst``.
    """
    rs, cs = window
    sres = src.resolution
    x0 = src.origin[0] + cs.start * sres
    x1 = src.origin[0] + cs.stop * sres
    y0 = src.origin[1] + rs.start * sres
    y1 = src.origin[1] + rs.stop * sres
    corners = transform.apply(np.array([[x0, y0], [x1, y0], [x0, y1], [x1, y1]]))
    dwin = dst.window(corners, margin=1)
    if dwin is None:
        return None
    drs, dcs = dwin
    inv = transform.inverse() if inverse is None else inverse
    r, t = inv.R, inv.T
    # the source cell under every destination cell centre (moved by the inverse motion)
    x = dst.origin[0] + (np.arange(dcs.start, dcs.stop) + 0.5) * dst.resolution
    y = dst.origin[1] + (np.arange(drs.start, drs.stop) + 0.5) * dst.resolution
    iu = np.floor((r[0, 0] * x[None, :] + r[0, 1] * y[:, None] + (t[0] - x0)) / sres)
    iv = np.floor((r[1, 0] * x[None, :] + r[1, 1] * y[:, None] + (t[1] - y0)) / sres)
    inside = (iu >= 0) & (iu < cs.stop - cs.start) & (iv >= 0) & (iv < rs.stop - rs.start)
    out = np.zeros(inside.shape, dtype=src_mask.dtype)
    out[inside] = src_mask[rs.start + iv[inside].astype(np.int64),
                           cs.start + iu[inside].astype(np.int64)]
    return dwin, out


def _or_patch(dst: np.ndarray, patch: np.ndarray, rs: slice, cs: slice) -> int:
    """``dst[rs, cs] |= patch`` (bool); returns how many cells of ``dst`` became true."""
    view = dst[rs, cs]
    new = int(np.count_nonzero(patch & ~view))
    view |= patch
    return new


class RobotMap:
    """An occupancy grid with "ever known" bookkeeping and a topological map: one robot's maps
    in its own start frame.

    Args:
        extent: ``(xmin, ymin, xmax, ymax)`` of the grid, metres.
        resolution: metres per cell.
        model: the grid's inverse sensor model (``None``: ``topo.SensorModel()``).

    Attributes:
        grid: the ``topo.OccupancyGrid``.
        geometry: its :class:`Geometry`.
        states: ``(H, W)`` int8 cell states (the grid's own read-only view).
        ever: ``(H, W)`` bool, cells known at least once (coverage never shrinks).
        n_ever: ``ever.sum()``, kept incrementally.
        bbox: ``[r0, r1, c0, c1]`` bounding box of :attr:`ever` (``None`` before the first scan).
        topomap: the latest extracted ``topo.TopoMap`` (own frame).
    """

    __slots__ = ("grid", "geometry", "states", "ever", "n_ever", "bbox", "topomap")

    def __init__(self, extent: tuple[float, float, float, float], resolution: float,
                 model: SensorModel | None = None) -> None:
        self.grid = OccupancyGrid(resolution=resolution, extent=extent, model=model)
        self.geometry = geometry_of(self.grid)
        self.states = self.grid.states()
        self.ever = np.zeros(self.geometry.shape, dtype=bool)
        self.n_ever = 0
        self.bbox: list[int] | None = None
        self.topomap = TopoMap.empty()

    def integrate(self, pose: np.ndarray, ranges: np.ndarray, angles: np.ndarray,
                  mount_radius: float, max_range: float, half_cone: float) -> np.ndarray:
        """Fold one sonar scan (taken at odometry ``pose``) into the grid and :attr:`ever`.

        Readings are measured from the transducers on the rim; the grid's sensor model puts all
        sensors at the robot centre, so ``mount_radius`` is added to ranges and to
        ``max_range``. Returns the counts of ``OccupancyGrid.update_tracked``, of which
        ``[n_fresh, r0, r1, c0, c1]`` matter here: how many cells became known for the first
        time and their bounding box (all zero if none).
        """
        # the grid's checks are skipped (update_valid's contract): the env's scans are valid by
        # construction, and checking them would add to every step's cost
        counts = self.grid.update_tracked(pose, ranges + mount_radius, angles,
                                          max_range + mount_radius, half_cone, self.ever)
        n = int(counts[0])
        if n:
            self.n_ever += n
            self.widen(*counts[1:5].tolist())
        return counts

    def widen(self, r0: int, r1: int, c0: int, c1: int) -> None:
        """Grow :attr:`bbox` to cover rows ``r0 … r1 - 1`` and columns ``c0 … c1 - 1``: cells
        scanned, or moved there when the map is recomposed (``GraphMerging.straighten``)."""
        if self.bbox is None:
            self.bbox = [r0, r1, c0, c1]
        else:
            b = self.bbox
            b[0], b[1] = min(b[0], r0), max(b[1], r1)
            b[2], b[3] = min(b[2], c0), max(b[3], c1)

    def copy(self) -> RobotMap:
        """An independent copy (grid, known cells, topological map): what a teammate keeps of
        this map after their contact ends."""
        out = RobotMap.__new__(RobotMap)
        out.grid = self.grid.copy()
        out.geometry = self.geometry
        out.states = out.grid.states()
        out.ever = self.ever.copy()
        out.n_ever = self.n_ever
        out.bbox = None if self.bbox is None else list(self.bbox)
        out.topomap = self.topomap
        return out

    def known_window(self) -> tuple[slice, slice] | None:
        """Slices of :attr:`bbox` (``None`` before the first scan)."""
        if self.bbox is None:
            return None
        return slice(self.bbox[0], self.bbox[1]), slice(self.bbox[2], self.bbox[3])

    def known_centre(self) -> np.ndarray | None:
        """The centre of :attr:`bbox` in the map's frame, metres (``None`` before the first
        scan)."""
        if self.bbox is None:
            return None
        r0, r1, c0, c1 = self.bbox
        g = self.geometry
        return np.array([g.origin[0] + 0.5 * (c0 + c1) * g.resolution,
                         g.origin[1] + 0.5 * (r0 + r1) * g.resolution])

    def extract(self, config: ExtractConfig | None = None) -> TopoMap:
        """Re-extract :attr:`topomap` from the cell states inside :attr:`bbox` with
        ``topo.extract_topomap`` (``config``: its :class:`topo.extract.ExtractConfig`)."""
        win = self.known_window()
        if win is None:
            return self.topomap
        rs, cs = win
        g = self.geometry
        origin = (g.origin[0] + cs.start * g.resolution, g.origin[1] + rs.start * g.resolution)
        self.topomap = extract_topomap(self.states[win], resolution=g.resolution, origin=origin,
                                       config=config)
        return self.topomap


@dataclass(frozen=True, slots=True)
class RobotMapSnapshot:
    """One robot's maps at one env step (own start frame), read-only and never changed by later
    steps: what :meth:`TwoRobotExploreEnv.robot_map` hands out.

    Attributes:
        grid: a copy of the robot's ``topo.OccupancyGrid`` (its arrays read-only).
        topomap: the latest extracted ``topo.TopoMap`` (immutable).
        odometry: ``(3,)`` read-only ``(x, y, heading)`` odometry pose.
        known_cells: cells known at least once (coverage never shrinks).
        step: the env step the snapshot was taken at (0 = after ``reset``).
    """

    grid: OccupancyGrid
    topomap: TopoMap
    odometry: np.ndarray
    known_cells: int
    step: int

    @classmethod
    def of(cls, robot_map: RobotMap, odometry: np.ndarray, step: int) -> RobotMapSnapshot:
        """Copy ``robot_map``'s grid and freeze it."""
        grid = robot_map.grid.copy()
        grid.freeze()
        odo = np.array(odometry, dtype=np.float64)
        odo.setflags(write=False)
        return cls(grid, robot_map.topomap, odo, int(robot_map.n_ever), int(step))


@dataclass(frozen=True, slots=True)
class FusedMapSnapshot:
    """One robot's fused map at one env step, in its own odometry frame, read-only and never
    changed by later steps: what :meth:`MultiRobotExploreEnv.fused_map` hands out.

    Attributes:
        states: ``(H, W)`` read-only int8 ``topo.grid.CellState`` codes (unknown 0, free 1,
            occupied 2) on the robot's own grid geometry (CONTRIBUTING.md conventions).
        resolution: metres per cell.
        origin: ``(x, y)`` of the lower-left corner of cell (0, 0) in the robot's frame, m.
        robots: the robots whose maps it holds (its fused component, sorted; itself included).
        known_cells: cells whose state is known in it now (not unknown).
        step: the env step the snapshot was taken at (0 = after ``reset``).
    """

    states: np.ndarray
    resolution: float
    origin: tuple[float, float]
    robots: tuple[int, ...]
    known_cells: int
    step: int

    @classmethod
    def of(cls, states: np.ndarray, geometry: Geometry, robots: Sequence[int],
           step: int) -> FusedMapSnapshot:
        """Freeze ``states`` (a new array the caller hands over) of a grid of ``geometry``."""
        states.setflags(write=False)
        return cls(states, geometry.resolution, geometry.origin, tuple(int(r) for r in robots),
                   int(np.count_nonzero(states)), int(step))

    def known_mask(self) -> np.ndarray:
        """``(H, W)`` bool: cells known (free or occupied)."""
        return self.states != CellState.UNKNOWN

    def occupied_mask(self) -> np.ndarray:
        """``(H, W)`` bool: occupied cells."""
        return self.states == CellState.OCCUPIED


def fused_states(owner: RobotMap, teammates: Sequence[tuple[RobotMap, Rigid2D]]
                 ) -> tuple[tuple[slice, slice], np.ndarray] | None:
    """The cell states of a rigid fused map on ``owner``'s grid: its states with each teammate
    map's known window moved in by its transform (``(map, to_owner)``: its frame → the
    owner's; nearest cell, :func:`warp_window`), the larger code winning where maps overlap
    (module docstring).

    Returns the window of the owner's grid holding every known cell and a new int8 array of
    the states there; ``None`` before the owner's first scan. One compositor for the
    renderer's fused panel and :meth:`MultiRobotExploreEnv.fused_map`.
    """
    win = owner.known_window()
    if win is None:
        return None
    g = owner.geometry
    rows, cols = win
    moved = []
    for peer, to_owner in teammates:
        if peer.known_window() is None:
            continue
        warped = warp_window(g, peer.geometry, peer.states, peer.known_window(), to_owner)
        if warped is not None:
            moved.append(warped)
            (r1, c1), _ = warped
            rows = slice(min(rows.start, r1.start), max(rows.stop, r1.stop))
            cols = slice(min(cols.start, c1.start), max(cols.stop, c1.stop))
    states = owner.states[rows, cols].copy()
    for (r1, c1), vals in moved:
        sub = (slice(r1.start - rows.start, r1.stop - rows.start),
               slice(c1.start - cols.start, c1.stop - cols.start))
        np.maximum(states[sub], vals, out=states[sub])
    return (rows, cols), states


class SharedMap:
    """A robot's fused map in its own frame: its known cells and those of the teammates merged
    with it, each moved by its transform into this frame (``map_0 ∪ T_01 · map_1 ∪ …``). The
    env keeps robot 0's (the team map the reward counts).

    Attributes:
        ever: ``(H, W)`` bool cells known in the fused map, the owner's geometry.
        count: ``ever.sum()`` kept incrementally.
        members: ``{j: (to_owner, from_owner)}`` for each merged teammate ``j``: its frame →
            the owner's and back (``fusion.Rigid2D``); empty until a merge is accepted.
        owner: the robot whose frame and map it is built on.
    """

    __slots__ = ("geometry", "ever", "count", "members", "owner")

    def __init__(self, geometry: Geometry, owner: int = 0) -> None:
        self.geometry = geometry
        self.owner = owner
        self.ever = np.zeros(geometry.shape, dtype=bool)
        self.count = 0
        self.members: dict[int, tuple[Rigid2D, Rigid2D]] = {}

    @property
    def transform(self) -> Rigid2D | None:
        """Robot 1's frame → the owner's (robot 0's) in use, ``None`` when robot 1 is not
        merged (the two-robot env's "merge transform in use")."""
        member = self.members.get(1)
        return None if member is None else member[0]

    @property
    def inverse(self) -> Rigid2D | None:
        """``transform``'s inverse (``None`` likewise)."""
        member = self.members.get(1)
        return None if member is None else member[1]

    @property
    def area(self) -> float:
        """Known area in m²."""
        return self.count * self.geometry.resolution ** 2

    def add(self, index: int, robot_map: RobotMap, window: tuple[slice, slice] | None) -> int:
        """OR robot ``index``'s known cells in ``window`` of ``robot_map`` (its map, or the
        owner's copy of it) into the fused map; returns how many fused cells became known
        (a teammate counts only while merged)."""
        if window is None:
            return 0
        if index == self.owner:
            rs, cs = window
            new = _or_patch(self.ever, robot_map.ever[rs, cs], rs, cs)
        else:
            member = self.members.get(index)
            if member is None:
                return 0
            res = warp_window(self.geometry, robot_map.geometry, robot_map.ever, window,
                              member[0], member[1])
            if res is None:
                return 0
            (rs, cs), vals = res
            new = _or_patch(self.ever, vals, rs, cs)
        self.count += new
        return new

    def rebuild(self, maps: Mapping[int, RobotMap],
                members: Mapping[int, tuple[Rigid2D, Rigid2D]]) -> int:
        """Start over with new merged teammates (``members`` as the attribute; ``maps``: the
        owner's map and each member's as the owner knows it); returns the change of the known
        cell count (negative if a new transform overlaps more, or teammates leave)."""
        before = self.count
        self.members = dict(members)
        own = maps[self.owner]
        self.ever[...] = own.ever
        self.count = own.n_ever
        for j in sorted(self.members):
            self.add(j, maps[j], maps[j].known_window())
        return self.count - before


class OracleCoverage:
    """True coverage: what the sonars have really swept, in the world frame.

    Each robot's scans are swept, from its **true** pose and with its **true** ranges (nearest
    real echo per cone, no noise, no dropout), into a world-frame mask: the cells the robots'
    inverse sensor model would update (free up to the echo or the usable range, the band at an
    echo within it). That model makes a cell known with a single update, so this is exactly
    the "ever known" mask of a world-frame grid folding the same scans, without keeping the
    grid. A dropped echo makes a robot believe it sees through a wall; the sweep stops at the
    wall. Odometry errors do not enter either. ``model`` is the robots' sensor model (``None``:
    ``topo.SensorModel()``).

    Attributes:
        swept: per robot, ``(H, W)`` bool world cells it has swept; ``n_swept``: their counts.
        union: ``(H, W)`` bool, world cells swept by any robot.
        both: sweeps of a cell another robot swept before; ``covered``: reachable cells swept
            by any robot (the coverage numerator); ``count``: ``union.sum()``.
    """

    __slots__ = ("geometry", "reachable", "n_reachable", "swept", "n_swept", "union", "both",
                 "covered", "count", "_model")

    def __init__(self, extent: tuple[float, float, float, float], resolution: float,
                 reachable: np.ndarray, model: SensorModel | None = None,
                 robots: int = 2) -> None:
        # the robots' cell size and sensor model
        grid = OccupancyGrid(resolution=resolution, extent=extent, model=model)
        self.geometry = geometry_of(grid)
        if self.geometry.shape != reachable.shape:
            raise ValueError(f"reachable must have the grid's shape {self.geometry.shape}, got "
                             f"{reachable.shape}")
        m = self._model = grid.model
        if not (-m.l_free > m.threshold and m.l_occupied > m.threshold):
            raise ValueError(f"the sweep needs a sensor model whose single update makes a cell "
                             f"known (|l_free| and l_occupied above threshold), got {m}")
        self.reachable = reachable
        self.n_reachable = int(np.count_nonzero(reachable))
        self.swept = [np.zeros(self.geometry.shape, dtype=bool) for _ in range(robots)]
        self.n_swept = [0] * robots
        self.union = np.zeros(self.geometry.shape, dtype=bool)
        self.both = 0
        self.covered = 0
        self.count = 0

    @property
    def fraction(self) -> float:
        """Swept fraction of the reachable free area."""
        return self.covered / self.n_reachable

    @property
    def overlap(self) -> float:
        """How much the robots swept twice: cells swept again by another robot over the most
        that could be (all but the largest sweep). With two robots, the fraction of the
        smaller robot's sweep the other also swept."""
        if len(self.n_swept) == 2:
            small = min(self.n_swept)
            return self.both / small if small else 0.0
        most = sum(self.n_swept) - max(self.n_swept)
        return (sum(self.n_swept) - self.count) / most if most else 0.0

    @property
    def area(self) -> float:
        """Area swept by either robot, m²."""
        return self.count * self.geometry.resolution ** 2

    def add(self, index: int, pose: np.ndarray, true_ranges: np.ndarray, angles: np.ndarray,
            mount_radius: float, max_range: float, half_cone: float) -> int:
        """Sweep robot ``index``'s scan from its true world ``pose`` (ranges from the
        transducers, as :meth:`RobotMap.integrate`); returns how many world cells the team
        swept for the first time."""
        g = self.geometry
        counts = sweep_scan(self.swept[index], g.origin, g.resolution, self._model, pose,
                            true_ranges + mount_radius, angles, max_range + mount_radius,
                            half_cone, self.union, self.reachable)
        fresh, both, new, covered = counts[[0, 5, 6, 7]].tolist()
        self.n_swept[index] += fresh
        self.both += both
        self.count += new
        self.covered += covered
        return new


_STATE_CODES = np.arange(len(LOCAL_MAP_VALUES), dtype=np.uint8)
"""The identity table: :meth:`LocalMapSampler.sample` gathers the cells' state codes."""


class LocalMapSampler:
    """The egocentric ``local_map``: a heading-up square around a pose, nearest-cell sampling.

    Pixel ``(r, c)`` of the ``size × size`` image lies ``(size/2 - r - 0.5) · resolution`` ahead
    of the robot and ``(size/2 - c - 0.5) · resolution`` to its left: the robot is at the
    centre facing up, its left on the image's left.
    """

    __slots__ = ("size", "_steps")

    def __init__(self, size: int, resolution: float) -> None:
        self.size = size
        # row r lies _steps[r] ahead, column c _steps[c] to the left
        self._steps = (size / 2.0 - np.arange(size) - 0.5) * resolution

    def sample(self, states: np.ndarray, geometry: Geometry, pose: np.ndarray,
               out: np.ndarray | None = None) -> np.ndarray:
        """``(size*size,)`` int8 states of ``states`` (in ``geometry``) around ``pose`` (that
        grid's frame); outside the grid is unknown. With ``out`` (a previous sample), the
        cell-wise maximum of both is written there (known beats unknown, occupied beats
        free) and returned."""
        img = np.empty((1, self.size, self.size), dtype=np.uint8)
        sample_image(img, _STATE_CODES, self._steps, self._steps, states, geometry.origin[0],
                     geometry.origin[1], geometry.resolution, float(pose[0]), float(pose[1]),
                     float(pose[2]), NO_STATES, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
        got = img.reshape(-1).view(np.int8)
        if out is None:
            return got
        np.maximum(out, got, out=out)
        return out

    def image(self, states: np.ndarray, geometry: Geometry, pose: np.ndarray,
              others: Sequence[tuple[np.ndarray, Geometry, np.ndarray]] = ()) -> np.ndarray:
        """The ``(1, size, size)`` uint8 ``local_map``: :data:`LOCAL_MAP_VALUES` of
        :meth:`sample`'s states, with ``others`` = ``(states, geometry, pose)`` of further
        grids of the cell-wise maximum of all samples (as ``sample(..., out=...)``); one
        compiled pass for up to one other grid, a fresh array."""
        img = np.empty((1, self.size, self.size), dtype=np.uint8)
        if len(others) > 1:
            out = self.sample(states, geometry, pose)
            for st, g, p in others:
                self.sample(st, g, p, out=out)
            img[0] = LOCAL_MAP_VALUES[out].reshape(self.size, self.size)
            return img
        if not others:
            states2, g2, pose2 = NO_STATES, geometry, pose
        else:
            states2, g2, pose2 = others[0]
        sample_image(img, LOCAL_MAP_VALUES, self._steps, self._steps, states,
                     geometry.origin[0], geometry.origin[1], geometry.resolution,
                     float(pose[0]), float(pose[1]), float(pose[2]), states2, g2.origin[0],
                     g2.origin[1], g2.resolution, float(pose2[0]), float(pose2[1]),
                     float(pose2[2]))
        return img


def compose_pose(transform: Rigid2D, pose: np.ndarray) -> np.ndarray:
    """``pose`` ``(x, y, heading)`` moved by ``transform``."""
    xy = transform.R @ pose[:2] + transform.T
    th = pose[2] + transform.theta
    return np.array([xy[0], xy[1], math.atan2(math.sin(th), math.cos(th))])
