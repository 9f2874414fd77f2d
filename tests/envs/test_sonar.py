"""The sonar's ray caster against pymunk's query and a slow numpy caster, and the sensor
model's rules."""

import math

import numpy as np
import pytest
from raycast_reference import cast_rays

from envs.explore.config import RobotConfig, SonarConfig, WorldConfig
from envs.explore.raycast import RayCaster
from envs.explore.robot import Robot, build_space
from envs.explore.sonar import Sonar
from envs.explore.worlds import procedural_world


def caster_of(segments, robots):
    caster = RayCaster(segments, RobotConfig().radius)
    for i, r in enumerate(robots):
        caster.discs[i] = r.true_pose()[:2]
    return caster


@pytest.fixture(scope="module")
def scene():
    world = procedural_world(WorldConfig(size=(14.0, 12.0)), np.random.default_rng(7))
    starts = world.sample_starts(np.random.default_rng(1), 0.45, 1.0)
    robots = [Robot(i, starts[i], RobotConfig()) for i in range(2)]
    space = build_space(world.segments, robots)
    return world, robots, space, caster_of(world.segments, robots)


def random_poses(world, rng, n):
    lo = np.array(world.origin)
    hi = lo + np.array(world.shape[::-1]) * world.resolution
    for _ in range(n):
        yield np.array([*rng.uniform(lo, hi), rng.uniform(-math.pi, math.pi)])


def test_rays_agree_with_numpy_reference(scene):
    world, robots, _space, caster = scene
    sonar = Sonar(SonarConfig(rays=5), mount_radius=0.25)
    rng = np.random.default_rng(3)
    cells = np.flatnonzero(world.drivable)
    teammate = robots[1]
    circle = np.array([[teammate.body.position.x, teammate.body.position.y, 0.25]])
    w = world.shape[1]
    checked = 0
    for c in rng.choice(cells, size=25, replace=False):
        iy, ix = divmod(int(c), w)
        pose = np.array([world.origin[0] + (ix + 0.5) * world.resolution,
                         world.origin[1] + (iy + 0.5) * world.resolution,
                         rng.uniform(-math.pi, math.pi)])
        if math.dist(pose[:2], circle[0, :2]) < 0.6:
            continue
        dist, cos_inc = sonar.cast(caster, pose, 0)
        starts, ends = sonar.ray_segments(pose)
        ref, normal = cast_rays(starts, ends, world.segments, circle)
        np.testing.assert_array_equal(np.isinf(dist), np.isinf(ref))
        hit = np.isfinite(ref)
        # readings are from the transducer, mount_radius out from the centre the rays start at
        np.testing.assert_allclose(dist[hit], ref[hit] - 0.25, atol=1e-6)
        dirs = (ends - starts) / np.hypot(*(ends - starts).T)[:, None]
        ref_cos = np.abs(np.einsum("ij,ij->i", dirs, normal))
        np.testing.assert_allclose(cos_inc[hit], ref_cos[hit], atol=1e-6)
        checked += int(hit.sum())
    assert checked > 100


def pymunk_hits(space, x, y, ends, shape_filter):
    """``(alpha, nx, ny)`` per ray from ``Space.segment_query_first`` (``inf``, 0, 0: none)."""
    out = np.zeros((len(ends), 3))
    for k, end in enumerate(ends.tolist()):
        hit = space.segment_query_first((x, y), end, 0.0, shape_filter)
        out[k] = (math.inf, 0.0, 0.0) if hit is None else (hit.alpha, *hit.normal)
    return out


def caster_hits(caster, x, y, ends, own):
    alpha, nx, ny = (np.empty(len(ends)) for _ in range(3))
    caster.cast(x, y, np.ascontiguousarray(ends), own, alpha, nx, ny)
    return np.stack([alpha, nx, ny], axis=1)


def test_caster_reads_what_pymunks_query_reads_bit_for_bit(scene):
    """From anywhere (inside walls, inside the teammate's disc too), each robot's rays."""
    world, robots, space, caster = scene
    sonar = Sonar(SonarConfig(rays=3), mount_radius=0.25)
    hits = 0
    for pose in random_poses(world, np.random.default_rng(11), 300):
        _starts, ends = sonar.ray_segments(pose)
        for own, robot in enumerate(robots):
            got = caster_hits(caster, pose[0], pose[1], ends, own)
            np.testing.assert_array_equal(got, pymunk_hits(space, pose[0], pose[1], ends,
                                                           robot.sensor_filter))
            hits += int(np.isfinite(got[:, 0]).sum())
    assert hits > 1000


