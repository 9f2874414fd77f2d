"""``benchmarks/real_maps.py``: a manifest of real map pairs in, one judged row per pair and
method out (errors against the truth in the maps' own frames), resumable, and a clear error for
a file that is not a manifest. What the table measures is read from RESULTS.md, not tested."""

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from topo.fileio import read_json_lines
from topo.maps import FloorPlan, load_ros_map, save_ros_map

ROOT = Path(__file__).resolve().parents[2]
# shared/maps beside the repository (or beside the folder of git worktrees)
MAPS = next((d / "shared" / "maps" for d in ROOT.parents[:2]
             if (d / "shared" / "maps").is_dir()), ROOT.parent / "shared" / "maps")
sys.path.insert(0, str(ROOT / "benchmarks"))

import real_maps  # noqa: E402

pytestmark = pytest.mark.skipif(not (MAPS / "ros" / "depot.yaml").is_file(),
                                reason="shared/maps not beside the repo")


def manifest(folder: Path) -> Path:
    """Two crops of the depot map, B turned a quarter and moved (truth known), and B against
    another map (no truth)."""
    plan = load_ros_map(MAPS / "ros" / "depot.yaml")
    h, w = plan.free.shape
    res = plan.resolution
    a = FloorPlan(plan.free[:, : int(w * 0.65)], plan.occupied[:, : int(w * 0.65)], res,
                  (0.0, 0.0), "a")
    c0 = int(w * 0.35)
    b = FloorPlan(np.ascontiguousarray(np.rot90(plan.free[:, c0:])),
                  np.ascontiguousarray(np.rot90(plan.occupied[:, c0:])), res, (3.0, -2.0), "b")
    for p in (a, b):
        save_ros_map(p, folder / f"{p.name}.yaml")
    other = load_ros_map(MAPS / "ros" / "tb3_sandbox.yaml")
    save_ros_map(other, folder / "other.yaml")
    pairs = [{"id": "p0", "building": "depot", "split": "dev", "a": "a.yaml", "b": "b.yaml",
              "truth": [w * res - 2.0, -3.0, math.pi / 2], "overlap": 0.4,
              "overlap_m2": 0.3 * h * w * res * res},
             {"id": "x0", "building": "depot+sandbox", "split": "test", "a": "other.yaml",
              "b": "b.yaml", "truth": None, "overlap": 0.0, "overlap_m2": 0.0}]
    path = folder / "manifest.json"
    path.write_text(json.dumps({"format": real_maps.FORMAT, "version": 1, "resolution": res,
                                "pairs": pairs}))
    return path


def test_rows_judge_the_estimate_against_the_truth_and_a_rerun_resumes(tmp_path, capsys):
    path = manifest(tmp_path)
    out = tmp_path / "out"
    assert real_maps.main(["--pairs", str(path), "--split", "all", "--out", str(out)]) == 0
    rows = {r["id"]: r for r in read_json_lines(out / "grid.jsonl")}
    assert set(rows) == {"p0", "x0"}
    p0, x0 = rows["p0"], rows["x0"]
    assert p0["right"] and p0["rotation_error_deg"] < 1.0 and p0["translation_error_m"] < 0.2
    assert p0["set"] == "real_pairs_dev" and p0["world"] == "depot" and p0["way"] == "ab"
    assert set(p0["features"]) >= {"log_margin", "log_overlap", "native_agreement"}
    assert not x0["right"] and x0["rotation_error_deg"] is None and x0["no_truth"]
    text = (out / "table.md").read_text()
    assert "| grid [sim: grid ≥ 0.9] | 2 | 1 |" in text
    before = (out / "grid.jsonl").read_bytes()
    capsys.readouterr()
    real_maps.main(["--pairs", str(path), "--split", "dev", "--out", str(out)])
    assert "1/1" not in capsys.readouterr().out  # done already: not merged again
    assert (out / "grid.jsonl").read_bytes() == before


def test_split_selects_pairs(tmp_path):
    path = manifest(tmp_path)
    assert [p["id"] for p in real_maps.read_manifest(path, "test")] == ["x0"]
    assert real_maps.read_manifest(path, "dev")[0]["a"] == str(tmp_path / "a.yaml")
    with pytest.raises(ValueError, match=r"split must be 'dev', 'test' or 'all', got 'x'"):
        real_maps.read_manifest(path, "x")


def test_not_a_manifest_is_named(tmp_path):
    bad = tmp_path / "m.json"
    bad.write_text(json.dumps({"format": "other", "version": 1, "pairs": []}))
    with pytest.raises(real_maps.ManifestError, match=r"m\.json: not a topomerge\.real_pairs "
                                                      r"version 1 manifest"):
        real_maps.read_manifest(bad)
    with pytest.raises(real_maps.ManifestError, match=r"nope\.json: manifest not found"):
        real_maps.read_manifest(tmp_path / "nope.json")
    bad.write_text(json.dumps({"format": real_maps.FORMAT, "version": 1,
                               "pairs": [{"id": "q", "a": "a.yaml"}]}))
    with pytest.raises(real_maps.ManifestError, match=r"pair 'q' lacks \['building'"):
        real_maps.read_manifest(bad)
