"""merge_maps: recovery from any rotation, ambiguity, rejection of unrelated maps, merged-map
invariants, determinism and bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fusion.evaluation.synthetic import SyntheticConfig, make_pair
from fusion.rigid import Rigid2D
from fusion.structural import (
    METHODS,
    MergeConfig,
    MergeEvidence,
    MergeResult,
    decide,
    fuse_maps,
    merge_maps,
)
from topo.graph import TopoMap

QUIET = SyntheticConfig(noise=0.05, drop_rate=0.05)


def errors(estimate: Rigid2D, truth: Rigid2D, b: TopoMap) -> tuple[float, float]:
    centre = b.xy.mean(axis=0)
    return math.degrees(estimate.rotation_error(truth)), estimate.translation_error(truth, centre)


@pytest.fixture(scope="module")
def pair():
    return make_pair(np.random.default_rng(11), QUIET, overlap=0.9, nodes=(35, 35))


def rotated(pair, extra: Rigid2D):
    """The pair with B's frame moved by ``extra`` (B' = extra(B)); truth' = truth ∘ extra⁻¹."""
    return pair.map_b.transformed(extra), pair.transform @ extra.inverse()


@pytest.mark.parametrize("degrees", range(0, 360, 45))
def test_recovers_any_rotation(pair, degrees):
    b, truth = rotated(pair, Rigid2D.from_degrees(degrees + 7.0, (3.0, -40.0)))
    result = merge_maps(pair.map_a, b)
    assert result.accepted, result.reason
    rot, trans = errors(result.transform, truth, b)
    assert rot < 2.0 and trans < 0.3


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(theta=st.floats(-math.pi, math.pi), tx=st.floats(-100, 100), ty=st.floats(-100, 100))
def test_identical_maps_are_aligned_exactly(pair, theta, tx, ty):
    motion = Rigid2D(theta, (tx, ty))
    result = merge_maps(pair.map_a, pair.map_a.transformed(motion.inverse()))
    assert result.accepted, result.reason
    assert result.transform.allclose(motion, atol=1e-6)
    assert len(result.matches) == pair.map_a.n_nodes


def square_loop_with_spurs() -> TopoMap:
    """A square corridor loop with a side corridor out of the middle of each side: it looks
    the same after every quarter turn."""
    corners = [(0, 0), (10, 0), (10, 10), (0, 10)]
    mids = [(5, 0), (10, 5), (5, 10), (0, 5)]
    spurs = [(5, -3), (13, 5), (5, 13), (-3, 5)]
    xy = np.array(corners + mids + spurs, dtype=float)
    edges = []
    for k in range(4):
        edges += [(k, 4 + k), (4 + k, (k + 1) % 4), (4 + k, 8 + k)]
    return TopoMap.from_arrays(xy, edges)


@pytest.mark.parametrize("method", ["auto", "exhaustive", "multistart_icp", "ransac"])
def test_symmetric_map_is_ambiguous_not_confidently_wrong(method):
    a = square_loop_with_spurs()
    b = a.transformed(Rigid2D.from_degrees(33.0, (4.0, -2.0)))
    result = merge_maps(a, b, method=method)
    assert not result.accepted
    assert "ambiguous" in result.reason


def test_bare_square_loop_rejected():
    a = TopoMap.from_arrays([(0, 0), (8, 0), (8, 8), (0, 8)], [(0, 1), (1, 2), (2, 3), (3, 0)])
    result = merge_maps(a, a.transformed(Rigid2D.from_degrees(120.0, (1.0, 1.0))))
    assert not result.accepted and result.reason


@pytest.mark.parametrize("kind", ["disjoint", "other_world"])
@pytest.mark.parametrize("seed", range(4))
def test_no_overlap_pairs_rejected(kind, seed):
    p = make_pair(np.random.default_rng([7, seed]), SyntheticConfig(noise=0.15), kind=kind,
                  nodes=(40, 40))
    result = merge_maps(p.map_a, p.map_b)
    assert not result.accepted
    assert result.merged is p.map_a


