"""extract_topomap: synthetic shapes with known answers, invariants, real maps, bad input."""

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage
from scipy.spatial import cKDTree

from topo import NodeKind, OccupancyGrid, TopoMap
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


def test_specks_only_give_dead_ends():
    """Free space whose skeleton is isolated pixels only (skan's ``Skeleton`` raises on it)."""
    mask = np.zeros((20, 20), bool)
    mask[5, 5] = mask[10, 12] = True
    m = extract_topomap(mask, RES, config=ExtractConfig(min_component_area=0, min_hole_area=0))
    assert m.n_nodes == 2 and m.n_edges == 0 and (m.kinds == NodeKind.DEAD_END).all()


REAL_COUNTS = {  # (junctions, dead ends, corners), as documented in topo/extract.py
    "ros/turtlebot3_world.yaml": (12, 0, 0),
    "ros/tb3_sandbox.yaml": (12, 0, 0),
    "ros/depot.yaml": (49, 17, 9),
    "dungeon/1.png": (7, 6, 4),
    "dungeon/10.png": (5, 3, 4),
    "dungeon/100.png": (4, 4, 5),
    "dungeon/105.png": (5, 3, 2),
}


def rotated_xy(xy, k, shape, res):
    """Positions in a mask's frame → the frame of ``np.rot90(mask, k)`` (origin (0, 0))."""
    h, w = shape
    for _ in range(k):
        xy = np.stack([xy[:, 1], w * res - xy[:, 0]], axis=1)
        h, w = w, h
    return xy


@pytest.mark.skipif(not MAPS.is_dir(), reason="shared/maps not beside the repo")
@pytest.mark.parametrize("name", sorted(REAL_COUNTS))
def test_real_maps(name):
    """Extraction on real maps gives the documented counts, a connected-enough plausible graph,
    and — rotated by 90°, 180°, 270° — the same graph up to the rotation: equal counts, every
    junction within one cell (diagonal included) of its twin, every node within 3.5 cells
    (``skeletonize`` is not rotation-symmetric; thinning ends a pixel or two apart at dead
    ends). ``depot`` (half-mapped boxes with free speckle inside) is held to a looser bar:
    counts within 10 %, 75 % of nodes matched within 2.5 cells."""
    plan = load_floor_plan(MAPS / name)
    res = plan.resolution
    m = extract_topomap(plan.free, res, plan.origin)
    assert counts(m) == REAL_COUNTS[name]
    assert m.n_edges >= m.n_nodes - 1 and m.degree().max() <= 8
    cells = np.floor((m.xy - plan.origin) / res).astype(int)[:, ::-1]
    assert plan.free[cells[:, 0], cells[:, 1]].all()
    local = m.xy - np.asarray(plan.origin)
    for k in (1, 2, 3):
        r = extract_topomap(np.ascontiguousarray(np.rot90(plan.free, k)), res)
        d, j = cKDTree(r.xy).query(rotated_xy(local, k, plan.free.shape, res))
        if name.endswith("depot.yaml"):
            assert abs(r.n_nodes - m.n_nodes) <= 0.1 * m.n_nodes
            assert np.mean((d <= 2.5 * res) & (r.kinds[j] == m.kinds)) >= 0.75
            continue
        assert counts(r) == counts(m), f"rotated by {90 * k}°"
        assert (r.kinds[j] == m.kinds).all()
        assert d[m.kinds == NodeKind.JUNCTION].max() <= np.sqrt(2) * res + 1e-9
        assert d.max() <= 3.5 * res


def test_bump_in_a_wide_corridor_is_no_dead_end():
    """A 0.3 m bump in a 3 m corridor makes a 1.8 m skeleton branch that protrudes 0.3 m: pruned.
    A 2.5 m side corridor is kept."""
    mask = np.zeros((80, 200), bool)
    mask[15:45, 10:190] = True
    bump = mask.copy()
    bump[45:48, 90:96] = True
    assert counts(extract_topomap(bump, resolution=RES)) == (0, 2, 0)
    keep_all = ExtractConfig(min_spur_length=0.0)
    assert counts(extract_topomap(bump, resolution=RES, config=keep_all)) == (1, 3, 0)
    side = mask.copy()
    side[45:70, 90:106] = True
    assert counts(extract_topomap(side, resolution=RES)) == (1, 3, 0)


