"""The pymunk sonar against a slow numpy caster, and the sensor model's rules."""

import math
import platform
import sys

import numpy as np
import pytest
from raycast_reference import cast_rays

from envs.two_robot_explore import _chipmunk
from envs.two_robot_explore import sonar as sonar_module
from envs.two_robot_explore.config import RobotConfig, SonarConfig, WorldConfig
from envs.two_robot_explore.robot import Robot, build_space
from envs.two_robot_explore.sonar import Sonar
from envs.two_robot_explore.worlds import procedural_world


@pytest.fixture(scope="module")
def scene():
    world = procedural_world(WorldConfig(size=(14.0, 12.0)), np.random.default_rng(7))
    starts = world.sample_starts(np.random.default_rng(1), 0.45, 1.0)
    robots = [Robot(i, starts[i], RobotConfig()) for i in range(2)]
    space = build_space(world.segments, robots)
    return world, robots, space


def test_pymunk_rays_agree_with_numpy_reference(scene):
    world, robots, space = scene
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
        dist, cos_inc = sonar.cast(space, pose, robots[0].sensor_filter)
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


def _cast_public(sonar, space, pose, shape_filter):
    """What ``Sonar.cast`` computes, through pymunk's public ``Space.segment_query_first``."""
    starts, ends = sonar.ray_segments(pose)
    dist, cos_inc = [], []
    for a, b in zip(starts.tolist(), ends.tolist(), strict=True):
        hit = space.segment_query_first(a, b, 0.0, shape_filter)
        if hit is None:
            dist.append(math.inf)
            cos_inc.append(1.0)
        else:
            length = math.dist(a, b)
            dist.append(hit.alpha * length - sonar.mount_radius)
            cos_inc.append(abs(hit.normal.x * (b[0] - a[0]) + hit.normal.y * (b[1] - a[1]))
                           / length)
    return np.array(dist), np.array(cos_inc)


def test_compiled_casts_are_used_where_the_calling_convention_allows():
    """Linux and macOS on x86-64 / ARM64 (CI's platform among them) cast scans compiled."""
    if sys.platform.startswith(("linux", "darwin")) and platform.machine().lower() in (
            "x86_64", "amd64", "aarch64", "arm64"):
        assert _chipmunk.AVAILABLE and sonar_module._COMPILED
        assert _chipmunk.usable()  # its check against pymunk's binding passes
    else:
        assert not _chipmunk.AVAILABLE and not _chipmunk.usable()


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "cffi-loop"])
def test_direct_chipmunk_casts_equal_pymunks_public_query(scene, monkeypatch, compiled):
    """The casts call chipmunk directly (a compiled loop, or a Python loop through pymunk's
    binding); ``Space.segment_query_first`` must give the same echoes, from inside walls, past
    the teammate, anywhere."""
    if compiled and not _chipmunk.AVAILABLE:
        pytest.skip("no compiled casts on this platform")
    monkeypatch.setattr(sonar_module, "_COMPILED", compiled)
    world, robots, space = scene
    sonar = Sonar(SonarConfig(rays=3), mount_radius=0.25)
    rng = np.random.default_rng(11)
    lo = np.array(world.origin)
    hi = lo + np.array(world.shape[::-1]) * world.resolution
    hits = 0
    for _ in range(300):
        pose = np.array([*rng.uniform(lo, hi), rng.uniform(-math.pi, math.pi)])
        for robot in robots:
            dist, cos_inc = sonar.cast(space, pose, robot.sensor_filter)
            ref_dist, ref_cos = _cast_public(sonar, space, pose, robot.sensor_filter)
            np.testing.assert_array_equal(np.isinf(dist), np.isinf(ref_dist))
            np.testing.assert_allclose(dist, ref_dist, rtol=0, atol=1e-12)
            np.testing.assert_allclose(cos_inc, ref_cos, rtol=0, atol=1e-12)
            hits += int(np.isfinite(dist).sum())
    assert hits > 1000


