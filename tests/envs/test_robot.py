"""Robots: differential drive, contacts, odometry; never leaving free space."""

import math

import numpy as np
import pytest

from envs.explore.config import ODOMETRY_PRESETS, RobotConfig, WorldConfig
from envs.explore.drift import drift_aware_error, drift_aware_truth
from envs.explore.robot import (
    Robot,
    build_space,
    sample_odometry,
    simulate,
    start_frame_pose,
)
from envs.explore.worlds import procedural_world
from fusion.rigid import Rigid2D


def _setup(seed=0, size=(12.0, 12.0)):
    world = procedural_world(WorldConfig(size=size), np.random.default_rng(seed))
    starts = world.sample_starts(np.random.default_rng(seed), 0.45, 2.0)
    robots = [Robot(i, starts[i], RobotConfig()) for i in range(2)]
    return world, robots, build_space(world.segments, robots)


def _segment_distance(p, seg):
    a, b = seg[:, :2], seg[:, 2:]
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.einsum("ij,ij->i", ab, ab), 0, 1)
    return np.hypot(*(a + t[:, None] * ab - p).T).min()


def test_straight_drive_and_turn_in_place():
    _, robots, space = _setup()
    r = robots[0]
    start = r.true_pose()
    r.command(0.0, math.radians(90))
    robots[1].command(0.0, 0.0)
    for _ in range(10):
        simulate(space, robots, 0.1, 4)
    pose = r.true_pose()
    assert math.dist(pose[:2], start[:2]) < 1e-6
    turned = math.atan2(math.sin(pose[2] - start[2]), math.cos(pose[2] - start[2]))
    # the wheels act from the second substep on (pymunk moves bodies before solving joints)
    lag = math.radians(90) * 0.1 / 4
    assert turned == pytest.approx(math.pi / 2 - lag, abs=2e-3)
    r.command(0.5, 0.0)
    for _ in range(10):
        simulate(space, robots, 0.1, 4)
    moved = math.dist(r.true_pose()[:2], pose[:2])
    assert moved == pytest.approx(0.5 - 0.5 * 0.1 / 4, abs=2e-3)


def test_odometry_without_noise_is_the_pose_in_the_start_frame():
    _, robots, space = _setup(1)
    rng = np.random.default_rng(0)
    for k in range(50):
        for r in robots:
            r.command(0.3, math.radians(20 if k < 25 else -30))
        simulate(space, robots, 0.1, 4)
        for r in robots:
            r.update_odometry((0.0, 0.0), rng)
    for r in robots:
        np.testing.assert_allclose(r.odometry, start_frame_pose(r.start, r.true_pose()),
                                   atol=1e-9)


def test_robots_never_leave_free_space_and_walls_stop_them():
    world, robots, space = _setup(3)
    rng = np.random.default_rng(3)
    cfg = RobotConfig()
    for k in range(1500):
        if k % 10 == 0:
            for r in robots:
                v, w = rng.uniform(-1, 1, 2)
                r.command(v * cfg.max_speed, w * math.radians(cfg.max_turn_rate))
        simulate(space, robots, cfg.dt, cfg.substeps)
        if k % 5 == 0:
            for r in robots:
                p = r.true_pose()[:2]
                assert world.is_free(p[None])[0]
                assert _segment_distance(p, world.segments) > cfg.radius - 0.03
    assert sum(r.collisions for r in robots) > 0  # random driving does bump into walls


def test_drive_sets_the_motor_along_the_heading_and_true_pose_reads_the_body():
    _, robots, space = _setup()
    r = robots[0]
    for k in range(20):
        r.command(0.5, 0.3 * (-1) ** k)
        r.drive()
        a = r.body.angle
        assert tuple(r.motor.velocity) == (0.5 * math.cos(a), 0.5 * math.sin(a))
        assert r.motor.angular_velocity == 0.3 * (-1) ** k
        space.step(0.025)
        p = r.body.position
        a = r.body.angle
        np.testing.assert_array_equal(r.true_pose(),
                                      [p.x, p.y, math.atan2(math.sin(a), math.cos(a))])


