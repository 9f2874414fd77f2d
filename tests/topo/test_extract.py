"""extract_topomap: synthetic shapes with known answers, invariants, real maps, bad input."""

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage
from scipy.spatial import cKDTree

from topo import NodeKind, OccupancyGrid
from topo.extract import ExtractConfig, extract_topomap
from topo.maps import load_floor_plan

MAPS = Path(__file__).resolve().parents[3] / "shared" / "maps"
RES = 0.1


def corridors(shape, segments, width=6):
    """Free mask of straight corridors ``(r0, c0, r1, c1)`` of ``width`` cells."""
    m = np.zeros(shape, bool)
    h = width // 2
    for r0, c0, r1, c1 in segments:
        m[min(r0, r1) - h: max(r0, r1) + h + 1, min(c0, c1) - h: max(c0, c1) + h + 1] = True
    return m


SHAPES = {
    "plus": (corridors((80, 80), [(40, 5, 40, 75), (5, 40, 75, 40)]), 1, 4, 0),
    "L": (corridors((80, 80), [(10, 10, 10, 70), (10, 10, 70, 10)]), 0, 2, 1),
    "loop": (corridors((80, 100), [(10, 10, 10, 90), (70, 10, 70, 90), (10, 10, 70, 10),
                                   (10, 90, 70, 90)]), 0, 0, 4),
    "T": (corridors((80, 80), [(10, 5, 10, 75), (10, 40, 75, 40)]), 1, 3, 0),
}


def counts(m):
    c = np.bincount(m.kinds, minlength=3)
    return c[NodeKind.JUNCTION], c[NodeKind.DEAD_END], c[NodeKind.CORNER]


@pytest.mark.parametrize("name", SHAPES)
def test_known_shapes(name):
    mask, junctions, dead_ends, corners = SHAPES[name]
    m = extract_topomap(mask, resolution=RES)
    assert counts(m) == (junctions, dead_ends, corners)
    check_invariants(m, mask)


def check_invariants(m, mask, origin=(0.0, 0.0)):
    # every node lies in free space
    cells = np.floor((m.xy - origin) / RES).astype(int)[:, ::-1]
    assert mask[cells[:, 0], cells[:, 1]].all()
    # edge lengths agree with their polylines (the skeleton path) within 10 %
    for e, path in enumerate(m.paths):
        poly = np.linalg.norm(np.diff(path, axis=0), axis=1).sum()
        assert abs(m.lengths[e] - poly) <= 0.1 * poly + 1e-9
        np.testing.assert_allclose(path[0], m.xy[m.edges[e, 0]])
        np.testing.assert_allclose(path[-1], m.xy[m.edges[e, 1]])
    # graph components match free-space components
    _, n_free = ndimage.label(mask)
    n_graph = len(list(__import__("networkx").connected_components(m.to_networkx())))
    assert n_graph == n_free


@settings(max_examples=25)
@given(st.integers(0, 3), st.integers(0, 30), st.integers(0, 30))
def test_shapes_any_rotation_and_place(k, dr, dc):
    """A shape rotated by k·90° and shifted gives the same kinds, positions moved along."""
    for mask, j, d, c in SHAPES.values():
        big = np.zeros((150, 150), bool)
        rot = np.rot90(mask, k)
        big[dr: dr + rot.shape[0], dc: dc + rot.shape[1]] = rot
        m = extract_topomap(big, resolution=RES, origin=(-3.0, 2.0))
        assert counts(m) == (j, d, c)
        check_invariants(m, big, origin=(-3.0, 2.0))


def test_deterministic_node_order_and_grid_input():
    mask = SHAPES["plus"][0]
    a = extract_topomap(mask, resolution=RES)
    b = extract_topomap(mask.copy(), resolution=RES)
    assert a.equals(b)
    order = np.lexsort((a.xy[:, 0], a.xy[:, 1]))
    np.testing.assert_array_equal(order, np.arange(a.n_nodes))
    g = OccupancyGrid(RES, (0, 0, 8, 8))
    g.log_odds[mask] = -2.0
    g._states[mask] = 1
    assert extract_topomap(g).equals(a)


