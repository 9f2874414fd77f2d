"""``OccupancyGrid``: a log-odds occupancy grid in a robot's own frame, with a sonar-cone inverse
sensor model (Elfes 1989 / Moravec 1988 style).

Geometry (CONTRIBUTING.md): a **fixed extent** ``(xmin, ymin, xmax, ymax)`` in metres, chosen
when the grid is made (the env uses a square around the start large enough for the whole world);
``log_odds[iy, ix]`` with row 0 at the bottom; ``origin = (xmin, ymin)`` is the lower-left corner
of cell (0, 0). Readings that fall outside the extent are ignored (documented, never an error).

Sonar inverse model, per sonar of a scan (pose ``(x, y, θ)``, direction ``θ + α``, cone half
width ``β``, range ``r``): every cell whose centre lies within the cone (bearing within ``β`` of
the axis) and closer than ``r − w/2`` gains ``l_free`` (more free); the arc ``|d − r| ≤ w/2``
gains ``l_occupied`` (more occupied), with ``w`` = ``hit_width`` (one cell by default); cells
beyond stay as they were. A reading ``r ≥ max_range`` is "no echo" and only frees, up to
``max_range``. With a ``usable_range`` (gmapping's ``maxUrange``), a reading beyond it counts
as no echo within it: it frees the cone up to ``usable_range`` and marks nothing. Why: an echo
lost to specular reflection makes a cone read long, through the wall it missed, and a far
echo's arc is wide (15° at 4 m: 1 m) and sweeps across doorways; near readings, taken again
as the robot moves, carry the map. Log-odds are clamped to ``±clamp``; a cell is free below
``−threshold``, occupied above ``+threshold``, unknown between (:class:`CellState`, the one
encoding table).

Speed: one compiled loop (numba) visits, per sonar, only the cells of each row of its cone
sector's bounding box that the sector's edges and arc can reach (plus one each side), and
tests each cell centre exactly (distance from the sensor, angle to the axis), so a scan costs
the same whatever the grid size. The state of touched cells is kept up to date, so
:meth:`states` is free. Cones are applied one after another: a cell inside two overlapping cones
is updated twice.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage

from topo._kernels import NO_COUNTS, NO_MASK, sonar_update
from topo.validation import as_points, check_real


def _float_array(value: Any, name: str, shape: str) -> np.ndarray:
    """``value`` as a float64 array, or a ``ValueError`` naming ``name`` (never numpy's own)."""
    if value is None or isinstance(value, (str, bytes, dict, set)):
        raise ValueError(f"{name} must be a numeric array {shape}, got {type(value).__name__}")
    if isinstance(value, np.ndarray) and value.dtype == np.float64:
        return value
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric array {shape}, got {value!r}") from exc


class CellState(enum.IntEnum):
    """The one encoding table of cell states (:meth:`OccupancyGrid.states`)."""

    UNKNOWN = 0
    FREE = 1
    OCCUPIED = 2


IMAGE_VALUES = np.array([128, 255, 0], dtype=np.uint8)
""":meth:`OccupancyGrid.to_image` grey level of each :class:`CellState`."""


@dataclass(frozen=True, slots=True)
class SensorModel:
    """Log-odds increments of the inverse sensor model (validated)."""

    l_free: float = -0.4
    l_occupied: float = 0.85
    clamp: float = 4.0
    threshold: float = 0.35
    hit_width: float | None = None
    """Thickness of the occupied arc in metres; ``None`` = one cell."""
    usable_range: float | None = None
    """Readings beyond this (metres) only free the cone up to it (module docstring);
    ``None`` uses every reading to its full range."""

    def __post_init__(self) -> None:
        check_real(self.l_free, "l_free", high=0.0, high_inclusive=False)
        check_real(self.l_occupied, "l_occupied", low=0.0)
        check_real(self.clamp, "clamp", low=0.0)
        check_real(self.threshold, "threshold", low=0.0, high=self.clamp, high_inclusive=False)
        if self.hit_width is not None:
            check_real(self.hit_width, "hit_width", low=0.0)
        if self.usable_range is not None:
            check_real(self.usable_range, "usable_range", low=0.0)

    @property
    def usable(self) -> float:
        """:attr:`usable_range`, ``inf`` for ``None`` (the kernel's argument)."""
        return math.inf if self.usable_range is None else float(self.usable_range)

    def classify(self, log_odds: np.ndarray) -> np.ndarray:
        """``(H, W)`` int8 :class:`CellState` codes of ``log_odds``: free below
        ``-threshold``, occupied above ``+threshold``, unknown between (the one rule every grid
        of this model is read by, composed ones included)."""
        t = self.threshold
        out = np.zeros(np.shape(log_odds), dtype=np.int8)
        out[log_odds < -t] = CellState.FREE
        out[log_odds > t] = CellState.OCCUPIED
        return out


class OccupancyGrid:
    """Log-odds occupancy grid over a fixed extent (module docstring).

    Args:
        resolution: cell size in metres, ``> 0``.
        extent: ``(xmin, ymin, xmax, ymax)`` in metres (the robot's own frame); at least one cell
            each way.
        model: inverse-sensor-model increments and thresholds.
    """

    __slots__ = ("resolution", "origin", "shape", "log_odds", "model", "_states")

    def __init__(self, resolution: float = 0.1,
                 extent: tuple[float, float, float, float] = (-20.0, -20.0, 20.0, 20.0),
                 model: SensorModel | None = None) -> None:
        self.resolution = check_real(resolution, "resolution", low=0.0)
        if (not isinstance(extent, (tuple, list, np.ndarray)) or np.ndim(extent) != 1
                or len(extent) != 4):
            raise ValueError(f"extent must be (xmin, ymin, xmax, ymax), got {extent!r}")
        xmin, ymin, xmax, ymax = (check_real(v, f"extent[{i}]") for i, v in enumerate(extent))
        if xmax - xmin < self.resolution or ymax - ymin < self.resolution:
            raise ValueError(f"extent must span at least one cell ({self.resolution} m) each way, "
                             f"got {tuple(extent)}")
        if model is not None and not isinstance(model, SensorModel):
            raise TypeError(f"model must be a SensorModel, got {type(model).__name__}")
        self.model = model or SensorModel()
        self.origin = (xmin, ymin)
        self.shape = (int(math.ceil((ymax - ymin) / self.resolution - 1e-9)),
                      int(math.ceil((xmax - xmin) / self.resolution - 1e-9)))
        self.log_odds = np.zeros(self.shape, dtype=np.float32)
        self._states = np.zeros(self.shape, dtype=np.int8)

    # ------------------------------------------------------------------ geometry
    @property
    def extent(self) -> tuple[float, float, float, float]:
        h, w = self.shape
        return (self.origin[0], self.origin[1], self.origin[0] + w * self.resolution,
                self.origin[1] + h * self.resolution)

    def world_to_cell(self, xy: Any) -> np.ndarray:
        """``(N, 2)`` int cells ``(iy, ix)`` containing the points ``xy`` (may lie outside)."""
        p = as_points(np.reshape(xy, (-1, 2)) if np.ndim(xy) == 1 else xy, "xy")
        ix = np.floor((p[:, 0] - self.origin[0]) / self.resolution).astype(np.int64)
        iy = np.floor((p[:, 1] - self.origin[1]) / self.resolution).astype(np.int64)
        return np.stack([iy, ix], axis=1)

    def cell_to_world(self, ij: Any) -> np.ndarray:
        """``(N, 2)`` world centres ``(x, y)`` of cells ``(iy, ix)``."""
        c = np.asarray(ij, dtype=np.float64).reshape(-1, 2)
        return np.stack([self.origin[0] + (c[:, 1] + 0.5) * self.resolution,
                         self.origin[1] + (c[:, 0] + 0.5) * self.resolution], axis=1)

    def in_bounds(self, ij: np.ndarray) -> np.ndarray:
        ij = np.asarray(ij)
        return ((ij[:, 0] >= 0) & (ij[:, 0] < self.shape[0]) & (ij[:, 1] >= 0)
                & (ij[:, 1] < self.shape[1]))

    # ------------------------------------------------------------------ sensing
    def update(self, pose: Any, ranges: Any, sensor_angles: Any, max_range: float,
               cone_half_width: float) -> None:
        """Fold one sonar scan into the grid (module docstring).

        Args:
            pose: ``(x, y, theta)`` of the sensor origin in the grid's frame.
            ranges: ``(K,)`` ranges in metres, ``>= 0``; ``>= max_range`` means no echo.
            sensor_angles: ``(K,)`` sonar directions relative to ``theta``, radians.
            max_range: sonar range limit in metres, ``> 0``.
            cone_half_width: half the cone's opening, radians, in ``(0, pi/2]``.
        """
        pose, ranges, angles = self._check_scan(pose, ranges, sensor_angles)
        max_range = check_real(max_range, "max_range", low=0.0)
        beta = check_real(cone_half_width, "cone_half_width", low=0.0, high=math.pi / 2)
        self.update_valid(pose, ranges, angles, max_range, beta)

    def update_valid(self, pose: np.ndarray, ranges: np.ndarray, sensor_angles: np.ndarray,
                     max_range: float, cone_half_width: float) -> None:
        """:meth:`update` without its checks, for callers whose scans are valid by construction
        (the env, which updates several grids every step): ``pose`` a float64 ``(3,)`` array,
        ``ranges`` and ``sensor_angles`` float64 ``(K,)`` arrays, all finite, ranges ``>= 0``,
        ``max_range > 0``, ``cone_half_width`` in ``(0, pi/2]``. The same update; bad input
        here is not diagnosed."""
        self._apply(pose, ranges, sensor_angles, max_range, cone_half_width, NO_MASK, NO_COUNTS)

    def update_tracked(self, pose: np.ndarray, ranges: np.ndarray, sensor_angles: np.ndarray,
                       max_range: float, cone_half_width: float, ever: np.ndarray
                       ) -> np.ndarray:
        """:meth:`update_valid` (same input contract) that also keeps ``ever``, a bool mask of
        the grid's shape of the cells known at least once: the cells this scan makes known
        join it. Returns int64 ``[n_fresh, r0, r1, c0, c1, 0, 0, 0]``: how many cells joined
        ``ever`` and their bounding box (all zero if none). Why: coverage that never shrinks,
        kept in the same pass as the update (the env calls this four times a step)."""
        fresh = np.zeros(8, dtype=np.int64)
        self._apply(pose, ranges, sensor_angles, max_range, cone_half_width, ever, fresh)
        return fresh

    def _apply(self, pose: np.ndarray, ranges: np.ndarray, angles: np.ndarray,
               max_range: float, beta: float, ever: np.ndarray, fresh: np.ndarray) -> None:
        m = self.model
        sonar_update(self.log_odds, self._states, self.origin[0], self.origin[1],
                     self.resolution, pose[0], pose[1], pose[2], ranges, angles, max_range,
                     beta, (m.hit_width or self.resolution) / 2.0, m.l_free, m.l_occupied,
                     m.clamp, m.threshold, m.usable, ever, NO_MASK, NO_MASK, fresh)

    def freeze(self) -> None:
        """Make :attr:`log_odds` and the states read-only (a snapshot that must not change);
        a later update raises numpy's ``ValueError`` for writing a read-only array."""
        self.log_odds.setflags(write=False)
        self._states.setflags(write=False)

    def _check_scan(self, pose: Any, ranges: Any, angles: Any):
        # sums instead of np.isfinite(...).all(): NaN and inf survive a sum, and on arrays this
        # small each numpy call costs more than the arithmetic (this runs every env step)
        p = _float_array(pose, "pose", "(x, y, theta)")
        if p.shape != (3,):
            raise ValueError(f"pose must be (x, y, theta), got shape {p.shape}")
        if not math.isfinite(p[0] + p[1] + p[2]):
            raise ValueError(f"pose must be finite, got {p.tolist()}")
        r = _float_array(ranges, "ranges", "(K,)")
        a = _float_array(angles, "sensor_angles", "(K,)")
        if r.ndim != 1:
            raise ValueError(f"ranges must be a 1-D array (K,), got shape {r.shape}")
        if a.ndim != 1:
            raise ValueError(f"sensor_angles must be a 1-D array (K,), got shape {a.shape}")
        if r.shape != a.shape:
            raise ValueError(f"ranges and sensor_angles must have the same length, got "
                             f"{r.size} and {a.size}")
        if r.size and (not math.isfinite(r.sum()) or r.min() < 0):
            raise ValueError(f"ranges must be finite and >= 0, got {r.tolist()}")
        if not math.isfinite(a.sum()):
            raise ValueError(f"sensor_angles must be finite, got {a.tolist()}")
        return p, r, a

    def _classify(self, log_odds: np.ndarray) -> np.ndarray:
        return self.model.classify(log_odds)

    # ------------------------------------------------------------------ views
    def states(self) -> np.ndarray:
        """``(H, W)`` int8 :class:`CellState` codes (a read-only view, kept up to date)."""
        view = self._states.view()
        view.setflags(write=False)
        return view

    def free_mask(self) -> np.ndarray:
        return self._states == CellState.FREE

    def occupied_mask(self) -> np.ndarray:
        return self._states == CellState.OCCUPIED

    def known_mask(self) -> np.ndarray:
        return self._states != CellState.UNKNOWN

    def coverage_m2(self) -> float:
        """Known (free or occupied) area in m²."""
        return float(np.count_nonzero(self._states)) * self.resolution ** 2

    def to_image(self) -> np.ndarray:
        """uint8 image of the states (:data:`IMAGE_VALUES`: unknown 128, free 255, occupied
        0), in array orientation (row 0 at the bottom: plot with ``origin="lower"``)."""
        return IMAGE_VALUES[self._states]

    # ------------------------------------------------------------------ combining
    def copy(self) -> OccupancyGrid:
        out = OccupancyGrid.__new__(OccupancyGrid)
        out.resolution, out.origin, out.shape, out.model = (self.resolution, self.origin,
                                                            self.shape, self.model)
        out.log_odds = self.log_odds.copy()
        out._states = self._states.copy()
        return out

    def reset(self) -> None:
        """Forget everything (all cells unknown)."""
        self.log_odds.fill(0.0)
        self._states.fill(CellState.UNKNOWN)

    def assign(self, log_odds: Any) -> None:
        """Replace the evidence with ``log_odds`` (``(H, W)``, this grid's shape), clamped to
        ``±model.clamp``, and the states with theirs, in place (views of :meth:`states` stay
        valid). Why: a map whose parts a pose graph moves is recomposed whole.

        Raises:
            ValueError: ``log_odds`` is not of this grid's shape or not finite.
        """
        values = np.asarray(log_odds)
        if values.shape != self.shape:
            raise ValueError(f"log_odds must have the grid's shape {self.shape}, got "
                             f"{values.shape}")
        if not np.isfinite(values).all():
            raise ValueError("log_odds must be finite")
        np.clip(values, -self.model.clamp, self.model.clamp, out=self.log_odds, casting="unsafe")
        self._states[:] = self._classify(self.log_odds)

    def empty_like(self) -> OccupancyGrid:
        out = self.copy()
        out.reset()
        return out

    def transformed(self, rigid: Any, into: OccupancyGrid | None = None) -> OccupancyGrid:
        """This grid moved by ``rigid`` (anything with ``apply`` and ``inverse``, e.g.
        :class:`fusion.Rigid2D`: a point ``p`` of this grid lands at ``rigid.apply(p)``) and
        resampled (nearest cell) onto the geometry of ``into`` (default: this grid's)."""
        if not all(callable(getattr(rigid, m, None)) for m in ("apply", "inverse")):
            raise TypeError(f"rigid must have apply() and inverse() (e.g. fusion.Rigid2D), got "
                            f"{type(rigid).__name__}")
        if into is not None and not isinstance(into, OccupancyGrid):
            raise TypeError(f"into must be an OccupancyGrid or None, got {type(into).__name__}")
        target = (into or self).empty_like()
        h, w = target.shape
        rows, cols = np.mgrid[0:h, 0:w]
        centres = target.cell_to_world(np.stack([rows.ravel(), cols.ravel()], axis=1))
        src = rigid.inverse().apply(centres)
        coords = np.stack([(src[:, 1] - self.origin[1]) / self.resolution - 0.5,
                           (src[:, 0] - self.origin[0]) / self.resolution - 0.5])
        lo = ndimage.map_coordinates(self.log_odds, coords, order=0, mode="constant", cval=0.0)
        target.log_odds[:] = lo.reshape(h, w)
        target._states[:] = target._classify(target.log_odds)
        return target

    def union(self, other: OccupancyGrid) -> OccupancyGrid:
        """Both grids' evidence combined (log-odds added, clamped) — same geometry required."""
        if not isinstance(other, OccupancyGrid):
            raise TypeError(f"other must be an OccupancyGrid, got {type(other).__name__}")
        if (other.shape, other.origin, other.resolution) != (self.shape, self.origin,
                                                             self.resolution):
            raise ValueError(
                "union needs grids of the same geometry; got shape/origin/resolution "
                f"{self.shape}/{self.origin}/{self.resolution} and "
                f"{other.shape}/{other.origin}/{other.resolution} (use transformed(into=...))")
        out = self.copy()
        np.clip(self.log_odds + other.log_odds, -self.model.clamp, self.model.clamp,
                out=out.log_odds)
        out._states[:] = out._classify(out.log_odds)
        return out

    def __repr__(self) -> str:
        return (f"OccupancyGrid(shape={self.shape}, resolution={self.resolution}, "
                f"origin={self.origin}, known={self.coverage_m2():.1f} m²)")


def sweep_scan(ever: np.ndarray, origin: tuple[float, float], resolution: float,
               model: SensorModel, pose: np.ndarray, ranges: np.ndarray,
               sensor_angles: np.ndarray, max_range: float, cone_half_width: float,
               union: np.ndarray, reachable: np.ndarray) -> np.ndarray:
    """Coverage of one scan without a grid: every cell an :class:`OccupancyGrid` of this
    geometry and ``model`` would update (the same cone test) joins ``ever`` (bool ``(H, W)``),
    cells already in it skipped untested; each cell joining ``ever`` is also folded into
    ``union`` (bool, same shape), noting whether it was ``reachable``. Input as
    :meth:`OccupancyGrid.update_valid` (valid by construction, not checked).

    Returns int64 ``[n_fresh, r0, r1, c0, c1, both, new, covered]``: the cells that joined
    ``ever``, their bounding box (all zero if none), how many were in ``union`` already, were
    added to it, and were added and ``reachable``. Why: ground-truth coverage of a sensor
    sweep, without keeping a grid per robot of the whole world.

    The sweep counts a cell as known after one update, so it matches a grid only for models
    whose single update makes a cell known (``|l_free|`` and ``l_occupied`` above
    ``threshold``)."""
    fresh = np.zeros(8, dtype=np.int64)
    sonar_update(_NO_LOG_ODDS, _NO_STATES, origin[0], origin[1], resolution, pose[0], pose[1],
                 pose[2], ranges, sensor_angles, max_range, cone_half_width,
                 (model.hit_width or resolution) / 2.0, model.l_free, model.l_occupied,
                 model.clamp, model.threshold, model.usable, ever, union, reachable, fresh)
    return fresh


_NO_LOG_ODDS = np.zeros((0, 0), dtype=np.float32)
_NO_STATES = np.zeros((0, 0), dtype=np.int8)
"""The kernel's "no grid" arguments (:func:`sweep_scan`)."""