def test_robot_pickles():
    import pickle

    _, robots, _ = _setup()
    r = pickle.loads(pickle.dumps(robots[0]))
    np.testing.assert_array_equal(r.true_pose(), robots[0].true_pose())
    r.command(0.5, 0.2)
    r.drive()
    assert tuple(r.motor.velocity) != (0.0, 0.0)


def _drive(robots, space, rng, steps):
    """Random driving (commands from ``rng``) with odometry updated from ``rng`` each step."""
    cfg = RobotConfig()
    for k in range(steps):
        if k % 10 == 0:
            for r in robots:
                v, w = rng.uniform(-1, 1, 2)
                r.command(v * cfg.max_speed, w * math.radians(cfg.max_turn_rate))
        simulate(space, robots, cfg.dt, cfg.substeps)
        for r in robots:
            r.update_odometry(None, rng)


def _noisy_setup(seed, **robot):
    world = procedural_world(WorldConfig(size=(12.0, 12.0)), np.random.default_rng(seed))
    starts = world.sample_starts(np.random.default_rng(seed), 0.45, 2.0)
    cfg = RobotConfig(**robot)
    robots = [Robot(i, starts[i], cfg) for i in range(2)]
    return robots, build_space(world.segments, robots)


@pytest.mark.parametrize("robot", [{}, {"odometry_model": "rot_trans_rot"}])
def test_noise_free_odometry_frame_is_the_start_pose(robot):
    robots, space = _noisy_setup(2, **robot)
    _drive(robots, space, np.random.default_rng(2), 200)
    for r in robots:
        frame = r.odometry_frame()
        assert frame.allclose(Rigid2D(r.start[2], r.start[:2]), atol=1e-9)
    truth = drift_aware_truth(robots[0], robots[1])
    start = Rigid2D(robots[0].start[2], robots[0].start[:2]).inverse() @ Rigid2D(
        robots[1].start[2], robots[1].start[:2])
    assert truth.allclose(start, atol=1e-9)
    assert drift_aware_error(start, robots[0], robots[1]) == pytest.approx((0.0, 0.0), abs=1e-6)


@pytest.mark.parametrize("robot", [{"odometry_noise": (0.05, 0.05)},
                                   {"odometry_model": "rot_trans_rot",
                                    "odometry_alphas": "pioneer3dx"}])
def test_drifting_odometry_frame_maps_the_odometry_onto_the_true_pose(robot):
    robots, space = _noisy_setup(4, **robot)
    _drive(robots, space, np.random.default_rng(4), 400)
    for r in robots:
        frame = r.odometry_frame()
        assert not frame.allclose(Rigid2D(r.start[2], r.start[:2]), atol=1e-3)  # it drifted
        np.testing.assert_allclose(frame.apply(r.odometry[:2]), r.true_pose()[:2], atol=1e-9)
        assert frame.rotation_error(Rigid2D(r.true_pose()[2] - r.odometry[2])) < 1e-9
    # the drift-aware truth puts robot 1 where robot 0's frame has it, and measures 0 error
    truth = drift_aware_truth(robots[0], robots[1])
    seen = robots[0].odometry_frame().apply(truth.apply(robots[1].odometry[:2]))
    np.testing.assert_allclose(seen, robots[1].true_pose()[:2], atol=1e-9)
    assert drift_aware_error(truth, robots[0], robots[1]) == pytest.approx((0.0, 0.0), abs=1e-6)
    rot, trans = drift_aware_error(Rigid2D.from_degrees(3.0) @ truth, robots[0], robots[1])
    assert rot == pytest.approx(3.0) and trans > 0.0


def test_drift_aware_error_wants_a_rigid2d():
    robots, _ = _noisy_setup(0)
    with pytest.raises(TypeError, match="transform must be a fusion.Rigid2D, got tuple"):
        drift_aware_error((0.0, 0.0), robots[0], robots[1])


@pytest.mark.parametrize("robot", [{"odometry_noise": (0.02, 0.02)},
                                   {"odometry_model": "rot_trans_rot",
                                    "odometry_alphas": (0.01, 0.001, 0.01, 0.001)}])
