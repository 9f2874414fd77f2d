"""merge_grids / hybrid_merge: recovery on grids of a known plan, ambiguity and no-overlap
rejection, degenerate input."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage

from fusion import Rigid2D
from fusion.evaluation.pairs import GridSnapshot
from fusion.grid_merge import (
    GridMergeConfig,
    check_with_grids,
    drift_prior,
    grid_agreement,
    merge_grids,
    refine_with_grids,
)
from fusion.hybrid import hybrid_merge, recheck
from topo import TopoMap

RES = 0.1
TINY = TopoMap.from_arrays([[0, 0], [1, 0]], [[0, 1]])  # too small for the structural merge


def plan(seed: int = 0) -> np.ndarray:
    """An asymmetric indoor plan (cell states: 1 free, 2 wall) of 30 x 30 m."""
    rng = np.random.default_rng(seed)
    s = np.full((300, 300), 2, np.int8)
    for _ in range(14):  # rooms and corridors of random sizes
        r, c = rng.integers(10, 230, 2)
        h, w = rng.integers(15, 70, 2)
        s[r: r + h, c: c + w] = 1
    s[:3], s[-3:], s[:, :3], s[:, -3:] = 2, 2, 2, 2
    # a sensor sees walls, not the inside of solid blocks: keep wall cells next to free space
    near_free = ndimage.binary_dilation(s == 1, iterations=2)
    s[(s == 2) & ~near_free] = 0
    return s


def view(states: np.ndarray, frame: Rigid2D, lo, hi) -> GridSnapshot:
    """What a robot whose frame is ``frame`` (its points → plan points) knows of the plan box
    ``lo..hi`` (plan metres): its own grid, sampled from the plan, unknown elsewhere."""
    corners = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [lo[0], hi[1]], [hi[0], hi[1]]])
    own = frame.inverse().apply(corners)
    o = own.min(axis=0) - 1.0
    n = np.ceil((own.max(axis=0) + 1.0 - o) / RES).astype(int)
    rows, cols = np.mgrid[0: n[1], 0: n[0]]
    pts = np.stack([o[0] + (cols + 0.5) * RES, o[1] + (rows + 0.5) * RES], -1).reshape(-1, 2)
    p = frame.apply(pts)
    ij = np.floor(p / RES).astype(int)
    inside = ((p[:, 0] >= lo[0]) & (p[:, 0] < hi[0]) & (p[:, 1] >= lo[1]) & (p[:, 1] < hi[1]))
    out = np.zeros(len(pts), np.int8)
    out[inside] = states[ij[inside, 1], ij[inside, 0]]
    return GridSnapshot(out.reshape(n[1], n[0]), RES, (float(o[0]), float(o[1])))


def overlapping_views(deg: float, frame_a: Rigid2D | None = None,
                      shift=(10.0, 4.0)) -> tuple[GridSnapshot, GridSnapshot, Rigid2D]:
    """Two robots' grids of plan 1 overlapping on (8..20, 6..22) m, and the true B → A."""
    frame_a = frame_a or Rigid2D.identity()
    frame_b = Rigid2D(frame_a.theta + math.radians(deg), shift)
    states = plan(1)
    a = view(states, frame_a, (1, 1), (20, 22))
    b = view(states, frame_b, (8, 6), (28, 28))
    return a, b, frame_a.inverse() @ frame_b


@pytest.mark.parametrize("deg", [0.0, 37.0, 133.0, 251.0])
def test_recovers_the_transform_of_overlapping_views(deg):
    a, b, truth = overlapping_views(deg, Rigid2D.from_degrees(20.0, (3.0, 2.0)), (12.0, 5.0))
    res = merge_grids(a, b)
    centre = np.array([0.0, 0.0])
    assert res.accepted, res.reason
    assert math.degrees(res.transform.rotation_error(truth)) < 1.0
    assert res.transform.translation_error(truth, at=centre) < 0.15


def test_disjoint_views_are_rejected():
    states = plan(2)
    frame = Rigid2D.from_degrees(10.0, (0.0, 0.0))
    a = view(states, frame, (1, 1), (12, 12))
    b = view(states, frame, (17, 17), (29, 29))
    assert not merge_grids(a, b).accepted


def test_a_symmetric_room_is_ambiguous():
    s = np.zeros((120, 120), np.int8)
    s[18:102, 28:92] = 2
    s[20:100, 30:90] = 1  # a plain rectangle looks the same after a half turn
    g = GridSnapshot(s, RES, (0.0, 0.0))
    res = merge_grids(g, g)
    # a perfect fit, but the half turn fits as well: the confidence says so
    assert res.wall_agreement == 1.0 and res.margin == pytest.approx(1.0, abs=0.01)
    assert not res.accepted and res.confidence <= 0.5
    assert "margin 1.00 over a distinct alignment" in res.reason


