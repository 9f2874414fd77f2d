"""Submaps (``mapping.pose_graph``): patches add up to the robot's own grid, a known rigid
correction moves walls where it should, and the odometry variance of an edge."""

from __future__ import annotations

import math

import numpy as np
import pytest

from envs.explore.config import MappingConfig
from envs.explore.mapping import Geometry, RobotMap
from envs.explore.submaps import (
    SNAP_CELLS,
    Patch,
    PatchCache,
    RobotSubmaps,
    ScanSettings,
    compose,
    step_variance,
)
from fusion.rigid import Rigid2D
from topo.grid import CellState, SensorModel

ANGLES = np.radians([90, 50, 30, 10, -10, -30, -50, -90])


def _drive(n_steps: int, every: int):
    """A robot in a 6 m square room, driving along x and turning, anchoring every
    ``every`` scans; returns its map and submaps."""
    rmap = RobotMap((-5.0, -5.0, 5.0, 5.0), 0.1, SensorModel(usable_range=2.5))
    sub = RobotSubmaps(rmap.geometry)
    for k in range(n_steps):
        pose = np.array([-2.0 + 0.03 * k, 0.2 * math.sin(0.05 * k), 0.02 * k])
        if k % every == 0:
            sub.start_anchor(pose, pose, rmap.grid.log_odds)
        # ranges to the walls x = ±3, y = ±3 along each sonar's direction
        ang = pose[2] + ANGLES
        c, s = np.cos(ang), np.sin(ang)
        with np.errstate(divide="ignore"):
            tx = np.where(c > 0, (3 - pose[0]) / c, (-3 - pose[0]) / c)
            ty = np.where(s > 0, (3 - pose[1]) / s, (-3 - pose[1]) / s)
        ranges = np.minimum(np.minimum(np.abs(tx), np.abs(ty)), 5.0) - 0.2
        rmap.integrate(pose, ranges, ANGLES, 0.2, 5.0, math.radians(7.5))
        sub.add_scan(pose, ranges)
    return rmap, sub


def test_identity_corrections_give_the_robot_its_own_grid():
    rmap, sub = _drive(120, 25)
    patches = sub.all_patches(rmap.grid.log_odds)
    assert len(patches) == len(sub.poses) == 5
    lo = compose(patches, [Rigid2D.identity()] * len(patches), rmap.geometry, rmap.geometry)
    np.testing.assert_allclose(lo, rmap.grid.log_odds, atol=1e-5)
    np.testing.assert_array_equal(rmap.grid.model.classify(lo), rmap.states)


def test_a_known_rigid_correction_moves_walls_where_it_should():
    g = Geometry((-5.0, -5.0), 0.1, (100, 100))
    delta = np.zeros((3, 3))
    delta[1, 1] = 2.0  # one occupied cell at (2.05, 0.05): row 50, col 70
    patch = Patch(49, 69, delta)
    turn = Rigid2D(math.pi / 2, (0.0, 0.0))  # (2.05, 0.05) -> (-0.05, 2.05): row 70, col 49
    lo = compose([patch], [turn], g, g)
    states = SensorModel().classify(lo)
    assert np.argwhere(states == CellState.OCCUPIED).tolist() == [[70, 49]]
    shift = Rigid2D(0.0, (1.0, -0.5))  # 10 columns right, 5 rows down
    lo = compose([patch], [shift], g, Geometry((-4.0, -5.0), 0.1, (100, 100)))
    # into a grid whose origin is 1 m further right: the same column, 5 rows down
    assert np.argwhere(SensorModel().classify(lo) == CellState.OCCUPIED).tolist() == [[45, 70]]


def test_a_rigid_correction_moves_a_whole_map():
    rmap, sub = _drive(120, 25)
    patches = sub.all_patches(rmap.grid.log_odds)
    moved = Rigid2D(math.radians(30), (0.7, -0.4))
    lo = compose(patches, [moved] * len(patches), rmap.geometry, rmap.geometry)
    # the same nearest-cell resampling as OccupancyGrid.transformed, patch by patch
    expected = rmap.grid.transformed(moved)
    np.testing.assert_allclose(lo, expected.log_odds, atol=1e-5)
    np.testing.assert_array_equal(rmap.grid.model.classify(lo), expected.states())


