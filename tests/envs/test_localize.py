"""Drift correction against the robot's own map (``envs.explore.localize``): the
scan-to-map match on a synthetic room, the config fields, and the env hook (off without odometry
noise, deterministic with it)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from envs import two_robot_explore_v0
from envs.explore.config import RobotConfig
from envs.explore.localize import DriftCorrector

RES = 0.1
ORIGIN = (-10.0, -10.0)
SHAPE = (200, 200)
ROOM = (-3.0, -2.0, 3.0, 2.0)  # a box room: every direction constrained
ANGLES = np.radians([-90.0, -50.0, -30.0, -10.0, 10.0, 30.0, 50.0, 90.0])
MOUNT = 0.25


def _room_log_odds() -> np.ndarray:
    """Log-odds of the room's walls (4, the clamp), two cells thick."""
    states = np.zeros(SHAPE, dtype=np.float32)
    x0, y0, x1, y1 = ROOM
    xs = np.arange(SHAPE[1]) * RES + ORIGIN[0] + RES / 2
    ys = np.arange(SHAPE[0]) * RES + ORIGIN[1] + RES / 2
    gx, gy = np.meshgrid(xs, ys)
    inside = (gx >= x0 - RES) & (gx <= x1 + RES) & (gy >= y0 - RES) & (gy <= y1 + RES)
    border = inside & ((np.abs(gx - x0) < RES) | (np.abs(gx - x1) < RES)
                       | (np.abs(gy - y0) < RES) | (np.abs(gy - y1) < RES))
    states[border] = 4.0
    return states


def _ranges(pose: np.ndarray) -> np.ndarray:
    """Sonar readings (from the rim) of the room's walls from ``pose``, central rays."""
    x0, y0, x1, y1 = ROOM
    out = []
    for a in ANGLES:
        c, s = math.cos(pose[2] + a), math.sin(pose[2] + a)
        ts = []
        for wall, d, p in ((x0, c, pose[0]), (x1, c, pose[0]), (y0, s, pose[1]),
                           (y1, s, pose[1])):
            if abs(d) > 1e-9 and (wall - p) / d > 0:
                ts.append((wall - p) / d)
        out.append(min(ts) - MOUNT)
    return np.array(out)


def _corrector(**kw) -> DriftCorrector:
    cfg = RobotConfig(odometry_noise=(0.02, 0.02), drift_correction=True,
                      drift_correction_every=20, drift_correction_window=20,
                      drift_correction_age=1, drift_correction_sigma=0.3, **kw)
    return DriftCorrector(cfg, ANGLES, MOUNT, 5.0, SHAPE, ORIGIN, RES)


def _drive(corrector: DriftCorrector, offset: tuple[float, float, float]) -> tuple[float, float]:
    """Drive 40 steps through the room with odometry off the true pose by ``offset`` (a fixed
    rotation about the origin and a shift); returns the position error before the correction
    at step 40 and after it."""
    states = _room_log_odds()
    dth, dx, dy = offset
    c, s = math.cos(dth), math.sin(dth)
    odometry = np.zeros(3)
    errors = []
    for step in range(1, 41):
        true = np.array([-2.0 + 0.1 * step, -0.5 + 0.02 * step, 0.3 * math.sin(step / 4)])
        if step < 40:
            odometry[:] = (c * true[0] - s * true[1] + dx, s * true[0] + c * true[1] + dy,
                           true[2] + dth)
        else:
            errors.append(math.dist(odometry[:2], true[:2]))
            odometry[:] = (c * true[0] - s * true[1] + dx, s * true[0] + c * true[1] + dy,
                           true[2] + dth)
            errors[0] = math.dist(odometry[:2], true[:2])
            corrector.covariance = np.diag([0.15 ** 2, 0.15 ** 2, math.radians(4.0) ** 2])
        corrector.step(step, odometry, _ranges(true), states)
    errors.append(math.dist(odometry[:2], true[:2]))
    return errors[0], errors[1]


def test_match_pulls_the_pose_back_onto_the_room():
    corrector = _corrector()
    before, after = _drive(corrector, (math.radians(2.0), 0.12, -0.08))
    assert corrector.applied == 1
    assert after < 0.7 * before


def test_no_correction_without_an_error():
    corrector = _corrector()
    before, after = _drive(corrector, (0.0, 0.0, 0.0))
    assert before == 0.0
    assert after < 0.1  # within a cell of the walls it already matched


@pytest.mark.parametrize("key, value, kind", [
    ("drift_correction", "yes", TypeError),
    ("drift_correction_every", 0, ValueError),
    ("drift_correction_window", -3, ValueError),
    ("drift_correction_age", 0, ValueError),
    ("drift_correction_sigma", 0.0, ValueError),
    ("drift_correction_sigma", float("nan"), ValueError),
])
def test_bad_config_values_name_the_field(key, value, kind):
    with pytest.raises(kind, match=f"robot.{key}"):
        RobotConfig(**{key: value})


def _odometry(robot: dict, seed: int, steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Both robots' odometry ``(2, 3)`` after ``steps`` seeded random steps, their true poses
    ``(2, 3)`` and their start poses ``(2, 3)`` (world frame)."""
    env = two_robot_explore_v0.parallel_env(max_cycles=steps, robot=robot,
                                            mapping={"merge_method": "none"})
    _, infos = env.reset(seed=seed)
    starts = np.stack([infos[a]["pose"] for a in env.possible_agents])
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        _, _, _, _, infos = env.step({a: rng.uniform(-1.0, 1.0, 2).astype(np.float32)
                                      for a in env.agents})
    return (np.stack([infos[a]["odometry"] for a in env.possible_agents]),
            np.stack([infos[a]["pose"] for a in env.possible_agents]), starts)


def test_off_without_odometry_noise():
    plain, *_ = _odometry({}, 3, 300)
    asked, poses, starts = _odometry({"drift_correction": True}, 3, 300)
    np.testing.assert_array_equal(plain, asked)
    # nothing moved the exact odometry: it is each true pose seen from the robot's start
    for odometry, pose, start in zip(asked, poses, starts, strict=True):
        c, s = math.cos(start[2]), math.sin(start[2])
        d = pose[:2] - start[:2]
        np.testing.assert_allclose(odometry[:2], [c * d[0] + s * d[1], -s * d[0] + c * d[1]],
                                   atol=1e-9)
        assert math.remainder(pose[2] - start[2] - odometry[2], math.tau) == pytest.approx(
            0.0, abs=1e-9)


def test_deterministic_with_noise():
    robot = {"odometry_noise": (0.02, 0.02), "drift_correction": True,
             "drift_correction_age": 50}
    a, *_ = _odometry(robot, 5, 400)
    b, *_ = _odometry(robot, 5, 400)
    np.testing.assert_array_equal(a, b)
    # the correction is on: the same noisy episode uncorrected ends elsewhere (the corrector
    # draws no random numbers, so the motion and the noise are the same)
    off, *_ = _odometry({**robot, "drift_correction": False}, 5, 400)
    assert (np.abs(a - off).max(axis=1) > 1e-4).all()  # each robot's
