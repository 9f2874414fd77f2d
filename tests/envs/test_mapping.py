"""Window resampling, the egocentric local map and the coverage bookkeeping, on synthetic
grids."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from envs.explore.mapping import (
    LOCAL_MAP_VALUES,
    Geometry,
    LocalMapSampler,
    OracleCoverage,
    RobotMap,
    compose_pose,
    warp_window,
)
from fusion.rigid import Rigid2D
from topo.grid import OccupancyGrid, SensorModel

G = Geometry((-2.0, -3.0), 0.1, (60, 40))
FULL = (slice(0, 60), slice(0, 40))


def _random_mask(seed):
    return np.random.default_rng(seed).random(G.shape) < 0.3


def test_identity_warp_is_a_copy():
    mask = _random_mask(0)
    (rows, cols), vals = warp_window(G, G, mask, FULL, Rigid2D.identity())
    out = np.zeros_like(mask)
    out[rows, cols] = vals
    np.testing.assert_array_equal(out, mask)


def test_quarter_turn_about_the_grid_centre_is_rot90():
    g = Geometry((-2.0, -2.0), 0.1, (40, 40))
    mask = np.random.default_rng(1).random(g.shape) < 0.3
    # cell centres sit at ±(k + 0.5) * 0.1 about the origin (0, 0), so +90° maps cells to cells
    (rows, cols), vals = warp_window(g, g, mask, (slice(0, 40), slice(0, 40)),
                                     Rigid2D.from_degrees(90.0))
    out = np.zeros_like(mask)
    out[rows, cols] = vals
    # (x, y) -> (-y, x): out[ix, n-1-iy] = mask[iy, ix], i.e. np.rot90(k=-1) of the [iy, ix]
    # array (row 0 at the bottom turns a CCW world rotation into a clockwise array one)
    np.testing.assert_array_equal(out, np.rot90(mask, k=-1))


def test_translation_by_whole_cells_shifts_the_window():
    mask = np.zeros(G.shape, bool)
    mask[10:14, 5:9] = True
    win = (slice(8, 16), slice(3, 11))
    (rows, cols), vals = warp_window(G, G, mask, win, Rigid2D(0.0, (0.5, -0.2)))
    out = np.zeros_like(mask)
    out[rows, cols] = vals
    expected = np.zeros_like(mask)
    expected[8:12, 10:14] = True
    np.testing.assert_array_equal(out, expected)


def test_window_landing_outside_is_none():
    assert warp_window(G, G, _random_mask(2), FULL, Rigid2D(0.0, (100.0, 0.0))) is None


def _warp_numpy(dst, src, src_mask, window, transform):
    """warp_window's resampling as numpy array arithmetic (its form before the kernel)."""
    rs, cs = window
    sres = src.resolution
    x0, y0 = src.origin[0] + cs.start * sres, src.origin[1] + rs.start * sres
    x1, y1 = src.origin[0] + cs.stop * sres, src.origin[1] + rs.stop * sres
    dwin = dst.window(transform.apply(np.array([[x0, y0], [x1, y0], [x0, y1], [x1, y1]])), 1)
    if dwin is None:
        return None
    drs, dcs = dwin
    xs = dst.origin[0] + (np.arange(dcs.start, dcs.stop) + 0.5) * dst.resolution
    ys = dst.origin[1] + (np.arange(drs.start, drs.stop) + 0.5) * dst.resolution
    inv = transform.inverse()
    r, t = inv.R, inv.T
    iu = np.floor((r[0, 0] * xs[None, :] + r[0, 1] * ys[:, None] + (t[0] - x0)) / sres)
    iv = np.floor((r[1, 0] * xs[None, :] + r[1, 1] * ys[:, None] + (t[1] - y0)) / sres)
    iu, iv = iu.astype(np.intp), iv.astype(np.intp)
    ok = (iu >= 0) & (iu < cs.stop - cs.start) & (iv >= 0) & (iv < rs.stop - rs.start)
    out = np.zeros(ok.shape, dtype=src_mask.dtype)
    out[ok] = src_mask[window][iv[ok], iu[ok]]
    return dwin, out


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), theta=st.floats(-math.pi, math.pi),
       tx=st.floats(-3.0, 3.0), ty=st.floats(-3.0, 3.0))
