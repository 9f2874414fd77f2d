"""extract_topomap: places, gateways and dead ends of known shapes; repeatability under
rotation and partial views; frontier flags; the compiled merge tree against brute force; bad
input. Imports nothing above topo."""

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage
from scipy.spatial import cKDTree

from topo import CellState, NodeKind, OccupancyGrid, TopoMap
from topo._kernels import basin_paths, merge_tree
from topo.extract import ExtractConfig, _box_sums, _touching, extract_topomap
from topo.maps import FloorPlan, load_floor_plan

MAPS = Path(__file__).resolve().parents[3] / "shared" / "maps"
RES = 0.1
FREE, OCCUPIED, UNKNOWN = int(CellState.FREE), int(CellState.OCCUPIED), int(CellState.UNKNOWN)


def corridors(shape, segments, width=16):
    """Free mask of straight corridors ``(r0, c0, r1, c1)`` ``width`` cells wide."""
    m = np.zeros(shape, bool)
    h = width // 2
    for r0, c0, r1, c1 in segments:
        m[min(r0, r1) - h: max(r0, r1) + h, min(c0, c1) - h: max(c0, c1) + h] = True
    return m


def two_rooms(door=10):
    """Two 4 × 4 m rooms side by side (0.1 m cells), a ``door``-cell doorway in the 1 m wall."""
    m = np.zeros((60, 110), bool)
    m[10:50, 10:50] = True
    m[10:50, 60:100] = True
    m[30 - door // 2: 30 + door - door // 2, 50:60] = True
    return m


def labels(m):
    return sorted(NodeKind(k).label for k in m.kinds)


def near(m, xy, tol):
    """Index of the node of ``m`` within ``tol`` of ``xy`` (the test fails if none)."""
    d = np.linalg.norm(m.xy - np.asarray(xy), axis=1)
    assert d.min() <= tol, f"no node within {tol} m of {xy}: nearest {d.min():.2f} m"
    return int(np.argmin(d))


# ------------------------------------------------------------------------------ known shapes
SHAPES = {
    # name: (mask, the place's kind, its position (m))
    "plus": (corridors((100, 100), [(50, 8, 50, 92), (8, 50, 92, 50)]), "junction", (5.0, 5.0)),
    "T": (corridors((100, 100), [(20, 8, 20, 92), (20, 50, 92, 50)]), "junction", (5.0, 2.0)),
    "L": (corridors((100, 100), [(15, 15, 15, 92), (15, 15, 92, 15)]), "corner", (1.5, 1.5)),
}


@pytest.mark.parametrize("name", SHAPES)
def test_corridor_crossings_and_bends_are_places_with_dead_ends_at_the_arms(name):
    """A plus, a T and an L of 1.6 m corridors: one place where the corridors meet (the
    widest spot), one dead end at each arm's closed end, a path from the place to each."""
    mask, kind, where = SHAPES[name]
    m = extract_topomap(mask, RES)
    arms = {"plus": 4, "T": 3, "L": 2}[name]
    assert labels(m) == sorted([kind] + ["dead_end"] * arms)
    place = near(m, where, 0.45)
    assert NodeKind(m.kinds[place]).label == kind
    assert m.n_edges == arms and (m.edges == place).any(axis=1).all()
    assert not m.frontier.any()  # a free mask has no unknown
    check_paths(m, mask)


def check_paths(m, mask, origin=(0.0, 0.0)):
    """Polylines run from their first node to their second, inside free space (0.1 m cells),
    and the lengths are theirs."""
    for e, path in enumerate(m.paths):
        np.testing.assert_allclose(path[0], m.xy[m.edges[e, 0]])
        np.testing.assert_allclose(path[-1], m.xy[m.edges[e, 1]])
        np.testing.assert_allclose(m.lengths[e], np.hypot(*np.diff(path, axis=0).T).sum())
        cells = np.floor((path - origin) / RES).astype(int)[:, ::-1]
        assert mask[cells[:, 0], cells[:, 1]].mean() > 0.9


def test_two_rooms_and_a_door():
    """Two rooms joined by a 1 m door: a place at each room's centre, a gateway in the door,
    paths room → door → room; the clearances are the rooms' half side and the door's half
    width (to the 0.2 m working cells)."""
    mask = two_rooms()
    m = extract_topomap(mask, RES)
    assert labels(m) == ["dead_end", "dead_end", "gateway"]
    left, door, right = near(m, (3.0, 3.0), 0.3), near(m, (5.5, 3.0), 0.3), near(m, (8.0, 3.0), 0.3)
    assert m.kinds[door] == NodeKind.GATEWAY
    assert sorted(map(sorted, m.edges.tolist())) == sorted([sorted([left, door]),
                                                            sorted([door, right])])
    np.testing.assert_allclose(m.clearance[[left, right]], 2.0, atol=0.1)
    assert 0.4 <= m.clearance[door] <= 0.65
    check_paths(m, mask)


@pytest.mark.parametrize("depth", [0.6, 0.8, 1.0, 2.0, 4.0])
def test_a_door_is_a_gateway_however_little_of_the_next_room_is_seen(depth):
    """A robot that has looked ``depth`` metres into the right room (the rest unknown) puts a
    gateway in the door, where one that saw the whole room does, even when what it saw of
    that room is too little to be a place of its own (0.6–0.8 m: its clearance maximum does
    not persist); the gateway hangs off the left room's place."""
    mask = two_rooms()
    states = np.full(mask.shape, OCCUPIED, dtype=np.int8)
    states[mask] = FREE
    states[:, 60 + round(depth / RES):] = UNKNOWN
    m = extract_topomap(states, RES)
    door = near(m, (5.5, 3.0), 0.3)
    assert m.kinds[door] == NodeKind.GATEWAY
    left = near(m, (3.0, 3.0), 0.3)
    assert sorted([left, door]) in sorted(map(sorted, m.edges.tolist()))


def test_a_wide_opening_is_a_path_without_a_gateway():
    """A 3 m opening between the rooms is no doorway: the places are joined directly."""
    m = extract_topomap(two_rooms(door=30), RES)
    assert NodeKind.GATEWAY not in m.kinds and m.n_edges == 1


# ------------------------------------------------------------------------------ repeatability
def matched_share(a_xy, b_xy, tol):
    if not len(a_xy) or not len(b_xy):
        return 0.0
    return float(np.mean(cKDTree(b_xy).query(a_xy)[0] <= tol))


def plan(name):
    return load_floor_plan(MAPS / name)


needs_maps = pytest.mark.skipif(not MAPS.is_dir(), reason="shared/maps not beside the repo")


def rot90_xy(xy, k, shape, res):
    """Positions in a mask of ``shape`` moved as ``np.rot90(mask, k)`` moves its cells (row 0
    at the bottom: rot90 turns the picture clockwise)."""
    h, w = shape
    for _ in range(k):
        xy = np.stack([xy[:, 1], w * res - xy[:, 0]], axis=1)
        h, w = w, h
    return xy


@needs_maps
@pytest.mark.parametrize("name", ["dungeon/1.png", "dungeon/100.png", "ros/depot.yaml"])
@pytest.mark.parametrize("k", [1, 2, 3])
def test_nodes_turn_with_the_map(name, k):
    """Turning a real map by 90°, 180° or 270° turns its nodes: at least 80 % of the nodes of
    each land within one working cell (0.2 m) and a half of a node of the other (pooling to
    the working cells starts from another corner of the turned map)."""
    p = plan(name)
    free = p.free[: p.free.shape[0] // 4 * 4, : p.free.shape[1] // 4 * 4]  # whole pooled cells
    m = extract_topomap(free, p.resolution)
    r = extract_topomap(np.ascontiguousarray(np.rot90(free, k)), p.resolution)
    turned = rot90_xy(m.xy, k, free.shape, p.resolution)
    assert abs(r.n_nodes - m.n_nodes) <= max(2, 0.1 * m.n_nodes)
    assert matched_share(turned, r.xy, 0.3) >= 0.8
    assert matched_share(r.xy, turned, 0.3) >= 0.8


@needs_maps
@pytest.mark.parametrize("angle", [17.0, 45.0, 128.0])
def test_nodes_turn_with_the_map_at_any_angle(angle):
    """Turned by an arbitrary angle (cells resampled), 75 % of a real map's nodes still land
    within 0.5 m of their turned twins: walls are re-rasterised, so less than at 90°."""
    p = plan("dungeon/100.png")
    m = extract_topomap(p.free, p.resolution)
    h, w = p.free.shape
    turned_mask = ndimage.rotate(p.free.astype(np.uint8), angle, order=0, reshape=True) > 0
    r = extract_topomap(turned_mask, p.resolution)
    th = np.radians(angle)
    # ndimage.rotate turns the array (row, col) about its centre by `angle` (counter-clockwise
    # in image order = clockwise with row 0 at the bottom) into a reshaped array
    centre = np.array([w, h]) * p.resolution / 2
    rot = np.array([[np.cos(th), np.sin(th)], [-np.sin(th), np.cos(th)]])
    hh, ww = turned_mask.shape
    turned = (m.xy - centre) @ rot.T + np.array([ww, hh]) * p.resolution / 2
    assert matched_share(turned, r.xy, 0.5) >= 0.75
    assert matched_share(r.xy, turned, 0.5) >= 0.75


def states_of(plan_, window):
    """The plan's cell states with everything outside ``window`` (row and column slices)
    unknown: what a robot that explored only there would know."""
    states = np.zeros(plan_.free.shape, dtype=np.int8)
    states[plan_.free] = FREE
    states[plan_.occupied | ~(plan_.free | plan_.occupied)] = OCCUPIED
    out = np.zeros_like(states)
    out[window] = states[window]
    return out


@needs_maps
@pytest.mark.parametrize("name", ["dungeon/1.png", "dungeon/10.png", "dungeon/103.png",
                                  "dungeon/104.png"])
def test_two_partial_views_agree_where_both_see(name):
    """Two robots that know overlapping parts of a map (65 % of its width each): every node
    off the frontier whose free disc (its clearance and 1 m more) lies inside the common part
    has a twin off the frontier within 0.5 m in the other view — 80 % of them at least."""
    p = plan(name)
    h, w = p.free.shape
    cut_a, cut_b = int(0.65 * w), int(0.35 * w)
    views = [extract_topomap(states_of(p, (slice(None), window)), p.resolution, p.origin)
             for window in (slice(0, cut_a), slice(cut_b, w))]
    lo = p.origin[0] + cut_b * p.resolution
    hi = p.origin[0] + cut_a * p.resolution
    shares = []
    for mine, other in (views, views[::-1]):
        reach = mine.clearance + 1.0
        inside = ~mine.frontier & (mine.xy[:, 0] - reach > lo) & (mine.xy[:, 0] + reach < hi)
        shares.append(matched_share(mine.xy[inside], other.xy[~other.frontier], 0.5))
        assert inside.sum() >= 1
    assert min(shares) >= 0.8


def test_frontier_flags_the_nodes_bounded_by_the_unknown():
    """The same two rooms as cell states: with every wall known, no node is on the frontier;
    with the right room's far half unknown (its far wall too), its place is flagged and the left
    room's is not."""
    mask = two_rooms()
    states = np.full(mask.shape, OCCUPIED, dtype=np.int8)
    states[mask] = FREE
    m = extract_topomap(states, RES)
    assert m.n_nodes == 3 and not m.frontier.any()
    states[:, 80:] = UNKNOWN
    m = extract_topomap(states, RES)
    left = near(m, (3.0, 3.0), 0.3)
    assert not m.frontier[left]
    right = [i for i in range(m.n_nodes) if m.xy[i, 0] > 6.0 and m.kinds[i] != NodeKind.GATEWAY]
    assert right and m.frontier[right].all()


def test_the_unknown_is_not_an_obstacle():
    """A room half-known along its length keeps its clearance from the walls it has seen:
    the place of the known half of a 4 m wide room has a clearance of about 2 m (1 m if the
    unknown were a wall)."""
    states = np.full((60, 110), OCCUPIED, dtype=np.int8)
    states[10:50, 10:100] = FREE
    states[:, 60:] = UNKNOWN
    m = extract_topomap(states, RES)
    assert m.n_nodes >= 1 and m.clearance.max() >= 1.8


def test_same_input_same_map_and_grids_give_their_states():
    mask = two_rooms()
    states = np.where(mask, np.int8(FREE), np.int8(OCCUPIED))
    a = extract_topomap(states, RES, origin=(-3.0, 2.0))
    b = extract_topomap(states.copy(), RES, origin=(-3.0, 2.0))
    assert a.equals(b) and np.array_equal(a.frontier, b.frontier)
    np.testing.assert_array_equal(a.clearance, b.clearance)
    fp = FloorPlan(mask, ~mask, RES, (-3.0, 2.0), "rooms")
    assert extract_topomap(fp).equals(a)
    grid = OccupancyGrid(resolution=RES, extent=(-6.0, -6.0, 6.0, 6.0))
    angles = np.radians([-90, -50, -30, -10, 10, 30, 50, 90])
    for theta in np.radians([0, 90, 180, 270]):
        grid.update((0.0, 0.0, theta), np.array([2.0, 2.5, 3.0, 2.0, 2.2, 3.5, 2.5, 2.0]),
                    angles, 5.0, np.radians(7.5))
    assert extract_topomap(grid).equals(extract_topomap(grid.states(), RES, grid.origin))


@needs_maps
@pytest.mark.parametrize("name", ["dungeon/1.png", "dungeon/105.png", "ros/depot.yaml"])
def test_real_maps_give_connected_plausible_graphs(name):
    p = plan(name)
    m = extract_topomap(p, config=ExtractConfig())
    assert m.n_nodes >= 3 and m.n_edges >= m.n_nodes // 2
    cells = np.floor((m.xy - p.origin) / p.resolution).astype(int)[:, ::-1]
    assert p.free[cells[:, 0], cells[:, 1]].mean() >= 0.95
    assert (m.clearance > 0).all()


# --------------------------------------------------------------------------- compiled kernels
def brute_persistence(field, domain):
    """For every local maximum (8-connected, strict by (value, -index)), the level at which its
    superlevel component first holds an older pixel (higher value, or equal and a lower flat
    index): a flood fill per level."""
    h, w = field.shape
    flat = field.ravel()
    out = {}
    for p in np.flatnonzero(domain.ravel()):
        levels = np.unique(flat[domain.ravel() & (flat <= flat[p])])[::-1]
        for t in levels:
            lab, _ = ndimage.label(domain & (field >= t), structure=np.ones((3, 3)))
            comp = lab.ravel() == lab.ravel()[p]
            older = comp & ((flat > flat[p]) | ((flat == flat[p]) & (np.arange(h * w) < p)))
            if older.any():
                if t < flat[p] or comp.sum() > 1:
                    out[int(p)] = float(t)
                break
    return out


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(3, 9), st.integers(3, 9))
def test_merge_tree_deaths_are_the_flood_fills(seed, h, w):
    """Every maximum that dies does so at the level where a flood fill first joins it to an
    older one (the elder rule), and the surviving component holds an older maximum."""
    rng = np.random.default_rng(seed)
    field = rng.integers(0, 6, (h, w)).astype(np.float64)
    domain = rng.random((h, w)) > 0.2
    inside = np.flatnonzero(domain)
    order = inside[np.lexsort((inside, -field.ravel()[inside]))]
    ascent, saddle, dying, survivor, into = merge_tree(field, domain, order)
    flat = field.ravel()
    brute = brute_persistence(field, domain)
    died = {int(d): float(flat[s]) for s, d in zip(saddle, dying, strict=True)}
    maxima = {k for k, t in brute.items() if ascent[k] == k}
    assert set(died) == maxima
    for d, level in died.items():
        assert level == brute[d]
    for d, k in zip(dying, survivor, strict=True):
        assert flat[k] > flat[d] or (flat[k] == flat[d] and k < d)
    assert set(np.unique(ascent[domain.ravel()])) <= set(np.flatnonzero(ascent == np.arange(
        h * w)))
    assert (ascent[~domain.ravel()] == -1).all() and (into >= 0).all()


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_basin_routes_are_shortest_and_stay_in_their_basin(seed):
    rng = np.random.default_rng(seed)
    basins = np.where(rng.random((12, 14)) > 0.15, rng.integers(0, 2, (12, 14)), -1)
    field = rng.random((12, 14))
    sources = []
    for k in (0, 1):
        cells = np.flatnonzero(basins.ravel() == k)
        if len(cells):
            sources.append(int(cells[0]))
    if not sources:
        return
    basins = np.where(np.isin(basins, range(len(sources))), basins, -1)
    parent, depth = basin_paths(basins, field, np.array(sources))
    flat = basins.ravel()
    for k, s in enumerate(sources):
        lab, _ = ndimage.label(basins == k, structure=np.ones((3, 3)))
        reach = lab.ravel() == lab.ravel()[s]
        assert ((parent >= 0) == reach)[flat == k].all()  # reached: its source's component
        for p in np.flatnonzero(reach):
            path = [p]
            while parent[path[-1]] != path[-1]:
                q = int(parent[path[-1]])
                dy, dx = divmod(q, 14)[0] - divmod(path[-1], 14)[0], q % 14 - path[-1] % 14
                assert max(abs(dy), abs(dx)) == 1 and flat[q] == k
                path.append(q)
            assert path[-1] == s and len(path) - 1 == depth[p]
            # Chebyshev distance bounds a shortest 8-connected route from below
            py, px = divmod(int(p), 14)
            sy, sx = divmod(s, 14)
            assert depth[p] >= max(abs(py - sy), abs(px - sx))


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 9), st.integers(1, 9))
def test_touching_cells_are_every_8_neighbour_pair_across_basins(seed, h, w):
    """The four shifted comparisons find each pair of 8-neighbours in two different basins
    exactly once."""
    rng = np.random.default_rng(seed)
    basins = np.where(rng.random((h, w)) > 0.2, rng.integers(0, 3, (h, w)), -1)
    a, b = _touching(basins)
    found = [tuple(sorted(pq)) for pq in zip(a.tolist(), b.tolist(), strict=True)]
    expected = set()
    for y, x in np.ndindex(h, w):
        for yy, xx in ((y + 1, x - 1), (y + 1, x), (y + 1, x + 1), (y, x + 1)):
            if 0 <= yy < h and 0 <= xx < w and basins[y, x] >= 0 and basins[yy, xx] >= 0 \
                    and basins[y, x] != basins[yy, xx]:
                expected.add((y * w + x, yy * w + xx))
    assert len(found) == len(set(found)) and set(found) == expected


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 12), st.integers(1, 12))
def test_box_counts_are_the_sums_over_clipped_squares(seed, h, w):
    """The summed-area tables' counts are the masks' sums over each node's squares clipped to
    the grid."""
    rng = np.random.default_rng(seed)
    a, b = rng.random((h, w)) > 0.6, rng.random((h, w)) > 0.5
    n = 5
    cells = np.column_stack([rng.integers(0, h, n), rng.integers(0, w, n)])
    outer = rng.integers(0, 6, n)
    inner = outer - rng.integers(0, 4, n)  # negative: no inner square
    n_a, n_b = _box_sums(a, cells, outer), _box_sums(b, cells, outer)
    inside = (inner >= 0) & (_box_sums(a, cells, np.maximum(inner, 0)) > 0)
    for k, (y, x) in enumerate(cells):
        box = np.s_[max(y - outer[k], 0):y + outer[k] + 1, max(x - outer[k], 0):x + outer[k] + 1]
        assert n_a[k] == a[box].sum() and n_b[k] == b[box].sum()
        r = inner[k]
        small = np.s_[max(y - r, 0):y + r + 1, max(x - r, 0):x + r + 1]
        assert inside[k] == (r >= 0 and bool(a[small].any()))