def test_merged_map_has_no_duplicates_and_keeps_a(pair):
    cfg = MergeConfig()
    result = merge_maps(pair.map_a, pair.map_b, config=cfg)
    assert result.accepted
    m = result.merged
    d = np.linalg.norm(m.xy[:, None] - m.xy[None, :], axis=-1)
    np.fill_diagonal(d, np.inf)
    assert d.min() > cfg.eps
    assert pair.map_a.n_nodes <= m.n_nodes < pair.map_a.n_nodes + pair.map_b.n_nodes
    assert m.n_edges >= pair.map_a.n_edges
    assert np.all(m.lengths >= np.linalg.norm(m.xy[m.edges[:, 0]] - m.xy[m.edges[:, 1]], axis=1))


@settings(max_examples=15, deadline=None)
@given(st.lists(st.tuples(st.floats(-20, 20), st.floats(-20, 20)), min_size=3, max_size=25),
       st.floats(0.2, 2.0))
def test_fusing_has_no_two_nodes_within_eps(points, eps):
    a = TopoMap.from_arrays(np.array(points), [(i, i + 1) for i in range(len(points) - 1)
                                               if points[i] != points[i + 1]])
    fused = fuse_maps(a, a, Rigid2D.from_degrees(3.0, (0.1, 0.0)), np.empty((0, 2)), eps)
    d = np.linalg.norm(fused.xy[:, None] - fused.xy[None, :], axis=-1)
    np.fill_diagonal(d, np.inf)
    assert d.min(initial=np.inf) > eps
    assert np.all(fused.edges[:, 0] != fused.edges[:, 1])


def test_deterministic(pair):
    runs = [merge_maps(pair.map_a, pair.map_b) for _ in range(2)]
    again = make_pair(np.random.default_rng(11), QUIET, overlap=0.9, nodes=(35, 35))
    runs.append(merge_maps(again.map_a, again.map_b))
    for r in runs[1:]:
        assert r.transform.allclose(runs[0].transform, atol=0.0)
        np.testing.assert_array_equal(r.matches, runs[0].matches)
        assert r.score == runs[0].score


@pytest.mark.parametrize("method", METHODS)
def test_every_method_returns_a_result(pair, method):
    result = merge_maps(pair.map_a, pair.map_b, method=method)
    assert isinstance(result, MergeResult) and result.method == method
    assert result.time_s > 0 and result.evidence is not None
    assert result.accepted == (result.reason is None)


def test_paper_icp_works_near_identity_and_fails_at_half_turn(pair):
    a = pair.map_a
    near = merge_maps(a, a.transformed(Rigid2D.from_degrees(-10.0, (0.5, 0.3))),
                      method="paper_icp")
    assert near.accepted
    assert near.transform.allclose(Rigid2D.from_degrees(-10.0, (0.5, 0.3)).inverse(), 1e-6)
    far = merge_maps(a, a.transformed(Rigid2D.from_degrees(180.0)), method="paper_icp")
    assert math.degrees(far.transform.rotation_error(Rigid2D.from_degrees(180.0))) > 2.0


def test_ransac_finds_the_pair_and_is_reproducible(pair):
    runs = [merge_maps(pair.map_a, pair.map_b, method="ransac") for _ in range(2)]
    assert runs[0].accepted
    assert runs[0].transform.rotation_error(pair.transform) < math.radians(2.0)
    assert runs[1].transform.allclose(runs[0].transform, atol=0.0)
    other = merge_maps(pair.map_a, pair.map_b, method="ransac",
                       config={"ransac_seed": 5, "ransac_iterations": 300})
    assert other.transform.rotation_error(pair.transform) < math.radians(2.0)


@pytest.mark.parametrize("field", ["ransac_iterations", "ransac_seed"])
def test_ransac_settings_validated(field):
    with pytest.raises(ValueError, match=f"{field} must be >= "):
        MergeConfig(**{field: -1})


def test_auto_agrees_with_exhaustive_search(pair):
    auto = merge_maps(pair.map_a, pair.map_b)
    exhaustive = merge_maps(pair.map_a, pair.map_b, method="exhaustive")
    assert auto.transform.rotation_error(exhaustive.transform) < math.radians(1.0)


