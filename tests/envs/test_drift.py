"""Odometry drift in the env: the rot1-trans-rot2 model drives it, the drift-aware truth
measures merges against the robots' current odometry frames."""

import numpy as np
import pytest
from conftest import SMALL

from envs import two_robot_explore_v0
from envs.explore.config import RobotConfig
from envs.explore.drift import (
    drift_aware_error,
    drift_aware_truth,
    odometry_noise_level,
)

PIONEER = {"odometry_model": "rot_trans_rot", "odometry_alphas": "pioneer3dx"}


def _run(seed, steps, robot):
    par = two_robot_explore_v0.parallel_env(**{**SMALL, "max_cycles": steps + 5,
                                               "robot": robot})
    par.reset(seed=seed)
    rng = np.random.default_rng(seed)
    for k in range(steps):
        if k % 10 == 0:
            act = {a: rng.uniform(-1, 1, 2) * [1.0, 0.5] for a in par.agents}
        par.step(act)
    return par


def test_perfect_odometry_makes_the_drift_aware_truth_the_start_frame_truth():
    par = _run(3, 150, {})
    assert drift_aware_truth(par.robots[0], par.robots[1]).allclose(par.true_merge, atol=1e-9)
    rot, trans = drift_aware_error(par.true_merge, par.robots[0], par.robots[1])
    assert rot < 1e-6 and trans < 1e-6


def test_the_pioneer_preset_drifts_the_same_way_for_the_same_seed():
    a, b = _run(4, 300, PIONEER), _run(4, 300, PIONEER)
    for ra, rb in zip(a.robots, b.robots, strict=True):
        np.testing.assert_array_equal(ra.odometry, rb.odometry)
    truth = drift_aware_truth(a.robots[0], a.robots[1])
    assert not truth.allclose(a.true_merge, atol=1e-4)  # the frames have drifted
    c = _run(5, 300, PIONEER)
    assert not np.array_equal(c.robots[0].odometry, a.robots[0].odometry)


def test_odometry_noise_level_reads_either_model():
    assert odometry_noise_level(RobotConfig()) == 0.0
    assert odometry_noise_level(RobotConfig(odometry_noise=(0.01, 0.03))) == 0.03
    assert odometry_noise_level(RobotConfig(**PIONEER)) == pytest.approx(0.05)
    # rotations exact, translations noisy: it drifts (the env's one "does it drift?" test)
    only_trans = RobotConfig(odometry_model="rot_trans_rot", odometry_alphas=(0, 0, 0.03 ** 2, 0))
    assert odometry_noise_level(only_trans) == pytest.approx(0.03)
    with pytest.raises(TypeError, match="cfg must be a RobotConfig, got dict"):
        odometry_noise_level({})
