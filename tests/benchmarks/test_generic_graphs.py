"""``benchmarks/generic_graphs.py``: several seeds pooled, and the threshold sweep — what other
accept thresholds would give, read from one run's confidences and hard gates."""

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))  # the scripts and their helpers, as when run

import generic_graphs as gg  # noqa: E402


def _rec(kind, confidence, right, gated=False):
    return {"kind": kind, "auto": {"confidence": confidence, "right": right, "gated": gated},
            "oracle": {"right": kind == "overlap"}}


def test_sweep_accepts_past_the_gates_at_each_threshold():
    recs = [_rec("overlap", 0.9, True), _rec("overlap", 0.7, True),
            _rec("overlap", 0.99, True, gated=True),  # refused by a hard gate at any threshold
            _rec("overlap", 0.8, False), _rec("other_world", 0.6, False),
            _rec("disjoint", 0.3, False)]
    rows = {r["threshold"]: r for r in gg.sweep(recs, "auto", (0.5, 0.75, 0.95))}
    assert rows[0.5] == {"threshold": 0.5, "success": 2, "wrong": 1, "false": 1,
                         "positives": 4, "negatives": 2}
    assert (rows[0.75]["success"], rows[0.75]["wrong"], rows[0.75]["false"]) == (1, 1, 0)
    assert (rows[0.95]["success"], rows[0.95]["wrong"], rows[0.95]["false"]) == (0, 0, 0)


def test_sweep_at_the_default_threshold_is_what_merge_maps_accepted():
    recs = gg.records(500, 10, [0.0], ["auto"])
    for r in recs:
        e = r["auto"]
        assert e["accepted"] == (not e["gated"] and e["confidence"] >= 0.8), r["name"]
    row = gg.sweep(recs, "auto", (0.8,))[0]
    pos = [r for r in recs if r["kind"] == "overlap"]
    assert row["success"] == sum(r["auto"]["accepted"] and r["auto"]["right"] for r in pos)


def test_sweep_report_names_the_threshold_the_false_accept_limit_allows():
    recs = [_rec("overlap", 0.9, True), _rec("overlap", 0.6, True),
            _rec("other_world", 0.7, False)]
    text = gg.sweep_report(recs, "auto")
    assert "allows threshold 0.75: success 50.0 % (1/2)" in text
    assert "Ceiling of any threshold (right and past the hard gates): 100.0 % (2/2)" in text
    recs.append(_rec("disjoint", 0.99, False))
    assert "No threshold of 0.5–0.95 keeps false accepts within 1 %" in \
        gg.sweep_report(recs, "auto")


def test_pooled_seeds_print_the_sweep(capsys):
    assert gg.main(["--seeds", "500,501", "--pairs", "5", "--noise", "0", "--methods", "auto",
                    "--sweep"]) == 0
    out = capsys.readouterr().out
    assert "seeds 500,501, 5 per noise level" in out
    assert "all overlapping (8)" in out  # 4 overlapping pairs of 5 per seed
    assert "| `auto` threshold |" in out


@pytest.mark.parametrize("text", ["500,x", "500,500"])
def test_bad_seeds_name_the_option_and_the_value(text):
    with pytest.raises(ValueError, match=f"--seeds .*{text}"):
        gg.main(["--seeds", text, "--pairs", "5", "--noise", "0", "--methods", "auto"])