# ------------------------------------------------------------------------------ degenerate
def test_too_small_maps_rejected_with_reason():
    tiny = TopoMap.from_arrays([(0, 0), (1, 0)], [(0, 1)])
    result = merge_maps(tiny, tiny)
    assert not result.accepted
    assert "map_a has 2 node(s) off the frontier (of 2); at least 3 are needed" in result.reason
    assert result.evidence is None


@pytest.mark.parametrize("method", METHODS)
def test_collinear_maps_rejected_not_raised(method):
    line = TopoMap.from_arrays([(x, 0.0) for x in (0, 2, 5, 9, 14)],
                               [(0, 1), (1, 2), (2, 3), (3, 4)])
    result = merge_maps(line, line.transformed(Rigid2D.from_degrees(30.0)), method=method)
    assert not result.accepted and result.reason


@pytest.mark.parametrize("method", METHODS)
def test_coincident_nodes_rejected_not_raised(method):
    same = TopoMap.from_arrays([(1.0, 1.0)] * 5)
    result = merge_maps(same, same, method=method)
    assert not result.accepted and result.reason


# ------------------------------------------------------------------------------- bad input
def test_nan_coordinates():
    good = square_loop_with_spurs()
    xy = good.xy.copy()
    xy[3, 1] = np.nan
    bad = TopoMap(xy, good.kinds, good.edges, good.lengths)
    with pytest.raises(ValueError, match=r"map_b.xy must be finite, got \[0.0, nan\] at node 3"):
        merge_maps(good, bad)


def test_wrong_types():
    good = square_loop_with_spurs()
    with pytest.raises(TypeError, match="map_a must be a topo.TopoMap, got ndarray"):
        merge_maps(good.xy, good)
    with pytest.raises(TypeError, match="config must be a MergeConfig, a dict of its fields"):
        merge_maps(good, good, config=[("eps", 1.0)])


def test_unknown_method_lists_valid_ones():
    good = square_loop_with_spurs()
    with pytest.raises(ValueError, match=r"method must be one of \['auto', 'paper_icp', "
                                         r"'exhaustive', 'multistart_icp', 'ransac'\], "
                                         r"got 'icp'"):
        merge_maps(good, good, method="icp")


@pytest.mark.parametrize("eps", [0.0, -0.5])
def test_eps_must_be_positive(eps):
    with pytest.raises(ValueError, match=f"eps must be > 0.0, got {eps}"):
        MergeConfig(eps=eps)
    with pytest.raises(ValueError, match="eps must be > 0.0"):
        merge_maps(square_loop_with_spurs(), square_loop_with_spurs(), config={"eps": eps})


def test_unknown_config_keys():
    with pytest.raises(ValueError, match=r"MergeConfig has unknown keys \['tolerance'\]"):
        MergeConfig.from_dict({"tolerance": 0.3})
    with pytest.raises(ValueError, match=r"config has unknown keys \['tolerance'\]; allowed"):
        merge_maps(square_loop_with_spurs(), square_loop_with_spurs(),
                   config={"tolerance": 0.3})


def test_config_type_errors():
    with pytest.raises(TypeError, match="candidates must be an integer, got float"):
        MergeConfig(candidates=3.5)


def test_decide_names_every_failed_criterion():
    weak = MergeEvidence(inliers=2, closeness=1.0, matched_edges=0, conflicts=3, crossings=1,
                         branches_agree=0, branches_disagree=4, near_misses=2, rmse=0.4,
                         collinear=True,
                         n_a=30, n_b=30, runner_up=5.0)
    reason = decide(weak)
    for part in ("too few matched nodes", "collinear", "weak evidence", "ambiguous"):
        assert part in reason
    assert 0.0 < weak.confidence < 0.5
    # the threshold alone: nothing else fails a strong, unambiguous alignment
    import dataclasses
    strong = dataclasses.replace(weak, inliers=12, closeness=10.0, collinear=False,
                                 runner_up=float("nan"), path_agree=80.0, conflicts=0,
                                 crossings=0, branches_disagree=0, near_misses=0)
    assert decide(strong, MergeConfig(accept_threshold=0.0)) is None
    assert decide(strong, MergeConfig(accept_threshold=1.0)).startswith("weak evidence")


