"""The paper's similarity ω and its exhaustive-search baseline."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fusion import Rigid2D, exhaustive_search, paper_example, similarity
from fusion.search import search_angles
from topo import TopoMap

# an asymmetric 8-node map: no rotation but the identity maps it onto itself
ASYM = np.array([[0, 0], [4, 0], [4, 3], [9, 3], [9, -2], [1, 6], [6, 8], [-3, 2]], float)


@settings(max_examples=20)
@given(st.floats(0, 360), st.floats(-50, 50), st.floats(-50, 50))
def test_exhaustive_recovers_any_rotation_within_the_step(deg, tx, ty):
    truth = Rigid2D.from_degrees(deg, (tx, ty))
    b = truth.inverse().apply(ASYM)
    # the nearest 2° grid angle is at most 1° off: 1° at the map's radius (~10 m) is ~0.18 m
    res = exhaustive_search(ASYM, b, step_deg=2.0, eps=0.4)
    assert res.score == len(ASYM)
    assert math.degrees(res.transform.rotation_error(truth)) <= 1.0 + 1e-9
    assert not res.ambiguous


def test_paper_counts_and_two_symmetric_optima():
    ex = paper_example()
    res = exhaustive_search(ex.map_a, ex.map_b, step_deg=2.0, eps=ex.eps)
    assert res.evaluations == 4 * 7 * 181 == 5068
    assert res.distinct_evaluations == 4 * 7 * 180 == 5040
    assert res.score == 4 and res.ambiguous and len(res.ties) == 2
    a, b = (p.transform for p in res.ties)
    assert math.degrees(a.rotation_error(b)) == pytest.approx(180.0, abs=2.0)
    # one of the two is the truth (within the 2° step)
    assert min(math.degrees(p.transform.rotation_error(ex.truth)) for p in res.ties) <= 1.0


def test_search_angles_count_0_to_360_inclusive():
    assert len(search_angles(2.0)) == 181
    assert len(search_angles(360.0)) == 2
    assert search_angles(7.0)[-1] == 357.0


def test_similarity_counts_coinciding_endpoint_pairs():
    ex = paper_example()
    assert similarity(ex.map_a, ex.map_b, ex.truth, eps=0.01) == 4
    assert similarity(ex.map_a, ex.map_b, Rigid2D.identity(), eps=0.01) == 0
    # the paper's double sum counts every pair within eps
    pts = np.array([[0.0, 0.0], [0.05, 0.0]])
    assert similarity(pts, pts, Rigid2D.identity(), eps=0.1) == 4
    assert similarity(TopoMap.empty(), pts, Rigid2D.identity()) == 0


@pytest.mark.parametrize(
    ("call", "error", "match"),
    [
        (lambda: exhaustive_search(ASYM, ASYM, step_deg=0), ValueError,
         r"step_deg must be > 0.0, got 0.0"),
        (lambda: exhaustive_search(ASYM, ASYM, step_deg=400), ValueError,
         r"step_deg must be <= 360.0, got 400.0"),
        (lambda: exhaustive_search(ASYM, ASYM, eps=-1), ValueError, r"eps must be > 0.0"),
        (lambda: exhaustive_search(TopoMap.empty(), ASYM), ValueError,
         "map_a must have at least 1 endpoint, got 0"),
        (lambda: similarity(ASYM, "B", Rigid2D.identity()), TypeError, "map_b must be an array"),
        (lambda: similarity(ASYM, ASYM, np.eye(3)), TypeError,
         "transform must be a fusion.Rigid2D, got ndarray"),
        (lambda: similarity(ASYM, ASYM, Rigid2D.identity(), eps=float("nan")), ValueError,
         "eps must be finite, got nan"),
    ],
)
def test_bad_input(call, error, match):
    with pytest.raises(error, match=match):
        call()