def test_nothing_known_is_a_reason_not_an_error():
    empty = GridSnapshot(np.zeros((10, 10), np.int8), RES, (0.0, 0.0))
    res = merge_grids(empty, empty)
    assert not res.accepted and res.reason == "a grid has no known cells"


def test_hybrid_falls_back_to_the_grids_and_fuses_the_maps():
    a, b, truth = overlapping_views(90.0)
    res = hybrid_merge(TINY, TINY, a, b)
    assert res.accepted and res.method == "hybrid"
    assert math.degrees(res.transform.rotation_error(truth)) < 1.0
    rejected = hybrid_merge(TINY, TINY, a, b, try_grids=False)
    assert not rejected.accepted


def test_bad_config():
    with pytest.raises(ValueError, match="GridMergeConfig.resolution must be > 0.0"):
        GridMergeConfig(resolution=0.0)
    with pytest.raises(ValueError, match="GridMergeConfig.min_wall_agreement must be <= 1.0"):
        GridMergeConfig(min_wall_agreement=2.0)
    with pytest.raises(ValueError, match="GridMergeConfig.coarse_factor must be >= 1, got 0"):
        GridMergeConfig(coarse_factor=0)
    with pytest.raises(TypeError, match="GridMergeConfig.refine_top must be an integer"):
        GridMergeConfig(refine_top=2.5)


def test_coarse_sweep_finds_what_the_full_resolution_sweep_finds():
    # the coarse-to-fine search must not lose the alignment the exhaustive sweep finds
    a, b, truth = overlapping_views(133.0, Rigid2D.from_degrees(20.0, (3.0, 2.0)), (12.0, 5.0))
    full = merge_grids(a, b, GridMergeConfig(coarse_factor=1, refine_top=1))
    fast = merge_grids(a, b, GridMergeConfig(coarse_factor=3))
    assert full.accepted and fast.accepted
    assert math.degrees(fast.transform.rotation_error(full.transform)) < 1.0
    assert fast.transform.translation_error(full.transform, at=np.zeros(2)) < 0.15


def test_grids_refute_a_wrong_transform():
    a, b, truth = overlapping_views(60.0)
    assert check_with_grids(a, b, truth) is None
    why = check_with_grids(a, b, Rigid2D.from_degrees(90.0) @ truth)
    assert why is not None and "wall agreement" in why


def test_recheck_replaces_a_wrong_transform_in_use_the_grids_disprove():
    a, b, truth = overlapping_views(90.0)
    for in_use in (truth, Rigid2D.from_degrees(180.0, (6.0, -3.0)) @ truth):
        res, refuted = recheck(TINY, TINY, a, b, in_use)
        assert res.accepted and refuted is None  # the caller installs res.transform
        assert math.degrees(res.transform.rotation_error(truth)) < 1.0


def test_recheck_refutes_a_transform_the_grids_no_longer_support():
    """A symmetric room: no alignment is confident, but every good one is far from a transform
    that shifts the room by 4 m, so that one is refuted; one of the room's own symmetries is
    kept (nothing clearly better)."""
    s = np.zeros((120, 120), np.int8)
    s[18:102, 28:92] = 2
    s[20:100, 30:90] = 1
    g = GridSnapshot(s, RES, (0.0, 0.0))
    res, refuted = recheck(TINY, TINY, g, g, Rigid2D(0.0, (4.0, 0.0)))
    assert not res.accepted
    assert refuted is not None and refuted.startswith("the grids refute the transform in use")
    assert refuted in res.reason
    assert recheck(TINY, TINY, g, g, merge_grids(g, g).transform)[1] is None


def test_grid_agreement_supports_the_truth_over_a_wrong_transform():
    a, b, truth = overlapping_views(60.0)
    right = grid_agreement(a, b, truth)
    wrong = grid_agreement(a, b, Rigid2D.from_degrees(90.0) @ truth)
    assert right.wall_agreement > 0.8 and right.conflict < 0.1
    assert right.support == pytest.approx(right.wall_hits * (right.wall_agreement
                                                             - right.conflict))
    assert right.support > 5 * max(wrong.support, 1.0)
    empty = GridSnapshot(np.zeros((10, 10), np.int8), RES, (0.0, 0.0))
    assert grid_agreement(a, empty, truth) is None
    with pytest.raises(TypeError, match="transform must be a fusion.Rigid2D, got ndarray"):
        grid_agreement(a, b, np.eye(3))