def test_config_for_noise_scales_tolerances():
    assert MergeConfig.for_noise(0.1) == MergeConfig()
    noisy = MergeConfig.for_noise(0.3)
    assert noisy.eps == pytest.approx(0.9) and noisy.fit_eps == pytest.approx(1.2)
    assert noisy.accept_threshold == MergeConfig().accept_threshold
    assert MergeConfig.for_noise(0.3, eps=1.0).eps == 1.0
    with pytest.raises(ValueError, match="sigma must be >= 0.0, got -0.1"):
        MergeConfig.for_noise(-0.1)
    with pytest.raises(ValueError, match="sigma must be <= 0.3, got 0.5"):
        MergeConfig.for_noise(0.5)
    with pytest.raises(ValueError, match=r"MergeConfig has unknown keys \['tolerance'\]"):
        MergeConfig.for_noise(0.3, tolerance=1.0)


def test_zero_length_paths_do_not_crash_the_evidence_kernel():
    """Two nodes at the same place joined by a path (seen in sonar maps) once divided by zero
    in the crossing test."""
    from fusion import Rigid2D, merge_maps
    from topo import TopoMap

    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 10, (12, 2))
    xy[3] = xy[2]
    edges = [[k, k + 1] for k in range(11)] + [[2, 5]]
    a = TopoMap.from_arrays(xy, edges)
    b = a.transformed(Rigid2D.from_degrees(30.0, (1.0, 2.0)))
    result = merge_maps(a, b)
    assert result.accepted


def test_coarse_score_refits_a_near_hypothesis_onto_the_truth(pair):
    """The refitted coarse score (fusion.structural._kernels.refined_scores): a hypothesis 0.5° and
    0.1 m off the motion that made B from A lands on it after one fit, every B node exactly on
    its A node (score = node count); one landing fewer than ``min_pairs`` nodes is left as is,
    scored 0. ``landed`` counts the nodes each paired before its refit."""
    from fusion.structural import _kernels as K
    from fusion.structural.hypotheses import hit_grid
    from fusion.structural.prepare import prepare_pair

    cfg = MergeConfig()
    a = pair.map_a
    truth = Rigid2D(0.7, np.array([3.0, -2.0]))
    b = a.transformed(truth.inverse())  # p_A = truth(p_B)
    table, x0, y0, inv_cell = hit_grid(prepare_pair(a, a, cfg)[0], cfg.coarse_tolerance, cfg.eps)
    theta = np.array([truth.theta + math.radians(0.5), truth.theta + 2.0])
    tx = np.array([truth.T[0] + 0.1, truth.T[0]])
    ty = np.array([truth.T[1] - 0.05, truth.T[1]])
    landed = np.full(2, -1, dtype=np.int64)
    scores = K.refined_scores(theta, tx, ty, np.cos(theta), np.sin(theta), a.xy, b.xy,
                              b.kinds.astype(np.int64), table, x0, y0, inv_cell, cfg.eps, 1, 4,
                              landed)
    assert landed[0] == a.n_nodes and 0 <= landed[1] < 4
    assert theta[0] == pytest.approx(truth.theta, abs=1e-9)
    assert [tx[0], ty[0]] == pytest.approx(truth.T.tolist(), abs=1e-9)
    assert scores[0] == pytest.approx(a.n_nodes)
    assert (theta[1], tx[1], ty[1], scores[1]) == (truth.theta + 2.0, truth.T[0], truth.T[1], 0.0)


def test_likelihood_rewards_tight_matches(pair):
    """MergeEvidence.likelihood: exact matches score the tightest spread's full log-ratio each;
    the same matches 0.3 m off score less (a chance-like distance), and the score with them."""
    from fusion.structural import _kernels as K
    from fusion.structural.evidence import evaluate
    from fusion.structural.prepare import prepare_pair

    cfg = MergeConfig()
    a = pair.map_a
    truth = Rigid2D(1.1, np.array([-4.0, 2.5]))
    pa, pb = prepare_pair(a, a.transformed(truth.inverse()), cfg)
    exact = evaluate(pa, pb, truth.theta, truth.T, cfg).evidence
    s2 = 2 * K.LIKELIHOOD_SIGMAS[0] ** 2
    assert exact.inliers == a.n_nodes
    assert exact.likelihood == pytest.approx(a.n_nodes * math.log(0.9 * cfg.eps**2 / s2 + 0.1))
    off = evaluate(pa, pb, truth.theta, truth.T + np.array([0.3, 0.0]), cfg).evidence
    assert off.likelihood < 0.5 * exact.likelihood
    assert off.score < exact.score