@pytest.mark.skipif(not _chipmunk.AVAILABLE, reason="no compiled casts on this platform")
def test_compiled_casts_are_the_cffi_loops_bit_for_bit(scene, monkeypatch):
    world, robots, space = scene
    sonar = Sonar(SonarConfig(rays=4), mount_radius=0.25)
    rng = np.random.default_rng(5)
    lo = np.array(world.origin)
    hi = lo + np.array(world.shape[::-1]) * world.resolution
    for _ in range(200):
        pose = np.array([*rng.uniform(lo, hi), rng.uniform(-math.pi, math.pi)])
        for robot in robots:
            monkeypatch.setattr(sonar_module, "_COMPILED", True)
            got = [a.copy() for a in sonar._cast(space, pose, robot.sensor_filter)]
            monkeypatch.setattr(sonar_module, "_COMPILED", False)
            want = sonar._cast(space, pose, robot.sensor_filter)
            for g, w in zip(got, want, strict=True):
                np.testing.assert_array_equal(g, w)


def test_own_disc_is_not_seen_but_teammate_is(scene):
    world, robots, space = scene
    sonar = Sonar(SonarConfig(rays=1, angles=(0.0,)), mount_radius=0.25)
    other = robots[1].true_pose()
    # stand 1 m behind the teammate, looking at it
    pose = np.array([other[0] - 1.0, other[1], 0.0])
    starts, ends = sonar.ray_segments(pose)
    ref, _ = cast_rays(starts, ends, world.segments, np.array([[other[0], other[1], 0.25]]))
    dist, _ = sonar.cast(space, pose, robots[0].sensor_filter)
    assert dist[0] > 0.1  # not the ray's own robot at alpha 0
    assert dist[0] == pytest.approx(ref[0] - 0.25, abs=1e-6)
    assert dist[0] == pytest.approx(1.0 - 0.25 - 0.25, abs=1e-6)
    own, _ = sonar.cast(space, robots[0].true_pose(), robots[0].sensor_filter)
    assert np.all(own > 0.1)


def test_reading_is_nearest_echo_clipped_and_noise_free_when_asked(scene):
    world, robots, space = scene
    cfg = SonarConfig(noise_std=0.0, dropout_prob=0.0)
    sonar = Sonar(cfg, 0.25)
    pose = robots[0].true_pose()
    reading = sonar.measure(space, pose, robots[0].sensor_filter, np.random.default_rng(0))
    dist, _ = sonar.cast(space, pose, robots[0].sensor_filter)
    nearest = dist.reshape(8, 3).min(axis=1)
    expected = np.clip(np.where(np.isfinite(nearest), nearest, cfg.max_range), cfg.min_range,
                       cfg.max_range)
    np.testing.assert_allclose(reading, expected)
    assert (reading < cfg.max_range).any()
    assert sonar.fresh
    np.testing.assert_array_equal(sonar.last_pose, pose)


def test_steep_echoes_drop_out(scene):
    world, robots, space = scene
    sonar = Sonar(SonarConfig(dropout_incidence=0.0, dropout_prob=1.0, noise_std=0.0), 0.25)
    pose = robots[0].true_pose()
    dist, cos_inc = sonar.cast(space, pose, robots[0].sensor_filter)
    reading = sonar.measure(space, pose, robots[0].sensor_filter, np.random.default_rng(0))
    straight = (cos_inc >= 1.0).reshape(8, 3).any(axis=1)
    assert np.all(reading[~straight] == sonar.cfg.max_range)


def test_measure_every_distance_keeps_the_last_scan(scene):
    world, robots, space = scene
    sonar = Sonar(SonarConfig(measure_every=0.1), 0.25)
    rng = np.random.default_rng(0)
    pose = robots[0].true_pose()
    first = sonar.measure(space, pose, robots[0].sensor_filter, rng, travelled=0.0).copy()
    assert sonar.fresh
    again = sonar.measure(space, pose, robots[0].sensor_filter, rng, travelled=0.06)
    assert not sonar.fresh
    np.testing.assert_array_equal(again, first)
    sonar.measure(space, pose, robots[0].sensor_filter, rng, travelled=0.05)
    assert sonar.fresh
