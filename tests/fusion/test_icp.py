"""ICP-SVD: recovery, monotone objective, closed form == SVD, degenerate input, bad input."""

import math

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from fusion import Rigid2D, icp_svd, svd_rotation
from fusion import icp as icp_module
from fusion.icp import best_rotation_angle, rigid_fit


def spread_points(seed: int, n: int) -> np.ndarray:
    """A well-spread set: jittered lattice with 1 m spacing (nearest neighbour ~1 m)."""
    rng = np.random.default_rng(seed)
    side = math.ceil(math.sqrt(n))
    grid = np.stack(np.meshgrid(np.arange(side), np.arange(side)), -1).reshape(-1, 2)[:n]
    return grid + rng.uniform(-0.2, 0.2, (n, 2))


@given(st.integers(0, 10_000), st.integers(6, 60), st.floats(-10, 10), st.floats(0, 2 * math.pi),
       st.floats(0.0, 0.1))
def test_small_motion_is_recovered_exactly(seed, n, deg, direction, shift):
    M = spread_points(seed, n)
    # keep the motion of every point below half the spacing so nearest neighbours are right
    radius = np.abs(M - M.mean(axis=0)).max() * math.sqrt(2)
    assume(radius * abs(math.radians(deg)) + shift < 0.25)
    truth = Rigid2D.from_degrees(deg, (shift * math.cos(direction), shift * math.sin(direction)))
    # D is M seen from B's frame: p_M = truth(p_D)
    res = icp_svd(M, truth.inverse().apply(M), tau=None, init=Rigid2D.identity())
    assert res.converged
    assert res.transform.rotation_error(truth) < 1e-6
    assert res.transform.translation_error(truth, at=M.mean(axis=0)) < 1e-6


@given(st.integers(0, 10_000), st.integers(3, 40), st.integers(3, 40), st.floats(-180, 180))
def test_rotation_proper_and_objective_never_increases(seed, n_m, n_d, deg):
    rng = np.random.default_rng(seed)
    M = rng.uniform(-5, 5, (n_m, 2))
    D = rng.uniform(-5, 5, (n_d, 2))
    res = icp_svd(M, D, tau=None, max_iter=50, init=Rigid2D.from_degrees(deg))
    assert np.isclose(np.linalg.det(res.R), 1.0)
    np.testing.assert_allclose(res.R.T @ res.R, np.eye(2), atol=1e-12)
    assert np.all(np.diff(res.errors) <= 1e-9 * (1 + res.errors[:-1]))
    assert len(res.errors) == res.iterations + 1


@given(st.integers(0, 10_000), st.integers(2, 30))
def test_closed_form_equals_reflection_safe_svd(seed, n):
    rng = np.random.default_rng(seed)
    P = rng.normal(size=(n, 2))
    Q = rng.normal(size=(n, 2)) * rng.uniform(0.1, 3)
    theta = best_rotation_angle(P, Q)
    R = svd_rotation(P, Q)
    assert np.isclose(np.linalg.det(R), 1.0)
    np.testing.assert_allclose([[math.cos(theta), -math.sin(theta)],
                                [math.sin(theta), math.cos(theta)]], R, atol=1e-9)


def test_brute_force_and_kd_tree_paths_agree(monkeypatch):
    M = spread_points(3, 200)
    truth = Rigid2D.from_degrees(4.0, (0.1, -0.05))
    D = truth.inverse().apply(M)[::2] + np.random.default_rng(0).normal(0, 0.01, (100, 2))
    brute = icp_svd(M, D, tau=None, rel_tol=1e-12)
    monkeypatch.setattr(icp_module, "BRUTE_FORCE_MAX_PAIRS", 0)
    tree = icp_svd(M, D, tau=None, rel_tol=1e-12)
    assert brute.iterations == tree.iterations
    assert brute.transform.allclose(tree.transform, atol=1e-10)
    np.testing.assert_array_equal(brute.correspondences, tree.correspondences)


