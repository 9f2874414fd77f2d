"""Merge errors that allow for odometry drift.

With drifting odometry a robot's map is bent: no rigid transform matches the start-frame truth
everywhere, and the part of the map that matters to the team now — where the robots are — is
mapped right in each robot's *current* odometry frame (:meth:`Robot.odometry_frame`). The
drift-aware truth of a merge of robot ``j``'s map onto robot ``i``'s is therefore
``frame_i⁻¹ ∘ frame_j``, and a merge is judged where the two robots are now. For perfect
odometry both frames are the start poses and this is the env's start-frame truth.
"""

from __future__ import annotations

import math

import numpy as np

from envs.explore.config import RobotConfig
from envs.explore.robot import Robot
from fusion.rigid import Rigid2D


def odometry_noise_level(cfg: RobotConfig) -> float:
    """One relative noise level σ of a robot's odometry, what
    ``fusion.grid_merge.drift_prior(σ, steps)`` reads and the one test of "does it drift?"
    (``> 0``) the env asks: the larger of ``odometry_noise`` for the ``"increment"`` model,
    the largest ``sqrt(αk)`` for ``"rot_trans_rot"`` (``sqrt(α1)``, the relative spread of
    each rotation, for the presets); ``0`` for perfect odometry. Why: one number lets the
    merge's drift prior treat both models alike."""
    if not isinstance(cfg, RobotConfig):
        raise TypeError(f"cfg must be a RobotConfig, got {type(cfg).__name__}")
    if cfg.odometry_model == "rot_trans_rot":
        return math.sqrt(max(cfg.odometry_alphas))
    return float(max(cfg.odometry_noise))


def drift_aware_truth(robot_i: Robot, robot_j: Robot) -> Rigid2D:
    """The transform from robot ``j``'s map frame onto robot ``i``'s that is right at the
    robots' current places: ``robot_i.odometry_frame()⁻¹ ∘ robot_j.odometry_frame()``."""
    return robot_i.odometry_frame().inverse() @ robot_j.odometry_frame()


def drift_aware_error(transform: Rigid2D, robot_i: Robot, robot_j: Robot
                      ) -> tuple[float, float]:
    """Rotation error (degrees) and translation error (metres) of ``transform`` (robot
    ``j``'s map frame → robot ``i``'s) against :func:`drift_aware_truth`; the translation
    error is the larger of those at the two robots' current odometry positions (both taken in
    ``j``'s frame), the places where a wrong merge misleads the team now.

    Raises:
        TypeError: ``transform`` is not a :class:`fusion.Rigid2D`.
    """
    if not isinstance(transform, Rigid2D):
        raise TypeError(f"transform must be a fusion.Rigid2D, got {type(transform).__name__}")
    truth = drift_aware_truth(robot_i, robot_j)
    at = np.stack([robot_j.odometry[:2], truth.inverse().apply(robot_i.odometry[:2])])
    trans = max(transform.translation_error(truth, at=p) for p in at)
    return math.degrees(transform.rotation_error(truth)), float(trans)
