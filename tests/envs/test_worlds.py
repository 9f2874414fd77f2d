"""Worlds: procedural generation, tracing walls, loaders and their errors."""

import json
import math

import numpy as np
import pytest

from envs.explore.config import RobotConfig, WorldConfig
from envs.explore.robot import Robot, build_space
from envs.explore.worlds import (
    World,
    load_houseexpo_json,
    load_world,
    procedural_world,
    trace_segments,
)


def test_same_seed_same_building_other_seed_other_building():
    cfg = WorldConfig(size=(16.0, 12.0))
    a = procedural_world(cfg, np.random.default_rng(5))
    b = procedural_world(cfg, np.random.default_rng(5))
    c = procedural_world(cfg, np.random.default_rng(6))
    np.testing.assert_array_equal(a.free, b.free)
    np.testing.assert_array_equal(a.segments, b.segments)
    assert not np.array_equal(a.free, c.free)


@pytest.mark.parametrize("seed", range(4))
def test_procedural_world_is_one_connected_building(seed):
    world = procedural_world(WorldConfig(size=(20.0, 20.0)), np.random.default_rng(seed))
    # every room is reachable: almost all free space is in the drivable region's component
    assert world.reachable.sum() >= 0.97 * world.free.sum()
    assert world.free.mean() > 0.5
    x0, y0, x1, y1 = world.extent
    assert (x1 - x0, y1 - y0) == pytest.approx((20.0, 20.0))


def test_walls_lie_between_free_and_blocked_cells():
    world = procedural_world(WorldConfig(size=(12.0, 12.0)), np.random.default_rng(2))
    seg = world.segments
    # points along every segment sit at a free/blocked boundary (within one cell)
    t = np.linspace(0.0, 1.0, 7)[:, None, None]
    pts = (seg[None, :, :2] * (1 - t) + seg[None, :, 2:] * t).reshape(-1, 2)
    r = world.resolution
    for dx, dy in ((0, 0),):
        near_free = np.zeros(len(pts), bool)
        near_wall = np.zeros(len(pts), bool)
        for ox in (-r, 0, r):
            for oy in (-r, 0, r):
                f = world.is_free(pts + (ox + dx, oy + dy))
                near_free |= f
                near_wall |= ~f
        assert near_free.all() and near_wall.all()


def test_collinear_runs_are_merged_into_one_segment():
    free = np.zeros((20, 30), bool)
    free[2:18, 2:28] = True  # a plain rectangle room: exactly 4 walls
    segs = trace_segments(free, 0.1, (0.0, 0.0), 0.05)
    assert len(segs) == 4
    lengths = np.hypot(segs[:, 2] - segs[:, 0], segs[:, 3] - segs[:, 1])
    # contours cut cell corners by at most half a cell
    np.testing.assert_allclose(sorted(lengths), [1.6, 1.6, 2.6, 2.6], atol=0.05 * 2 ** 0.5)
    ends = segs[:, :2]
    on_edge = np.minimum.reduce([np.abs(ends[:, 0] - 0.2), np.abs(ends[:, 0] - 2.8),
                                 np.abs(ends[:, 1] - 0.2), np.abs(ends[:, 1] - 1.8)])
    assert on_edge.max() <= 0.05 + 1e-9


def test_physics_and_sonar_use_the_same_segments():
    world = procedural_world(WorldConfig(size=(10.0, 10.0)), np.random.default_rng(0))
    starts = world.sample_starts(np.random.default_rng(0), 0.45, 2.0)
    space = build_space(world.segments, [Robot(i, starts[i], RobotConfig()) for i in range(2)])
    walls = sorted((tuple(s.a), tuple(s.b)) for s in space.static_body.shapes)
    expected = sorted(((x0, y0), (x1, y1)) for x0, y0, x1, y1 in world.segments.tolist())
    assert walls == expected


def test_starts_are_drivable_apart_and_seeded():
    world = procedural_world(WorldConfig(size=(20.0, 20.0)), np.random.default_rng(1))
    for seed in range(10):
        poses = world.sample_starts(np.random.default_rng(seed), 0.45, 3.0)
        assert world.is_free(poses[:, :2]).all()
        ij = world.cell_of(poses[:, :2])
        assert world.drivable[ij[:, 0], ij[:, 1]].all()
        assert (world.clearance[ij[:, 0], ij[:, 1]] >= 0.45).all()
        assert math.dist(poses[0, :2], poses[1, :2]) >= 3.0
        np.testing.assert_array_equal(poses,
                                      world.sample_starts(np.random.default_rng(seed), 0.45, 3.0))


