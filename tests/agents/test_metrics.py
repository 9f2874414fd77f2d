"""EpisodeRecorder: coverage thresholds (with censoring), path length, merge bookkeeping."""

import math

import numpy as np

from agents.metrics import EpisodeRecorder


def infos(cov, x, accepted=False, collisions=0):
    common = {"true_coverage": cov, "merge_accepted": accepted, "overlap": 0.25,
              "merge_errors_valid": accepted,
              "merge_rotation_error_deg": 1.5 if accepted else 0.0,
              "merge_translation_error_m": 0.1 if accepted else 0.0}
    return {"robot_0": {**common, "pose": np.array([x, 0.0, 0.0]), "collisions": collisions},
            "robot_1": {**common, "pose": np.array([0.0, 2 * x, 0.0]), "collisions": 0}}


def test_thresholds_path_and_merges():
    rec = EpisodeRecorder()
    covs = [0.1, 0.3, 0.55, 0.7, 0.86, 0.9]
    for step, c in enumerate(covs, start=1):
        rec(step, {}, {}, infos(c, float(step), accepted=step >= 4, collisions=step // 3))
    rec(7, {}, {}, {})  # the final, empty infos of a finished episode are skipped
    s = rec.summary()
    assert (s["T50"], s["reached_T50"]) == (3, True)
    assert (s["T85"], s["reached_T85"]) == (5, True)
    assert (s["T95"], s["reached_T95"]) == (7, False)  # censored at length + 1
    assert s["path_length_m"] == {"robot_0": 5.0, "robot_1": 10.0}
    assert s["collisions"] == 2
    assert s["merge_first_accept_step"] == 4 and s["merge_accept_fraction"] == 0.5
    assert s["merge_rotation_error_deg"] == 1.5 and s["overlap"] == 0.25
    np.testing.assert_array_equal(s["coverage"], covs)


def test_merge_errors_are_nan_without_a_transform_in_use_at_the_end():
    rec = EpisodeRecorder()
    rec(1, {}, {}, infos(0.1, 1.0, accepted=True))
    rec(2, {}, {}, infos(0.2, 2.0, accepted=False))  # dropped: the infos' errors are 0.0
    s = rec.summary()
    assert math.isnan(s["merge_rotation_error_deg"]) and math.isnan(s["merge_translation_error_m"])
