"""The paper's similarity ω and its exhaustive-search baseline."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fusion import Rigid2D, exhaustive_search, paper_example, similarity
from fusion.search import (
    DEFAULT_MAX_EVALUATIONS,
    exhaustive_evaluations,
    fitting_step,
    search_angles,
)
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


def test_exhaustive_refuses_large_maps_at_once_saying_how_long_and_what_fits():
    big = np.random.default_rng(0).uniform(0, 40, (300, 2))
    with pytest.raises(ValueError, match=(
            r"^exhaustive_search: 300 × 300 endpoints × 181 angles \(step_deg=2\) = 16,290,000 "
            r"placements, above max_evaluations=5,000,000 \(about 33 s at 2 µs each; step_deg "
            r">= 6.6 fits\); pass max_evaluations=None \(or a larger limit\) to run it anyway, "
            r"or a coarser step_deg \(merge_maps: MergeConfig.exhaustive_step_deg\)$")):
        exhaustive_search(big, big)
    assert exhaustive_evaluations(300, 300, 6.6) <= DEFAULT_MAX_EVALUATIONS
    assert exhaustive_evaluations(300, 300, 6.5) > DEFAULT_MAX_EVALUATIONS


def test_exhaustive_limit_is_exact_and_can_be_lifted():
    n = len(ASYM) ** 2 * 181
    assert exhaustive_search(ASYM, ASYM, max_evaluations=n).evaluations == n
    with pytest.raises(ValueError, match=r"= 11,584 placements, above max_evaluations=11,583 "):
        exhaustive_search(ASYM, ASYM, max_evaluations=n - 1)
    assert exhaustive_search(ASYM, ASYM, max_evaluations=None).evaluations == n
    # the step the refusal suggests runs within the limit
    step = fitting_step(len(ASYM), len(ASYM), 1000)
    assert exhaustive_search(ASYM, ASYM, step_deg=step, max_evaluations=1000).evaluations <= 1000
    with pytest.raises(ValueError, match=r"no step_deg fits: the maps are too large"):
        exhaustive_search(ASYM, ASYM, max_evaluations=100)  # 64 × 2 angles > 100


@settings(max_examples=50)
@given(st.integers(1, 400), st.integers(1, 400), st.integers(1, 10**7))
def test_fitting_step_is_the_finest_tenth_of_a_degree_that_fits(n_a, n_b, limit):
    step = fitting_step(n_a, n_b, limit)
    if step is None:
        assert n_a * n_b * 2 > limit
    else:
        assert exhaustive_evaluations(n_a, n_b, step) <= limit
        assert step == 0.1 or exhaustive_evaluations(n_a, n_b, round(step - 0.1, 1)) > limit


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
        (lambda: exhaustive_search(ASYM, ASYM, max_evaluations=0), ValueError,
         "max_evaluations must be >= 1, got 0"),
        (lambda: exhaustive_search(ASYM, ASYM, max_evaluations=1e6), TypeError,
         "max_evaluations must be an integer, got float"),
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


def test_too_fine_a_step_is_refused_before_the_angles_are_built():
    import tracemalloc

    ex = paper_example()
    tracemalloc.start()
    try:
        with pytest.raises(ValueError, match=r"360000001 angles \(step_deg=1e-06\).*coarser "
                                             r"step_deg"):
            exhaustive_search(ex.map_a, ex.map_b, step_deg=1e-6)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 10_000_000  # the 360 M angles alone would be 2.9 GB


@pytest.mark.parametrize("step", ["2", None, float("nan"), 0.0, -1.0, 361.0])
def test_bad_step_deg_names_it(step):
    ex = paper_example()
    with pytest.raises((TypeError, ValueError), match="step_deg"):
        exhaustive_search(ex.map_a, ex.map_b, step_deg=step)