def test_spread_starts_are_deterministic_apart_and_refused_when_impossible():
    free = np.zeros((60, 60), bool)
    free[5:55, 5:55] = True  # a 5 m square room
    world = World.from_free_mask(free, 0.1)
    poses = world.spread_starts(0.45, 3.5, 4)  # only the corners of its 4 m start area work
    assert poses.shape == (4, 3) and (poses[:, 2] == 0).all()
    assert world.is_free(poses[:, :2]).all()
    gaps = [math.dist(a, b) for i, a in enumerate(poses[:, :2]) for b in poses[i + 1:, :2]]
    assert min(gaps) >= 3.5
    np.testing.assert_array_equal(poses, world.spread_starts(0.45, 3.5, 4))
    assert world.spread_starts(0.45, 3.5, 5) is None
    assert world.spread_starts(3.0, 0.5, 2) is None  # no cell with that clearance


def test_json_world_over_the_cell_limit_is_refused(tmp_path, monkeypatch):
    import envs.explore.worlds as worlds

    monkeypatch.setattr(worlds, "MAX_WORLD_CELLS", 1000)
    path = _write_json(tmp_path / "big.json", {"verts": [[0, 0], [8, 0], [8, 3], [0, 3]]})
    with pytest.raises(ValueError, match=r"world file '.*big.json' \(8.4 x 3.4 m at 0.1 m\) "
                                         r"needs \d+ cells, more than MAX_WORLD_CELLS = 1000"):
        load_world(WorldConfig(source=str(path)))


def _write_json(path, data):
    path.write_text(json.dumps(data))
    return path


def test_houseexpo_json_polygon_becomes_free_space(tmp_path):
    verts = [[0, 0], [8, 0], [8, 3], [3, 3], [3, 6], [0, 6]]  # an L: 8*3 + 3*3 = 33 m^2
    path = _write_json(tmp_path / "house.json", {"id": "x", "verts": verts, "bbox": {}})
    free, res, origin = load_houseexpo_json(path, 0.1)
    assert free.sum() * res ** 2 == pytest.approx(33.0, rel=0.03)
    world = load_world(WorldConfig(source=str(path)))
    assert world.reachable_area == pytest.approx(33.0, rel=0.03)
    assert world.is_free(np.array([[1.0, 5.0], [7.0, 1.0]])).all()
    assert not world.is_free(np.array([[6.0, 5.0]])).any()


def test_world_file_errors_name_the_problem(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        load_world(WorldConfig(source=str(tmp_path / "nope.json")))
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        load_world(WorldConfig(source=str(bad)))
    with pytest.raises(ValueError, match="'verts' key"):
        load_world(WorldConfig(source=str(_write_json(tmp_path / "a.json", {"v": []}))))
    with pytest.raises(ValueError, match="at least 3"):
        load_world(WorldConfig(source=str(_write_json(tmp_path / "b.json", {"verts": [[0, 0]]}))))
    tiny = _write_json(tmp_path / "tiny.json", {"verts": [[0, 0], [0.4, 0], [0.4, 0.4], [0, 0.4]]})
    with pytest.raises(ValueError, match="no free cell with 0.25 m clearance"):
        load_world(WorldConfig(source=str(tiny)))


def test_malformed_ros_map_names_the_file(tmp_path):
    bad = tmp_path / "broken.yaml"
    bad.write_text("image: missing.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n")
    with pytest.raises(ValueError, match="broken.yaml|missing.pgm"):
        load_world(WorldConfig(source=str(bad)))


def test_map_too_small_for_two_robots_is_an_error():
    free = np.zeros((20, 20), bool)
    free[5:15, 5:15] = True  # 1 m square room
    world = World.from_free_mask(free, 0.1)
    with pytest.raises(ValueError, match="too small for two robots"):
        world.sample_starts(np.random.default_rng(0), 0.3, 2.0)


def test_grid_without_free_space_is_an_error():
    with pytest.raises(ValueError, match="has no free cell"):
        World.from_free_mask(np.zeros((30, 30), bool), 0.1, name="solid")
