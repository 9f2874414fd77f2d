"""fusion.inputs: every fusion entry point refuses malformed input, and work beyond its bounds,
with an error naming the argument, before it allocates; odd input never hangs."""

import contextlib
import faulthandler
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fusion import exhaustive_search, icp_svd, merge_maps, similarity
from fusion.evaluation.pairs import GridSnapshot
from fusion.grid_merge import GridMergeConfig, GridMergeResult, merge_grids
from fusion.hybrid import HybridResult, hybrid_merge
from fusion.inputs import MAX_NODES, MAX_POINTS, MAX_ROTATIONS
from fusion.rigid import Rigid2D
from topo import OccupancyGrid, TopoMap

TINY = TopoMap.from_arrays([[0, 0], [1, 0]], [[0, 1]])


def room(res: float = 0.1) -> GridSnapshot:
    s = np.zeros((40, 40), np.int8)
    s[5:35, 5:35] = 2
    s[6:34, 6:34] = 1
    return GridSnapshot(s, res, (0.0, 0.0))


@contextlib.contextmanager
def hard_timeout(seconds: float):
    """Abort the whole test run (with every thread's traceback) if the block hangs: works even
    inside compiled code, which a Python signal handler cannot interrupt."""
    faulthandler.dump_traceback_later(seconds, exit=True)
    try:
        yield
    finally:
        faulthandler.cancel_dump_traceback_later()


BAD_GRIDS = [
    (None, TypeError, r"grid_b must be an occupancy grid .*got NoneType"),
    (np.zeros((5, 5), np.int8), TypeError, r"grid_b must be an occupancy grid .*got ndarray"),
    (GridSnapshot(room().states, 0.0, (0.0, 0.0)), ValueError,
     r"grid_b.resolution must be > 0.0, got 0.0"),
    (GridSnapshot(room().states, -0.1, (0.0, 0.0)), ValueError,
     r"grid_b.resolution must be > 0.0, got -0.1"),
    (GridSnapshot(room().states, float("nan"), (0.0, 0.0)), ValueError,
     r"grid_b.resolution must be finite, got nan"),
    (GridSnapshot(room().states, None, (0.0, 0.0)), TypeError,
     r"grid_b.resolution must be a real number, got NoneType"),
    (GridSnapshot(room().states, 0.1, (0.0,)), ValueError,
     r"grid_b.origin must be two finite numbers \(x, y\), got \[0.0\]"),
    (GridSnapshot(room().states, 0.1, (0.0, float("inf"))), ValueError,
     r"grid_b.origin must be two finite numbers"),
    (GridSnapshot(np.zeros((4, 4, 2), np.int8), 0.1, (0.0, 0.0)), ValueError,
     r"grid_b.states must be a 2-D array \[iy, ix\], got shape \(4, 4, 2\)"),
    (GridSnapshot(np.zeros((4, 4)), 0.1, (0.0, 0.0)), TypeError,
     r"grid_b.states must be integer cell-state codes, got dtype float64"),
    (GridSnapshot(np.full((4, 4), 7, np.int8), 0.1, (0.0, 0.0)), ValueError,
     r"grid_b.states must hold topo.CellState codes \[0, 1, 2\], got 7"),
]


@pytest.mark.parametrize(("grid", "exc", "match"), BAD_GRIDS)
def test_merge_grids_names_a_malformed_grid(grid, exc, match):
    with hard_timeout(60), pytest.raises(exc, match=match):
        merge_grids(room(), grid)


@pytest.mark.parametrize(("grid", "exc", "match"), BAD_GRIDS[:4])
def test_hybrid_merge_names_a_malformed_grid_even_without_try_grids(grid, exc, match):
    with pytest.raises(exc, match=match):
        hybrid_merge(TINY, TINY, room(), grid, try_grids=False)


def test_hybrid_merge_needs_both_grids():
    with pytest.raises(TypeError, match=r"grid_a must be an occupancy grid .*got NoneType"):
        hybrid_merge(TINY, TINY, None, None, try_grids=False)


def test_a_config_that_is_not_a_grid_merge_config_is_named():
    with pytest.raises(TypeError, match=r"config must be a fusion.grid_merge.GridMergeConfig or "
                                        r"None, got dict"):
        merge_grids(room(), room(), {"resolution": 0.2})


