"""OccupancyGrid: the sonar inverse model, geometry round trips, combining grids, bad input."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from fusion import Rigid2D
from topo.grid import CellState, OccupancyGrid

BETA = math.radians(7.5)


def beam_row(g: OccupancyGrid, pose=(0.02, 0.03, 0.0), r=2.0):
    g.update(pose, [r], [0.0], 5.0, BETA)
    cy, cx = g.world_to_cell(pose[:2])[0]
    return g.states()[cy, cx:]


def test_wall_at_two_metres_one_beam():
    g = OccupancyGrid(0.1, (-5, -5, 5, 5))
    row = beam_row(g)
    d = (np.arange(len(row)) + 0.5) * 0.1  # cell-centre distance along the beam (approx.)
    assert (row[(d > 0.3) & (d < 1.9)] == CellState.FREE).all()
    assert (row[(d > 1.95) & (d < 2.1)] == CellState.OCCUPIED).any()
    assert (row[d > 2.2] == CellState.UNKNOWN).all()  # behind the wall
    # off the cone: the cells beside the beam stay unknown
    cy, cx = g.world_to_cell([0.02, 0.03])[0]
    assert (g.states()[cy + 8, cx:cx + 25] == CellState.UNKNOWN).all()


def test_max_range_beam_only_frees():
    g = OccupancyGrid(0.1, (-6, -6, 6, 6))
    g.update((0.02, 0.03, math.pi / 2), [5.0], [0.0], 5.0, BETA)
    assert not g.occupied_mask().any()
    cy, cx = g.world_to_cell([0.02, 0.03])[0]
    col = g.states()[cy:, cx]
    assert (col[5:48] == CellState.FREE).all() and (col[52:] == CellState.UNKNOWN).all()


def test_repeated_evidence_saturates_and_flips():
    g = OccupancyGrid(0.1, (-3, -3, 3, 3))
    for _ in range(50):
        g.update((0.02, 0.03, 0.0), [1.0], [0.0], 5.0, BETA)
    assert g.log_odds.max() == pytest.approx(g.model.clamp)
    assert g.log_odds.min() == pytest.approx(-g.model.clamp)
    for _ in range(50):  # the obstacle moved away: the same cells become free
        g.update((0.02, 0.03, 0.0), [2.5], [0.0], 5.0, BETA)
    cy, cx = g.world_to_cell([1.0, 0.03])[0]
    assert g.states()[cy, cx] == CellState.FREE


def test_readings_off_the_grid_are_ignored():
    g = OccupancyGrid(0.1, (0, 0, 1, 1))
    g.update((0.5, 0.5, 0.0), [3.0, 5.0], [0.0, math.pi], 5.0, BETA)
    assert g.known_mask().sum() > 0 and g.shape == (10, 10)


@given(st.lists(st.tuples(st.floats(-20, 20), st.floats(-20, 20)), min_size=1, max_size=20))
def test_world_cell_round_trip(points):
    g = OccupancyGrid(0.1, (-20.0, -15.0, 25.0, 30.0))
    cells = g.world_to_cell(np.array(points))
    centres = g.cell_to_world(cells)
    assert np.all(np.abs(centres - np.array(points)) <= 0.05 + 1e-9)
    np.testing.assert_array_equal(g.world_to_cell(centres), cells)


def test_states_are_one_table_and_image_matches():
    g = OccupancyGrid(0.1, (-3, -3, 3, 3))
    g.update((0.0, 0.0, 0.0), [1.5], [0.0], 5.0, BETA)
    img = g.to_image()
    s = g.states()
    assert set(np.unique(img[s == CellState.FREE])) == {255}
    assert set(np.unique(img[s == CellState.OCCUPIED])) == {0}
    assert set(np.unique(img[s == CellState.UNKNOWN])) == {128}
    assert g.coverage_m2() == pytest.approx(g.known_mask().sum() * 0.01)
    with pytest.raises(ValueError):
        s[0, 0] = 1  # read-only view


def test_transformed_and_union():
    a = OccupancyGrid(0.1, (-6, -6, 6, 6))
    b = a.empty_like()
    b.update((0.0, 0.0, 0.0), [3.0], [0.0], 5.0, BETA)
    t = Rigid2D.from_degrees(90.0, (0.0, 0.0))
    moved = b.transformed(t, into=a)
    # the beam along +x in B lies along +y once moved
    cy, cx = moved.world_to_cell([0.0, 2.0])[0]
    assert moved.states()[cy, cx] == CellState.FREE
    cy, cx = moved.world_to_cell([2.0, 0.0])[0]
    assert moved.states()[cy, cx] == CellState.UNKNOWN
    a.update((0.0, 0.0, 0.0), [3.0], [math.pi], 5.0, BETA)
    both = a.union(moved)
    assert both.coverage_m2() == pytest.approx(a.coverage_m2() + moved.coverage_m2(), rel=0.05)
    with pytest.raises(ValueError, match="same geometry"):
        a.union(OccupancyGrid(0.2, (-6, -6, 6, 6)))


def test_copy_and_reset_are_independent():
    g = OccupancyGrid(0.1, (-3, -3, 3, 3))
    g.update((0.0, 0.0, 0.0), [1.0], [0.0], 5.0, BETA)
    c = g.copy()
    g.reset()
    assert g.coverage_m2() == 0 and c.coverage_m2() > 0


@pytest.mark.parametrize(
    ("call", "error", "match"),
    [
        (lambda g: g.update((0, np.nan, 0), [1.0], [0.0], 5.0, BETA), ValueError,
         r"pose must be finite, got \[0.0, nan, 0.0\]"),
        (lambda g: g.update((0, 0), [1.0], [0.0], 5.0, BETA), ValueError,
         r"pose must be \(x, y, theta\)"),
        (lambda g: g.update((0, 0, 0), [-1.0], [0.0], 5.0, BETA), ValueError,
         r"ranges must be finite and >= 0, got \[-1.0\]"),
        (lambda g: g.update((0, 0, 0), [np.nan], [0.0], 5.0, BETA), ValueError,
         "ranges must be finite"),
        (lambda g: g.update((0, 0, 0), [1.0, 2.0], [0.0], 5.0, BETA), ValueError,
         "ranges and sensor_angles must have the same length, got 2 and 1"),
        (lambda g: g.update((0, 0, 0), [1.0], [0.0], 0.0, BETA), ValueError,
         "max_range must be > 0.0, got 0.0"),
        (lambda g: g.update((0, 0, 0), [1.0], [0.0], 5.0, 2.0), ValueError,
         r"cone_half_width must be <= 1.5707"),
    ],
)
def test_bad_scans(call, error, match):
    with pytest.raises(error, match=match):
        call(OccupancyGrid(0.1, (-2, -2, 2, 2)))


def test_bad_geometry():
    with pytest.raises(ValueError, match="resolution must be > 0.0, got 0.0"):
        OccupancyGrid(0.0)
    with pytest.raises(ValueError, match="resolution must be > 0.0, got -0.1"):
        OccupancyGrid(-0.1)
    with pytest.raises(ValueError, match=r"extent must be \(xmin, ymin, xmax, ymax\)"):
        OccupancyGrid(0.1, (0, 0, 1))
    with pytest.raises(ValueError, match="extent must span at least one cell"):
        OccupancyGrid(0.1, (0, 0, 1, 0))