def _path_field_numpy(seg, x0, y0, cell, ny, nx, reach):
    """The obvious distance-to-path raster: every cell centre's squared distance to every
    segment, the nearest kept, capped at reach²."""
    cx, cy = np.meshgrid(x0 + (np.arange(nx) + 0.5) * cell, y0 + (np.arange(ny) + 0.5) * cell)
    p = np.stack([cx.ravel(), cy.ravel()], axis=1)[:, None, :]
    u, v = seg[:, :2], seg[:, 2:] - seg[:, :2]
    ll = (v * v).sum(axis=1)
    t = np.clip(((p - u) * v).sum(axis=-1) / np.where(ll > 0, ll, 1.0), 0.0, 1.0)
    d2 = ((u + t[..., None] * v - p) ** 2).sum(axis=-1).min(axis=1)
    return np.minimum(d2, reach**2).reshape(ny, nx)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_path_field_is_the_distance_to_the_nearest_segment(seed):
    """fusion.structural._kernels.path_field against the obvious computation (horizontal,
    vertical and zero-length segments included)."""
    from fusion.structural import _kernels as K

    rng = np.random.default_rng(seed)
    seg = rng.uniform(0.0, 12.0, (9, 4))
    seg[0, 2] = seg[0, 0]  # vertical
    seg[1, 3] = seg[1, 1]  # horizontal
    seg[2, 2:] = seg[2, :2]  # a point
    x0, y0, cell, ny, nx, reach = -2.5, -2.0, 0.3, 55, 52, 2.0
    field = K.path_field(seg, x0, y0, cell, ny, nx, reach)
    assert field == pytest.approx(_path_field_numpy(seg, x0, y0, cell, ny, nx, reach), abs=1e-5)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_path_field_on_grid_aligned_segments(seed):
    """fusion.structural._kernels.path_field walks each segment's band of cells row by row:
    on grid-aligned coordinates (ends on cell edges, rows exactly at a segment's reach;
    horizontal, vertical, zero-length and shared-end segments) it still finds every cell's
    nearest segment (float32 raster: to a tolerance)."""
    from fusion.structural import _kernels as K

    rng = np.random.default_rng(seed)
    seg = np.round(rng.uniform(0.0, 12.0, (12, 4)) * 2.5) / 2.5
    seg[0, 2] = seg[0, 0]  # vertical
    seg[1, 3] = seg[1, 1]  # horizontal
    seg[2, 2:] = seg[2, :2]  # a point
    seg[3, :2] = seg[4, 2:]  # chained
    x0, y0, cell, ny, nx, reach = -2.4, -2.0, 0.4, 41, 42, 2.0
    got = K.path_field(seg, x0, y0, cell, ny, nx, reach)
    assert got == pytest.approx(_path_field_numpy(seg, x0, y0, cell, ny, nx, reach), abs=1e-5)


def _corridors(shift: float = 0.0) -> TopoMap:
    """A comb of corridors (a 12 m spine, three 4 m branches), moved up by ``shift``."""
    xy = np.array([[0, 0], [4, 0], [8, 0], [12, 0], [4, 4], [8, 4], [12, 4]], dtype=float)
    return TopoMap.from_arrays(xy + [0.0, shift], [[0, 1], [1, 2], [2, 3], [1, 4], [2, 5],
                                                   [3, 6]])


def test_path_evidence_counts_paths_on_and_beside_the_other_maps():
    """MergeEvidence.path_agree: aligned copies lay all their paths (24 m each, both ways) on
    each other's (the raster's cells, PATH_CELL wide, cost a few tenths of the soft weight);
    moved 1.2 m aside the corridors run beside each other (path_off), and only the branches
    that still overlap agree."""
    from fusion.structural.evidence import evaluate
    from fusion.structural.prepare import prepare_pair

    cfg = MergeConfig()
    a, b = prepare_pair(_corridors(), _corridors(), cfg)
    same = evaluate(a, b, 0.0, np.zeros(2), cfg).evidence
    assert 0.8 * 48.0 < same.path_agree <= 48.0 and same.path_off == 0.0
    a, b = prepare_pair(_corridors(), _corridors(1.2), cfg)
    aside = evaluate(a, b, 0.0, np.zeros(2), cfg).evidence
    assert aside.path_off > 12.0 and aside.path_agree < 0.6 * same.path_agree  # the 2 × 12 m spines


