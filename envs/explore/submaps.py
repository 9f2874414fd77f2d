"""Submaps: one robot's map as a chain of anchors, each owning what the grid gained under it.

With ``mapping.pose_graph`` (experimental) a robot starts a new **anchor** every
``mapping.anchor_every`` steps, at its odometry pose. The anchor owns a **patch**: the change
of the robot's log-odds while it was the newest anchor, cut to the bounding box of the cells
that changed, in the robot's odometry frame. A robot's map under the pose graph is its patches
added up, each moved by its own correction (``fusion.PoseGraph.corrections``), clamped and
classified as ``topo.OccupancyGrid`` does; with every correction the identity the patches add
up to the robot's own grid. The anchor also keeps the scans taken under it, so that a window
of consecutive anchors can be rebuilt as one fresh grid for alignment (a revisited wall is in
the window's grid, not only in the patch of the anchor that first saw it).

Why: a map built on drifting odometry bends; submaps short enough to be rigid can each be put
where the pose graph says, which unbends the whole.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from envs.explore.mapping import Geometry
from fusion.rigid import Rigid2D
from topo.grid import OccupancyGrid, SensorModel


@dataclass(frozen=True, slots=True)
class Patch:
    """An anchor's share of the log-odds: ``delta`` (float64) added at rows ``r0 …`` and
    columns ``c0 …`` of the robot's grid, in its odometry frame."""

    r0: int
    c0: int
    delta: np.ndarray


@dataclass(frozen=True, slots=True)
class ScanSettings:
    """What a scan needs to be folded into a grid again (as ``RobotMap.integrate``)."""

    angles: np.ndarray
    mount_radius: float
    max_range: float
    half_cone: float
    model: SensorModel


def step_variance(before: np.ndarray, after: np.ndarray, noise: tuple[float, float],
                  alphas: tuple[float, float, float, float] | None) -> tuple[float, float]:
    """Position (m², per axis) and heading (rad²) variance the odometry model adds over one
    odometry increment ``before → after`` (poses ``(x, y, θ)``): the ``"rot_trans_rot"``
    alphas' variances (``envs.explore.robot.sample_odometry``, a rotation error swinging the
    step sideways) or the ``"increment"`` model's ``noise``; zero for perfect odometry. Why: the
    pose graph weighs odometry edges by the noise that really made them."""
    dx, dy = float(after[0] - before[0]), float(after[1] - before[1])
    trans = math.hypot(dx, dy)
    dth = math.remainder(float(after[2] - before[2]), math.tau)
    if alphas is not None:
        a1, a2, a3, a4 = alphas
        rot1 = math.remainder(math.atan2(dy, dx) - float(before[2]), math.tau) if trans else 0.0
        rot2 = math.remainder(dth - rot1, math.tau)
        r1 = min(abs(rot1), math.pi - abs(rot1))
        r2 = min(abs(rot2), math.pi - abs(rot2))
        t2 = trans * trans
        rot1_var = a1 * r1 * r1 + a2 * t2
        pos = a3 * t2 + a4 * (r1 * r1 + r2 * r2) + t2 * rot1_var
        return pos, rot1_var + a1 * r2 * r2 + a2 * t2
    return (noise[0] * trans) ** 2, (noise[1] * (abs(dth) + 0.1 * trans)) ** 2