def test_caster_on_arbitrary_segments_and_discs_reads_what_pymunk_reads():
    """Long diagonal segments across many cells, short ones, a ray's end past the grid."""
    rng = np.random.default_rng(4)
    a = rng.uniform(-12.0, 12.0, (60, 2))
    b = a + rng.normal(0.0, 4.0, (60, 2)) * rng.uniform(0.05, 1.5, (60, 1))
    segments = np.hstack([a, b])
    robots = [Robot(i, np.array([*rng.uniform(-8.0, 8.0, 2), 0.0]), RobotConfig())
              for i in range(2)]
    space = build_space(segments, robots)
    caster = caster_of(segments, robots)
    for _ in range(300):
        x, y = rng.uniform(-14.0, 14.0, 2)
        ang = rng.uniform(-math.pi, math.pi, 16)
        ends = np.stack([x + 9.0 * np.cos(ang), y + 9.0 * np.sin(ang)], axis=1)
        for own, robot in enumerate(robots):
            np.testing.assert_array_equal(caster_hits(caster, x, y, ends, own),
                                          pymunk_hits(space, x, y, ends, robot.sensor_filter))


def test_own_disc_is_not_seen_but_teammate_is(scene):
    world, robots, space, caster = scene
    sonar = Sonar(SonarConfig(rays=1, angles=(0.0,)), mount_radius=0.25)
    other = robots[1].true_pose()
    # stand 1 m behind the teammate, looking at it
    pose = np.array([other[0] - 1.0, other[1], 0.0])
    starts, ends = sonar.ray_segments(pose)
    ref, _ = cast_rays(starts, ends, world.segments, np.array([[other[0], other[1], 0.25]]))
    dist, _ = sonar.cast(caster, pose, 0)
    assert dist[0] > 0.1  # not the ray's own robot at alpha 0
    assert dist[0] == pytest.approx(ref[0] - 0.25, abs=1e-6)
    assert dist[0] == pytest.approx(1.0 - 0.25 - 0.25, abs=1e-6)
    own, _ = sonar.cast(caster, robots[0].true_pose(), 0)
    assert np.all(own > 0.1)


def test_reading_is_nearest_echo_clipped_and_noise_free_when_asked(scene):
    world, robots, space, caster = scene
    cfg = SonarConfig(noise_std=0.0, dropout_prob=0.0)
    sonar = Sonar(cfg, 0.25)
    pose = robots[0].true_pose()
    reading = sonar.measure(caster, pose, 0, np.random.default_rng(0))
    dist, _ = sonar.cast(caster, pose, 0)
    nearest = dist.reshape(8, 3).min(axis=1)
    expected = np.clip(np.where(np.isfinite(nearest), nearest, cfg.max_range), cfg.min_range,
                       cfg.max_range)
    np.testing.assert_allclose(reading, expected)
    assert (reading < cfg.max_range).any()
    assert sonar.fresh
    np.testing.assert_array_equal(sonar.last_pose, pose)


def test_steep_echoes_drop_out(scene):
    world, robots, space, caster = scene
    sonar = Sonar(SonarConfig(dropout_incidence=0.0, dropout_prob=1.0, noise_std=0.0), 0.25)
    pose = robots[0].true_pose()
    dist, cos_inc = sonar.cast(caster, pose, 0)
    reading = sonar.measure(caster, pose, 0, np.random.default_rng(0))
    straight = (cos_inc >= 1.0).reshape(8, 3).any(axis=1)
    assert np.all(reading[~straight] == sonar.cfg.max_range)


def test_measure_every_distance_keeps_the_last_scan(scene):
    world, robots, space, caster = scene
    sonar = Sonar(SonarConfig(measure_every=0.1), 0.25)
    rng = np.random.default_rng(0)
    pose = robots[0].true_pose()
    first = sonar.measure(caster, pose, 0, rng, travelled=0.0).copy()
    assert sonar.fresh
    again = sonar.measure(caster, pose, 0, rng, travelled=0.06)
    assert not sonar.fresh
    np.testing.assert_array_equal(again, first)
    sonar.measure(caster, pose, 0, rng, travelled=0.05)
    assert sonar.fresh


def test_a_world_without_walls_sees_only_the_teammate():
    robots = [Robot(i, np.array([2.0 * i, 0.0, 0.0]), RobotConfig()) for i in range(2)]
    caster = caster_of(np.zeros((0, 4)), robots)
    got = caster_hits(caster, 0.0, 0.0, np.array([[5.0, 0.0], [-5.0, 0.0]]), 0)
    assert got[0, 0] == pytest.approx((2.0 - 0.25) / 5.0) and np.isinf(got[1, 0])
