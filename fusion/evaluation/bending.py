"""Truth under bending maps: judge a fused map itself, not one rigid transform.

A map built on drifting odometry bends, so no single transform to the world is right
everywhere. Two measures that read the map's shape instead: the absolute trajectory error of
its anchors (:func:`ate_rms`: RMS after the one best rigid alignment to the true poses,
:func:`world_alignment`) and the share of its occupied cells that lie near a true wall once
the map is put in the world by that same alignment. Why: a fused map that folds or smears
shows in both, where a merge's error at one place does not.

For a rigid merge of two bent maps (a dataset pair, ``agents.dataset generate --odometry``),
:class:`PairTrajectories` judges the fused trajectory the merge makes: :meth:`~PairTrajectories.ate`
of both robots' trajectories once B's is moved by the merge, against
:meth:`~PairTrajectories.floor`, the least any rigid merge can reach on those two maps.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from fusion.icp import rigid_fit
from fusion.rigid import Rigid2D

WALL_TOLERANCE_M = 0.2
"""An occupied cell within this distance (metres) of a true wall counts as on a wall."""


def _xy(poses: np.ndarray, name: str) -> np.ndarray:
    p = np.asarray(poses, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] < 2:
        raise ValueError(f"{name} must be (K, 2) or (K, 3) rows, got shape {p.shape}")
    return p[:, :2]


def world_alignment(estimated: np.ndarray, truth: np.ndarray) -> Rigid2D:
    """The rigid motion (map frame → world) best aligning ``estimated`` anchor positions with
    their ``truth`` (``(K, 2|3)`` rows, least squares; ``K ≥ 1``).

    Raises:
        ValueError: the two differ in length, or are empty or malformed."""
    p, q = _xy(estimated, "estimated"), _xy(truth, "truth")
    if p.shape != q.shape or not len(p):
        raise ValueError(f"estimated and truth must have the same number (≥ 1) of rows, got "
                         f"{len(p)} and {len(q)}")
    theta, t = rigid_fit(p, q)
    return Rigid2D(theta, t)


def ate_rms(estimated: np.ndarray, truth: np.ndarray) -> float:
    """Absolute trajectory error: the RMS distance (metres) between ``estimated`` and ``truth``
    positions (``(K, 2|3)`` rows) after :func:`world_alignment` — a map in its own frame is
    judged for its shape.

    Raises:
        ValueError: as :func:`world_alignment`."""
    moved = world_alignment(estimated, truth).apply(_xy(estimated, "estimated"))
    return float(np.sqrt(np.mean(np.sum((moved - _xy(truth, "truth")) ** 2, axis=1))))


@dataclass(frozen=True, slots=True, eq=False)
class PairTrajectories:
    """Two robots' trajectories, as each mapped it and as it truly was: what judges a rigid
    merge of their bent maps.

    Attributes:
        odometry_a, odometry_b: ``(K, 2|3)`` rows: each robot's poses in its own map frame
            (its odometry: drifting).
        truth_a, truth_b: ``(K, 2|3)`` rows: the same poses' true positions, both in one
            common frame (any: only their shape and relation matter).

    Raises:
        ValueError: a trajectory and its truth differ in length, or one is empty or
            malformed.
    """

    odometry_a: np.ndarray
    odometry_b: np.ndarray
    truth_a: np.ndarray
    truth_b: np.ndarray

    def __post_init__(self) -> None:
        for robot in "ab":
            odo = _xy(getattr(self, f"odometry_{robot}"), f"odometry_{robot}")
            truth = _xy(getattr(self, f"truth_{robot}"), f"truth_{robot}")
            if len(odo) != len(truth) or not len(odo):
                raise ValueError(f"odometry_{robot} and truth_{robot} must have the same number "
                                 f"(≥ 1) of rows, got {len(odo)} and {len(truth)}")
            object.__setattr__(self, f"odometry_{robot}", odo)
            object.__setattr__(self, f"truth_{robot}", truth)

    @classmethod
    def from_start_frames(cls, rows_a: np.ndarray, rows_b: np.ndarray,
                          start_b_to_a: Rigid2D) -> PairTrajectories:
        """From two robots' rows ``[x, y, θ, true x, true y, true θ]`` (odometry in the robot's
        map frame; truth in its start frame, the frame its map would be in without drift) and
        the true motion of B's start frame into A's (a dataset pair's ``transform``).

        Raises:
            ValueError: rows that are not ``(K, 6)`` with ``K ≥ 1``."""
        out = []
        for name, rows in (("rows_a", rows_a), ("rows_b", rows_b)):
            r = np.asarray(rows, dtype=np.float64)
            if r.ndim != 2 or r.shape[1] != 6 or not len(r):
                raise ValueError(f"{name} must be (K, 6) rows x, y, theta, true x, true y, "
                                 f"true theta with K >= 1, got shape {r.shape}")
            out.append(r)
        return cls(out[0][:, :2], out[1][:, :2], out[0][:, 3:5],
                   start_b_to_a.apply(out[1][:, 3:5]))

    def ate(self, transform: Rigid2D) -> float:
        """The ATE (m, :func:`ate_rms`) of both trajectories in A's map frame once B's is
        moved by ``transform`` (B's map frame → A's): how straight the fused map this merge
        makes is, after one best rigid fit to the truth.

        Raises:
            TypeError: ``transform`` is not a :class:`fusion.Rigid2D`."""
        if not isinstance(transform, Rigid2D):
            raise TypeError(f"transform must be a fusion.Rigid2D, got "
                            f"{type(transform).__name__}")
        est = np.vstack([self.odometry_a, transform.apply(self.odometry_b)])
        return ate_rms(est, np.vstack([self.truth_a, self.truth_b]))

    def floor(self) -> float:
        """The least :meth:`ate` of any rigid merge: each trajectory fitted to its truth on
        its own, pooled (B's best fit and A's are two independent motions, so no one merge
        does better) — the two maps' own bend."""
        sq = [ate_rms(o, t) ** 2 * len(o) for o, t in ((self.odometry_a, self.truth_a),
                                                        (self.odometry_b, self.truth_b))]
        return float(np.sqrt(sum(sq) / (len(self.odometry_a) + len(self.odometry_b))))

    def best_merge(self) -> Rigid2D:
        """The rigid merge (B's map frame → A's) reaching :meth:`floor`: A's best fit to the
        world, inverted, after B's."""
        to_world_a = world_alignment(self.odometry_a, self.truth_a)
        to_world_b = world_alignment(self.odometry_b, self.truth_b)
        return to_world_a.inverse() @ to_world_b


class WallIndex:
    """True walls made searchable once: points along every segment, spaced well below the
    tolerance, in a KD-tree. :meth:`share` is :func:`wall_share` for these walls. Why: a map
    judged on every merge step of an episode is judged against the same walls.

    Args:
        segments: ``(M, 4)`` rows ``x0, y0, x1, y1`` (world frame), ``M ≥ 1``.
        tolerance: an occupied cell within this many metres of a wall counts as on it (> 0).

    Raises:
        ValueError: ``segments`` is not ``(M, 4)`` with ``M ≥ 1``, or ``tolerance <= 0``.
    """

    def __init__(self, segments: np.ndarray, tolerance: float = WALL_TOLERANCE_M) -> None:
        seg = np.asarray(segments, dtype=np.float64)
        if seg.ndim != 2 or seg.shape[1] != 4 or not len(seg):
            raise ValueError(f"segments must be (M, 4) rows x0, y0, x1, y1 with M >= 1, got "
                             f"shape {seg.shape}")
        if not tolerance > 0:
            raise ValueError(f"tolerance must be > 0, got {tolerance}")
        self.tolerance = float(tolerance)
        self._step = self.tolerance / 4
        samples = []
        for x0, y0, x1, y1 in seg:
            n = max(2, int(np.ceil(np.hypot(x1 - x0, y1 - y0) / self._step)) + 1)
            s = np.linspace(0.0, 1.0, n)[:, None]
            samples.append(np.array([x0, y0]) * (1 - s) + np.array([x1, y1]) * s)
        self._tree = cKDTree(np.vstack(samples))

    def share(self, occupied_xy: np.ndarray, to_world: Rigid2D) -> float:
        """The share of ``occupied_xy`` (``(N, 2)`` map-frame centres of occupied cells) within
        :attr:`tolerance` of a wall once moved by ``to_world``; NaN without occupied cells."""
        pts = np.asarray(occupied_xy, dtype=np.float64).reshape(-1, 2)
        if not len(pts):
            return float("nan")
        dist, _ = self._tree.query(to_world.apply(pts),
                                   distance_upper_bound=self.tolerance + self._step)
        return float(np.mean(dist <= self.tolerance))


def wall_share(occupied_xy: np.ndarray, to_world: Rigid2D, segments: np.ndarray,
               tolerance: float = WALL_TOLERANCE_M) -> float:
    """The share of ``occupied_xy`` (``(N, 2)`` map-frame centres of occupied cells) that lie
    within ``tolerance`` metres of a true wall (``segments``: ``(M, 4)`` rows
    ``x0, y0, x1, y1``, world frame) once moved by ``to_world``; NaN without occupied cells
    (:class:`WallIndex` keeps the walls for many calls).

    Raises:
        ValueError: ``segments`` is not ``(M, 4)`` with ``M ≥ 1``, or ``tolerance <= 0``."""
    return WallIndex(segments, tolerance).share(occupied_xy, to_world)
