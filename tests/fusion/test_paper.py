"""The paper's worked example: sizes, truth, and ICP-SVD on full overlap."""

import numpy as np

from fusion import icp_svd, paper_example
from fusion.paper import PAPER_R, PAPER_T, PAPER_TAU


def test_example_has_the_papers_sizes_and_truth():
    ex = paper_example()
    assert ex.map_a.n_nodes == 4 and ex.map_b.n_nodes == 7
    np.testing.assert_allclose(ex.truth.R, PAPER_R, atol=1e-4)
    np.testing.assert_allclose(
        ex.map_a.xy, ex.truth.apply(ex.map_b.xy[ex.shared_b]), atol=1e-12)


def test_full_overlap_recovers_the_papers_R_and_T():
    """B = the paper's transform applied to A's vertices (both maps complete)."""
    ex = paper_example()
    for points in (ex.map_a.xy, ex.map_b.xy):
        M = points
        D = ex.truth.inverse().apply(points)
        res = icp_svd(M, D, tau=PAPER_TAU * 1e-6)
        np.testing.assert_allclose(res.R, PAPER_R, atol=1e-3)
        np.testing.assert_allclose(res.T, PAPER_T, atol=1e-3)
        assert res.converged and res.degenerate is None


def test_partial_overlap_biases_plain_icp_and_gated_refinement_fixes_it():
    """The honest gap: B's three extra vertices pull the paper's ICP-SVD off the truth."""
    ex = paper_example()
    M, D = ex.map_a.endpoints(), ex.map_b.endpoints()
    plain = icp_svd(M, D, tau=PAPER_TAU)
    assert np.degrees(plain.transform.rotation_error(ex.truth)) > 2.0
    refined = icp_svd(M, D, tau=PAPER_TAU, init=ex.truth, max_distance=ex.eps)
    assert refined.transform.allclose(ex.truth, atol=1e-9)