@dataclass(slots=True)
class RobotSubmaps:
    """One robot's anchors, patches and scans (module docstring).

    Attributes:
        poses: each anchor's odometry pose (``fusion.Rigid2D``, anchor frame → odometry frame).
        truths: each anchor's true world pose ``(x, y, θ)`` when it was started — for
            metrics only; explorers must not read it.
        sigmas: per anchor, the odometry's standard deviations ``(x, y, θ)`` since the
            previous anchor (zeros for the first).
        patches: the closed anchors' patches (the newest anchor's is :meth:`live_patch`).
        scans: per anchor, its scans as ``(odometry pose, ranges)``.
    """

    geometry: Geometry
    poses: list[Rigid2D] = field(default_factory=list)
    truths: list[np.ndarray] = field(default_factory=list)
    sigmas: list[tuple[float, float, float]] = field(default_factory=list)
    patches: list[Patch] = field(default_factory=list)
    scans: list[list[tuple[np.ndarray, np.ndarray]]] = field(default_factory=list)
    _base: np.ndarray | None = None  # log-odds when the newest anchor started (float64)
    _var: list[float] = field(default_factory=lambda: [0.0, 0.0])
    _swing: list[tuple[float, float, float]] = field(default_factory=list)  # (x, y, rot var)
    _last: np.ndarray | None = None  # odometry at the last accumulated increment

    def start_anchor(self, odometry: np.ndarray, truth: np.ndarray,
                     log_odds: np.ndarray) -> int:
        """Close the newest anchor (its patch: ``log_odds`` minus the log-odds it started
        with) and start one at ``odometry``; returns the new anchor's index."""
        lo = np.asarray(log_odds, dtype=np.float64)
        if self._base is not None:
            self.patches.append(_patch(lo - self._base))
        self._base = lo.copy()
        self.accumulate(odometry)
        first = not self.poses
        pos_var = self._var[0]
        if self._swing:  # a heading error at each step swings the rest of the path
            sw = np.array(self._swing)
            pos_var += float(np.sum(sw[:, 2] * ((odometry[0] - sw[:, 0]) ** 2
                                                + (odometry[1] - sw[:, 1]) ** 2)))
        self.sigmas.append((0.0, 0.0, 0.0) if first else (
            math.sqrt(pos_var), math.sqrt(pos_var), math.sqrt(self._var[1])))
        self._var = [0.0, 0.0]
        self._swing = []
        self.poses.append(Rigid2D.from_pose(odometry))
        self.truths.append(np.array(truth, dtype=np.float64))
        self.scans.append([])
        return len(self.poses) - 1

    def accumulate(self, odometry: np.ndarray, noise: tuple[float, float] = (0.0, 0.0),
                   alphas: tuple[float, float, float, float] | None = None) -> None:
        """Add the odometry variance of the increment since the last call
        (:func:`step_variance`) to the newest anchor's edge; the heading variance of each
        increment also swings the path driven after it, which enters the edge's position
        variance when the anchor closes."""
        odo = np.array(odometry, dtype=np.float64)
        if self._last is not None and (any(noise) or alphas is not None):
            pos, rot = step_variance(self._last, odo, noise, alphas)
            self._var[0] += pos
            self._var[1] += rot
            self._swing.append((float(odo[0]), float(odo[1]), rot))
        self._last = odo

    def add_scan(self, odometry: np.ndarray, ranges: np.ndarray) -> None:
        """Keep a scan (taken at ``odometry``) under the newest anchor."""
        self.scans[-1].append((np.array(odometry, dtype=np.float64),
                               np.array(ranges, dtype=np.float64)))

    @property
    def base(self) -> np.ndarray:
        """The log-odds the newest anchor's patch is counted from (float64; read-only view)."""
        view = self._base.view()
        view.flags.writeable = False
        return view

    def rebase(self, base: np.ndarray) -> None:
        """Count the newest anchor's patch from ``base`` on: the grid was recomposed
        (``GraphMerging.straighten``) as ``base`` plus that patch so far."""
        self._base = np.array(base, dtype=np.float64)

    def live_patch(self, log_odds: np.ndarray) -> Patch:
        """The newest anchor's patch so far."""
        return _patch(np.asarray(log_odds, dtype=np.float64) - self._base)

    def all_patches(self, log_odds: np.ndarray) -> list[Patch]:
        """Every anchor's patch, the newest one's so far included (index = anchor)."""
        return [*self.patches, self.live_patch(log_odds)]

    def window_grid(self, first: int, last: int, resolution: float,
                    scan: ScanSettings) -> OccupancyGrid | None:
        """A fresh grid (odometry frame) of the scans of anchors ``first … last`` (closed
        anchors), sized to their poses plus the sonar's reach; ``None`` without scans."""
        taken = [s for k in range(first, last + 1) for s in self.scans[k]]
        if not taken:
            return None
        xy = np.array([p[:2] for p, _ in taken])
        reach = scan.max_range + scan.mount_radius + 2 * resolution
        lo, hi = xy.min(axis=0) - reach, xy.max(axis=0) + reach
        grid = OccupancyGrid(resolution, (float(lo[0]), float(lo[1]), float(hi[0]),
                                          float(hi[1])), scan.model)
        for pose, ranges in taken:
            grid.update_valid(pose, ranges + scan.mount_radius, scan.angles,
                              scan.max_range + scan.mount_radius, scan.half_cone)
        return grid


