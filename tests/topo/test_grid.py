"""OccupancyGrid: the sonar inverse model, geometry round trips, combining grids, bad input."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from motion import Motion

from topo.grid import CellState, OccupancyGrid, SensorModel

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


def test_readings_beyond_the_usable_range_only_free_up_to_it():
    """An echo at 3 m with a 2 m usable range: free to 2 m, no wall, unknown beyond; an echo
    within the usable range is drawn as without one."""
    g = OccupancyGrid(0.1, (-5, -5, 5, 5), SensorModel(usable_range=2.0))
    row = beam_row(g, r=3.0)
    d = (np.arange(len(row)) + 0.5) * 0.1
    assert not g.occupied_mask().any()
    assert (row[(d > 0.3) & (d < 1.9)] == CellState.FREE).all()
    assert (row[d > 2.1] == CellState.UNKNOWN).all()
    near = OccupancyGrid(0.1, (-5, -5, 5, 5), SensorModel(usable_range=2.0))
    full = OccupancyGrid(0.1, (-5, -5, 5, 5))
    np.testing.assert_array_equal(beam_row(near, r=1.5), beam_row(full, r=1.5))


@pytest.mark.parametrize("kwargs, error, match", [
    ({"l_free": 0.4}, ValueError, "l_free must be < 0.0, got 0.4"),
    ({"threshold": 4.0}, ValueError, "threshold must be < 4.0, got 4.0"),
    ({"usable_range": 0}, ValueError, "usable_range must be > 0.0, got 0.0"),
    ({"usable_range": "far"}, TypeError, "usable_range must be a real number, got str"),
])
def test_bad_sensor_models_name_the_field(kwargs, error, match):
    with pytest.raises(error, match=match):
        SensorModel(**kwargs)


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
    t = Motion(math.pi / 2)
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


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda g: g.update({"x": 0}, [1.0], [0.0], 5.0, BETA), "pose must be a numeric array"),
        (lambda g: g.update(("a", "b", "c"), [1.0], [0.0], 5.0, BETA),
         "pose must be a numeric array"),
        (lambda g: g.update((0, 0, 0), ["far"], [0.0], 5.0, BETA),
         "ranges must be a numeric array"),
        (lambda g: g.update((0, 0, 0), [[1.0], [2.0]], [0.0, 1.0], 5.0, BETA),
         r"ranges must be a 1-D array \(K,\), got shape \(2, 1\)"),
        (lambda g: g.update((0, 0, 0), [1.0], None, 5.0, BETA),
         "sensor_angles must be a numeric array"),
        (lambda g: g.update((0, 0, 0), [1.0], [np.inf], 5.0, BETA),
         "sensor_angles must be finite"),
        (lambda g: g.update((0, 0, 0), [1.0], [0.0], float("nan"), BETA),
         "max_range must be finite"),
    ],
)
def test_bad_scans_name_the_argument(call, match):
    with pytest.raises(ValueError, match=match):
        call(OccupancyGrid(0.1, (-2, -2, 2, 2)))


def test_bad_extent_and_combining_arguments():
    with pytest.raises(ValueError, match=r"extent must be \(xmin, ymin, xmax, ymax\), got None"):
        OccupancyGrid(0.1, None)
    with pytest.raises(TypeError, match=r"extent\[1\] must be a real number"):
        OccupancyGrid(0.1, (0, "y", 1, 1))
    g = OccupancyGrid(0.1, (-2, -2, 2, 2))
    with pytest.raises(TypeError, match="rigid must have apply"):
        g.transformed((0.0, 0.0, 0.0))
    with pytest.raises(TypeError, match="into must be an OccupancyGrid"):
        g.transformed(Motion(), into=np.zeros((40, 40)))
    with pytest.raises(TypeError, match="other must be an OccupancyGrid"):
        g.union(np.zeros((40, 40)))


def reference_update(g: OccupancyGrid, pose, ranges, angles, max_range, beta) -> None:
    """The inverse model the slow obvious way: every cell of the grid, beam after beam."""
    m = g.model
    half = (m.hit_width or g.resolution) / 2.0
    h, w = g.shape
    xs = g.origin[0] + (np.arange(w) + 0.5) * g.resolution
    ys = g.origin[1] + (np.arange(h) + 0.5) * g.resolution
    dx, dy = xs[None, :] - pose[0], ys[:, None] - pose[1]
    dist = np.sqrt(dx * dx + dy * dy)
    usable = m.usable_range or math.inf
    for r, a in zip(ranges, angles, strict=True):
        ax = pose[2] + a
        inside = np.cos(ax) * dx + np.sin(ax) * dy >= np.cos(beta) * dist
        echo = r < max_range and r <= usable
        free = inside & (dist < (r - half if echo else min(max_range, usable)))
        hit = inside & ~free & echo & (np.abs(dist - r) <= half)
        delta = np.where(free, m.l_free, np.where(hit, m.l_occupied, 0.0))
        touched = free | hit
        new = np.clip(g.log_odds.astype(np.float64) + delta, -m.clamp, m.clamp)
        g.log_odds[touched] = new[touched]


@settings(max_examples=40, deadline=None)
@given(st.floats(-2.5, 2.5), st.floats(-2.5, 2.5), st.floats(-4.0, 4.0),
       st.lists(st.tuples(st.floats(0.0, 6.0), st.floats(-np.pi, np.pi)), min_size=1,
                max_size=8),
       st.floats(0.01, np.pi / 2), st.one_of(st.none(), st.floats(0.1, 6.0)))
def test_compiled_update_matches_the_slow_reference(x, y, theta, beams, beta, usable):
    """Same model whatever the pose, ranges (including no-echo ones and ones beyond the usable
    range), cone width (up to the 90° the model allows: the compiled loop skips the cells
    outside the cone's edges), and cells off the grid (the grid is smaller than the sonar's
    reach)."""
    ranges = [r for r, _ in beams]
    angles = [a for _, a in beams]
    fast = OccupancyGrid(0.1, (-3.0, -2.0, 3.0, 2.5), SensorModel(usable_range=usable))
    slow = fast.copy()
    for _ in range(2):  # twice: the second scan starts from non-zero log-odds
        fast.update((x, y, theta), ranges, angles, 5.0, beta)
        reference_update(slow, (x, y, theta), ranges, angles, 5.0, beta)
    np.testing.assert_allclose(fast.log_odds, slow.log_odds, atol=1e-5)
    np.testing.assert_array_equal(fast.states(), slow._classify(slow.log_odds))


@given(st.integers(0, 2**32 - 1))
def test_update_valid_is_update_without_the_checks(seed):
    rng = np.random.default_rng(seed)
    a = OccupancyGrid(0.1, (-4.0, -4.0, 4.0, 4.0))
    b = OccupancyGrid(0.1, (-4.0, -4.0, 4.0, 4.0))
    angles = np.radians([-90.0, -50, -30, -10, 10, 30, 50, 90])
    for _ in range(5):
        pose = np.array([*rng.uniform(-2, 2, 2), rng.uniform(-math.pi, math.pi)])
        ranges = rng.uniform(0.0, 6.0, 8)
        a.update(pose, ranges, angles, 5.0, math.radians(7.5))
        b.update_valid(pose, ranges, angles, 5.0, math.radians(7.5))
    np.testing.assert_array_equal(a.log_odds, b.log_odds)
    np.testing.assert_array_equal(a.states(), b.states())


def test_assign_replaces_the_evidence_clamped_and_keeps_state_views():
    grid = OccupancyGrid(0.1, (0.0, 0.0, 1.0, 1.0))
    view = grid.states()
    values = np.zeros(grid.shape)
    values[0, 0], values[1, 1], values[2, 2] = 10.0, -10.0, 0.1
    grid.assign(values)
    clamp = grid.model.clamp
    assert grid.log_odds[0, 0] == clamp and grid.log_odds[1, 1] == -clamp
    assert view[0, 0] == CellState.OCCUPIED and view[1, 1] == CellState.FREE
    assert view[2, 2] == CellState.UNKNOWN
    with pytest.raises(ValueError, match=r"log_odds must have the grid's shape \(10, 10\), "
                                         r"got \(3, 3\)"):
        grid.assign(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="log_odds must be finite"):
        grid.assign(np.full(grid.shape, np.nan))