@pytest.mark.parametrize("k", range(4))
def test_rounded_corner_is_one_corner_and_a_jog_is_none(k):
    wide_l = corridors((120, 120), [(20, 20, 20, 110), (20, 20, 110, 20)], width=20)
    assert counts(extract_topomap(np.ascontiguousarray(np.rot90(wide_l, k)), RES)) == (0, 2, 1)
    jog = np.zeros((60, 200), bool)
    jog[20:30, 10:100] = True
    jog[26:36, 100:190] = True  # the corridor steps 0.6 m sideways
    assert counts(extract_topomap(np.ascontiguousarray(np.rot90(jog, k)), RES)) == (0, 2, 0)


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


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.3, 0.7), st.integers(8, 64), st.integers(8, 64))
def test_skeleton_paths_are_skans(seed, density, h, w):
    """The compiled tracing gives exactly the paths of ``skan.csr.Skeleton`` (same pixels, same
    order), on skeletons of random blobs, which have junction clusters, loops and isolated
    pixels; a skeleton of isolated pixels only (where skan raises) has no paths."""
    from skimage.morphology import skeletonize

    from topo._extract_kernels import skan_paths, skeleton_paths

    rng = np.random.default_rng(seed)
    blobs = ndimage.binary_opening(rng.random((h, w)) < density)
    for skel in (skeletonize(blobs), skeletonize(rng.random((h, w)) < density)):
        got, want = skeleton_paths(skel), skan_paths(skel)
        for a, b in zip(got, want, strict=True):
            np.testing.assert_array_equal(a, b)


def test_skeleton_paths_of_isolated_pixels_and_nothing():
    from topo._extract_kernels import skeleton_paths

    skel = np.zeros((5, 6), bool)
    coords, bounds, pixels = skeleton_paths(skel)
    assert coords.shape == (0, 2) and bounds.tolist() == [0] and len(pixels) == 0
    skel[1, 1] = skel[3, 4] = True
    coords, bounds, pixels = skeleton_paths(skel)
    assert coords.tolist() == [[1, 1], [3, 4]] and bounds.tolist() == [0] and len(pixels) == 0


@given(st.integers(0, 2**32 - 1), st.integers(0, 400), st.sampled_from([1.0, 0.1, 0.05]),
       st.booleans())
def test_polyline_length_is_numpys_float(seed, n, scale, reverse):
    """The compiled length is bit for bit numpy's (pairwise summation) on pixel paths, scaled
    paths and random points, contiguous or reversed views."""
    from topo._extract_kernels import polyline_length

    rng = np.random.default_rng(seed)
    poly = np.cumsum(rng.integers(-1, 2, (n, 2)), axis=0) * scale + rng.random((n, 2)) * (
        seed % 2)
    if reverse:
        poly = poly[::-1]
    d = poly[1:] - poly[:-1]
    assert polyline_length(poly) == float(np.sqrt((d * d).sum(axis=1)).sum())


@given(st.integers(0, 2**32 - 1), st.integers(1, 30), st.integers(1, 30), st.integers(0, 4),
       st.booleans())
