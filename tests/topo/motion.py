"""A rigid motion for the topo tests: what ``transformed`` takes (anything with ``apply`` and
``inverse``), without importing ``fusion.Rigid2D`` from the layer above topo."""

from __future__ import annotations

import math

import numpy as np


class Motion:
    """``p -> R(theta) p + t`` (``theta`` radians CCW)."""

    def __init__(self, theta: float = 0.0, t=(0.0, 0.0)) -> None:
        self.theta = float(theta)
        self.t = np.asarray(t, dtype=np.float64)
        c, s = math.cos(self.theta), math.sin(self.theta)
        self.R = np.array([[c, -s], [s, c]])

    def apply(self, points) -> np.ndarray:
        return np.asarray(points, dtype=np.float64) @ self.R.T + self.t

    def inverse(self) -> Motion:
        return Motion(-self.theta, -(self.R.T @ self.t))
