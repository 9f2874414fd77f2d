"""Drift correction of a robot's odometry against its own map.

With noisy odometry a robot's map bends: what it mapped long ago sits where the odometry then
put it, what it maps now where the odometry now puts it. :class:`DriftCorrector` pulls the pose
estimate back onto the robot's own older map, a scan-to-map match done every
``RobotConfig.drift_correction_every`` steps:

* **Submap.** The sonar echoes (hit points, at most :data:`MAX_HIT_RANGE` from the robot) of
  the last ``drift_correction_window`` steps, each placed by the odometry pose it was taken at:
  in the current estimated frame, the odometry increments since relate them.
* **Reference.** The robot's wall cells (log-odds above :data:`WALL_LOG_ODDS`) that were
  walls already ``drift_correction_age`` steps ago and still are: the map as it was before the
  robot came back, so the match does not chase the walls it is drawing now with the current
  drift. Over the submap's window: each cell's nearest old wall cell
  (``scipy.ndimage.distance_transform_edt`` with its indices) and the walls' normals and how
  line-like they are (``skimage.feature.structure_tensor``).
* **Fit.** ``scipy.optimize.least_squares`` (``cauchy`` loss, scale :data:`FIT_SCALE`) of the
  rigid correction ``(dθ, dx, dy)`` about the robot's position, bounded by three standard
  deviations of the pose uncertainty, on the echoes within :data:`MATCH_DISTANCE` of an old
  wall (at least :data:`MIN_POINTS` of them): point-to-line residuals to the nearest old wall
  cell (ICP; the correspondences are re-found at every evaluation), plus the along-wall
  offset weighted by ``1 − coherence`` (corners constrain both ways, straight walls only
  across).
* **Fusion.** The pose uncertainty ``P`` grows every step as the odometry noise model says
  (first-order propagation of the increment noise, :func:`increment_covariance`); the fit's
  information ``H = JᵀJ / σ²`` (``J`` the loss-weighted Jacobian at the solution,
  ``σ = drift_correction_sigma`` per echo: the echoes of one wall err together, so ``σ`` is
  far above the sonar's noise) is fused with it as a Kalman update in information form: the
  applied correction is ``(I + P H)⁻¹ P H c`` and ``P ← (I + P H)⁻¹ P``. Directions the match
  does not constrain (along a corridor) get no correction, and the correction never exceeds
  what the noise accumulated since the last one allows. A fit whose Mahalanobis distance
  exceeds :data:`GATE` (χ² with 3 degrees of freedom, p = 0.01) is rejected.

Experimental: ``robot.drift_correction`` is off by default, since on the default robots it does
not reduce the drift.

Applied corrections move :attr:`Robot.odometry` (the env then draws new cells where they belong
and the drift-aware truth follows the corrected frame) and the buffered echoes with it. Nothing
here draws random numbers; the env builds a corrector only when the config asks for one and the
odometry is noisy, so noise-free episodes are untouched.
"""

from __future__ import annotations

import collections
import math

import numpy as np
from scipy import ndimage, optimize
from skimage import feature

from envs.explore.config import RobotConfig

MAX_HIT_RANGE = 2.0
"""Echoes farther than this (metres from the robot centre) are left out: a 15° cone's arc at
2 m is 0.5 m wide."""

MATCH_DISTANCE = 0.6
"""Echoes farther than this from an old wall at the start of the fit are not matched (m)."""

FIT_SCALE = 0.1
"""``f_scale`` of the robust loss: residuals beyond about one cell weigh less (m)."""

LOSS = "cauchy"
"""``least_squares``'s robust loss: bounded influence, so echoes of walls the old map does not
have (new walls near old ones) cannot drag the fit."""

MIN_POINTS = 30
"""Fewest matched echoes for a fit."""

WALL_LOG_ODDS = 1.5
"""A reference wall cell's log-odds must exceed this (two hits net of frees: the single-hit
default threshold 0.35 also keeps the ends of every echo's arc)."""

GATE = 11.34
"""χ²₃ at p = 0.01: a fit farther than this (Mahalanobis) from the prior is an outlier."""