def test_free_crop_is_the_numpy_crop(seed, h, w, n_free, strided):
    """The compiled crop to the free cells (grown by one cell, padded by a non-free border) is
    the numpy slice and ``np.pad``: free cells on the mask's edges, none, one, strided views."""
    from topo._extract_kernels import free_crop, free_crop_reference

    rng = np.random.default_rng(seed)
    mask = np.zeros((h, w), bool)
    mask[rng.integers(0, h, n_free), rng.integers(0, w, n_free)] = True
    if seed % 2:
        mask |= ndimage.binary_opening(rng.random((h, w)) < 0.6)
    if strided:
        mask = np.repeat(np.repeat(mask, 2, 0), 2, 1)[::2, ::2]
    got, want = free_crop(mask), free_crop_reference(mask)
    assert got[0].dtype == bool and got[0].shape == want[0].shape
    np.testing.assert_array_equal(got[0], want[0])
    assert got[1:] == want[1:]


@given(st.integers(0, 2**32 - 1), st.floats(0.2, 0.9), st.integers(3, 70), st.integers(3, 70),
       st.integers(0, 60), st.integers(-1, 4), st.floats(0.0, 80.0))
def test_clean_free_is_the_library_morphology(seed, density, h, w, max_hole, radius,
                                              min_cells):
    """The compiled free-space clean-up (hole filling, erosion by a disk, dropping small
    components) gives exactly skimage's and scipy's mask, on random blobs with holes, specks
    and free cells on the array's edge."""
    from skimage.morphology import disk

    from topo._extract_kernels import clean_free, clean_free_reference

    rng = np.random.default_rng(seed)
    given = rng.random((h, w)) < density
    if seed % 3:
        given = ndimage.binary_opening(given)
    footprint = None if radius < 0 else disk(radius)
    got = clean_free(given, max_hole, footprint, min_cells)
    np.testing.assert_array_equal(got, clean_free_reference(given, max_hole, footprint,
                                                            min_cells))


@given(st.integers(0, 2**32 - 1), st.floats(0.1, 0.95), st.integers(1, 50), st.integers(1, 50))
def test_wall_distances_are_the_kd_trees(seed, density, h, w):
    """The compiled free-disc radius (a search in square rings) is the cKDTree distance to the
    wall pixels, bit for bit, at free and non-free pixels and points between pixels (inf when
    no pixel borders free space)."""
    from topo._extract_kernels import wall_distances, wall_distances_reference

    rng = np.random.default_rng(seed)
    free = np.pad(rng.random((h, w)) < density, 1)
    points = rng.integers(0, [h + 2, w + 2], (20, 2)).astype(np.float64)
    points[10:] += rng.uniform(-0.5, 0.5, (10, 2))  # merged node means lie between pixels
    np.testing.assert_array_equal(wall_distances(free, points),
                                  wall_distances_reference(free, points))
    assert np.isinf(wall_distances(np.zeros((4, 4), bool), points[:3])).all()


