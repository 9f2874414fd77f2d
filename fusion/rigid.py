"""``Rigid2D``: a planar rigid motion, the paper's eq. (1).

Convention (DESIGN.md): ``p_A = R p_B + T`` — the transform moves map B (the paper's D) onto the
fixed map A (the paper's M). ``theta`` is counter-clockwise in radians, kept in ``(-pi, pi]``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from topo.validation import check_real


def wrap_angle(theta: float | np.ndarray) -> float | np.ndarray:
    """Angle(s) wrapped to ``(-pi, pi]``.

    A float is wrapped by Python's ``%``, which is numpy's ``remainder`` (``fmod``, then the
    divisor's sign): the same bits as the array form, without numpy's call overhead (hot paths
    wrap one angle at a time)."""
    if isinstance(theta, float):
        return float(-((-theta + math.pi) % (2 * math.pi)) + math.pi)
    wrapped = -np.remainder(-np.asarray(theta, dtype=np.float64) + math.pi, 2 * math.pi) + math.pi
    return float(wrapped) if np.ndim(wrapped) == 0 else wrapped


def rotation_matrix(theta: float) -> np.ndarray:
    """The 2×2 CCW rotation matrix of eq. (1)."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


class Rigid2D:
    """A 2-D rigid motion ``p ↦ R(theta) p + T`` (rotate CCW by ``theta``, then translate).

    Immutable. Compose with :meth:`compose` or ``@``: ``(a @ b).apply(p) == a.apply(b.apply(p))``.

    Args:
        theta: rotation in radians (any real; stored wrapped to ``(-pi, pi]``).
        T: translation ``(t_x, t_y)`` in the map's units (metres in topomerge).

    Example:
        >>> t = Rigid2D.from_degrees(90.0, (1.0, 0.0))
        >>> t.apply([[1.0, 0.0]]).round(12)
        array([[1., 1.]])
    """

    __slots__ = ("_theta", "_T", "_R")

    def __init__(self, theta: float = 0.0, T: Any = (0.0, 0.0)) -> None:
        theta = check_real(theta, "theta")
        if T is None or isinstance(T, (str, bytes, dict)):
            raise TypeError(f"T must be a 2-vector (t_x, t_y), got {type(T).__name__}")
        try:
            t = np.array(T, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"T must be a numeric 2-vector, got {type(T).__name__}") from exc
        if t.shape != (2,):
            raise ValueError(f"T must be a 2-vector (t_x, t_y), got shape {t.shape}")
        if not (math.isfinite(t[0]) and math.isfinite(t[1])):  # cheaper than np.isfinite
            raise ValueError(f"T must be finite, got {t.tolist()}")
        self._theta = float(wrap_angle(theta))
        self._T = t
        self._T.setflags(write=False)
        self._R = rotation_matrix(self._theta)
        self._R.setflags(write=False)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def trusted(cls, theta: float, T: np.ndarray) -> Rigid2D:
        """Build without validation, from a finite float ``theta`` and a float64 ``(2,)`` array
        the caller owns (hot paths: ICP, merges). Users want the validating constructor."""
        out = cls.__new__(cls)
        out._theta = math.remainder(theta, 2 * math.pi)
        if out._theta == -math.pi:  # keep (-pi, pi]
            out._theta = math.pi
        c, s = math.cos(out._theta), math.sin(out._theta)
        out._R = np.array([[c, -s], [s, c]])
        out._R.setflags(write=False)
        out._T = T
        T.setflags(write=False)
        return out

    @classmethod
    def identity(cls) -> Rigid2D:
        return cls(0.0, (0.0, 0.0))

    @classmethod
    def from_pose(cls, pose: Any) -> Rigid2D:
        """The motion placing a frame at ``pose`` = ``(x, y, theta)`` (a robot's pose: its
        frame → the world's), so that ``from_pose(p).apply((0, 0)) == (x, y)``.

        Raises:
            ValueError: ``pose`` does not hold 3 numbers (or they are not finite).
        """
        if isinstance(pose, (str, bytes)) or len(pose) != 3:
            raise ValueError(f"pose must be (x, y, theta), got {pose!r}")
        return cls(float(pose[2]), (float(pose[0]), float(pose[1])))

    @classmethod
    def from_degrees(cls, degrees: float, T: Any = (0.0, 0.0)) -> Rigid2D:
        return cls(math.radians(check_real(degrees, "degrees")), T)

    @classmethod
    def from_matrix(cls, matrix: Any, atol: float = 1e-6) -> Rigid2D:
        """From a 3×3 homogeneous matrix (eq. 1) or a 2×2 rotation.

        Raises:
            ValueError: if the matrix is not a proper rotation (orthonormal, det = +1) within
                ``atol``, or the homogeneous row is not ``[0, 0, 1]``.
        """
        m = np.asarray(matrix, dtype=np.float64)
        if m.shape not in ((2, 2), (3, 3)) or not np.all(np.isfinite(m)):
            raise ValueError(f"matrix must be a finite 2x2 or 3x3 array, got shape {m.shape}")
        if m.shape == (3, 3) and not np.allclose(m[2], (0.0, 0.0, 1.0), atol=atol):
            raise ValueError(f"matrix last row must be [0, 0, 1], got {m[2].tolist()}")
        r = m[:2, :2]
        if not np.allclose(r.T @ r, np.eye(2), atol=atol) or np.linalg.det(r) < 0:
            raise ValueError(
                f"matrix rotation block must be a proper rotation (R^T R = I, det = +1), "
                f"got {r.tolist()} with det {np.linalg.det(r):.6g}"
            )
        t = m[:2, 2] if m.shape == (3, 3) else (0.0, 0.0)
        return cls(math.atan2(r[1, 0], r[0, 0]), t)

    # ------------------------------------------------------------------ views
    @property
    def theta(self) -> float:
        """Rotation angle in radians, in ``(-pi, pi]``."""
        return self._theta

    @property
    def degrees(self) -> float:
        return math.degrees(self._theta)

    @property
    def R(self) -> np.ndarray:  # noqa: N802 - the paper's name
        """2×2 rotation matrix (read-only)."""
        return self._R

    @property
    def T(self) -> np.ndarray:  # noqa: N802 - the paper's name
        """Translation ``(t_x, t_y)`` (read-only)."""
        return self._T

    def matrix(self) -> np.ndarray:
        """The 3×3 homogeneous matrix of eq. (1)."""
        out = np.eye(3)
        out[:2, :2] = self._R
        out[:2, 2] = self._T
        return out

    # ------------------------------------------------------------------ algebra
    def apply(self, points: Any) -> np.ndarray:
        """Map an ``(N, 2)`` array (or a single ``(2,)`` point) through the motion."""
        p = np.asarray(points, dtype=np.float64)
        if p.shape == (2,):
            return self._R @ p + self._T
        if p.ndim != 2 or p.shape[1] != 2:
            raise ValueError(f"points must have shape (N, 2) or (2,), got shape {p.shape}")
        return p @ self._R.T + self._T

    def inverse(self) -> Rigid2D:
        """The motion that undoes this one: ``p = R^T (p' - T)``."""
        return Rigid2D(-self._theta, -(self._R.T @ self._T))

    def compose(self, other: Rigid2D) -> Rigid2D:
        """``self ∘ other``: apply ``other`` first, then ``self``."""
        if not isinstance(other, Rigid2D):
            raise TypeError(f"other must be a Rigid2D, got {type(other).__name__}")
        return Rigid2D(self._theta + other._theta, self._R @ other._T + self._T)

    def __matmul__(self, other: Rigid2D) -> Rigid2D:
        return self.compose(other)

    # ------------------------------------------------------------------ comparison
    def rotation_error(self, other: Rigid2D) -> float:
        """Absolute angle between the two rotations, radians in ``[0, pi]``."""
        return abs(float(wrap_angle(self._theta - other._theta)))

    def translation_error(self, other: Rigid2D, at: Any = (0.0, 0.0)) -> float:
        """Distance between where the two motions send the point ``at``.

        With ``at`` = the centroid of map B this is the translation error used in evaluation;
        ``‖ΔT‖`` alone depends on B's arbitrary origin.
        """
        p = np.asarray(at, dtype=np.float64).reshape(2)
        return float(np.linalg.norm(self.apply(p) - other.apply(p)))

    def allclose(self, other: Rigid2D, atol: float = 1e-9) -> bool:
        """Same rotation and translation within ``atol``."""
        return self.rotation_error(other) <= atol and bool(
            np.allclose(self._T, other._T, rtol=0.0, atol=atol)
        )

    def __repr__(self) -> str:
        return f"Rigid2D(theta={self.degrees:.4f} deg, T=({self._T[0]:.6g}, {self._T[1]:.6g}))"

    def __reduce__(self):
        return (Rigid2D, (self._theta, tuple(self._T.tolist())))