HEADING_ONLY = False
"""Use only the fit's heading (its translation along with the heading through the pose
uncertainty's correlations)."""

NEVER = np.iinfo(np.int32).max


def increment_covariance(cfg: RobotConfig, dist: float, dth: float) -> np.ndarray:
    """The ``(3, 3)`` covariance of one odometry increment ``(dx, dy, dθ)`` (robot frame at the
    step's start) of length ``dist`` and turn ``dth`` under ``cfg``'s noise model: the
    ``"increment"`` model's own variances; for ``"rot_trans_rot"`` a first-order reading of
    the alphas (the turn split evenly between ``rot1`` and ``rot2``)."""
    if cfg.odometry_model == "rot_trans_rot":
        a1, a2, a3, a4 = cfg.odometry_alphas
        half2 = 0.25 * dth * dth
        rot = a1 * half2 + a2 * dist * dist
        var = (a3 * dist * dist + 2.0 * a4 * half2, dist * dist * rot, 2.0 * rot)
    else:
        st, sr = cfg.odometry_noise
        t = (st * dist) ** 2
        var = (t, t, (sr * (abs(dth) + 0.1 * dist)) ** 2)
    return np.diag(var)


class DriftCorrector:
    """One robot's scan-to-map drift correction (module docstring).

    Args:
        cfg: the robot's settings (``drift_correction_*`` and the odometry noise model).
        angles: ``(S,)`` sonar directions in the robot frame, radians.
        mount_radius: transducer distance from the robot centre, metres.
        max_range: the sonar's "no echo" reading, metres.
        shape, origin, resolution: the robot's grid.

    Attributes:
        covariance: ``(3, 3)`` pose uncertainty ``(x, y, θ)`` relative to the map.
        applied, rejected, skipped: fits applied, rejected by the gate, and corrections due
            but not fitted (too few matched echoes or no old walls near).
        moved: total metres and radians of correction applied.
    """

    def __init__(self, cfg: RobotConfig, angles: np.ndarray, mount_radius: float,
                 max_range: float, shape: tuple[int, int], origin: tuple[float, float],
                 resolution: float) -> None:
        self.cfg = cfg
        self.every = cfg.drift_correction_every
        self.window = cfg.drift_correction_window
        self.age = cfg.drift_correction_age
        self.info_scale = 1.0 / cfg.drift_correction_sigma ** 2
        self._dirs = np.stack([np.cos(angles), np.sin(angles)], axis=1)  # the cones' axes
        self._mount = float(mount_radius)
        self._max_range = float(max_range)
        self._origin = np.asarray(origin, dtype=np.float64)
        self._res = float(resolution)
        self._first = np.full(shape, NEVER, dtype=np.int32)  # step a cell was first occupied
        self._scans: collections.deque = collections.deque()
        self._prev: tuple[float, float, float] | None = None
        self.covariance = np.zeros((3, 3))
        self.applied = self.rejected = self.skipped = 0
        self.moved = [0.0, 0.0]

    # ------------------------------------------------------------------ per step
    def step(self, step: int, odometry: np.ndarray, ranges: np.ndarray | None,
             log_odds: np.ndarray) -> np.ndarray | None:
        """Account for one env step: propagate the uncertainty over the odometry's increment
        since the last call, buffer the fresh scan's echoes (``ranges`` from the transducers,
        ``None`` when no scan was taken), and every ``every`` steps match and correct
        ``odometry`` in place. ``log_odds``: the robot's grid's log-odds (before this step's
        scan). Returns the applied correction ``(dθ, dx, dy)`` or ``None``."""
        self._propagate(odometry)
        if ranges is not None:
            self._buffer(step, odometry, ranges)
        if step % self.every:
            return None
        occupied = log_odds > WALL_LOG_ODDS
        fresh = occupied & (self._first == NEVER)
        self._first[fresh] = step
        while self._scans and self._scans[0][0] <= step - self.window:
            self._scans.popleft()
        if step <= self.age or not self._scans:
            return None
        reference = occupied & (self._first <= step - self.age)
        correction = self._correct(odometry, reference)
        if correction is not None:
            self._apply(odometry, correction)
        return correction

    def _propagate(self, odometry: np.ndarray) -> None:
        x, y, th = (float(v) for v in odometry)
        if self._prev is None:
            self._prev = x, y, th
            return
        px, py, pth = self._prev
        self._prev = x, y, th
        dxw, dyw = x - px, y - py
        dist = math.hypot(dxw, dyw)
        dth = math.atan2(math.sin(th - pth), math.cos(th - pth))
        if dist == 0.0 and dth == 0.0:
            return
        f = np.array([[1.0, 0.0, -dyw], [0.0, 1.0, dxw], [0.0, 0.0, 1.0]])
        c, s = math.cos(pth), math.sin(pth)
        g = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        q = increment_covariance(self.cfg, dist, dth)
        self.covariance = f @ self.covariance @ f.T + g @ q @ g.T

    def _buffer(self, step: int, odometry: np.ndarray, ranges: np.ndarray) -> None:
        dist = ranges + self._mount
        keep = (ranges < self._max_range) & (dist <= MAX_HIT_RANGE)
        if not keep.any():
            return
        local = self._dirs[keep] * dist[keep, None]
        c, s = math.cos(odometry[2]), math.sin(odometry[2])
        pts = local @ np.array([[c, s], [-s, c]]) + odometry[:2]
        self._scans.append((step, pts))

    # ------------------------------------------------------------------ the match
    def _correct(self, odometry: np.ndarray, reference: np.ndarray) -> np.ndarray | None:
        pts = np.concatenate([p for _, p in self._scans])
        if len(pts) < MIN_POINTS:
            self.skipped += 1
            return None
        sd = np.sqrt(np.maximum(np.diag(self.covariance), 1e-12))
        # the submap's window plus what the bounded correction can move it by
        reach = float(3.0 * sd[0] + 3.0 * sd[1]
                      + 3.0 * sd[2] * np.max(np.hypot(*(pts - odometry[:2]).T)))
        margin = reach + MATCH_DISTANCE + 2 * self._res
        lo = np.floor((pts.min(axis=0) - margin - self._origin) / self._res).astype(int)
        hi = np.ceil((pts.max(axis=0) + margin - self._origin) / self._res).astype(int) + 1
        h, w = reference.shape
        c0, r0 = max(lo[0], 0), max(lo[1], 0)
        c1, r1 = min(hi[0], w), min(hi[1], h)
        if c1 <= c0 or r1 <= r0:
            self.skipped += 1
            return None
        ref = reference[r0:r1, c0:c1]
        if not ref.any():
            self.skipped += 1
            return None
        field, nearest = ndimage.distance_transform_edt(~ref, return_indices=True)
        field = field * self._res
        # the centre of every cell's nearest old wall cell, metres
        base = self._origin + np.array([c0, r0]) * self._res + 0.5 * self._res
        wall = np.stack([base[0] + nearest[1] * self._res, base[1] + nearest[0] * self._res])
        hh, ww = ref.shape

        def cells(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            ix = np.clip(np.floor((q[:, 0] - base[0]) / self._res + 0.5).astype(int), 0, ww - 1)
            iy = np.clip(np.floor((q[:, 1] - base[1]) / self._res + 0.5).astype(int), 0, hh - 1)
            return iy, ix

        near = field[cells(pts)] <= MATCH_DISTANCE
        if np.count_nonzero(near) < MIN_POINTS:
            self.skipped += 1
            return None
        rel = pts[near] - odometry[:2]
        pivot = odometry[:2].copy()

        def moved(x: np.ndarray) -> np.ndarray:
            c, s = math.cos(x[0]), math.sin(x[0])
            return rel @ np.array([[c, s], [-s, c]]) + pivot + x[1:]

        # each wall cell's normal and how line-like the wall is there (the structure tensor
        # of the old walls, skimage): along a wall an echo constrains only across it
        arr, arc, acc = feature.structure_tensor(ref.astype(np.float64), sigma=1.5,
                                                 order="rc")
        angle = 0.5 * np.arctan2(2.0 * arc, acc - arr)  # the normal's angle, (x, y) frame
        spread = np.hypot(acc - arr, 2.0 * arc)
        coherence = np.where(acc + arr > 0, spread / np.maximum(acc + arr, 1e-12), 0.0)

        def frames(iy: np.ndarray, ix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            """Per echo the wall's normal and its tangent weighted by 1 - coherence."""
            a = angle[iy, ix]
            n = np.stack([np.cos(a), np.sin(a)], axis=1)
            t = np.stack([-n[:, 1], n[:, 0]], axis=1) * (1.0 - coherence[iy, ix])[:, None]
            return n, t

        def residuals(x: np.ndarray) -> np.ndarray:
            # point-to-line residuals to each echo's nearest old wall cell (ICP)
            q = moved(x)
            iy, ix = cells(q)
            d = q - wall[:, iy, ix].T
            n, t = frames(iy, ix)
            return np.stack([np.sum(n * d, axis=1), np.sum(t * d, axis=1)], axis=1).ravel()

        def jacobian(x: np.ndarray) -> np.ndarray:
            c, s = math.cos(x[0]), math.sin(x[0])
            dp = np.zeros((len(rel), 2, 3))  # d(echo position) / d(dθ, dx, dy)
            dp[:, 0, 0] = -s * rel[:, 0] - c * rel[:, 1]
            dp[:, 1, 0] = c * rel[:, 0] - s * rel[:, 1]
            dp[:, 0, 1] = 1.0
            dp[:, 1, 2] = 1.0
            n, t = frames(*cells(moved(x)))
            return np.stack([np.einsum("ni,nij->nj", n, dp), np.einsum("ni,nij->nj", t, dp)],
                            axis=1).reshape(-1, 3)

        bound = 3.0 * np.array([sd[2], sd[0], sd[1]]) + 1e-9
        fit = optimize.least_squares(residuals, np.zeros(3), jac=jacobian, bounds=(-bound, bound),
                                     loss=LOSS, f_scale=FIT_SCALE,
                                     x_scale=np.array([0.02, 0.05, 0.05]), method="trf")
        measured = fit.x
        info = fit.jac.T @ fit.jac * self.info_scale
        if HEADING_ONLY:
            measured = measured * np.array([1.0, 0.0, 0.0])
            info = info * np.outer([1.0, 0.0, 0.0], [1.0, 0.0, 0.0])
        # (dθ, dx, dy) order for the fit; the covariance is (x, y, θ)
        perm = np.array([2, 0, 1])
        p = self.covariance[np.ix_(perm, perm)]
        gain = np.linalg.solve(np.eye(3) + p @ info, np.eye(3))
        posterior = gain @ p
        innovation = info - info @ posterior @ info
        if float(measured @ innovation @ measured) > GATE:
            self.rejected += 1
            return None
        correction = posterior @ info @ measured
        back = np.argsort(perm)
        posterior = 0.5 * (posterior + posterior.T)
        self.covariance = posterior[np.ix_(back, back)]
        self.applied += 1
        return correction

    def _apply(self, odometry: np.ndarray, correction: np.ndarray) -> None:
        """Move the pose (and the buffered echoes) by ``correction`` about the robot."""
        dth, dx, dy = (float(v) for v in correction)
        pivot = odometry[:2].copy()
        c, s = math.cos(dth), math.sin(dth)
        rot = np.array([[c, s], [-s, c]])
        shift = np.array([dx, dy])
        for k, (step, pts) in enumerate(self._scans):
            self._scans[k] = (step, (pts - pivot) @ rot + pivot + shift)
        odometry[0] += dx
        odometry[1] += dy
        th = float(odometry[2]) + dth
        odometry[2] = math.atan2(math.sin(th), math.cos(th))
        self._prev = (float(odometry[0]), float(odometry[1]), float(odometry[2]))
        self.moved[0] += math.hypot(dx, dy)
        self.moved[1] += abs(dth)