def _peaks_reference(turn, candidate, group):
    """The numpy form of the corner peaks (as extract_topomap had it): each run of consecutive
    candidates within a group, its sharpest point, the middle one of equally sharp ones."""
    idx = np.flatnonzero(candidate)
    if len(idx) == 0:
        return idx
    breaks = np.flatnonzero((np.diff(idx) != 1) | (np.diff(group[idx]) != 0)) + 1
    out = []
    for run in np.split(idx, breaks):
        t = turn[run]
        best = run[np.flatnonzero(t >= t.max() - 1e-9)]
        out.append(int(best[len(best) // 2]))
    return np.asarray(out, dtype=np.int64)


@given(st.integers(0, 2**32 - 1), st.integers(0, 300), st.sampled_from([0.3, 0.6, 0.9]))
def test_corner_peaks_kernel_is_the_numpy_form(seed, n, density):
    """Ties (quantised turns, and turns within 1e-9), runs across group boundaries, empty
    input."""
    from topo._extract_kernels import peaks

    rng = np.random.default_rng(seed)
    turn = np.round(rng.uniform(0, 3, n), int(rng.integers(0, 3)))
    turn[rng.random(n) < 0.1] += 5e-10
    candidate = rng.random(n) < density
    group = np.sort(rng.integers(0, max(n // 10, 1), n))
    np.testing.assert_array_equal(peaks(turn, candidate, group),
                                  _peaks_reference(turn, candidate, group))


def assert_same_maps(a, b):
    """Two TopoMaps equal bit for bit (arrays, dtypes, polylines)."""
    for f in ("xy", "kinds", "edges", "lengths"):
        x, y = getattr(a, f), getattr(b, f)
        assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes(), f
    assert (a.paths is None) == (b.paths is None)
    if a.paths is not None:
        assert len(a.paths) == len(b.paths)
        for p, q in zip(a.paths, b.paths, strict=True):
            assert p.dtype == q.dtype and p.shape == q.shape and p.tobytes() == q.tobytes()


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.4, 0.8), st.integers(8, 80), st.integers(8, 80),
       st.sampled_from([1.0, 0.5, 0.25]), st.booleans())
def test_topomap_output_kernel_is_the_loop(seed, density, h, w, res, sonar):
    """The compiled conversion of the cleaned-up graph to a TopoMap (metres, turned polylines,
    lengths) gives exactly the edge-by-edge form's map, on random blobs' graphs (coarse cells,
    so most have tens of paths: loops, parallel paths, isolated nodes; some are empty)."""
    from topo import extract

    to_topomap = extract._to_topomap
    seen = []

    def both(g, res_, origin):
        got = to_topomap(g, res_, origin)
        assert_same_maps(got, extract._to_topomap_loop(g, res_, origin))
        seen.append(got)
        return got

    rng = np.random.default_rng(seed)
    mask = ndimage.binary_opening(rng.random((h, w)) < density)
    cfg = ExtractConfig.for_sonar() if sonar else ExtractConfig()
    with pytest.MonkeyPatch.context() as m:
        m.setattr(extract, "_to_topomap", both)
        m.setattr(extract, "_graph_topomap", extract._graph_topomap_reference)  # its caller
        extract_topomap(mask, resolution=res, origin=(rng.uniform(-5, 5), rng.uniform(-5, 5)),
                        config=cfg)
    assert len(seen) == int(mask.any())


@settings(max_examples=80, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.2, 0.9), st.integers(1, 70), st.integers(1, 70),
       st.integers(0, 3))
def test_skeletonize_is_skimages(seed, density, h, w, opening):
    """The compiled Zhang–Suen thinning gives exactly ``skimage.morphology.skeletonize``, on
    noise and on opened blobs (thick regions, holes, touching borders)."""
    from skimage.morphology import skeletonize as skimage_skeletonize

    from topo._extract_kernels import skeletonize

    rng = np.random.default_rng(seed)
    mask = rng.random((h, w)) < density
    if opening:
        mask = ndimage.binary_opening(mask, iterations=opening)
    got = skeletonize(mask)
    assert got.dtype == bool and got.shape == mask.shape
    np.testing.assert_array_equal(got, skimage_skeletonize(mask))


def test_skeletonize_on_every_small_image():
    """Every image up to 4×4 (the images that fix most of the lookup table,
    ``tests/topo/zhang_lut_derivation.py``), and empty and full ones."""
    from skimage.morphology import skeletonize as skimage_skeletonize

    from topo._extract_kernels import skeletonize

    for h, w in ((1, 1), (2, 3), (3, 3), (4, 4), (3, 5), (5, 3)):
        bits = (np.arange(1 << (h * w))[:, None] >> np.arange(h * w)) & 1
        for row in bits.astype(bool):
            mask = row.reshape(h, w)
            np.testing.assert_array_equal(skeletonize(mask), skimage_skeletonize(mask))
    for mask in (np.zeros((6, 9), bool), np.ones((6, 9), bool), np.ones((40, 3), bool)):
        np.testing.assert_array_equal(skeletonize(mask), skimage_skeletonize(mask))


def test_skeletonize_table_code_10_timing_is_invisible():
    """The one table entry skimage's outputs leave open (in which subpass code 10 goes) cannot
    change an output (``zhang_lut_derivation.code_10_timing_is_invisible``, restated)."""
    from topo._extract_kernels import _ZHANG_LUT

    nw, n, ne, e, se, s, sw, w = (1 << i for i in range(8))
    north = [s | se | a | b | c for a in (0, nw) for b in (0, n) for c in (0, ne)]
    east = [nw | w | a | b | c for a in (0, ne) for b in (0, e) for c in (0, se)]
    assert all(_ZHANG_LUT[m] == 0 and _ZHANG_LUT[m & ~s] == 0 for m in north)
    assert all(_ZHANG_LUT[m] == 0 and _ZHANG_LUT[m & ~w] == 0 for m in east)
    assert _ZHANG_LUT[10] == _ZHANG_LUT[40] == _ZHANG_LUT[160] == _ZHANG_LUT[130] == 3


@settings(max_examples=80, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 12), st.floats(0.5, 12.0),
       st.floats(0.1, 2.5), st.floats(0.0, 6.0))
def test_open_corners_kernels_are_the_numpy_form(seed, n_polys, arm, min_turn, margin):
    """The compiled corner step (arc lengths, chord products, candidates, peaks) gives the
    numpy form's corner indices, and its arc lengths and chord products are numpy's floats,
    on random 8-connected pixel walks (repeated points, straight runs, sharp turns)."""
    from topo import extract
    from topo._extract_kernels import corner_arms

    rng = np.random.default_rng(seed)
    moves = np.array([[-1, -1], [-1, 0], [-1, 1], [0, 1], [1, 1], [1, 0], [1, -1], [0, -1],
                      [0, 0]], dtype=np.float64)
    polys = []
    for _ in range(n_polys):
        k = int(rng.integers(2, 60))
        heading = rng.integers(0, 8, size=k)
        heading[rng.random(k) < 0.6] = heading[0]  # long straight runs, then turns
        if rng.random() < 0.3:
            heading[rng.integers(0, k)] = 8  # a repeated point
        start = rng.integers(0, 50, size=2).astype(np.float64)
        polys.append(np.concatenate([start[None], start + np.cumsum(moves[heading], axis=0)]))
    assert extract._open_corners(polys, arm, min_turn, margin) == \
        extract._open_corners_numpy(polys, arm, min_turn, margin)
    points = np.concatenate(polys)
    lens = np.array([len(p) for p in polys], dtype=np.int64)
    arc, cross, dot = corner_arms(points, lens, arm)
    first = np.concatenate([[0], np.cumsum(lens)[:-1]])
    step = np.zeros(len(points))
    d = np.diff(points, axis=0)
    step[1:] = np.sqrt((d * d).sum(axis=1))
    step[first] = 2.0 * arm + 1.0
    step[0] = 0.0
    want_arc = np.cumsum(step)
    assert arc.tobytes() == want_arc.tobytes()
    group = np.repeat(np.arange(len(polys)), lens)
    lo, hi = first[group], (first + lens - 1)[group]
    back = np.maximum(np.searchsorted(want_arc, want_arc - arm, side="right") - 1, lo)
    ahead = np.minimum(np.searchsorted(want_arc, want_arc + arm, side="left"), hi)
    a, b = points - points[back], points[ahead] - points
    assert cross.tobytes() == (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).tobytes()
    assert dot.tobytes() == (a * b).sum(axis=1).tobytes()


@settings(max_examples=80, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(2, 200), st.floats(0.5, 12.0),
       st.floats(0.1, 2.5), st.floats(0.0, 6.0), st.booleans())
def test_loop_corners_kernel_is_the_numpy_form(seed, k, arm, min_turn, margin, ring):
    """The corner step on a closed polyline with the compiled arcs and chord products gives the
    numpy form's corners, for one margin and for several at once: random closed pixel walks
    (straight runs, repeated points, a jump back to the start) and rectangles' rings."""
    from topo import extract

    rng = np.random.default_rng(seed)
    if ring:
        h, w = int(rng.integers(1, 30)), int(rng.integers(1, 30))
        corners = np.array([[0, 0], [0, w], [h, w], [h, 0], [0, 0]], dtype=np.float64)
        poly = np.concatenate([np.linspace(a, b, int(max(abs(b - a).max(), 1)) + 1)[:-1]
                               for a, b in zip(corners[:-1], corners[1:], strict=True)]
                              + [corners[:1]])
        poly = np.roll(poly[:-1], int(rng.integers(0, len(poly) - 1)), axis=0)
        poly = np.concatenate([poly, poly[:1]])
    else:
        moves = np.array([[-1, -1], [-1, 0], [-1, 1], [0, 1], [1, 1], [1, 0], [1, -1], [0, -1],
                          [0, 0]], dtype=np.float64)
        heading = rng.integers(0, 8, size=k)
        heading[rng.random(k) < 0.6] = heading[0]
        heading[rng.random(k) < 0.05] = 8
        walk = np.cumsum(moves[heading], axis=0)
        poly = np.concatenate([[[0.0, 0.0]], walk, [[0.0, 0.0]]])
    want = [extract._loop_corners_numpy(poly, arm, min_turn, m) for m in (margin, 0.0)]
    got = extract._loop_corner_sets(poly, arm, min_turn, (margin, 0.0))
    for a, b in zip(got, want, strict=True):
        assert a.dtype == b.dtype
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(extract._loop_corners(poly, arm, min_turn, margin), want[0])


# ---------------------------------------------------------------- the compiled clean-up
@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(st.booleans(), st.integers(0, 3), st.booleans()), max_size=80),
       st.integers(0, 9))