# ---------------------------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"grid": np.ones((5, 5), np.uint8), "resolution": 0.1}, TypeError,
         r"must have dtype bool \(a free mask\) or int8 \(CellState codes.*got uint8"),
        ({"grid": np.ones((5, 5), float), "resolution": 0.1}, TypeError, "got float64"),
        ({"grid": np.full((5, 5), 7, np.int8), "resolution": 0.1}, ValueError,
         r"cell codes other than CellState \[0, 1, 2\]: \[7\]"),
        ({"grid": np.ones(5, bool), "resolution": 0.1}, ValueError,
         r"must be a 2-D array, got shape \(5,\)"),
        ({"grid": [[True]], "resolution": 0.1}, TypeError,
         "must be an OccupancyGrid, a FloorPlan, .* got list"),
        ({"grid": np.ones((5, 5), bool)}, ValueError, "resolution is required"),
        ({"grid": np.ones((5, 5), bool), "resolution": 0.0}, ValueError,
         "resolution must be > 0.0, got 0.0"),
        ({"grid": np.ones((5, 5), bool), "resolution": 0.1, "origin": (0, float("nan"))},
         ValueError, "origin must be finite"),
        ({"grid": np.ones((5, 5), bool), "resolution": 0.1, "config": {"spur": 1}},
         ValueError, r"ExtractConfig has unknown keys \['spur'\]"),
        ({"grid": np.ones((5, 5), bool), "resolution": 0.1, "config": 3}, TypeError,
         "config must be an ExtractConfig, a dict of its fields or None, got int"),
    ],
)
def test_bad_input(kwargs, error, match):
    with pytest.raises(error, match=match):
        extract_topomap(**kwargs)