def test_path_evidence_follows_polylines():
    """A path's polyline, not the straight line between its nodes, is what lies on the other
    map: a path bowed 1.5 m out does not agree with a straight one; the same bow does."""
    from fusion.structural.evidence import evaluate
    from fusion.structural.prepare import prepare_pair

    cfg = MergeConfig()
    xy = [[0.0, 0.0], [10.0, 0.0], [10.0, 5.0]]
    bow = [np.array([[0.0, 0.0], [5.0, 1.5], [10.0, 0.0]]), np.array([[10.0, 0.0], [10.0, 5.0]])]
    straight_map = TopoMap.from_arrays(xy, [[0, 1], [1, 2]])
    bowed_map = TopoMap.from_arrays(xy, [[0, 1], [1, 2]], paths=bow)
    ev_bow = evaluate(*prepare_pair(bowed_map, bowed_map, cfg), 0.0, np.zeros(2), cfg).evidence
    ev_mixed = evaluate(*prepare_pair(straight_map, bowed_map, cfg), 0.0, np.zeros(2),
                         cfg).evidence
    assert ev_mixed.path_agree < ev_bow.path_agree - 10.0
    assert ev_mixed.path_off > 5.0 and ev_bow.path_off == 0.0


def test_path_pool_must_be_a_positive_integer():
    with pytest.raises(ValueError, match="path_pool must be >= 1, got 0"):
        MergeConfig(path_pool=0)


def test_sparse_pool_must_be_a_non_negative_integer():
    assert MergeConfig(sparse_pool=0).sparse_pool == 0
    with pytest.raises(ValueError, match="sparse_pool must be >= 0, got -1"):
        MergeConfig(sparse_pool=-1)


def test_sparse_pool_finds_a_pair_sharing_three_nodes():
    """Maps sharing exactly 3 nodes: the right hypothesis lands 3 B nodes, fewer than the
    coarse ranking holds; the sparse pool carries it to the candidates (the best alignment is
    right), without it (``sparse_pool=0``) a chance alignment of the lattice wins."""
    p = make_pair(np.random.default_rng(11), overlap=0.25, nodes=(30, 30),
                  config=SyntheticConfig(noise=0.05))
    assert len(p.correspondences) == 3
    rot, move = errors(merge_maps(p.map_a, p.map_b).transform, p.transform, p.map_b)
    assert rot < 2.0 and move < 0.3
    rot, move = errors(merge_maps(p.map_a, p.map_b, config={"sparse_pool": 0}).transform,
                       p.transform, p.map_b)
    assert rot > 5.0 or move > 1.0