def test_node_rows_keep_paths_in_ascending_id(ops, width):
    """The compiled clean-up's per-node rows of path ids are ``sorted(inc[n])`` after every new
    path (a new path has the highest id yet; a loop joins its node once) and every removal; a
    full row sets the overflow flag and is left as it was."""
    from topo._extract_kernels import DEG, OVER, _attach, _detach

    ni = np.zeros((2, 4), dtype=np.int64)
    inc = np.full((2, width), -7, dtype=np.int64)
    cnt = np.zeros(4, dtype=np.int64)
    ref: list[set[int]] = [set(), set()]
    next_id = 0
    for add, pick, loop in ops:
        if add:
            ends = (0, 0) if loop else (0, 1)
            for n in ends:
                before = inc[n].copy()
                _attach(ni, inc, cnt, n, next_id)
                if len(ref[n] | {next_id}) > width:
                    assert cnt[OVER] and (inc[n] == before).all()
                    return
                ref[n].add(next_id)
            next_id += 1
        else:
            key = pick if not ref[0] else sorted(ref[0])[pick % len(ref[0])]
            _detach(ni, inc, 0, key)
            ref[0].discard(key)
        assert not cnt[OVER]
        for n in (0, 1):
            assert inc[n, : ni[n, DEG]].tolist() == sorted(ref[n])


