"""fusion.evaluation.diagnose: the classes of auto's misses."""

import numpy as np

from fusion.evaluation.diagnose import CLASSES, classify, diagnose, main
from fusion.evaluation.results import EvalPair
from fusion.evaluation.synthetic import make_pair
from fusion.structural import MergeConfig


def _pair(seed: int = 3, overlap: float = 0.8) -> EvalPair:
    p = make_pair(np.random.default_rng(seed), overlap=overlap, nodes=(30, 30))
    return EvalPair("p", p.map_a, p.map_b, p.transform, p.correspondences, p.overlap,
                    "overlap", 0.15)


def test_a_clear_pair_is_no_failure():
    assert classify(_pair(), MergeConfig()) is None


def test_an_unreachable_threshold_blames_the_evidence_not_the_search():
    # the right alignment is found but nothing can pass accept_threshold=1: the truth fails it too
    assert classify(_pair(), MergeConfig(accept_threshold=1.0)) == "truth_below_threshold"


def test_a_pair_sharing_too_few_nodes_is_told_from_weak_evidence():
    # no alignment can match 1000 nodes: the truth lacks the matches, not the score
    assert classify(_pair(), MergeConfig(min_inliers=1000)) == "truth_too_few_matches"
    assert classify(_pair(), MergeConfig(min_inliers=1000, accept_threshold=1.0)) == (
        "truth_too_few_matches")


def test_table_counts_every_pair_once(capsys):
    pairs = [_pair(s) for s in range(3)]
    table, fixable = diagnose(pairs, MergeConfig(accept_threshold=1.0))
    rows = list(table.values())
    assert sum(r["pairs"] for r in rows) == 3
    assert all(r["oracle"] == r["auto"] + sum(r[c] for c in CLASSES) for r in rows)
    assert sum(r["truth_below_threshold"] for r in rows) == sum(r["oracle"] for r in rows)
    assert fixable == []
    assert main(["--synthetic", "2", "--noise", "0.05"]) == 0
    assert "truth_below_threshold" in capsys.readouterr().out