def test_warp_window_is_the_numpy_form(seed, theta, tx, ty):
    """Bit for bit, any window and motion, bool masks and int8 states, another cell size."""
    rng = np.random.default_rng(seed)
    src = Geometry((-2.5, -1.5), 0.1, (50, 45))
    r0, c0 = int(rng.integers(0, 40)), int(rng.integers(0, 35))
    win = (slice(r0, r0 + int(rng.integers(1, 11))), slice(c0, c0 + int(rng.integers(1, 11))))
    t = Rigid2D(theta, (tx, ty))
    for dst in (G, Geometry((-2.0, -3.0), 0.15, (40, 30))):
        for mask in (rng.random(src.shape) < 0.4,
                     rng.integers(0, 3, src.shape).astype(np.int8)):
            got = warp_window(dst, src, mask, win, t)
            want = _warp_numpy(dst, src, mask, win, t)
            assert (got is None) == (want is None)
            if got is not None:
                assert got[0] == want[0]
                assert got[1].dtype == want[1].dtype
                np.testing.assert_array_equal(got[1], want[1])
            if got is not None:
                assert warp_window(dst, src, mask, win, t, t.inverse())[0] == got[0]


@settings(max_examples=40, deadline=None)
@given(theta=st.floats(-math.pi, math.pi), x=st.floats(-1.0, 1.0), y=st.floats(-1.0, 1.0))
def test_local_map_puts_what_is_ahead_at_the_top(theta, x, y):
    g = Geometry((-5.0, -5.0), 0.1, (100, 100))
    states = np.zeros(g.shape, dtype=np.int8)
    ahead = (x + 1.2 * math.cos(theta), y + 1.2 * math.sin(theta))
    left = (x - 1.2 * math.sin(theta), y + 1.2 * math.cos(theta))
    for (px, py), code in ((ahead, 2), (left, 1)):
        ix, iy = int((px + 5.0) / 0.1), int((py + 5.0) / 0.1)
        states[iy - 1:iy + 2, ix - 1:ix + 2] = code
    sampler = LocalMapSampler(64, 0.1)
    img = sampler.sample(states, g, np.array([x, y, theta])).reshape(64, 64)
    # 1.2 m ahead = 12 pixels above the centre; 1.2 m left = 12 pixels left of it
    assert img[32 - 12 - 1, 31] == 2 or img[32 - 12, 31] == 2 or img[32 - 12 - 1, 32] == 2
    assert img[31, 32 - 12 - 1] == 1 or img[31, 32 - 12] == 1 or img[32, 32 - 12 - 1] == 1
    assert img[63, :].max() == 0  # behind: nothing there


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), merged=st.booleans())
def test_local_map_image_is_the_sampled_states_as_pixels(seed, merged):
    # image() is written out in one loop for speed (helpers per pixel measured 4x slower), so
    # it is pinned here to sample(), the plain form: the same states, mapped to pixel values
    rng = np.random.default_rng(seed)
    g1 = Geometry(tuple(rng.uniform(-8, -2, 2)), 0.1, (int(rng.integers(30, 120)), 90))
    g2 = Geometry(tuple(rng.uniform(-8, -2, 2)), 0.05, (80, int(rng.integers(30, 160))))
    s1 = rng.integers(0, 3, g1.shape).astype(np.int8)
    s2 = rng.integers(0, 3, g2.shape).astype(np.int8)
    p1, p2 = rng.uniform(-6, 6, 3), rng.uniform(-6, 6, 3)
    sampler = LocalMapSampler(64, 0.1)
    want = sampler.sample(s1, g1, p1)
    if merged:
        sampler.sample(s2, g2, p2, out=want)
    got = sampler.image(s1, g1, p1, [(s2, g2, p2)] if merged else [])
    assert got.shape == (1, 64, 64) and got.dtype == np.uint8
    np.testing.assert_array_equal(got.ravel(), LOCAL_MAP_VALUES[want])