def test_work_beyond_the_bounds_is_refused_at_once():
    with pytest.raises(ValueError, match=rf"config.step_deg=0.01 asks for 36,000 rotations, "
                                         rf"above MAX_ROTATIONS={MAX_ROTATIONS:,}: give "
                                         rf"step_deg >= 0.1"):
        merge_grids(room(), room(), GridMergeConfig(step_deg=0.01))
    with pytest.raises(ValueError, match=r"grid_a: 40 × 40 cells of 0.1 m pool to about "
                                         r"[\d,]+ cells of config.resolution=1e-05 m, above "
                                         r"MAX_POOLED_CELLS"):
        merge_grids(room(), room(), GridMergeConfig(resolution=1e-5))
    huge = GridSnapshot(room().states, 1e6, (0.0, 0.0))
    with pytest.raises(ValueError, match="grid_b: 40 × 40 cells of 1e\\+06 m pool"):
        merge_grids(room(), huge)


def test_occupancy_grids_and_empty_grids_still_merge_or_are_rejected():
    g = OccupancyGrid(resolution=0.1, extent=(0.0, 0.0, 4.0, 4.0))
    res = merge_grids(g, g)
    assert not res.accepted and res.reason == "a grid has no known cells"
    empty = GridSnapshot(np.zeros((0, 0), np.int8), 0.1, (0.0, 0.0))
    assert merge_grids(empty, room()).reason == "a grid has no known cells"


def test_merge_maps_refuses_maps_beyond_max_nodes():
    xy = np.column_stack([np.arange(MAX_NODES + 1.0), np.zeros(MAX_NODES + 1)])
    big = TopoMap.from_arrays(xy, np.empty((0, 2), np.int64))
    with pytest.raises(ValueError, match=rf"map_b has {MAX_NODES + 1:,} nodes, above "
                                         rf"MAX_NODES={MAX_NODES:,}"):
        merge_maps(TINY, big)


def test_point_sets_beyond_max_points_are_refused():
    many = np.zeros((MAX_POINTS + 1, 2))
    few = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 2.0]])
    with pytest.raises(ValueError, match=rf"D has {MAX_POINTS + 1:,} points, above MAX_POINTS"):
        icp_svd(few, many)
    with pytest.raises(ValueError, match=r"map_a has [\d,]+ points, above MAX_POINTS"):
        similarity(many, few, Rigid2D.identity())
    with pytest.raises(ValueError, match=r"map_b has [\d,]+ points, above MAX_POINTS"):
        exhaustive_search(few, many, max_evaluations=None)


ODD_FLOATS = st.one_of(st.sampled_from([0.0, -0.1, float("nan"), float("inf"), 1e-9, 1e9]),
                       st.floats(0.01, 1.0))
ODD_STATES = st.one_of(
    st.tuples(st.integers(0, 30), st.integers(0, 30)).flatmap(
        lambda hw: st.lists(st.integers(-1, 3), min_size=hw[0] * hw[1],
                            max_size=hw[0] * hw[1]).map(
            lambda v, hw=hw: np.array(v, np.int8).reshape(hw))),
    st.sampled_from([np.zeros((3, 3, 3), np.int8), np.ones((4, 4)), np.ones(5, np.int8),
                     np.ones((6, 6), bool), np.int8(1)]),
)
ODD_GRIDS = st.one_of(
    st.none(), st.just(SimpleNamespace(resolution=0.1)),
    st.builds(lambda s, r, o: GridSnapshot(s, r, o), ODD_STATES, ODD_FLOATS,
              st.sampled_from([(0.0, 0.0), (1.5, -2.0), (float("nan"), 0.0), (0.0,), "xy"])),
)
ODD_MAPS = st.sampled_from([
    TINY, TopoMap.empty(), None, "map",
    TopoMap.from_arrays([[0, 0], [2, 0], [2, 2], [0, 2]], [[0, 1], [1, 2], [2, 3]]),
    TopoMap.from_arrays([[0, 0], [1, 0], [2, 0], [3, 0]], [[0, 1], [1, 2], [2, 3]]),
])


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(ODD_GRIDS, ODD_GRIDS)
def test_odd_grids_give_a_result_or_a_named_error_never_a_hang(grid_a, grid_b):
    with hard_timeout(120):
        try:
            res = merge_grids(grid_a, grid_b)
        except (TypeError, ValueError) as exc:
            assert "grid_a" in str(exc) or "grid_b" in str(exc)
        else:
            assert isinstance(res, GridMergeResult)


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(ODD_MAPS, ODD_MAPS, ODD_GRIDS, st.booleans())
def test_odd_hybrid_inputs_give_a_result_or_a_named_error(map_a, map_b, grid_b, try_grids):
    with hard_timeout(120):
        try:
            res = hybrid_merge(map_a, map_b, room(), grid_b, try_grids=try_grids)
        except (TypeError, ValueError) as exc:
            assert any(name in str(exc) for name in ("map_a", "map_b", "grid_b"))
        else:
            assert isinstance(res, HybridResult)