def test_a_confident_look_alike_does_not_replace_a_better_supported_transform(monkeypatch):
    """An accepted alignment clearly different from the transform in use (a look-alike part of
    the building) is rejected when the grids support the one in use better, and does not
    refute it; with nothing in use, or a worse-supported one, it is taken."""
    import dataclasses

    import fusion.grid_merge as gm

    a, b, truth = overlapping_views(90.0)
    look_alike = Rigid2D.from_degrees(90.0, (3.0, 0.0)) @ truth
    real = gm.merge_grids
    monkeypatch.setattr(gm, "merge_grids", lambda ga, gb, config=None: dataclasses.replace(
        real(ga, gb, config), transform=look_alike, accepted=True, confidence=0.99))
    assert hybrid_merge(TINY, TINY, a, b).accepted  # nothing in use: taken
    res = hybrid_merge(TINY, TINY, a, b, in_use=truth)
    assert not res.accepted
    assert "the grids support the transform in use better" in res.reason
    res, refuted = recheck(TINY, TINY, a, b, truth)
    assert not res.accepted and refuted is None
    res, refuted = recheck(TINY, TINY, a, b, Rigid2D.from_degrees(180.0, (6.0, -3.0)) @ truth)
    assert res.accepted and res.transform is not None and refuted is None
    with pytest.raises(TypeError, match=r"in_use must be a fusion.Rigid2D \(the transform in "
                                        r"use\) or None, got ndarray"):
        hybrid_merge(TINY, TINY, a, b, in_use=np.eye(3))


def test_the_transform_in_use_stays_only_when_clearly_better_supported(monkeypatch):
    """In a building of repeated rooms a look-alike in use can out-support a confident right
    alignment a little (support grows with the overlap); it stays only when the grids support
    it more than IN_USE_MARGIN times better than the new one."""
    import dataclasses

    import fusion.grid_merge as gm
    import fusion.hybrid as hy

    a, b, truth = overlapping_views(90.0)
    in_use = Rigid2D.from_degrees(90.0, (3.0, 0.0)) @ truth
    real = gm.merge_grids
    monkeypatch.setattr(gm, "merge_grids", lambda ga, gb, config=None: dataclasses.replace(
        real(ga, gb, config), transform=truth, accepted=True, confidence=0.99))
    real_agreement = gm.grid_agreement
    for ratio, replaced in ((1.2, True), (0.9 * hy.IN_USE_MARGIN, True),
                            (1.1 * hy.IN_USE_MARGIN, False), (3.0, False)):
        def agreement(ga, gb, transform, config=None, ratio=ratio):
            out = real_agreement(ga, gb, truth, config)  # the new one's, scaled for in_use
            if transform is in_use:
                return out._replace(wall_hits=int(round(out.wall_hits * ratio)))
            return out
        monkeypatch.setattr(gm, "grid_agreement", agreement)
        res = hybrid_merge(TINY, TINY, a, b, in_use=in_use)
        assert res.accepted is replaced, ratio
        assert replaced or "the grids support the transform in use better" in res.reason


def test_recheck_needs_a_transform_in_use():
    a, b, _ = overlapping_views(90.0)
    with pytest.raises(TypeError, match=r"in_use must be a fusion.Rigid2D \(the transform in "
                                        r"use\), got ndarray"):
        recheck(TINY, TINY, a, b, np.eye(3))