def test_spurs_are_pruned_and_small_holes_filled():
    mask = corridors((80, 80), [(40, 5, 40, 75)])
    mask[36:40, 30:33] = True  # a bump: a short spur in the skeleton
    mask[40, 50] = False       # one noisy occupied cell inside the corridor
    m = extract_topomap(mask, resolution=RES)
    assert counts(m) == (0, 2, 0) and m.n_edges == 1
    keep = extract_topomap(mask, resolution=RES,
                           config=ExtractConfig(min_spur_length=0.0, min_hole_area=0.0))
    assert m.n_nodes < keep.n_nodes


def test_empty_free_space_gives_an_empty_map():
    assert extract_topomap(np.zeros((20, 20), bool), resolution=RES).n_nodes == 0


@pytest.mark.skipif(not MAPS.is_dir(), reason="shared/maps not beside the repo")
@pytest.mark.parametrize("name", ["dungeon/1.png", "dungeon/10.png", "dungeon/100.png",
                                  "ros/turtlebot3_world.yaml", "ros/depot.yaml"])
def test_real_maps(name):
    """Counts seen: dungeon 1/10/100 → 17/12/13 nodes; turtlebot3_world → 16 (a lattice of
    paths around its nine pillars: 12 junctions, 4 corners); depot → 128."""
    plan = load_floor_plan(MAPS / name)
    m = extract_topomap(plan.free, plan.resolution, plan.origin)
    assert m.n_nodes >= 2 and m.n_edges >= 1
    assert m.degree().max() <= 8
    if name.startswith("dungeon"):
        # rotating the map by 90° gives the same graph, rotated: equal counts, positions within
        # 2.5 cells (skeletonize puts even-width corridors' skeletons one cell off-centre, on a
        # side that turns with the map)
        r = extract_topomap(np.rot90(plan.free), plan.resolution)
        assert counts(r) == counts(m)
        width = plan.free.shape[1] * plan.resolution
        mapped = np.stack([m.xy[:, 1], width - m.xy[:, 0]], axis=1)
        d, _ = cKDTree(r.xy).query(mapped)
        assert d.max() <= 2.5 * plan.resolution


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"grid_or_free_mask": np.ones((5, 5), np.uint8), "resolution": 0.1}, TypeError,
         "must have dtype bool, got uint8"),
        ({"grid_or_free_mask": np.ones(5, bool), "resolution": 0.1}, ValueError,
         r"must be a 2-D array, got shape \(5,\)"),
        ({"grid_or_free_mask": [[True]], "resolution": 0.1}, TypeError,
         "must be an OccupancyGrid or a 2-D boolean array, got list"),
        ({"grid_or_free_mask": np.ones((5, 5), bool)}, ValueError, "resolution is required"),
        ({"grid_or_free_mask": np.ones((5, 5), bool), "resolution": 0.0}, ValueError,
         "resolution must be > 0.0, got 0.0"),
        ({"grid_or_free_mask": np.ones((5, 5), bool), "resolution": 0.1,
          "origin": (0, float("nan"))}, ValueError, "origin must be finite"),
        ({"grid_or_free_mask": np.ones((5, 5), bool), "resolution": 0.1,
          "config": {"spur": 1}}, ValueError, r"ExtractConfig has unknown keys \['spur'\]"),
    ],
)
def test_bad_input(kwargs, error, match):
    with pytest.raises(error, match=match):
        extract_topomap(**kwargs)


def test_bad_config_values():
    with pytest.raises(ValueError, match="ExtractConfig.min_spur_length must be >= 0.0"):
        ExtractConfig(min_spur_length=-1)
    with pytest.raises(ValueError, match="ExtractConfig.corner_angle must be <= 180.0"):
        ExtractConfig(corner_angle=270)


def test_sonar_preset_is_a_valid_simpler_config():
    cfg = ExtractConfig.for_sonar()
    assert cfg.erode_radius > 0 and cfg.min_spur_length > ExtractConfig().min_spur_length
    mask = SHAPES["plus"][0]
    assert counts(extract_topomap(mask, resolution=RES, config=cfg)) == (1, 4, 0)
