"""The sonar ring: a sensor object (VMAS ``Lidar`` style) over the world's ray caster.

Each of the ``S`` sonars (the Pioneer front ring by default) is a cone sampled by ``K`` rays
spread evenly across it. The rays are cast from the robot's centre by the world's
:class:`~envs.explore.raycast.RayCaster`, which sees the wall segments (the very
shapes robots collide with) and the teammate's disc, not the robot's own. Ranges are reported
from the transducers on the rim (``mount_radius`` less than the distance from the centre).
Rays start at the centre, not on the rim, because a robot pressed against a wall has its rim
on (or, within the contact slop, just past) the wall: a ray from there could miss it.

Per ray, an echo whose incidence angle (between the ray and the surface normal) exceeds
``dropout_incidence`` is lost with probability ``dropout_prob`` (specular reflection: the sound
bounces away). A sonar reads the nearest surviving echo of its rays plus Gaussian noise,
clipped to ``[min_range, max_range]``; ``max_range`` means "no echo". With ``measure_every``
set, a new scan is taken only after the robot has travelled that far since the last one (the
paper's robots measured every 0.10 m); otherwise every step.

The rays' end points, the echoes and the readings are compiled loops over arrays the sonar
keeps (no Python arithmetic per ray).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from envs.explore.config import SonarConfig
from envs.explore.raycast import RayCaster


@njit(cache=True, nogil=True)
def _ray_ends(x, y, c, s, length, local_dir, ends, dirs):
    """World directions ``dirs`` and end points ``ends`` (``length`` from ``(x, y)``) of the
    rays ``local_dir`` (robot frame) of a robot at heading ``(cos, sin) = (c, s)``."""
    for i in range(local_dir.shape[0]):
        lc = local_dir[i, 0]
        ls = local_dir[i, 1]
        dx = c * lc - s * ls
        dy = s * lc + c * ls
        dirs[i, 0] = dx
        dirs[i, 1] = dy
        ends[i, 0] = x + length * dx
        ends[i, 1] = y + length * dy


@njit(cache=True, nogil=True)
def _echoes(alpha, nx, ny, dirs, length, mount):
    """:meth:`Sonar.cast`'s distances from the transducers and incidence cosines, from each
    ray's hit fraction ``alpha`` (``inf``: no hit) and surface normal ``(nx, ny)``."""
    n = alpha.shape[0]
    dist = np.empty(n)
    cos_inc = np.empty(n)
    for i in range(n):
        if alpha[i] == math.inf:
            dist[i] = math.inf
            cos_inc[i] = 1.0
        else:
            dist[i] = alpha[i] * length - mount
            cos_inc[i] = abs(nx[i] * dirs[i, 0] + ny[i] * dirs[i, 1])
    return dist, cos_inc


@njit(cache=True, nogil=True)
def _readings(alpha, nx, ny, dirs, length, mount, u, noise, k_rays, steep, p_drop, lo, hi, std,
              reading, truth):
    """One scan's readings from its casts (:func:`_echoes` of them): per sonar ``k`` (rays
    ``k*K`` to ``(k+1)*K - 1``) ``reading[k]`` is the nearest echo not dropped (ray ``i`` is
    dropped when its incidence cosine is below ``steep`` and ``u[i] < p_drop``) plus
    ``noise[k] * std``, ``hi`` without one, and ``truth[k]`` the nearest echo; both clipped
    to ``[lo, hi]``."""
    dist, cos_inc = _echoes(alpha, nx, ny, dirs, length, mount)
    for k in range(noise.shape[0]):
        best = true = math.inf
        for i in range(k * k_rays, (k + 1) * k_rays):
            if dist[i] < true:
                true = dist[i]
            if dist[i] < best and not (cos_inc[i] < steep and u[i] < p_drop):
                best = dist[i]
        r = best + noise[k] * std if best != math.inf else hi
        reading[k] = lo if r < lo else hi if r > hi else r
        truth[k] = lo if true < lo else hi if true > hi else true