def test_local_map_image_of_several_teammates_is_the_cellwise_maximum():
    rng = np.random.default_rng(5)
    grids = [(rng.integers(0, 3, (60, 70)).astype(np.int8),
              Geometry(tuple(rng.uniform(-4, -2, 2)), 0.1, (60, 70)), rng.uniform(-1, 1, 3))
             for _ in range(4)]
    sampler = LocalMapSampler(64, 0.1)
    want = sampler.sample(*grids[0])
    for g in grids[1:]:
        sampler.sample(*g, out=want)
    got = sampler.image(*grids[0], grids[1:])
    np.testing.assert_array_equal(got.ravel(), LOCAL_MAP_VALUES[want])


def test_local_map_outside_the_grid_is_unknown():
    g = Geometry((0.0, 0.0), 0.1, (20, 20))
    states = np.ones(g.shape, dtype=np.int8)
    img = LocalMapSampler(64, 0.1).sample(states, g, np.array([1.0, 1.0, 0.3])).reshape(64, 64)
    assert (img == 1).sum() == pytest.approx(400, rel=0.1)
    assert (img == 0).sum() > 3000
    assert list(LOCAL_MAP_VALUES) == [128, 255, 0]


def test_compose_pose_matches_rigid_apply():
    t = Rigid2D.from_degrees(33.0, (1.0, -2.0))
    pose = np.array([0.4, 0.7, 2.9])
    out = compose_pose(t, pose)
    np.testing.assert_allclose(out[:2], t.apply(pose[:2]))
    assert math.cos(out[2]) == pytest.approx(math.cos(2.9 + math.radians(33.0)))
    assert -math.pi <= out[2] <= math.pi


def _assert_same_maps(a, b):
    """Two TopoMaps equal bit for bit (arrays, dtypes, polylines)."""
    for f in ("xy", "kinds", "edges", "lengths"):
        x, y = getattr(a, f), getattr(b, f)
        assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes(), f
    assert (a.paths is None) == (b.paths is None)
    for p, q in zip(a.paths or (), b.paths or (), strict=True):
        assert p.dtype == q.dtype and p.shape == q.shape and p.tobytes() == q.tobytes()


def test_env_extracts_each_robots_whole_known_map():
    """Every extraction of a short episode: the robot's map extracted from its window of known
    cells is the map of its whole grid (the window is all the extraction reads)."""
    from envs import two_robot_explore_v0
    from topo.extract import extract_topomap

    par = two_robot_explore_v0.parallel_env(max_cycles=200, mapping={"topo_every": 20,
                                                                      "topo_growth": 0.0})
    par.reset(seed=3)
    rng = np.random.default_rng(3)
    checked = 0
    while par.agents:
        par.step({a: np.array([rng.uniform(0.3, 1.0), rng.uniform(-1, 1)]) for a in par.agents})
        if par.steps % 20 == 0:
            for rmap in par.maps:
                assert rmap.topomap.equals(extract_topomap(rmap.grid))
                checked += rmap.topomap.n_nodes > 0
    assert checked >= 10


def test_structural_merge_on_a_small_env_pair():
    """Two Frontier robots in a 12 m building, 600 steps: the structural merge of their own
    topological maps (no grids) is accepted and within 2° and 0.3 m of the truth."""
    from agents.registry import make_team
    from envs import two_robot_explore_v0
    from fusion.structural import merge_maps

    env = two_robot_explore_v0.parallel_env(max_cycles=600, world={"size": (12, 12)},
                                            mapping={"merge_every": 0})
    team = make_team("frontier", env=env)
    observations, infos = env.reset(seed=0)
    for explorer in team.values():
        explorer.reset(seed=0)
    while env.agents:
        observations, _, _, _, infos = env.step(
            {a: team[a].act(observations[a], infos[a]) for a in env.agents})
    for rmap in env.maps:
        rmap.extract()
    map_a, map_b = env.maps[0].topomap, env.maps[1].topomap
    result = merge_maps(map_a, map_b)
    assert result.accepted, result.reason
    assert math.degrees(result.transform.rotation_error(env.true_merge)) < 2.0
    assert result.transform.translation_error(env.true_merge, map_b.xy.mean(axis=0)) < 0.3


