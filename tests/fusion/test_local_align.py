"""fusion.local_align.align_near: a local search near an estimate finds the alignment the
estimate is near, refuses what the grids disprove, and names bad arguments."""

import math

import numpy as np
import pytest
from test_grid_merge import overlapping_views, plan, view

from fusion import Rigid2D
from fusion.local_align import MAX_TRANSLATIONS, NEAR_FEATURES, align_near, near_features


def _off(truth: Rigid2D, deg: float, dx: float, dy: float) -> Rigid2D:
    return Rigid2D(truth.theta + math.radians(deg), truth.T + np.array([dx, dy]))


@pytest.mark.parametrize("deg, dx, dy", [(0.0, 0.0, 0.0), (2.0, 0.3, -0.2), (-2.5, -0.4, 0.4)])
def test_recovers_the_truth_from_an_estimate_within_the_box(deg, dx, dy):
    a, b, truth = overlapping_views(37.0, Rigid2D.from_degrees(20.0, (3.0, 2.0)), (12.0, 5.0))
    found = align_near(a, b, _off(truth, deg, dx, dy))
    assert found is not None
    centre = np.array([12.0, 5.0])
    assert math.degrees(found.rotation_error(truth)) < 1.0
    assert found.translation_error(truth, at=centre) < 0.15


def test_an_estimate_far_outside_the_box_is_not_pulled_to_the_truth():
    a, b, truth = overlapping_views(0.0)
    found = align_near(a, b, _off(truth, 25.0, 3.0, -3.0))
    centre = np.array([12.0, 5.0])
    assert found is None or found.translation_error(truth, at=centre) > 1.0


def test_grids_that_do_not_overlap_give_none():
    states = plan(2)
    frame = Rigid2D.from_degrees(10.0, (0.0, 0.0))
    a = view(states, frame, (1, 1), (12, 12))
    b = view(states, frame, (17, 17), (29, 29))
    assert align_near(a, b, Rigid2D()) is None


def test_bad_arguments_are_named():
    a, b, truth = overlapping_views(0.0)
    with pytest.raises(TypeError, match="estimate must be a fusion.Rigid2D"):
        align_near(a, b, (0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="max_deg must be <= 180"):
        align_near(a, b, truth, max_deg=400.0)
    with pytest.raises(ValueError, match="step_deg must be > 0"):
        align_near(a, b, truth, step_deg=0.0)
    with pytest.raises(ValueError, match=rf"reach_m=50.0 gives .* \(at most {MAX_TRANSLATIONS}\)"):
        align_near(a, b, truth, reach_m=50.0)
    with pytest.raises(ValueError, match="reach_m must be finite"):
        align_near(a, b, truth, reach_m=float("nan"))


def test_near_features_read_how_far_the_search_moved_and_how_walls_land():
    a, b, truth = overlapping_views(37.0, Rigid2D.from_degrees(20.0, (3.0, 2.0)), (12.0, 5.0))
    same = near_features(a, b, truth, truth, loop=True)
    assert tuple(same) == NEAR_FEATURES
    assert same["corr_deg"] == pytest.approx(0.0, abs=1e-9)
    assert same["log_corr_m"] == pytest.approx(math.log(0.05))
    assert same["loop"] == 1.0 and same["anchor_shift_deg"] == 0.0
    assert same["wall_agreement"] > 0.8 and same["conflict"] < 0.1
    moved = near_features(a, b, _off(truth, 2.0, 0.3, 0.0), truth, anchor_shift_deg=1.5)
    assert moved["corr_deg"] == pytest.approx(2.0)
    assert moved["log_corr_m"] > same["log_corr_m"] and moved["loop"] == 0.0
    assert moved["anchor_shift_deg"] == 1.5
    wrong = near_features(a, b, truth, _off(truth, 0.0, 2.0, -2.0))
    assert wrong["wall_agreement"] < same["wall_agreement"]
    assert wrong["conflict"] > same["conflict"] and wrong["native_deep"] > same["native_deep"]


def test_near_features_name_bad_arguments():
    a, b, truth = overlapping_views(0.0)
    with pytest.raises(TypeError, match="transform must be a fusion.Rigid2D, got tuple"):
        near_features(a, b, truth, (0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="anchor_shift_deg must be >= 0"):
        near_features(a, b, truth, truth, anchor_shift_deg=-1.0)


def test_the_stored_near_model_reads_these_features_and_says_a_probability():
    from fusion.calibration import load_model

    model = load_model("window_near")
    assert tuple(model.names) == NEAR_FEATURES
    a, b, truth = overlapping_views(37.0, Rigid2D.from_degrees(20.0, (3.0, 2.0)), (12.0, 5.0))
    good = model(near_features(a, b, truth, truth))
    far = model(near_features(a, b, _off(truth, 3.0, 0.5, 0.0), truth, anchor_shift_deg=4.0))
    assert 0.0 < far < good < 1.0


def test_near_features_check_the_grids_as_align_near_does():
    a, _, truth = overlapping_views(0.0)
    with pytest.raises((TypeError, ValueError), match="grid_b"):
        near_features(a, "not a grid", truth, truth)