@pytest.mark.parametrize("seed", range(6))
def test_gated_kd_tree_search_gives_the_brute_force_transform(seed, monkeypatch):
    """With a gate the KD-tree stops searching beyond it: unshared points stay unpaired, and
    the transform is bit for bit the all-pairs one (at most one update fewer)."""
    rng = np.random.default_rng(seed)
    M = spread_points(seed, 300)
    truth = Rigid2D.from_degrees(rng.uniform(-4, 4), rng.uniform(-0.3, 0.3, 2))
    D = np.vstack([truth.inverse().apply(M[:200]) + rng.normal(0, 0.03, (200, 2)),
                   rng.uniform(30, 40, (40, 2))])  # 40 points far from any of M
    kw = {"tau": None, "rel_tol": 1e-9, "max_distance": 0.4, "trim": 0.9,
          "init": Rigid2D.identity()}
    monkeypatch.setattr(icp_module, "BRUTE_FORCE_MAX_PAIRS", 10**9)
    brute = icp_svd(M, D, **kw)
    monkeypatch.setattr(icp_module, "BRUTE_FORCE_MAX_PAIRS", 0)
    tree = icp_svd(M, D, **kw)
    assert brute.transform.theta == tree.transform.theta
    np.testing.assert_array_equal(brute.T, tree.T)
    np.testing.assert_array_equal(brute.correspondences, tree.correspondences)
    assert (tree.correspondences[-40:] == -1).all()
    assert 0 <= brute.iterations - tree.iterations <= 1 and tree.converged


def test_prebuilt_tree_gives_the_same_result(monkeypatch):
    """A KD-tree built once on M and passed in is what icp_svd would build itself."""
    M = spread_points(4, 300)
    truth = Rigid2D.from_degrees(3.0, (0.2, -0.1))
    D = truth.inverse().apply(M)[::3] + np.random.default_rng(1).normal(0, 0.02, (100, 2))
    monkeypatch.setattr(icp_module, "BRUTE_FORCE_MAX_PAIRS", 0)
    kw = {"tau": None, "rel_tol": 1e-9, "max_distance": 0.5, "trim": 0.8}
    own = icp_svd(M, D, **kw)
    given_tree = icp_svd(M, D, tree=cKDTree(M), **kw)
    assert own.transform.theta == given_tree.transform.theta
    np.testing.assert_array_equal(own.T, given_tree.T)
    np.testing.assert_array_equal(own.errors, given_tree.errors)
    np.testing.assert_array_equal(own.correspondences, given_tree.correspondences)


def test_paper_init_and_tau():
    M = spread_points(0, 25)
    truth = Rigid2D.from_degrees(3.0, (20.0, -7.0))  # large shift: Step 1 aligns centroids
    res = icp_svd(M, truth.inverse().apply(M), tau=1e-12)
    assert res.transform.allclose(truth, atol=1e-9)
    loose = icp_svd(M, truth.inverse().apply(M) + 0.3, tau=1e6)
    assert loose.iterations == 1 and loose.converged  # |Δf| < tau after the first update


def test_max_iter_stops_without_convergence():
    M = spread_points(1, 100)
    D = Rigid2D.from_degrees(25.0).apply(M)
    res = icp_svd(M, D, tau=None, max_iter=2)
    assert res.iterations == 2 and not res.converged and len(res.errors) == 3


def test_gating_and_trim_ignore_unshared_points():
    M = spread_points(2, 30)
    truth = Rigid2D.from_degrees(5.0, (0.2, 0.1))
    extra = np.array([[30.0, 30.0], [-20.0, 25.0], [40.0, -10.0]])
    D = np.vstack([truth.inverse().apply(M), extra])
    plain = icp_svd(M, D, tau=None, init=truth)
    assert plain.transform.rotation_error(truth) > 1e-3  # the paper's ICP drifts
    for kw in ({"max_distance": 0.5}, {"trim": 30 / 33}):
        res = icp_svd(M, D, tau=None, init=truth, **kw)
        assert res.transform.allclose(truth, atol=1e-9)
        assert (res.correspondences[-3:] == -1).all()
        assert res.rmse < 1e-9