@given(st.integers(0, 2**32 - 1), st.integers(1, 60), st.integers(1, 40),
       st.sampled_from([0.0, math.pi / 2, 1.0, -2.5]))
def test_nearest_nodes_are_the_nearest_offsets(seed, n, n_max, theta):
    """More nodes than rows, equal distances (stable: ties by index), offsets beyond the clip,
    any heading: the rows of the rotated offsets, nearest first, at a tolerance."""
    from envs.explore._kernels import nearest_nodes

    rng = np.random.default_rng(seed)
    xy = np.round(rng.uniform(-30, 30, (n, 2)), int(rng.integers(0, 2)))
    x, y = np.round(rng.uniform(-3, 3, 2), 1)
    c, s = math.cos(theta), math.sin(theta)
    d = xy - (x, y)
    rel = d @ np.array([[c, -s], [s, c]])
    static = rng.random((n, 4)).astype(np.float32)
    lim = 20.0
    nodes = np.zeros((n_max, 6), np.float32)
    mask = np.zeros(n_max, np.float32)
    order = nearest_nodes(xy, x, y, c, s, static, lim, nodes, mask)
    dist = np.hypot(*d.T)  # a rotation keeps distances
    k = min(n, n_max)
    np.testing.assert_allclose(dist[order], np.sort(dist)[:k], atol=1e-9)  # nearest first
    if theta == 0.0:  # unrotated offsets: equal squared distances in index order
        d2 = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]
        np.testing.assert_array_equal(order, np.argsort(d2, kind="stable")[:k])
    ref_nodes = np.zeros_like(nodes)
    ref_nodes[:k, :2] = np.clip(rel[order], -lim, lim)
    ref_nodes[:k, 2:] = static[order]
    np.testing.assert_allclose(nodes, ref_nodes, atol=1e-5)
    np.testing.assert_array_equal(mask, (np.arange(n_max) < k).astype(np.float32))


@given(st.integers(0, 2**32 - 1), st.integers(1, 60), st.integers(0, 80), st.integers(1, 40))
def test_adjacency_joins_listed_nodes(seed, n, n_edges, n_max):
    """Edges between listed nodes only, both directions, parallel edges, any order (against a
    plain loop over the edges)."""
    from envs.explore.observations import adjacency

    rng = np.random.default_rng(seed)
    order = rng.permutation(n)[:n_max]
    edges = rng.integers(0, n, (n_edges, 2))
    adj = np.zeros((n_max, n_max), np.float32)
    adjacency(order, edges, n, adj)
    row = {int(q): j for j, q in enumerate(order)}
    ref = np.zeros_like(adj)
    for u, v in edges.tolist():
        if u in row and v in row:
            ref[row[u], row[v]] = ref[row[v], row[u]] = 1.0
    np.testing.assert_array_equal(adj, ref)


PIONEER = np.radians([-90.0, -50.0, -30.0, -10.0, 10.0, 30.0, 50.0, 90.0])


def _scans(seed, n=25):
    """Random scans in a 6 m square: poses, ranges (some beyond the 2.5 m range: no echo)."""
    rng = np.random.default_rng(seed)
    for _ in range(n):
        pose = np.array([*rng.uniform(-2.5, 2.5, 2), rng.uniform(-math.pi, math.pi)])
        yield pose, rng.uniform(0.0, 3.0, PIONEER.size)


MODELS = [None, SensorModel(usable_range=1.5)]


