"""``benchmarks/bending_in_loop.py``: a tiny run prints its tables, and its bend floor (how
often even a perfect window aligner's link is wrong) is zero for rigid maps and not for bent
ones."""

import math
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

from fusion import Rigid2D

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))  # as when run: its shared helpers (_timing)

import bending_in_loop as bil  # noqa: E402


def _graph(turn_per_anchor_deg: float, anchors: int = 12, window: int = 4):
    """Two robots driving the same square loop (side 4 m, an anchor a metre), robot 1 starting
    half a metre aside; each robot's odometry is its true path seen from a rotated, shifted
    start frame, robot 0's heading drifting ``turn_per_anchor_deg`` per anchor (its path bent
    with it)."""
    subs = []
    for r, start in enumerate((Rigid2D(0.3, (1.0, -2.0)), Rigid2D(-1.2, (0.5, 3.0)))):
        true, odo = [], []
        pose, bent = Rigid2D(0.0, (0.0, 0.5 * r)), Rigid2D()
        for k in range(anchors):
            true.append([pose.T[0], pose.T[1], pose.theta])
            o = start @ bent
            odo.append(Rigid2D(o.theta, (float(o.T[0]), float(o.T[1]))))
            step = Rigid2D(math.pi / 2 if k % 4 == 3 else 0.0, (1.0, 0.0))
            pose = pose @ step
            drift = math.radians(turn_per_anchor_deg) if r == 0 else 0.0
            bent = bent @ Rigid2D(step.theta + drift, step.T)
        subs.append(SimpleNamespace(patches=[None] * anchors, poses=odo, truths=true))
    return SimpleNamespace(config=SimpleNamespace(window_anchors=window), submaps=subs)


def test_bend_floor_is_zero_for_rigid_maps_and_not_for_bent_ones():
    rigid = bil.bend_floor(_graph(0.0))
    assert rigid["floor_pairs"] > 20
    assert rigid["floor_mid_wrong"] == rigid["floor_last_wrong"] == 0.0
    bent = bil.bend_floor(_graph(12.0))
    assert bent["floor_pairs"] == rigid["floor_pairs"]
    assert 0.0 < bent["floor_mid_wrong"] <= bent["floor_last_wrong"]


def test_a_tiny_run_prints_both_tables(capsys):
    pytest.importorskip("gtsam")
    bil.main(["--worlds", "1", "--steps", "40", "--size", "10", "--settings", "on", "off"])
    out = capsys.readouterr().out
    assert "loops kept wrong | bend floor: ideal window links wrong (middle / newest anchors)" in out
    rows = [line for line in out.splitlines() if line.startswith(("on |", "off |"))]
    assert len(rows) == 2 and rows[0].split(" | ")[1] == "0/1"


def test_rows_are_written_and_their_calibration_printed(tmp_path, capsys):
    pytest.importorskip("gtsam")
    path = tmp_path / "near.jsonl"
    bil.main(["--worlds", "1", "--steps", "40", "--size", "10", "--settings", "on",
              "--rows", str(path)])
    assert "near searches: none" in capsys.readouterr().out
    assert path.read_text() == ""  # no window closes in 40 steps: no rows, but the file
    lines = bil.calibration_lines([{"confidence": 0.92, "right": True},
                                   {"confidence": 0.91, "right": False},
                                   {"confidence": 0.6, "right": True}])
    assert lines[0] == "near searches: 3, mean confidence 0.810, right 0.667"
    assert "0.90–0.95 | 2 | 0.915 | 0.500" in lines


def test_a_run_resumes_from_its_out_file_and_is_compared_paired(tmp_path, capsys, monkeypatch):
    pytest.importorskip("gtsam")
    out = tmp_path / "run.jsonl"
    tiny = ["--worlds", "1", "--steps", "40", "--size", "10", "--settings", "on"]
    bil.main([*tiny, "--out", str(out)])
    first = out.read_text()
    assert len(first.splitlines()) == 1

    def no_episode(*args, **kwargs):
        raise AssertionError("a resumed run ran an episode it had")

    monkeypatch.setattr(bil, "episode", no_episode)
    bil.main([*tiny, "--out", str(out)])
    assert out.read_text() == first
    with pytest.raises(ValueError, match=r"--out .*run.jsonl holds a run with other options "
                                         r"\(.*'steps': 40.*\): resume it with those"):
        bil.main([*tiny[:2], "--steps", "41", *tiny[4:], "--out", str(out)])
    capsys.readouterr()
    bil.main(["--from", str(out), "--against", str(out)])
    text = capsys.readouterr().out
    assert "paired: 1 episodes (new minus old)" in text
    assert "fused ATE m | " in text and "| +0.000 (nan) | 0 / 0" in text
    with pytest.raises(FileNotFoundError, match=r"nothing.jsonl: no run rows"):
        bil.main(["--from", str(tmp_path / "nothing.jsonl")])
    with pytest.raises(SystemExit):
        bil.main(["--from", str(out), "--out", str(tmp_path / "again.jsonl")])
    assert "--from summarises runs already made: it takes no --out" in capsys.readouterr().err


def _row(seed: int, fused: float, own: float, wall: float, first_right: int | None) -> dict:
    return {"seed": seed, "graph": True, "fused_ate_m": fused, "own_ate_m": own,
            "fused_wall_share": wall, "own_wall_share": 0.5, "merged": 10 * bool(first_right),
            "first_right": first_right, "links_kept": 10, "links_kept_wrong": 1,
            "loops_kept": 4, "loops_kept_wrong": 2}


def test_paired_lines_count_better_and_worse_episodes_and_folds():
    old = [_row(0, 0.30, 0.50, 0.70, 500), _row(1, 0.30, 0.50, 0.70, 900),
           _row(2, 0.30, 0.50, 0.70, None), {**_row(3, 0.1, 0.1, 0.9, 1), "graph": False}]
    new = [_row(0, 0.20, 0.50, 0.75, 400), _row(1, 0.31, 0.50, 0.69, 1000),
           _row(2, 0.90, 0.50, 0.60, None), _row(4, 0.1, 0.1, 0.9, 1)]
    lines = bil.paired_lines(old, new)
    assert lines[0] == "paired: 3 episodes (new minus old)"
    assert "fused ATE m | 0.300 | 0.470 | +0.170 (0.217) | 1 / 1" in lines
    assert "fused wall share | 0.700 | 0.680 | -0.020 (0.044) | 1 / 1" in lines
    assert lines[6].endswith("folded (fused ATE > own + 0.3 m) 0: []")
    assert lines[7].endswith("folded (fused ATE > own + 0.3 m) 1: [2]")
    assert lines[8] == ("first right, the 2 episodes both merged right: mean difference +0 "
                        "steps (100)")
    assert bil.paired_lines(old, [])[0] == "paired: no pose-graph episode in both runs"