def _patch(delta: np.ndarray) -> Patch:
    """``delta`` cut to the bounding box of its non-zero cells."""
    rows = np.flatnonzero(delta.any(axis=1))
    if not len(rows):
        return Patch(0, 0, np.zeros((0, 0)))
    cols = np.flatnonzero(delta.any(axis=0))
    r0, r1, c0, c1 = int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1
    return Patch(r0, c0, delta[r0:r1, c0:c1].copy())


SNAP_CELLS = 0.1
"""A kept patch is drawn again (:class:`PatchCache`) once its correction moves some corner of
it by more than this many cells since it was drawn: every optimisation of the pose graph moves
every anchor a little, and nearest-cell resampling hardly changes for less."""


@dataclass(frozen=True, slots=True)
class _Moved:
    """A patch drawn into a target grid at ``correction``: ``values`` to add at rows
    ``r0 …`` and columns ``c0 …`` of the target (``None``: it falls outside)."""

    correction: Rigid2D
    r0: int
    c0: int
    values: np.ndarray | None


class PatchCache:
    """Patches that never change (closed anchors'), drawn into a target grid and kept across
    compositions under a caller's key — one key per patch and target grid: :func:`compose`
    draws such a patch again only when its correction has moved it by more than
    :data:`SNAP_CELLS` cells. It holds one drawing per key for the episode: a few times the
    patches' own memory for each target grid read. Why: a fused map is recomposed on every
    merge step from all its patches, and most of them barely move."""

    def __init__(self) -> None:
        self._moved: dict[object, _Moved] = {}

    def moved(self, key: object, patch: Patch, corr: Rigid2D, src: Geometry,
              dst: Geometry) -> _Moved:
        """``patch`` drawn into ``dst`` at ``corr``: the kept drawing under ``key`` if its
        correction is within :data:`SNAP_CELLS` cells of ``corr`` over the patch, else a
        new one (kept)."""
        kept = self._moved.get(key)
        if kept is not None and shift_cells(kept.correction, corr, patch, src) <= SNAP_CELLS:
            return kept
        kept = _move(patch, corr, src, dst)
        self._moved[key] = kept
        return kept


def _corners(patch: Patch, src: Geometry) -> np.ndarray:
    """The metric corners of ``patch``'s bounding box in ``src``'s frame, ``(4, 2)``."""
    ph, pw = patch.delta.shape
    cells = np.array([[patch.c0, patch.r0], [patch.c0 + pw, patch.r0],
                      [patch.c0, patch.r0 + ph], [patch.c0 + pw, patch.r0 + ph]],
                     dtype=np.float64)
    return cells * src.resolution + np.array(src.origin)


def shift_cells(a: Rigid2D, b: Rigid2D, patch: Patch, src: Geometry) -> float:
    """How far (cells) the two corrections put ``patch``'s points apart at most (a rigid
    motion's largest displacement over a box is at a corner)."""
    corners = _corners(patch, src)
    return float(np.max(np.linalg.norm(a.apply(corners) - b.apply(corners), axis=1))
                 / src.resolution)