@pytest.mark.parametrize("model", MODELS, ids=["full-range", "usable-1.5"])
@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_robot_map_ever_known_is_the_grid_known_after_each_scan(model, seed):
    """``RobotMap.integrate`` folds the newly known cells into ``ever`` in the grid update: the
    same as OR-ing ``states != UNKNOWN`` in after every scan of a plain ``OccupancyGrid``,
    with the count and bounding box of the new cells."""
    rmap = RobotMap((-3.0, -3.0, 3.0, 3.0), 0.1, model)
    grid = OccupancyGrid(resolution=0.1, extent=(-3.0, -3.0, 3.0, 3.0), model=model)
    ever = np.zeros(grid.shape, dtype=bool)
    mount, max_range, half = 0.2, 2.5, math.radians(7.5)
    for pose, ranges in _scans(seed):
        counts = rmap.integrate(pose, ranges, PIONEER, mount, max_range, half)
        grid.update(pose, ranges + mount, PIONEER, max_range + mount, half)
        new = (grid.states() != 0) & ~ever
        ever |= new
        np.testing.assert_array_equal(rmap.states, grid.states())
        np.testing.assert_array_equal(rmap.ever, ever)
        assert counts[0] == new.sum() and rmap.n_ever == ever.sum()
        if new.any():
            rows, cols = np.nonzero(new)
            assert counts[1:5].tolist() == [rows.min(), rows.max() + 1, cols.min(),
                                            cols.max() + 1]
        else:
            assert counts[1:5].tolist() == [0, 0, 0, 0]


@pytest.mark.parametrize("model", MODELS, ids=["full-range", "usable-1.5"])
@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_true_coverage_sweep_is_the_ever_known_of_a_grid(model, seed):
    """``OracleCoverage`` sweeps without a grid: per robot the cells a world-frame
    ``OccupancyGrid`` folding the same scans has ever known, and the union's counts."""
    extent = (-3.0, -3.0, 3.0, 3.0)
    reachable = np.random.default_rng(seed).random((60, 60)) < 0.7
    oracle = OracleCoverage(extent, 0.1, reachable, model)
    grids = [OccupancyGrid(resolution=0.1, extent=extent, model=model) for _ in range(2)]
    ever = [np.zeros((60, 60), dtype=bool) for _ in range(2)]
    union = np.zeros((60, 60), dtype=bool)
    covered = both = 0
    mount, max_range, half = 0.2, 2.5, math.radians(7.5)
    for k, (pose, ranges) in enumerate(_scans(seed, 40)):
        i = k % 2
        new_union = oracle.add(i, pose, ranges, PIONEER, mount, max_range, half)
        grids[i].update(pose, ranges + mount, PIONEER, max_range + mount, half)
        new = (grids[i].states() != 0) & ~ever[i]
        ever[i] |= new
        assert new_union == (new & ~union).sum()
        both += int((new & union).sum())
        covered += int((new & ~union & reachable).sum())
        union |= new
        np.testing.assert_array_equal(oracle.swept[i], ever[i])
        assert oracle.n_swept[i] == ever[i].sum()
    np.testing.assert_array_equal(oracle.union, union)
    assert (oracle.both, oracle.covered, oracle.count) == (both, covered, union.sum())


def test_unchanged_maps_are_neither_extracted_nor_merged_again():
    """With ``topo_growth`` out of reach a map is extracted once (its first known cells) and,
    without grid alignments, the two unchanged graphs are merged once: the same maps would give
    the same answer. With 0 every due step extracts anew."""
    from envs import two_robot_explore_v0

    def run(growth):
        par = two_robot_explore_v0.parallel_env(
            max_cycles=120, world={"size": (12, 12)},
            mapping={"topo_every": 10, "merge_every": 10, "grid_merge_every": 0,
                     "topo_growth": growth})
        par.reset(seed=1)
        rng = np.random.default_rng(1)
        graphs, merges = [], 0  # the graphs themselves: an id() is reused once one is freed
        while par.agents:
            par.step({a: np.array([0.8, rng.uniform(-1, 1)]) for a in par.agents})
            if not any(g is par.maps[0].topomap for g in graphs):
                graphs.append(par.maps[0].topomap)
            merges = par.merge_state().merges
        return len(graphs), merges

    frozen, fresh = run(10.0), run(0.0)
    assert frozen[0] == 1 and frozen[1] <= 1  # extracted once, at reset
    assert fresh[0] >= 10 and fresh[1] >= 5