class Sonar:
    """The sonar ring of one robot.

    Args:
        cfg: the sonar settings.
        mount_radius: distance of the transducers from the robot centre, metres.

    Attributes:
        angles: ``(S,)`` sensor directions in the robot frame, radians.
        ray_angles: ``(S, K)`` ray directions in the robot frame, radians.
        last: ``(S,)`` the latest reading, metres (``max_range`` = no echo); kept for
            observations and rendering.
        true_last: ``(S,)`` what the latest scan would read without noise and dropout (the
            nearest real echo of each cone), for ground-truth coverage.
        last_pose: the world pose ``(x, y, heading)`` the latest reading was taken from.
        fresh: whether the latest :meth:`measure` call took a new scan.
    """

    __slots__ = ("cfg", "mount_radius", "angles", "ray_angles", "last", "true_last",
                 "last_pose", "fresh", "_local_dir", "_length", "_cos_dropout", "_since",
                 "_n_rays", "_rays", "_ends", "_dirs", "_alpha", "_nx", "_ny")

    def __init__(self, cfg: SonarConfig, mount_radius: float) -> None:
        self.cfg = cfg
        self.mount_radius = float(mount_radius)
        self.angles = np.radians(np.asarray(cfg.angles, dtype=np.float64))
        half = math.radians(cfg.cone) / 2.0
        offsets = np.linspace(-half, half, cfg.rays) if cfg.rays > 1 else np.zeros(1)
        self.ray_angles = self.angles[:, None] + offsets[None, :]
        self._rays = self.ray_angles.shape[1]
        self._n_rays = self.ray_angles.size
        ra = self.ray_angles.ravel()
        self._local_dir = np.stack([np.cos(ra), np.sin(ra)], axis=1)
        self._length = self.mount_radius + cfg.max_range
        self._cos_dropout = math.cos(math.radians(cfg.dropout_incidence))
        self.last = np.full(len(self.angles), cfg.max_range)
        self.true_last = self.last.copy()
        self.last_pose = np.zeros(3)
        self.fresh = False
        self._since = math.inf
        # each scan's ray directions and end points (written by _ray_ends) and per-ray hits
        # (written by the caster): arrays kept for the sonar's life, overwritten every scan
        self._ends = np.zeros((self._n_rays, 2))
        self._dirs = np.zeros((self._n_rays, 2))
        self._alpha = np.zeros(self._n_rays)
        self._nx = np.zeros(self._n_rays)
        self._ny = np.zeros(self._n_rays)

    def reset(self) -> None:
        """Forget the last scan (the next :meth:`measure` always scans)."""
        self.last = np.full(len(self.angles), self.cfg.max_range)
        self.true_last = self.last.copy()
        self.fresh = False
        self._since = math.inf

    def ray_segments(self, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World ``(S*K, 2)`` start and end points of every ray from ``pose``: from the centre,
        ``mount_radius + max_range`` long."""
        c, s = math.cos(pose[2]), math.sin(pose[2])
        rot = np.array([[c, s], [-s, c]])
        starts = np.broadcast_to(pose[:2], (self._n_rays, 2))
        ends = starts + (self._local_dir @ rot) * self._length
        return starts, ends

    def cast(self, caster: RayCaster, pose: np.ndarray, own: int
             ) -> tuple[np.ndarray, np.ndarray]:
        """Noise-free ray casts from ``pose`` by ``caster``, not seeing disc ``own`` (the robot
        carrying the sonar): ``(S*K,)`` hit distances from the transducers (``inf`` = nothing
        within ``max_range``) and ``(S*K,)`` cosines of the incidence angles."""
        alpha, nx, ny = self._cast(caster, pose, own)
        return _echoes(alpha, nx, ny, self._dirs, self._length, self.mount_radius)

    def _cast(self, caster: RayCaster, pose: np.ndarray, own: int
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per ray the hit fraction of its length (``inf``: no hit) and the surface normal
        ``(nx, ny)`` (0 without a hit); leaves the rays' world directions in ``_dirs``. The
        arrays are overwritten by the next cast."""
        x, y, th = float(pose[0]), float(pose[1]), float(pose[2])
        _ray_ends(x, y, math.cos(th), math.sin(th), self._length, self._local_dir, self._ends,
                  self._dirs)
        caster.cast(x, y, self._ends, own, self._alpha, self._nx, self._ny)
        return self._alpha, self._nx, self._ny

    def measure(self, caster: RayCaster, pose: np.ndarray, own: int,
                rng: np.random.Generator, travelled: float = 0.0) -> np.ndarray:
        """Scan (or, with ``measure_every``, keep the last scan until the robot has travelled
        far enough) and return :attr:`last`.

        Args:
            caster: the world's ray caster, its discs at the robots' positions.
            pose: the robot's true world pose ``(x, y, heading)``.
            own: the index of the robot carrying the sonar (its disc is not seen).
            rng: the env's generator (dropout and noise; the same draws every scan).
            travelled: metres driven since the previous call.
        """
        cfg = self.cfg
        self._since += travelled
        if cfg.measure_every is not None and self._since < cfg.measure_every:
            self.fresh = False
            return self.last
        self._since = 0.0
        alpha, nx, ny = self._cast(caster, pose, own)
        u = rng.random(self._n_rays)
        noise = rng.standard_normal(len(self.angles))
        self.last = np.empty(len(self.angles))
        self.true_last = np.empty(len(self.angles))
        _readings(alpha, nx, ny, self._dirs, self._length, self.mount_radius, u, noise,
                  self._rays, self._cos_dropout, cfg.dropout_prob, cfg.min_range, cfg.max_range,
                  cfg.noise_std, self.last, self.true_last)
        self.last_pose = np.array(pose, dtype=np.float64)
        self.fresh = True
        return self.last

    def origins(self, pose: np.ndarray) -> np.ndarray:
        """``(S, 2)`` transducer positions in the frame of ``pose`` (world or odometry)."""
        c, s = math.cos(pose[2]), math.sin(pose[2])
        o = np.stack([np.cos(self.angles), np.sin(self.angles)], axis=1) * self.mount_radius
        return o @ np.array([[c, s], [-s, c]]) + pose[:2]
