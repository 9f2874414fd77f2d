"""fusion.evaluation.repeatability: node repeatability of a map pair against its true transform."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fusion.evaluation.pairs import GridSnapshot
from fusion.evaluation.repeatability import in_region, node_repeatability, shared_region
from fusion.rigid import Rigid2D
from topo.graph import TopoMap
from topo.grid import CellState

RES = 0.1
NODES = np.array([[1.0, 1.0], [3.0, 1.5], [2.0, 3.0], [4.0, 4.0], [1.5, 4.2]])


def grid(shape=(50, 50), origin=(0.0, 0.0), known=None) -> GridSnapshot:
    """A 5 × 5 m grid, free where ``known`` (default everywhere), unknown elsewhere."""
    states = np.full(shape, CellState.UNKNOWN, dtype=np.int8)
    states[np.ones(shape, bool) if known is None else known] = CellState.FREE
    return GridSnapshot(states, RES, origin)


def topomap(xy, frontier=None) -> TopoMap:
    return TopoMap.from_arrays(np.asarray(xy, dtype=float), frontier=frontier)


def test_a_map_repeats_itself():
    rep = node_repeatability(topomap(NODES), topomap(NODES), grid(), grid(), Rigid2D())
    np.testing.assert_allclose(rep.repeatability, [1.0, 1.0])
    assert rep.nodes_a == rep.nodes_b == rep.mutual == len(NODES)
    np.testing.assert_array_equal(rep.hits, [[5, 5], [5, 5]])
    assert rep.region_m2 == pytest.approx(float(shared_region(grid(), grid(), Rigid2D()).sum())
                                          * RES * RES)


def test_radii_separate_near_and_far_nodes():
    near = NODES[:3]  # well inside the region, and 0.7 m further
    rep = node_repeatability(topomap(near), topomap(near + [0.7, 0.0]), grid(), grid(),
                             Rigid2D())
    assert rep.repeatability[0] == 0.0 and rep.repeatability[1] == 1.0
    assert rep.mutual == 0
    # a node of the other map just outside the shared region (x ≥ 4.7 m) is still its node
    # there: it repeats A's, though only A's side has a region node to count
    edge = node_repeatability(topomap(NODES[3:4]), topomap(NODES[3:4] + [0.7, 0.0]), grid(),
                              grid(), Rigid2D())
    assert (edge.nodes_a, edge.nodes_b) == (1, 0)
    np.testing.assert_array_equal(edge.repeatability, [0.0, 1.0])
    np.testing.assert_array_equal(edge.hits, [[0, 0], [1, 0]])
    pair = node_repeatability(topomap([[4.5, 4.5]]), topomap([[4.8, 4.5]]), grid(), grid(),
                              Rigid2D())
    assert pair.mutual == 1 and pair.nodes_b == 0  # one node of the pair in the region
    # nodes outside the region on both sides count for nothing
    out = node_repeatability(topomap([[4.8, 4.8]]), topomap([[4.8, 4.8]]), grid(), grid(),
                             Rigid2D())
    assert out.nodes == 0 and out.mutual == 0 and np.isnan(out.repeatability).all()


@settings(max_examples=25, deadline=None)
@given(theta=st.floats(-math.pi, math.pi), tx=st.floats(-20, 20), ty=st.floats(-20, 20))
def test_repeatability_does_not_depend_on_the_frames(theta, tx, ty):
    truth = Rigid2D(theta, (tx, ty))  # p_A = truth(p_B)
    in_b = truth.inverse().apply(NODES)
    # B knows a large square around its nodes, so the shared region is A's known area
    big = GridSnapshot(np.full((600, 600), CellState.FREE, dtype=np.int8), RES,
                       tuple(in_b.mean(axis=0) - 30.0))
    rep = node_repeatability(topomap(NODES), topomap(in_b), grid(), big, truth)
    np.testing.assert_allclose(rep.repeatability, [1.0, 1.0])
    assert rep.mutual == len(NODES)


def test_only_nodes_both_robots_know_count():
    left = np.zeros((50, 50), bool)
    left[:, :25] = True  # B knows x < 2.5 m
    rep = node_repeatability(topomap(NODES), topomap(NODES[:3]), grid(), grid(known=left),
                             Rigid2D())
    # the region is x < 2.5 m less 0.3 m: A's nodes at x = 1, 2, 1.5; B's at x = 1, 2
    assert rep.nodes_a == 3 and rep.nodes_b == 2
    np.testing.assert_array_equal(rep.hits[0], [2, 2])
    assert rep.repeatability[0] == pytest.approx(0.5 * (2 / 3 + 1.0))


def test_frontier_nodes_are_left_out_unless_asked():
    flags = np.array([False, False, False, False, True])
    rep = node_repeatability(topomap(NODES), topomap(NODES, frontier=flags), grid(), grid(),
                             Rigid2D())
    assert rep.nodes_a == 5 and rep.nodes_b == 4
    assert rep.repeatability[0] == pytest.approx(0.5 * (4 / 5 + 1.0))
    both = node_repeatability(topomap(NODES), topomap(NODES, frontier=flags), grid(), grid(),
                              Rigid2D(), include_frontier=True)
    assert both.repeatability[0] == 1.0


def test_chance_is_the_level_of_random_nodes_at_the_same_density():
    rep = node_repeatability(topomap(NODES), topomap(NODES[:2]), grid(), grid(), Rigid2D(),
                             radii=(0.5,))
    density_a, density_b = 5 / rep.region_m2, 2 / rep.region_m2
    expected = 0.5 * ((1 - math.exp(-density_b * math.pi * 0.25))
                      + (1 - math.exp(-density_a * math.pi * 0.25)))
    assert rep.chance[0] == pytest.approx(expected)
    # and random nodes do score about that
    rng = np.random.default_rng(0)
    region = shared_region(grid(), grid(), Rigid2D())
    rows, cols = np.nonzero(region)
    scores = []
    for _ in range(300):
        pick = rng.choice(len(rows), 7)
        pts = np.stack([cols[pick] + 0.5, rows[pick] + 0.5], axis=1) * RES
        scores.append(node_repeatability(topomap(pts[:5]), topomap(pts[5:]), grid(), grid(),
                                         Rigid2D(), radii=(0.5,)).repeatability[0])
    assert np.mean(scores) == pytest.approx(expected, abs=0.04)


def test_no_nodes_in_the_region():
    empty = TopoMap.empty()
    rep = node_repeatability(empty, empty, grid(), grid(), Rigid2D())
    assert np.isnan(rep.repeatability).all() and rep.nodes == 0
    one_sided = node_repeatability(topomap(NODES), empty, grid(), grid(), Rigid2D())
    np.testing.assert_array_equal(one_sided.repeatability, [0.0, 0.0])


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"map_a": NODES}, TypeError, "map_a must be a TopoMap, got ndarray"),
        ({"grid_b": np.zeros((5, 5))}, TypeError,
         "grid_b must be an OccupancyGrid or a grid snapshot"),
        ({"truth": np.eye(3)}, TypeError, "truth must be a Rigid2D, got ndarray"),
        ({"radii": (1.0, 0.5)}, ValueError,
         r"radii must be a non-empty increasing sequence, got \(1.0, 0.5\)"),
        ({"radii": ()}, ValueError, "radii must be a non-empty increasing sequence"),
        ({"erode": -0.1}, ValueError, "erode"),
    ],
)
def test_bad_input(kwargs, error, match):
    args = {"map_a": topomap(NODES), "map_b": topomap(NODES), "grid_a": grid(),
            "grid_b": grid(), "truth": Rigid2D(), **kwargs}
    with pytest.raises(error, match=match):
        node_repeatability(**args)


def test_in_region_finds_the_points_on_the_region_cells():
    """A region of the grid's left half holds the points there; points right of it or off the
    grid are outside; the count agrees with node_repeatability's own."""
    left = np.zeros((50, 50), bool)
    left[:, :25] = True
    g = grid()
    inside = in_region([[1.0, 1.0], [2.45, 4.9], [2.55, 1.0], [-0.1, 1.0], [1.0, 5.1]], left, g)
    np.testing.assert_array_equal(inside, [True, True, False, False, False])
    region = shared_region(g, g, Rigid2D())
    rep = node_repeatability(topomap(NODES), topomap(NODES), g, g, Rigid2D())
    assert int(in_region(NODES, region, g).sum()) == rep.nodes_a
    assert in_region(np.empty((0, 2)), region, g).shape == (0,)


@pytest.mark.parametrize(
    ("xy", "region", "error", "match"),
    [
        ([1.0, 1.0], np.ones((50, 50), bool), ValueError,
         r"xy must be \(N, 2\) points, got shape \(2,\)"),
        ([[1.0, 1.0]], np.ones((40, 50), bool), ValueError,
         r"region must be a mask of the grid's shape \(50, 50\), got shape \(40, 50\)"),
    ],
)
def test_in_region_bad_input(xy, region, error, match):
    with pytest.raises(error, match=match):
        in_region(xy, region, grid())
    with pytest.raises(TypeError, match="grid must be an OccupancyGrid or a grid snapshot"):
        in_region([[1.0, 1.0]], np.ones((50, 50), bool), np.zeros((50, 50)))