def test_noisy_odometry_is_deterministic_given_the_generator(robot):
    runs = []
    for _ in range(2):
        robots, space = _noisy_setup(5, **robot)
        _drive(robots, space, np.random.default_rng(11), 600)
        runs.append(np.concatenate([r.odometry for r in robots]))
    np.testing.assert_array_equal(runs[0], runs[1])
    robots, space = _noisy_setup(5, **robot)
    _drive(robots, space, np.random.default_rng(12), 600)
    assert not np.array_equal(runs[0], np.concatenate([r.odometry for r in robots]))


def test_sample_odometry_without_noise_recomposes_the_motion():
    rng = np.random.default_rng(0)
    for before, after in [((0.0, 0.0, 0.0), (0.05, 0.01, 0.2)),
                          ((1.0, 2.0, 3.0), (0.96, 1.98, -3.1)),  # backwards, across ±π
                          ((0.0, 0.0, 1.0), (0.0, 0.0, 1.3))]:  # turn in place
        rot1, trans, rot2 = sample_odometry(before, after, (0.0, 0.0, 0.0, 0.0), rng)
        heading = before[2] + rot1
        x = before[0] + trans * math.cos(heading)
        y = before[1] + trans * math.sin(heading)
        th = math.remainder(heading + rot2 - after[2], math.tau)
        assert (x, y, th) == pytest.approx((after[0], after[1], 0.0), abs=1e-12)


def test_sample_odometry_spreads_as_the_alphas_say():
    rng = np.random.default_rng(1)
    before, after = (0.0, 0.0, 0.0), (0.1 * math.cos(0.3), 0.1 * math.sin(0.3), 0.5)
    alphas = (0.04, 0.0, 0.01, 0.0)  # 20 % of each rotation, 10 % of the translation
    reads = np.array([sample_odometry(before, after, alphas, rng) for _ in range(4000)])
    np.testing.assert_allclose(reads.mean(axis=0), [0.3, 0.1, 0.2], atol=3e-3)
    np.testing.assert_allclose(reads.std(axis=0), [0.2 * 0.3, 0.1 * 0.1, 0.2 * 0.2], rtol=0.06)


@pytest.mark.parametrize(("robot", "error", "match"), [
    ({"odometry_model": "gps"}, ValueError,
     r"robot.odometry_model must be one of \['increment', 'rot_trans_rot'\], got 'gps'"),
    ({"odometry_model": "rot_trans_rot", "odometry_alphas": "roomba"}, ValueError,
     r"robot.odometry_alphas must be four numbers >= 0 or one of \['pioneer3dx'\], "
     r"got 'roomba'"),
    ({"odometry_model": "rot_trans_rot", "odometry_alphas": (0.1, 0.1)}, TypeError,
     r"robot.odometry_alphas must be four numbers >= 0 or one of \['pioneer3dx'\], "
     r"got \(0.1, 0.1\)"),
    ({"odometry_model": "rot_trans_rot", "odometry_alphas": (0.1, -0.1, 0.0, 0.0)},
     ValueError, r"robot.odometry_alphas\[1\]"),
    ({"odometry_alphas": (0.1, 0.0, 0.0, 0.0)}, ValueError,
     r"robot.odometry_alphas apply to robot.odometry_model 'rot_trans_rot' only, got "
     r"\(0.1, 0.0, 0.0, 0.0\) with odometry_model 'increment'"),
    ({"odometry_model": "rot_trans_rot", "odometry_noise": (0.02, 0.02)}, ValueError,
     r"robot.odometry_noise applies to robot.odometry_model 'increment' only, got "
     r"\(0.02, 0.02\) with odometry_model 'rot_trans_rot'"),
])
def test_odometry_config_errors_name_the_field_value_and_choices(robot, error, match):
    with pytest.raises(error, match=match):
        RobotConfig(**robot)


def test_odometry_preset_is_stored_as_its_alphas():
    cfg = RobotConfig(odometry_model="rot_trans_rot", odometry_alphas="pioneer3dx")
    assert cfg.odometry_alphas == ODOMETRY_PRESETS["pioneer3dx"]
    assert cfg.odometry_alphas[0] == pytest.approx(0.05 ** 2)
