"""``benchmarks/topo_repeatability.py``'s merge table: success per overlap bin, wrong accepts,
and how many accepted merges are within 2° of the true rotation."""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))  # the scripts and their helpers, as when run

import topo_repeatability as tr  # noqa: E402


def _row(overlap, accepted, success, rotation):
    return {"overlap": overlap, "methods": {"auto": {"accepted": accepted, "success": success,
                                                     "time_s": 0.001,
                                                     "rotation_deg": rotation}}}


def test_merge_table_counts_accepted_merges_within_2_degrees():
    rows = [_row(0.5, True, True, 0.4),
            _row(0.5, True, False, 2.3),  # the right place, 2.3° off: a near miss
            _row(0.8, True, False, 0.1),  # a look-alike shifted along a corridor: within 2°
            _row(0.8, False, False, 1.0),  # rejected: not counted
            _row(0.0, True, False, None)]  # no rotation to compare: not within
    head, line = tr.merge_table(rows, ["auto"])
    assert "within 2 deg" in head
    assert "3/5   (60.0%)" in line  # wrong accepts of all pairs
    assert "2/4   ( 50.0%)" in line  # within 2° of the accepted