def test_final_fit_reads_path_points_only_for_maps_without_polylines(monkeypatch):
    """The final least-squares fit pairs B's path points with A's paths when both maps' paths
    are node-to-node segments; maps with polylines (routes through each robot's own free
    space, which run apart between the same places) fit on their nodes alone, so a route
    hugging one side of a corridor does not turn an exact node match."""
    import dataclasses

    import fusion.structural.refine as refine
    from fusion.icp import rigid_fit
    from fusion.structural.prepare import prepare_pair

    cfg = MergeConfig()
    a = _corridors()
    matches = np.column_stack([np.arange(a.n_nodes), np.arange(a.n_nodes)])
    # segments: the path points take part (the fit moves when their weight is switched off)
    rng = np.random.default_rng(4)
    noisy = TopoMap.from_arrays(a.xy + rng.normal(0.0, 0.15, a.xy.shape), a.edges)
    pa, pb = prepare_pair(a, noisy, cfg)
    assert not (pa.polylines or pb.polylines)
    theta, t = refine.least_squares(pa, pb, matches, 0.0, np.zeros(2), cfg.fit_eps)
    monkeypatch.setattr(refine, "PATH_FIT_WEIGHT", 0.0)
    theta0, t0 = refine.least_squares(pa, pb, matches, 0.0, np.zeros(2), cfg.fit_eps)
    assert abs(theta - theta0) > 1e-4 or np.linalg.norm(t - t0) > 1e-4
    monkeypatch.undo()
    # polylines: B's nodes where A's are, its routes up the branches 0.3 m to the side
    straight = [np.array([a.xy[u], a.xy[v]]) for u, v in a.edges]
    side = np.array([0.3, 0.0])
    routes = [np.array([a.xy[u], (a.xy[u] + a.xy[v]) / 2 + side, a.xy[v]])
              if a.xy[u, 0] == a.xy[v, 0] else np.array([a.xy[u], a.xy[v]])
              for u, v in a.edges]  # the three branches bow 0.3 m to the right
    pa, pb = prepare_pair(TopoMap.from_arrays(a.xy, a.edges, paths=straight),
                          TopoMap.from_arrays(a.xy, a.edges, paths=routes), cfg)
    assert pa.polylines and pb.polylines
    theta, t = refine.least_squares(pa, pb, matches, 0.0, np.zeros(2), cfg.fit_eps)
    node_theta, node_t = rigid_fit(a.xy, a.xy, np.ones(a.n_nodes))
    assert theta == pytest.approx(node_theta, abs=1e-12) and abs(theta) < 1e-9
    assert np.allclose(t, node_t) and np.allclose(t, 0.0, atol=1e-9)
    # the same routes read as if they were segments would pull the fit off the nodes
    theta_s, _ = refine.least_squares(dataclasses.replace(pa, polylines=False),
                                      dataclasses.replace(pb, polylines=False), matches, 0.0,
                                      np.zeros(2), cfg.fit_eps)
    assert abs(theta_s) > 1e-3


def test_final_fit_weighs_a_pair_by_its_distance():
    """Each matched pair weighs ``1 − d²/eps²`` in the final fit: five nodes matched exactly
    and one 0.5 m off (within a 0.6 m gate; as likely a neighbour as the same place) turn the
    fit less than the plain SVD fit of the six pairs does, and exactly as the SVD fit
    with those weights."""
    from fusion.icp import rigid_fit
    from fusion.structural import refine
    from fusion.structural.prepare import prepare_pair

    xy = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0], [2.0, 1.5], [6.0, 1.0]])
    b = xy.copy()
    b[5] += [0.0, 0.5]
    edges = np.array([[0, 1], [1, 2], [2, 3], [3, 0], [1, 5]])
    pa, pb = prepare_pair(*(TopoMap.from_arrays(p, edges, paths=[p[[u, v]] for u, v in edges])
                            for p in (xy, b)), MergeConfig())
    matches = np.column_stack([np.arange(6), np.arange(6)])
    theta, t = refine.least_squares(pa, pb, matches, 0.0, np.zeros(2), 0.6)
    weights = np.ones(6)
    weights[5] = 1.0 - 0.5**2 / 0.6**2
    expected, expected_t = rigid_fit(b, xy, weights)
    plain, _ = rigid_fit(b, xy, np.ones(6))
    assert theta == pytest.approx(expected, abs=1e-12) and np.allclose(t, expected_t)
    assert 0.0 < abs(theta) < abs(plain)


def test_pixel_fine_polylines_are_read_as_chords():
    """Extracted maps carry a polyline point per grid cell; the path evidence reads them as
    chords about PATH_CHORD long that keep each polyline's ends and stay on its pixels, so a
    pixel-fine map scores like the same map drawn with straight pieces."""
    from fusion.structural.evidence import evaluate
    from fusion.structural.prepare import PATH_CHORD, path_segments, prepare_pair

    cfg = MergeConfig()
    xy = [[0.0, 0.0], [6.0, 0.0], [6.0, 4.0]]
    fine = [np.stack([np.arange(0.0, 6.05, 0.1), np.zeros(61)], 1),
            np.stack([np.full(41, 6.0), np.arange(0.0, 4.05, 0.1)], 1)]
    m = TopoMap.from_arrays(xy, [[0, 1], [1, 2]], paths=fine)
    chords = path_segments(m)
    lengths = np.hypot(chords[:, 2] - chords[:, 0], chords[:, 3] - chords[:, 1])
    assert 25 <= len(chords) <= 27 and lengths.max() <= PATH_CHORD + 0.1 + 1e-9  # 15 + 10
    assert lengths.sum() == pytest.approx(10.0)
    starts, ends = chords[:, :2].tolist(), chords[:, 2:].tolist()
    assert [0.0, 0.0] in starts and [6.0, 0.0] in ends and [6.0, 0.0] in starts
    assert [6.0, 4.0] in ends
    plain = TopoMap.from_arrays(xy, [[0, 1], [1, 2]])
    ev_fine = evaluate(*prepare_pair(m, m, cfg), 0.0, np.zeros(2), cfg).evidence
    ev_plain = evaluate(*prepare_pair(plain, plain, cfg), 0.0, np.zeros(2), cfg).evidence
    assert ev_fine.path_agree == pytest.approx(ev_plain.path_agree, rel=0.05)