def _compare(monkeypatch):
    """Make ``extract_topomap`` compute each map both ways and compare; returns the list of
    compared maps."""
    from topo import extract

    seen = []
    compiled = extract._graph_topomap

    def both(*args):
        got = compiled(*args)
        assert_same_maps(got, extract._graph_topomap_reference(*args))
        seen.append(got)
        return got

    monkeypatch.setattr(extract, "_graph_topomap", both)
    return seen


@settings(max_examples=80, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.35, 0.85), st.integers(4, 90), st.integers(4, 90),
       st.sampled_from([1.0, 0.5, 0.25, 0.1]), st.booleans(), st.integers(0, 2))
def test_compiled_clean_up_is_the_python_passes(seed, density, h, w, res, sonar, opening):
    """Bit for bit the map of ``_Graph``'s passes, on random blobs' skeletons at coarse and fine
    cells (spurs, junction clusters, loops, parallel paths, corners, isolated nodes, nodes off
    free space, empty maps), with both configs."""
    rng = np.random.default_rng(seed)
    mask = rng.random((h, w)) < density
    if opening:
        mask = ndimage.binary_opening(mask, iterations=opening)
    cfg = ExtractConfig.for_sonar() if sonar else ExtractConfig()
    with pytest.MonkeyPatch.context() as m:
        seen = _compare(m)
        extract_topomap(mask, resolution=res, origin=(rng.uniform(-5, 5), rng.uniform(-5, 5)),
                        config=cfg)
    assert len(seen) == int(mask.any())


