"""The one merge rule (fusion.decision): its defaults are the configs', it reads a config, every
step says why it stops a merge, and bad values are refused by name."""

import dataclasses
import math

import pytest

from fusion import MergeConfig, MergeEvidence, Rigid2D, decide
from fusion.decision import (
    DEFAULT_ACCEPT_THRESHOLD,
    DEFAULT_RULE,
    STRUCTURAL_ACCEPT_THRESHOLD,
    TEAM_ACCEPT_THRESHOLD,
    MergeRule,
    pair_verdict,
)
from fusion.grid_merge import GridAgreement, GridMergeConfig, GridMergeResult


def test_the_configs_defaults_are_the_rules():
    """One place for every default: the structural config's gates and threshold, the grid
    config's gates, margins and threshold, the env's thresholds."""
    from envs.explore.config import MappingConfig

    grid, merge, mapping = GridMergeConfig(), MergeConfig(), MappingConfig()
    assert grid.accept_threshold == mapping.accept_threshold == DEFAULT_ACCEPT_THRESHOLD == 0.9
    assert merge.accept_threshold == STRUCTURAL_ACCEPT_THRESHOLD == 0.8
    assert mapping.team_accept_threshold == TEAM_ACCEPT_THRESHOLD == 0.97
    assert MergeRule.of(grid) == dataclasses.replace(DEFAULT_RULE)
    structural = MergeRule.of(merge)
    assert (structural.min_inliers, structural.min_margin) == (merge.min_inliers,
                                                               merge.min_margin)
    assert structural.accept_threshold == 0.8


def test_of_reads_a_config_and_overrides():
    rule = MergeRule.of(GridMergeConfig(accept_threshold=0.7, drift_prior=0.02),
                        first_merge_check=False)
    assert (rule.accept_threshold, rule.drift_prior, rule.first_merge_check) == (0.7, 0.02,
                                                                                 False)
    with pytest.raises(TypeError, match=r"MergeRule has no fields \['threshold'\]"):
        MergeRule.of(None, threshold=0.5)


@pytest.mark.parametrize("field, value, message", [
    ("accept_threshold", 1.5, r"MergeRule.accept_threshold must be <= 1.0, got 1.5"),
    ("team_accept_threshold", -0.1, r"MergeRule.team_accept_threshold must be >= 0.0, got -0.1"),
    ("min_inliers", 2, r"MergeRule.min_inliers must be >= 3, got 2"),
    ("in_use_margin", 0.0, r"MergeRule.in_use_margin must be > 0.0, got 0.0"),
    ("drift_prior", math.nan, r"MergeRule.drift_prior must be finite, got nan"),
])
def test_bad_values_are_refused_by_name(field, value, message):
    with pytest.raises(ValueError, match=message):
        MergeRule(**{field: value})
    with pytest.raises(TypeError, match="MergeRule.first_merge_check must be a bool, got int"):
        MergeRule(first_merge_check=1)


def _evidence(**kw):
    base = dict(inliers=6, closeness=5.0, matched_edges=4, conflicts=0, crossings=0,
                branches_agree=6, branches_disagree=0, near_misses=0, rmse=0.1,
                collinear=False, n_a=20, n_b=20, likelihood=10.0, path_agree=20.0)
    return MergeEvidence(**{**base, **kw})


def test_the_structural_step_is_fusion_decide():
    """``fusion.decide`` is the rule's structural step at the config's values, each gate
    named in the reason."""
    for evidence in (_evidence(), _evidence(inliers=2), _evidence(collinear=True),
                     _evidence(runner_up=1e9)):
        for config in (None, MergeConfig(accept_threshold=0.3, min_inliers=4)):
            assert decide(evidence, config) == MergeRule.of(
                config or MergeConfig()).structural(evidence)
    why = decide(_evidence(inliers=2, collinear=True))
    assert "too few matched nodes: 2 < min_inliers=3" in why
    assert "matched nodes are collinear" in why


def test_grid_steps_name_what_failed():
    rule = MergeRule()
    assert rule.grid(0.95, 10.0, 3.0, 0.8, 0.05) is None
    assert rule.grid(0.95, 2.0, 3.0, 0.8, 0.05) == "overlap 2.0 m² < min_overlap_m2=6.0"
    assert rule.grid(0.5, 10.0, 3.0, 0.8, 0.05).startswith("confidence 0.50 < "
                                                           "accept_threshold=0.9")
    assert rule.tie_capped(0.99, 1.01) == 0.5 and rule.tie_capped(0.99, 2.0) == 0.99
    assert rule.grid_check(None) == "a grid has no known cells"
    assert rule.grid_check(GridAgreement(10.0, 0.8, 0.1, 0.0, 100)) is None
    assert rule.grid_check(GridAgreement(10.0, 0.5, 0.4, 0.0, 100)) == (
        "wall agreement 0.50 < min_wall_agreement=0.6; conflict 0.40 > max_conflict=0.3")


def test_the_transform_in_use_steps():
    """Replace unless clearly better supported; vouch, drop and refute as documented."""
    rule = MergeRule(drift_prior=0.02)
    strong, weak = GridAgreement(10, 0.9, 0.0, 0.0, 200), GridAgreement(10, 0.9, 0.0, 0.0, 100)
    assert rule.keeps(strong, weak).startswith("the grids support the transform in use better")
    assert rule.keeps(weak, strong) is None and rule.keeps(None, weak) is None
    truth = Rigid2D.from_degrees(30.0, (1.0, 2.0))
    grid = GridMergeResult(truth, False, 50.0, 10.0, 0.8, 0.1, 3.0, 0.0, "low", (0.0, 0.0),
                           0.5)
    assert rule.vouches(grid, truth).startswith("the grids' confidence in it is 0.50 < "
                                                "accept_threshold=0.9 (drift_prior 0.02)")
    assert rule.vouches(grid, Rigid2D.from_degrees(90.0) @ truth) == (
        "the grids' best alignment is another one")
    assert rule.drops(grid) is not None  # 0.5 < 0.9 - 0.3, no tie
    assert rule.drops(dataclasses.replace(grid, margin=1.0)) is None  # a tie keeps it
    assert MergeRule().drops(grid) is None  # without drift the drop rule is off
    assert rule.refutes(grid, truth, "kept") is None
    assert rule.refutes(grid, Rigid2D.identity(), None).startswith(
        "the grids refute the transform in use: their best alignment is 30°")
    assert rule.needs_vouch(False) and not MergeRule().needs_vouch(False)
    assert MergeRule().first_merge_vouch(None) and not MergeRule().first_merge_vouch(truth)
    assert not MergeRule(first_merge_check=False).first_merge_vouch(None)


def test_team_threshold_applies_from_three_robots():
    rule = MergeRule(team_accept_threshold=0.95)
    assert rule.team_min_unconfirmed(2) == 0.0 and rule.team_min_unconfirmed(3) == 0.95


def test_pair_verdict():
    a, b = Rigid2D.from_degrees(10.0), Rigid2D.from_degrees(50.0)
    assert pair_verdict(True, a, 0.9, None, 0.0, None) == "replace"
    assert pair_verdict(True, b, 0.9, a, 0.95, None) == "replace"
    assert pair_verdict(True, a, 0.97, a, 0.95, None) == "confirm"
    assert pair_verdict(True, a, 0.9, a, 0.95, None) is None
    assert pair_verdict(False, b, 0.2, a, 0.95, "refuted") == "drop"
    assert pair_verdict(False, b, 0.2, None, 0.0, "refuted") is None