def _move(patch: Patch, corr: Rigid2D, src: Geometry, dst: Geometry) -> _Moved:
    """``patch`` (cells of ``src``) moved by ``corr`` into ``dst``, nearest-cell resampled with
    ``scipy.ndimage.affine_transform``, cut to the target cells it can reach."""
    ph, pw = patch.delta.shape
    if not ph:
        return _Moved(corr, 0, 0, None)
    if src == dst and corr.allclose(Rigid2D.identity(), atol=1e-9):
        return _Moved(corr, patch.r0, patch.c0, patch.delta)
    res = dst.resolution
    s_org, d_org = np.array(src.origin), np.array(dst.origin)
    # cell centres in cells: x / res = origin / res + col + 0.5
    sx, sy = s_org / res + 0.5
    dx, dy = d_org / res + 0.5
    h, w = dst.shape
    # the moved patch's target cells: its corners through the correction, a cell of margin
    moved = (corr.apply(_corners(patch, src)) - d_org) / res
    c0 = max(int(math.floor(moved[:, 0].min())) - 1, 0)
    c1 = min(int(math.ceil(moved[:, 0].max())) + 1, w)
    r0 = max(int(math.floor(moved[:, 1].min())) - 1, 0)
    r1 = min(int(math.ceil(moved[:, 1].max())) + 1, h)
    if r0 >= r1 or c0 >= c1:
        return _Moved(corr, 0, 0, None)
    inv = corr.inverse()
    rot, t = inv.R, inv.T / res
    # (row, col) in the patch under each target cell centre: the inverse correction
    matrix = np.array([[rot[1, 1], rot[1, 0]], [rot[0, 1], rot[0, 0]]])
    u, v = c0 + dx, r0 + dy  # target cell (r0, c0)'s centre, in cells
    offset = np.array([rot[1, 0] * u + rot[1, 1] * v + t[1] - sy - patch.r0,
                       rot[0, 0] * u + rot[0, 1] * v + t[0] - sx - patch.c0])
    return _Moved(corr, r0, c0, ndimage.affine_transform(
        patch.delta, matrix, offset=offset, output_shape=(r1 - r0, c1 - c0), order=0,
        mode="grid-constant", cval=0.0))


def compose(patches: list[Patch], corrections: list[Rigid2D], src: Geometry, dst: Geometry,
            out: np.ndarray | None = None, *, cache: PatchCache | None = None,
            keys: list[object] | None = None) -> np.ndarray:
    """Add up ``patches`` (cells of a grid of geometry ``src``, their robot's odometry frame),
    each moved by its correction (that frame → the target frame, a grid of geometry ``dst``),
    nearest-cell resampled with ``scipy.ndimage.affine_transform``; into ``out`` (float64
    log-odds of ``dst``'s shape, added to) or a fresh zero grid. With ``cache``, the patches
    whose ``keys`` entry is not ``None`` (patches that never change under that key) are drawn
    through it (:class:`PatchCache`: again only once their correction moved them more than
    :data:`SNAP_CELLS` cells). Returns the log-odds (``topo.SensorModel.classify`` turns them
    into states).

    Raises:
        ValueError: ``patches``, ``corrections`` (and ``keys``) differ in length, or the two
            geometries' resolutions differ.
    """
    if len(patches) != len(corrections):
        raise ValueError(f"patches and corrections must be as many, got {len(patches)} and "
                         f"{len(corrections)}")
    if keys is not None and len(keys) != len(patches):
        raise ValueError(f"keys and patches must be as many, got {len(keys)} and "
                         f"{len(patches)}")
    if src.resolution != dst.resolution:
        raise ValueError(f"src and dst must have the same resolution, got {src.resolution} "
                         f"and {dst.resolution}")
    acc = np.zeros(dst.shape, dtype=np.float64) if out is None else out
    for k, (patch, corr) in enumerate(zip(patches, corrections, strict=True)):
        key = None if cache is None or keys is None else keys[k]
        moved = _move(patch, corr, src, dst) if key is None else cache.moved(
            key, patch, corr, src, dst)
        if moved.values is not None:
            h, w = moved.values.shape
            acc[moved.r0:moved.r0 + h, moved.c0:moved.c0 + w] += moved.values
    return acc