def _pooled_numpy(states: np.ndarray, fine: float, res: float):
    """The obvious form of the crop-and-pool: nonzero for the known box, block reductions."""
    rows, cols = np.nonzero(states != 0)
    f = max(1, int(round(res / fine)))
    r0, c0 = rows.min(), cols.min()
    h, w = (rows.max() - r0) // f + 1, (cols.max() - c0) // f + 1
    crop = np.zeros((h * f, w * f), dtype=states.dtype)
    part = states[r0: r0 + h * f, c0: c0 + w * f]
    crop[: part.shape[0], : part.shape[1]] = part
    blocks = crop.reshape(h, f, w, f)
    wall = (blocks == 2).any(axis=(1, 3))
    free = ((blocks == 1).sum(axis=(1, 3)) * 2 > f * f) & ~wall
    return wall, free, np.array([c0, r0]) * fine


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000), res=st.sampled_from([0.1, 0.2, 0.3, 0.4]))
def test_pooling_kernels_are_the_numpy_form(seed, res):
    """The known box and fusion._kernels.pool (via grid_merge._pooled, one or several
    resolutions in one read) give the masks and origin of the numpy reductions, known cells
    reaching the grid's edges included."""
    from fusion.grid_merge import _pooled

    rng = np.random.default_rng(seed)
    states = np.zeros(tuple(rng.integers(5, 40, 2)), dtype=np.int8)
    r, c = rng.integers(0, states.shape[0]), rng.integers(0, states.shape[1])
    states[r:, c:] = rng.choice([0, 1, 1, 2], size=states[r:, c:].shape)
    states[r, c] = 1
    snap = GridSnapshot(states, RES, (0.0, 0.0))
    wall, free, origin = _pooled(snap, res)
    ref = _pooled_numpy(states, RES, res)
    np.testing.assert_array_equal(wall, ref[0])
    np.testing.assert_array_equal(free, ref[1])
    np.testing.assert_array_equal(origin, ref[2])
    (w1, f1, _), (w2, f2, _) = _pooled(snap, (RES, res))
    np.testing.assert_array_equal(w2, ref[0])
    np.testing.assert_array_equal(f2, ref[1])
    at_fine = _pooled_numpy(states, RES, RES)
    np.testing.assert_array_equal(w1, at_fine[0])
    np.testing.assert_array_equal(f1, at_fine[1])
    assert _pooled(GridSnapshot(np.zeros((4, 4), np.int8), RES, (0.0, 0.0)), res) is None


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_rotated_raster_kernel_is_the_numpy_form(seed):
    """fusion._kernels.raster_rotated sets the cells the fancy-indexed numpy form sets."""
    from fusion import _kernels as GK

    rng = np.random.default_rng(seed)
    pts = rng.uniform(-3.0, 3.0, (int(rng.integers(1, 60)), 2))
    centre, res = pts.mean(axis=0), 0.2
    radius = float(np.max(np.linalg.norm(pts - centre, axis=1)))
    side = int(math.ceil(2 * radius / res)) + 2
    half = side // 2
    thetas = rng.uniform(-math.pi, math.pi, 5)
    got = np.zeros((5, side, side), np.float32)
    GK.raster_rotated(got, pts, float(centre[0]), float(centre[1]), np.cos(thetas),
                      np.sin(thetas), res, half)
    want = np.zeros_like(got)
    c, s = np.cos(thetas)[:, None], np.sin(thetas)[:, None]
    d = pts - centre
    ix = np.floor((c * d[:, 0] - s * d[:, 1]) / res).astype(np.int64) + half
    iy = np.floor((s * d[:, 0] + c * d[:, 1]) / res).astype(np.int64) + half
    layer = np.broadcast_to(np.arange(5)[:, None], ix.shape)
    want[layer, side - 1 - iy, side - 1 - ix] = 1.0
    np.testing.assert_array_equal(got, want)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10_000), theta=st.floats(-math.pi, math.pi))