def test_empty_unwalled_and_all_free_maps():
    """Nothing known, or nothing but free cells with no wall seen: no places (nothing bounds
    the free space). An all-free *mask* is walled by its outside: one room, one place."""
    assert extract_topomap(np.zeros((20, 20), np.int8), RES).n_nodes == 0
    assert extract_topomap(np.full((20, 20), FREE, np.int8), RES).n_nodes == 0
    assert extract_topomap(np.zeros((20, 20), bool), RES).n_nodes == 0
    room = extract_topomap(np.ones((40, 40), bool), RES)
    assert room.n_nodes == 1 and np.allclose(room.xy, [2.0, 2.0], atol=0.25)
    assert room.n_edges == 0 and room.paths == () and room.lengths.shape == (0,)


def test_bad_config_values():
    with pytest.raises(ValueError, match="ExtractConfig.persistence must be >= 0.0, got -1"):
        ExtractConfig(persistence=-1)
    with pytest.raises(ValueError, match="ExtractConfig.gateway_ratio must be <= 1.0"):
        ExtractConfig(gateway_ratio=2)
    with pytest.raises(ValueError, match="ExtractConfig.resolution must be > 0.0"):
        ExtractConfig(resolution=0)
    with pytest.raises(TypeError, match="data must be a dict, got list"):
        ExtractConfig.from_dict([])
    assert ExtractConfig.from_dict({"persistence": 0.4}).persistence == 0.4
    assert isinstance(extract_topomap(two_rooms(), RES, config={"persistence": 0.4}), TopoMap)
