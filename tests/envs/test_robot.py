"""Robots: differential drive, contacts, odometry; never leaving free space."""

import math

import numpy as np
import pytest

from envs.two_robot_explore.config import RobotConfig, WorldConfig
from envs.two_robot_explore.robot import Robot, build_space, simulate, start_frame_pose
from envs.two_robot_explore.worlds import procedural_world


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