def test_window_scores_are_the_fft_score_map(seed, theta):
    """Correlator.box_scores (fusion._kernels.box_correlation) gives the FFT score map's
    block, at its edges too, up to single-precision rounding; window_best its best cell
    within reach."""
    from fusion.grid_layers import Correlator, cell_centres, pooled_layers

    cfg = GridMergeConfig()
    states = plan(seed % 7)
    grid_a = GridSnapshot(states[:200, :220], RES, (0.0, 0.0))
    grid_b = GridSnapshot(states[60:, 40:], RES, (4.0, 6.0))
    la, lb = pooled_layers(grid_a, 0.2), pooled_layers(grid_b, 0.2)
    pw, pf = cell_centres(lb[0], lb[2], 0.2), cell_centres(lb[1], lb[2], 0.2)
    centre = pw.mean(axis=0)
    radius = float(np.max(np.linalg.norm(np.vstack([pw, pf]) - centre, axis=1)))
    corr = Correlator(la[0], la[1], la[2], 0.2, pw, pf, centre, radius, cfg)
    _, at, smap = corr.best(np.array([theta]), keep_best=True)
    rng = np.random.default_rng(seed)
    h, w = smap.shape
    for r0, c0 in ((-3, -2), (h - 5, w - 4), tuple(rng.integers(0, (h - 9, w - 9)))):
        got = corr.box_scores(theta, int(r0), int(c0), 9, 9)
        want = np.zeros((9, 9))
        rows, cols = slice(max(r0, 0), r0 + 9), slice(max(c0, 0), c0 + 9)
        block = smap[rows, cols]
        want[rows.start - r0: rows.start - r0 + block.shape[0],
             cols.start - c0: cols.start - c0 + block.shape[1]] = block
        inside = np.zeros((9, 9), bool)
        inside[rows.start - r0: rows.start - r0 + block.shape[0],
               cols.start - c0: cols.start - c0 + block.shape[1]] = True
        np.testing.assert_allclose(got[inside], want[inside], atol=1e-3)
    r_best, c_best = divmod(int(at[0]), w)
    T = corr.translation(int(at[0]), theta, w)
    score, k = corr.window_best(theta, T, 3.0)
    assert score == pytest.approx(float(smap[r_best, c_best]), abs=1e-3)
    assert abs(k // w - r_best) <= 3 and abs(k % w - c_best) <= 3


def test_acceptance_is_the_confidence_against_the_threshold():
    a, b, truth = overlapping_views(37.0)
    res = merge_grids(a, b)
    assert 0.0 <= res.confidence <= 1.0
    assert res.confidence == pytest.approx(
        __import__("fusion.calibration", fromlist=["load_model"]).load_model("grid")(
            res.features()))
    assert res.accepted == (res.confidence >= GridMergeConfig().accept_threshold
                            and res.overlap_m2 >= GridMergeConfig().min_overlap_m2)
    strict = merge_grids(a, b, GridMergeConfig(accept_threshold=1.0))
    assert strict.transform.allclose(res.transform)  # the threshold only decides
    assert not strict.accepted and "accept_threshold=1.0" in strict.reason
    assert merge_grids(a, b, GridMergeConfig(accept_threshold=0.0)).accepted
    gated = merge_grids(a, b, GridMergeConfig(accept_threshold=0.0, min_overlap_m2=1e6))
    assert not gated.accepted and "min_overlap_m2" in gated.reason


def test_threshold_and_refinement_settings_are_checked():
    with pytest.raises(ValueError, match="GridMergeConfig.accept_threshold must be <= 1.0, got"
                                         " 1.5"):
        GridMergeConfig(accept_threshold=1.5)
    with pytest.raises(TypeError, match="GridMergeConfig.native_refine must be a bool, got int"):
        GridMergeConfig(native_refine=1)


def _fine(snapshot: GridSnapshot, factor: int) -> GridSnapshot:
    """The same grid with cells ``factor`` times finer (walls one fine cell thick)."""
    s = np.asarray(snapshot.states)
    up = np.kron(s, np.ones((factor, factor), np.int8))
    wall = up == 2
    up[wall & ndimage.binary_erosion(wall, iterations=1)] = 0  # thin walls: what a fine map sees
    return GridSnapshot(up, snapshot.resolution / factor, snapshot.origin)


def test_fine_grids_are_pooled_to_exact_cells_and_refined_on_their_own_cells():
    """Cells of 0.1 / 3 m do not pool to whole 0.2 m cells: rounding to 7 fine cells would
    stretch the map by 5 %; and the refinement on the grids' own cells is finer than the
    pooled alignment."""
    from fusion.grid_merge import _pooled

    s = np.zeros((10, 300), np.int8)
    s[:, 180] = 2  # a wall at x = 6.0–6.033 m
    s[:, :180] = 1
    wall, free, origin = _pooled(GridSnapshot(s, 0.1 / 3, (0.0, 0.0)), 0.2)
    assert np.flatnonzero(wall[0]).tolist() == [30]  # 6.0 m / 0.2 m
    assert free[0, :30].all() and not free[0, 31:].any()

    a, b, truth = overlapping_views(37.0, Rigid2D.from_degrees(20.0, (3.0, 2.0)), (12.0, 5.0))
    fa, fb = _fine(a, 3), _fine(b, 3)
    centre = np.array([15.0, 12.0])
    fine = merge_grids(fa, fb)
    coarse = merge_grids(fa, fb, GridMergeConfig(native_refine=False))
    err = fine.transform.translation_error(truth, at=centre)
    assert err < 0.06 and math.degrees(fine.transform.rotation_error(truth)) < 0.3
    assert err <= coarse.transform.translation_error(truth, at=centre) + 0.01


def test_hybrid_results_carry_the_grid_confidence_and_obey_the_threshold():
    from fusion.hybrid import HybridResult

    a, b, truth = overlapping_views(90.0)
    res = hybrid_merge(TINY, TINY, a, b)
    assert isinstance(res, HybridResult) and res.grid is not None
    assert res.confidence == res.grid.confidence and res.accepted == res.grid.accepted
    assert res.score == pytest.approx(math.log(res.confidence / (1 - res.confidence)))
    strict = hybrid_merge(TINY, TINY, a, b, config=GridMergeConfig(accept_threshold=1.0))
    assert not strict.accepted and "accept_threshold=1.0" in strict.reason
    without = hybrid_merge(TINY, TINY, a, b, try_grids=False)
    assert without.grid is None and not without.accepted and without.confidence == 0.0


def test_refine_with_grids_pulls_a_nearby_transform_onto_the_walls():
    """A transform 1.5° and 0.15 m off the truth (or 4° or 6°: more than the grid search's
    step), refined on two views of one room's walls (B's resampled by nearest cell, so a few
    cells alias), lands within 0.6° and 0.1 m of it; without ``native_refine`` it is returned
    unchanged."""
    a, b, truth = _pair_of_room_views()
    start = truth @ Rigid2D.from_degrees(1.5, (0.1, -0.1))
    refined = refine_with_grids(a, b, start)
    centre = np.array([2.0, 2.0])
    assert math.degrees(refined.rotation_error(truth)) < 0.6
    assert refined.translation_error(truth, at=centre) < 0.1
    assert refine_with_grids(a, b, start, GridMergeConfig(native_refine=False)) is start
    # a structural merge can be degrees off: more than merge_grids' own step, still refined
    for deg in (4.0, 6.0):
        refined = refine_with_grids(a, b, truth @ Rigid2D.from_degrees(deg, (0.1, -0.1)))
        assert math.degrees(refined.rotation_error(truth)) < 0.6
        assert refined.translation_error(truth, at=centre) < 0.1
    with pytest.raises(TypeError, match="transform must be a fusion.Rigid2D, got tuple"):
        refine_with_grids(a, b, (0, 0, 0))


def _pair_of_room_views():
    """A 6 x 4 m room with a wall stub, as seen from two frames related by ``truth``."""
    states = np.zeros((60, 80), dtype=np.int8)
    states[5:55, 5:75] = 1
    states[5:55, [5, 74]] = 2
    states[[5, 54], 5:75] = 2
    states[25:55, 40] = 2
    truth = Rigid2D.from_degrees(30.0, (1.0, -0.5))
    a = GridSnapshot(states, RES, (0.0, 0.0))
    # B: the same cells, resampled in B's frame (A = truth · B)
    h, w = states.shape
    ys, xs = np.mgrid[0:h, 0:w]
    pts_b = np.stack([(xs + 0.5) * RES - 3.0, (ys + 0.5) * RES - 3.0], -1).reshape(-1, 2)
    pts_a = truth.apply(pts_b)
    ij = np.floor(pts_a / RES).astype(int)
    ok = (ij[:, 0] >= 0) & (ij[:, 0] < w) & (ij[:, 1] >= 0) & (ij[:, 1] < h)
    sb = np.zeros(h * w, dtype=np.int8)
    sb[ok] = states[ij[ok, 1], ij[ok, 0]]
    b = GridSnapshot(sb.reshape(h, w), RES, (-3.0, -3.0))
    return a, b, truth


def test_recheck_drops_a_transform_in_use_whose_confidence_fell_by_the_margin(monkeypatch):
    """Drift bends the maps: the grids still align them where the transform in use does, but
    no longer trust it. With a drift prior, below accept_threshold − drop_margin the merge is
    dropped; within the margin it stays (no drop-and-accept flicker at the threshold);
    without a drift prior the rule is off."""
    import dataclasses

    import fusion.grid_merge as gm

    a, b, truth = overlapping_views(90.0)
    cfg = GridMergeConfig(drift_prior=0.02)
    real = gm.merge_grids
    for confidence, dropped in ((0.2, True), (cfg.accept_threshold - cfg.drop_margin - 0.01, True),
                                (cfg.accept_threshold - cfg.drop_margin + 0.01, False)):
        monkeypatch.setattr(gm, "merge_grids", lambda ga, gb, config=None, c=confidence:
                            dataclasses.replace(real(ga, gb, config), accepted=False,
                                                confidence=c, reason="low confidence"))
        assert recheck(TINY, TINY, a, b, truth)[1] is None  # no drift prior: kept
        res, why = recheck(TINY, TINY, a, b, truth, cfg)
        assert not res.accepted and res.grid.margin > gm.TIE_MARGIN
        assert (why is not None) is dropped, confidence
        if dropped:
            assert why.startswith(f"the grids no longer trust the transform in use: their "
                                  f"alignment of it has confidence {confidence:.2f} < "
                                  f"accept_threshold - drop_margin = 0.60")
            assert why in res.reason
    # the same low confidence from a tie of look-alikes (a symmetric room) keeps it
    monkeypatch.setattr(gm, "merge_grids", lambda ga, gb, config=None: dataclasses.replace(
        real(ga, gb, config), accepted=False, confidence=0.2, margin=1.0, reason="a tie"))
    assert recheck(TINY, TINY, a, b, truth, cfg)[1] is None


def test_drop_margin_is_checked():
    with pytest.raises(ValueError, match="GridMergeConfig.drop_margin must be <= 1.0, got 1.5"):
        GridMergeConfig(drop_margin=1.5)


def test_with_vouch_or_drift_a_structural_merge_needs_the_grids_to_vouch(monkeypatch):
    """With ``vouch`` (the env's first merge of a pair) and with drifting odometry, an
    accepted structural merge also needs the grids' best alignment to be the same one at
    their calibrated confidence (which weighs the drift prior); otherwise they are not
    asked."""
    import dataclasses

    import fusion.grid_merge as gm
    import fusion.hybrid as hy

    a, b, truth = overlapping_views(90.0)
    real_topo = hy.merge_maps
    monkeypatch.setattr(hy, "merge_maps", lambda ma, mb, **kw: dataclasses.replace(
        real_topo(ma, mb, **kw), transform=truth, accepted=True, reason=None))
    calls = []
    real = gm.merge_grids

    def low(ga, gb, config=None):
        calls.append(config.drift_prior if config else 0.0)
        return dataclasses.replace(real(ga, gb, config), accepted=False, confidence=0.3,
                                   reason="low confidence")

    monkeypatch.setattr(gm, "merge_grids", low)
    res = hybrid_merge(TINY, TINY, a, b, try_grids=False, vouch=True)
    assert not res.accepted and calls == [0.0]
    assert ("structural merge refuted by the grids: the grids' confidence in it is 0.30 < "
            "accept_threshold=0.9;") in res.reason + ";"
    for in_use in (None, truth):  # without vouch or drift the grids are not asked
        res = hybrid_merge(TINY, TINY, a, b, try_grids=False, in_use=in_use)
        assert res.accepted and res.supplied_by == "structural" and calls == [0.0]
    drifting = GridMergeConfig(drift_prior=0.04)
    res = hybrid_merge(TINY, TINY, a, b, try_grids=False, config=drifting, in_use=truth)
    assert not res.accepted and calls == [0.0, 0.04]
    assert ("structural merge refuted by the grids: the grids' confidence in it is 0.30 < "
            "accept_threshold=0.9 (drift_prior 0.04)") in res.reason
    res = hybrid_merge(TINY, TINY, a, b, try_grids=True, config=drifting)
    assert not res.accepted and calls == [0.0, 0.04, 0.04]  # the grids aligned once, not twice
    monkeypatch.setattr(gm, "merge_grids", lambda ga, gb, config=None: dataclasses.replace(
        real(ga, gb, config), accepted=True, confidence=0.99, reason=None))
    res = hybrid_merge(TINY, TINY, a, b, try_grids=False, config=drifting)
    assert res.accepted and res.supplied_by == "structural"
    assert hybrid_merge(TINY, TINY, a, b, try_grids=False).accepted
    # confident grids whose best alignment is another one do not vouch for it either
    turned = Rigid2D.from_degrees(180.0) @ truth
    monkeypatch.setattr(gm, "merge_grids", lambda ga, gb, config=None: dataclasses.replace(
        real(ga, gb, config), transform=turned, accepted=True, confidence=0.99, reason=None))
    for config, vouch in ((None, True), (drifting, False)):
        res = hybrid_merge(TINY, TINY, a, b, try_grids=False, config=config, vouch=vouch)
        assert not res.accepted
        assert ("structural merge refuted by the grids: the grids' best alignment is another "
                "one") in res.reason
    # the env's entry point asks it of a pair's first merge (no transform in use) only
    from envs.explore.merging import run_merge

    assert not run_merge(TINY, TINY, "hybrid", a, b)[0].accepted
    assert run_merge(TINY, TINY, "hybrid", a, b, in_use=truth)[0].accepted
    assert run_merge(TINY, TINY, "hybrid", a, b, first_merge_check=False)[0].accepted
    with pytest.raises(TypeError, match="vouch must be a bool, got int"):
        hybrid_merge(TINY, TINY, a, b, vouch=1)


def test_drift_prior_is_the_noise_over_the_steps_and_a_feature():
    assert drift_prior(0.02, 1500) == pytest.approx(0.03)
    assert drift_prior(0.0, 3000) == 0.0
    with pytest.raises(ValueError, match="odometry_noise must be >= 0"):
        drift_prior(-0.1, 10)
    with pytest.raises(ValueError, match="steps must be >= 0"):
        drift_prior(0.1, -1)
    with pytest.raises(ValueError, match="GridMergeConfig.drift_prior must be >= 0"):
        GridMergeConfig(drift_prior=-0.5)
    a, b, _ = overlapping_views(37.0)
    res = merge_grids(a, b, GridMergeConfig(drift_prior=0.07))
    assert res.drift_prior == 0.07 and res.features()["drift_prior"] == 0.07


def test_layer_cache_gives_the_grids_own_layers_and_merge():
    """A LayerCache pools each resolution once, read-only, to the grid's own layers, and
    merge_grids / refine_with_grids give the same results on it as on the grid."""
    from fusion.grid_layers import LayerCache, pooled_layers
    from fusion.grid_refine import native_walls

    states = plan(3)
    grid_a = GridSnapshot(states[:220, :240], RES, (0.0, 0.0))
    grid_b = GridSnapshot(np.ascontiguousarray(np.rot90(states[70:, 50:])), RES, (2.0, -1.0))
    cache_a, cache_b = LayerCache(grid_a), LayerCache(grid_b)
    assert LayerCache.of(cache_a) is cache_a
    for res in (0.2, (0.2, 0.4)):
        want, got = pooled_layers(grid_a, res), pooled_layers(cache_a, res)
        for w, g in zip(want if isinstance(res, tuple) else [want],
                        got if isinstance(res, tuple) else [got], strict=True):
            for a, b in zip(w, g, strict=True):
                np.testing.assert_array_equal(a, b)
    assert pooled_layers(cache_a, 0.2)[0] is pooled_layers(cache_a, 0.2)[0]
    assert not pooled_layers(cache_a, 0.2)[0].flags.writeable
    np.testing.assert_array_equal(native_walls(cache_b)[0], native_walls(grid_b)[0])
    assert pooled_layers(LayerCache(GridSnapshot(np.zeros((5, 5), np.int8), RES, (0, 0))),
                         (0.2, 0.4)) is None
    r, rc = merge_grids(grid_a, grid_b), merge_grids(cache_a, cache_b)
    assert (r.transform.theta, tuple(r.transform.T), r.score, r.confidence, r.margin) == (
        rc.transform.theta, tuple(rc.transform.T), rc.score, rc.confidence, rc.margin)
    t, tc = refine_with_grids(grid_a, grid_b, r.transform), refine_with_grids(cache_a, cache_b,
                                                                             r.transform)
    assert t.theta == tc.theta and np.array_equal(t.T, tc.T)
    # A's wall trees were built once and are reused: a second merge gives the same result
    trees = {k: v for k, v in cache_a.memo.items() if k[0] == "wall_tree"}
    assert ("wall_tree", "native") in trees and ("wall_tree", ("pooled", 0.2)) in trees
    # so are A's score layers and B's cell centres, read-only
    kept = {k: v for k, v in {**cache_a.memo, **cache_b.memo}.items()
            if k[0] in ("score_layers", "centres")}
    assert ("score_layers", 0.2, 1.0, 0.05) in kept and ("centres", 0.2) in kept
    assert not any(a.flags.writeable for v in kept.values() for a in v)
    again = merge_grids(cache_a, cache_b)
    assert all(cache_a.memo[k] is v for k, v in trees.items())
    assert all({**cache_a.memo, **cache_b.memo}[k] is v for k, v in kept.items())
    assert (again.transform.theta, tuple(again.transform.T), again.confidence) == (
        r.transform.theta, tuple(r.transform.T), r.confidence)


@pytest.mark.parametrize("deg", [37.0, 251.0])
def test_the_large_map_path_recovers_the_transform(deg, monkeypatch):
    """Grids above LARGE_POOLED_CELLS (lowered here) take the pyramid sweep and windowed
    refinement: the same alignment as the full sweep, accepted; the symmetric room stays a
    tie."""
    import fusion.grid_merge as GM

    a, b, truth = overlapping_views(deg, Rigid2D.from_degrees(20.0, (3.0, 2.0)), (12.0, 5.0))
    full = merge_grids(a, b)
    monkeypatch.setattr(GM, "LARGE_POOLED_CELLS", 1000)
    res = merge_grids(a, b)
    assert res.accepted, res.reason
    assert math.degrees(res.transform.rotation_error(truth)) < 1.0
    assert res.transform.translation_error(truth, at=np.zeros(2)) < 0.15
    assert math.degrees(res.transform.rotation_error(full.transform)) < 0.2
    s = np.zeros((120, 120), np.int8)
    s[18:102, 28:92] = 2
    s[20:100, 30:90] = 1
    g = GridSnapshot(s, RES, (0.0, 0.0))
    tie = merge_grids(g, g)
    assert tie.margin == pytest.approx(1.0, abs=0.01) and not tie.accepted


def test_blocks_merge_pooled_cells_by_the_layers_rule():
    """fusion.grid_merge.blocks: a wall where any cell of the block is, free where most are
    and none is a wall, the partial blocks at the far edges padded with unknown cells."""
    from fusion.grid_merge import blocks

    wall = np.zeros((5, 3), bool)
    free = np.zeros((5, 3), bool)
    wall[0, 0] = True
    free[0:2, 1] = True
    free[2:4, 0:2] = True
    free[4, 2] = True
    wb, fb, origin = blocks(wall, free, np.array([1.0, 2.0]), 2)
    np.testing.assert_array_equal(wb, [[True, False], [False, False], [False, False]])
    np.testing.assert_array_equal(fb, [[False, False], [True, False], [False, False]])
    np.testing.assert_array_equal(origin, [1.0, 2.0])


@pytest.mark.parametrize("shape", [(0, 5), (3, 0), (2, 3), (40, 70)])
def test_true_cells_is_nonzero(shape):
    """true_cells gives np.nonzero's rows and columns, in its order and dtype."""
    from fusion.grid_layers import true_cells

    mask = np.random.default_rng(len(shape) + shape[0]).random(shape) < 0.3
    for got, want in zip(true_cells(mask), np.nonzero(mask), strict=True):
        assert got.dtype == want.dtype
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("shape", [(0, 3), (1, 7), (7, 1), (60, 45)])
def test_dilated_is_scipys_binary_dilation(shape):
    """dilated: scipy.ndimage.binary_dilation with its default cross, one iteration."""
    from scipy import ndimage

    from fusion.grid_layers import dilated

    mask = np.random.default_rng(shape[0]).random(shape) < 0.1
    np.testing.assert_array_equal(dilated(mask), ndimage.binary_dilation(mask, iterations=1))