def _chords_plain(paths: list[np.ndarray], chord: float) -> np.ndarray:
    """Polyline chords the obvious way: along each polyline, its first and last point and the
    first point past each multiple of ``chord`` of arc length, joined in order."""
    out = []
    for q in paths:
        arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(q, axis=0).T))])
        bucket = np.floor(arc / chord)
        ends = [0] + [k for k in range(1, len(q))
                      if k == len(q) - 1 or bucket[k] != bucket[k - 1]]
        out += [(*q[i], *q[k]) for i, k in zip(ends[:-1], ends[1:], strict=True)]
    return np.array(out).reshape(-1, 4)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), chord=st.sampled_from([0.05, 0.4, 1.3]))
def test_polyline_chords_are_the_plain_walk(seed, chord):
    """The chords of fusion.structural.prepare.path_segments (vectorised over every polyline
    at once) are the plain walk's along each polyline, single-point polylines and repeated
    points included."""
    from fusion.structural.prepare import _polyline_chords

    rng = np.random.default_rng(seed)
    paths = [np.cumsum(rng.normal(0.0, 0.2, (int(rng.integers(1, 40)), 2)), axis=0)
             for _ in range(int(rng.integers(1, 6)))]
    paths[0] = np.vstack([paths[0], paths[0][-1:]])  # a repeated point
    got = _polyline_chords(np.concatenate(paths), np.array([len(q) for q in paths]), chord)
    np.testing.assert_allclose(got, _chords_plain(paths, chord), rtol=0, atol=1e-12)


def test_point_to_line_fit_takes_the_rotation_from_long_corridors():
    """Nodes off by 0.15 m leave a node fit about a degree off; the corridors' polylines, exact
    here, bring it about halfway back (``fusion.structural.refine.line_fit``)."""
    from fusion.icp import rigid_fit
    from fusion.structural.prepare import prepare_pair
    from fusion.structural.refine import line_fit

    xy = np.array([(0, 0), (12, 0), (24, 0), (0, 9), (12, 9), (24, 9), (6, -5), (18, 14)],
                  dtype=float)
    edges = [(0, 1), (1, 2), (3, 4), (4, 5), (0, 3), (1, 4), (2, 5), (1, 6), (4, 7)]
    paths = [np.linspace(xy[u], xy[v], 25) for u, v in edges]
    a = TopoMap.from_arrays(xy, edges, paths=paths)
    truth = Rigid2D.from_degrees(40.0, (3.0, -7.0))
    noisy = xy + np.random.default_rng(4).normal(0.0, 0.15, xy.shape)
    b = TopoMap.from_arrays(truth.inverse().apply(noisy), edges,
                            paths=[truth.inverse().apply(p) for p in paths])
    pa, pb = prepare_pair(a, b, MergeConfig())
    pairs = np.stack([np.arange(len(xy)), np.arange(len(xy))], axis=1)
    theta, t = rigid_fit(b.xy, a.xy)
    node_error = abs(math.remainder(theta - truth.theta, 2 * math.pi))
    theta, t = line_fit(pa, pb, pairs, theta, t, 0.6)
    line_error = abs(math.remainder(theta - truth.theta, 2 * math.pi))
    assert math.degrees(node_error) > 0.3
    assert line_error < 0.6 * node_error  # about half (0.25° against 0.48°)