def test_a_cached_patch_is_drawn_again_only_once_its_correction_moves_it():
    rmap, sub = _drive(120, 25)
    patches, g = sub.patches, rmap.geometry
    keys = [("robot", k) for k in range(len(patches))]
    cache = PatchCache()
    first = Rigid2D(math.radians(30), (0.7, -0.4))
    lo = compose(patches, [first] * len(patches), g, g, cache=cache, keys=keys)
    np.testing.assert_array_equal(lo, compose(patches, [first] * len(patches), g, g))
    # a nudge just under SNAP_CELLS: the kept drawings, not new ones (which differ)
    nudged = Rigid2D(first.theta, first.T + (0.9 * SNAP_CELLS * g.resolution, 0.0))
    again = compose(patches, [nudged] * len(patches), g, g, cache=cache, keys=keys)
    np.testing.assert_array_equal(again, lo)
    assert not np.array_equal(again, compose(patches, [nudged] * len(patches), g, g))
    # a cell's move: every patch drawn afresh; a patch without a key always is
    moved = Rigid2D(first.theta, first.T + (g.resolution, 0.0))
    fresh = compose(patches, [moved] * len(patches), g, g)
    np.testing.assert_array_equal(
        compose(patches, [moved] * len(patches), g, g, cache=cache, keys=keys), fresh)
    np.testing.assert_array_equal(
        compose(patches, [nudged] * len(patches), g, g, cache=cache,
                keys=[None] * len(patches)),
        compose(patches, [nudged] * len(patches), g, g))


def test_window_grid_rebuilds_the_scans():
    rmap, sub = _drive(120, 25)
    scan = ScanSettings(ANGLES, 0.2, 5.0, math.radians(7.5), rmap.grid.model)
    grid = sub.window_grid(0, 3, 0.1, scan)
    assert grid.occupied_mask().sum() >= 10 and grid.free_mask().sum() > 500
    assert sub.window_grid(4, 4, 0.1, scan) is not None


def test_compose_refuses_mismatched_input():
    g = Geometry((0.0, 0.0), 0.1, (10, 10))
    with pytest.raises(ValueError, match="patches and corrections must be as many, got 1 and 0"):
        compose([Patch(0, 0, np.ones((1, 1)))], [], g, g)
    with pytest.raises(ValueError, match="keys and patches must be as many, got 0 and 1"):
        compose([Patch(0, 0, np.ones((1, 1)))], [Rigid2D()], g, g, cache=PatchCache(), keys=[])
    with pytest.raises(ValueError, match="same resolution, got 0.1 and 0.2"):
        compose([], [], g, Geometry((0.0, 0.0), 0.2, (10, 10)))


def test_step_variance():
    a, b = np.zeros(3), np.array([0.1, 0.0, 0.05])
    assert step_variance(a, b, (0.0, 0.0), None) == (0.0, 0.0)
    pos, rot = step_variance(a, b, (0.02, 0.02), None)
    assert pos == pytest.approx((0.02 * 0.1) ** 2) and rot > 0
    pos, rot = step_variance(a, b, (0.0, 0.0), (0.05 ** 2, 0.01 ** 2, 0.03 ** 2, 0.01 ** 2))
    assert pos > 0 and rot > 0


@pytest.mark.parametrize(("field", "value", "match"), [
    ("pose_graph", 1, "mapping.pose_graph"),
    ("anchor_every", 5, "mapping.anchor_every must be >= 10, got 5"),
    ("window_anchors", 1, "mapping.window_anchors must be >= 2, got 1"),
    ("window_searches", 0, "mapping.window_searches must be >= 1, got 0"),
    ("anchor_every", 10.5, "mapping.anchor_every must be an integer"),
])
def test_bad_pose_graph_settings_are_named(field, value, match):
    with pytest.raises((TypeError, ValueError), match=match):
        MappingConfig(**{field: value})


def test_pose_graph_needs_merge_steps():
    with pytest.raises(ValueError, match="mapping.merge_every must be > 0 with it, got 0"):
        MappingConfig(pose_graph=True, merge_every=0)


def test_pose_graph_takes_any_merge_cadence():
    # the grid alignments' cadence must divide by merge_every only where grids are aligned
    assert MappingConfig(pose_graph=True, merge_every=7).merge_every == 7
    with pytest.raises(ValueError, match=r"mapping.grid_merge_every must be 0 or a multiple of "
                                         r"mapping.merge_every \(7\), got 100"):
        MappingConfig(merge_every=7)