def test_degenerate_geometry_is_reported_not_nan():
    same = icp_svd([[1, 1], [1, 1], [1, 1]], [[0, 0], [0, 0]])
    assert "coincide" in same.degenerate
    assert np.isfinite(same.T).all() and np.isclose(np.linalg.det(same.R), 1)
    line = icp_svd([[0, 0], [1, 0], [2, 0]], [[0, 1], [1, 1], [2, 1]])
    assert "collinear" in line.degenerate and np.isclose(np.linalg.det(line.R), 1)
    far = icp_svd([[0, 0], [1, 0], [0, 1]], [[50, 50], [51, 50], [50, 51]],
                  init=Rigid2D.identity(), max_distance=1.0)
    assert "only 0 pair(s)" in far.degenerate and far.iterations == 0


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"M": []}, ValueError, r"M must have at least 2 points, got 0"),
        ({"D": [[0.0, 0.0]]}, ValueError, r"D must have at least 2 points, got 1"),
        ({"M": [[0, 0, 0], [1, 1, 1]]}, ValueError, r"M must have shape \(N, 2\), got shape \(2, 3\)"),
        ({"D": [[0, 0], [np.inf, 0]]}, ValueError, r"D must be finite, got \[inf, 0.0\] at row 1"),
        ({"M": "points"}, TypeError, "M must be an array of shape"),
        ({"D": {"a": 1}}, TypeError, "D must be an array of shape"),
        ({"tau": 0.0}, ValueError, r"tau must be > 0.0, got 0.0"),
        ({"tau": -1}, ValueError, r"tau must be > 0.0, got -1.0"),
        ({"max_iter": 0}, ValueError, r"max_iter must be >= 1, got 0"),
        ({"max_iter": 2.5}, TypeError, "max_iter must be an integer, got float"),
        ({"rel_tol": -1e-3}, ValueError, "rel_tol must be > 0.0"),
        ({"trim": 1.5}, ValueError, r"trim must be <= 1.0, got 1.5"),
        ({"max_distance": 0}, ValueError, "max_distance must be > 0.0, got 0.0"),
        ({"init": np.eye(3)}, TypeError, "init must be a fusion.Rigid2D or None, got ndarray"),
        ({"tree": np.eye(2)}, TypeError, "tree must be a scipy.spatial.cKDTree or None, got "
                                         "ndarray"),
        ({"tree": cKDTree([[0, 0], [1, 0]])}, ValueError,
         "tree must be built on M: it holds 2 points of dimension 2, M 3 other points"),
    ],
)
def test_bad_input(kwargs, error, match):
    args = {"M": [[0, 0], [1, 0], [0, 1]], "D": [[0, 0], [1, 0], [0, 1]], **kwargs}
    with pytest.raises(error, match=match):
        icp_svd(**args)


@given(st.integers(0, 10_000), st.integers(3, 20))
def test_rigid_fit_recovers_a_motion_and_weights_count_as_repeats(seed, n):
    rng = np.random.default_rng(seed)
    P = rng.normal(size=(n, 2)) * 3
    theta, T = rng.uniform(-math.pi, math.pi), rng.normal(size=2)
    R = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    est, t = rigid_fit(P, P @ R.T + T)
    assert math.isclose(math.remainder(est - theta, 2 * math.pi), 0.0, abs_tol=1e-9)
    np.testing.assert_allclose(t, T, atol=1e-9)
    # noisy pairs: integer weights fit like the pairs repeated that many times
    Q = P @ R.T + T + rng.normal(0.0, 0.3, P.shape)
    k = rng.integers(1, 4, n)
    weighted = rigid_fit(P, Q, k.astype(float))
    repeated = rigid_fit(np.repeat(P, k, axis=0), np.repeat(Q, k, axis=0))
    assert weighted[0] == pytest.approx(repeated[0], abs=1e-9)
    np.testing.assert_allclose(weighted[1], repeated[1], atol=1e-9)