class _BackwardsSet(set):
    """A set iterating in descending order (whatever CPython's layout would give)."""

    def __iter__(self):
        return iter(sorted(set.__iter__(self), reverse=True))


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.45, 0.75), st.sampled_from([0.25, 0.1]),
       st.booleans())
def test_python_passes_do_not_depend_on_set_order(seed, density, res, sonar):
    """``_Graph``'s map is the same when its sets of a node's paths iterate backwards: every
    pass visits them in an explicit order (``paths_of``), not in the set's."""
    from topo import extract

    rng = np.random.default_rng(seed)
    mask = ndimage.binary_opening(rng.random((70, 80)) < density)
    cfg = ExtractConfig.for_sonar() if sonar else ExtractConfig()
    args = []
    with pytest.MonkeyPatch.context() as m:
        m.setattr(extract, "_graph_topomap", lambda *a: args.append(a) or TopoMap.empty())
        extract_topomap(mask, resolution=res, config=cfg)
    if not args:
        return
    want = extract._graph_topomap_reference(*args[0])
    start, add_node = extract._Graph.start, extract._Graph.add_node

    def start_backwards(self, *a):
        start(self, *a)
        self.inc = {n: _BackwardsSet(s) for n, s in self.inc.items()}

    def add_node_backwards(self, rc):
        n = add_node(self, rc)
        self.inc[n] = _BackwardsSet()
        return n

    with pytest.MonkeyPatch.context() as m:
        m.setattr(extract._Graph, "start", start_backwards)
        m.setattr(extract._Graph, "add_node", add_node_backwards)
        assert_same_maps(extract._graph_topomap_reference(*args[0]), want)


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**32 - 1), st.sampled_from([4, 1000]))
def test_compiled_clean_up_grows_its_arrays(seed, shrink):
    """Starting from arrays far too small, the compiled passes re-run with larger ones and give
    the same map."""
    from topo import extract

    rng = np.random.default_rng(seed)
    mask = ndimage.binary_opening(rng.random((60, 70)) < 0.6)
    with pytest.MonkeyPatch.context() as m:
        seen = _compare(m)
        m.setattr(extract, "_SHRINK", shrink)
        extract_topomap(mask, resolution=0.25)
    assert len(seen) == 1


def test_compiled_clean_up_on_real_maps(monkeypatch):
    """A real floor plan's crops (tens of junctions, long loops)."""
    seen = _compare(monkeypatch)
    plan = load_floor_plan(MAPS / "dungeon" / "1.png", resolution=0.1)
    for r0, c0 in ((0, 0), (150, 200), (230, 390)):
        extract_topomap(np.ascontiguousarray(plan.free[r0: r0 + 250, c0: c0 + 250]), 0.1)
    assert len(seen) == 3 and max(m.n_nodes for m in seen) >= 10


def test_compiled_clean_up_on_every_env_extraction(monkeypatch):
    """Every extraction of a short env episode (the robots' sonar grids, ``for_sonar``)."""
    from envs import two_robot_explore_v0

    seen = _compare(monkeypatch)
    par = two_robot_explore_v0.parallel_env(max_cycles=300, mapping={"topo_every": 5})
    par.reset(seed=4)
    rng = np.random.default_rng(4)
    while par.agents:
        par.step({a: np.array([rng.uniform(0.3, 1.0), rng.uniform(-1, 1)]) for a in par.agents})
    assert len(seen) >= 100 and max(m.n_nodes for m in seen) >= 10
