"""The map-merge tool (``python -m fusion merge``): ROS maps in, merged map and transforms out,
and a clear error or "not merged" for bad input."""

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from PIL import Image

from fusion.__main__ import main as fusion_main
from fusion.mapmerge import (
    EXIT_BAD_INPUT,
    EXIT_MERGED,
    EXIT_NOT_MERGED,
    load_input,
    main,
    resampled,
)
from fusion.rigid import Rigid2D
from topo.maps import FloorPlan, MapFileError, load_ros_map, save_ros_map

MAPS = Path(__file__).resolve().parents[3] / "shared" / "maps"
RES = 0.1


def building(seed: int, shape=(160, 240)) -> FloorPlan:
    """A walled floor of rooms and boxes, none alike (the rooms' doors and boxes are random)."""
    rng = np.random.default_rng(seed)
    h, w = shape
    occ = np.zeros(shape, dtype=bool)
    occ[[0, -1], :] = True
    occ[:, [0, -1]] = True
    for c in range(40, w - 20, int(rng.integers(45, 60))):  # room walls with doors
        occ[:, c] = True
        for _ in range(2):
            d = int(rng.integers(5, h - 15))
            occ[d:d + 10, c] = False
    for _ in range(14):  # boxes of random sizes
        r, c = int(rng.integers(5, h - 20)), int(rng.integers(5, w - 20))
        dh, dw = (int(v) for v in rng.integers(3, 14, size=2))
        occ[r:r + dh, c:c + dw] = True
    return FloorPlan(~occ, occ, RES, (0.0, 0.0), f"building{seed}")


def crops(plan: FloorPlan, origin_b=(3.0, -2.0)):
    """A = the left 65 % of ``plan``, B = the right 65 % turned 90° (``np.rot90``) at
    ``origin_b``, and the true B → A transform."""
    h, w = plan.free.shape
    a_w, b_c0 = int(w * 0.65), int(w * 0.35)
    a = FloorPlan(plan.free[:, :a_w], plan.occupied[:, :a_w], RES, (0.0, 0.0), "a")
    b = FloorPlan(np.ascontiguousarray(np.rot90(plan.free[:, b_c0:])),
                  np.ascontiguousarray(np.rot90(plan.occupied[:, b_c0:])), RES, origin_b, "b")
    # B cell (i, j) is plan cell (row j, col w - 1 - i): x_a = -y_b + w·res - oy, y_a = x_b - ox
    truth = Rigid2D(math.pi / 2, (w * RES + origin_b[1], -origin_b[0]))
    return a, b, truth


def run(argv, capsys):
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def placed(out_dir: Path, name: str) -> dict:
    rows = json.loads((out_dir / "transforms.json").read_text())["maps"]
    return next(r for r in rows if r["name"] == name)


def assert_close(row: dict, truth: Rigid2D, tol_m=0.15, tol_deg=1.0):
    assert row["merged"] and row["why"] is None
    assert math.degrees(abs(row["yaw"] - truth.theta)) < tol_deg
    assert math.hypot(row["x"] - truth.T[0], row["y"] - truth.T[1]) < tol_m


def test_two_ros_maps_merge_and_every_output_is_written(tmp_path, capsys):
    plan = building(0)
    a, b, truth = crops(plan)
    ya, yb = save_ros_map(a, tmp_path / "a.yaml"), save_ros_map(b, tmp_path / "b.yaml")
    code, out, _ = run([ya, yb, "--out", tmp_path / "out"], capsys)
    assert code == EXIT_MERGED
    assert "b: x=" in out
    out_dir = tmp_path / "out"
    assert_close(placed(out_dir, "b"), truth)
    assert placed(out_dir, "a")["method"] == "reference"
    assert placed(out_dir, "a")["colour"] == "#1f77b4" and placed(out_dir, "b")["colour"]
    doc = yaml.safe_load((out_dir / "transforms.yaml").read_text())
    assert doc["reference"] == "a" and doc["all_merged"] is True
    merged = load_ros_map(out_dir / "merged.yaml")  # map_server's format, read back
    assert merged.resolution == pytest.approx(RES)
    assert merged.origin[0] == pytest.approx(0.0, abs=RES) and merged.origin[1] == pytest.approx(
        0.0, abs=RES)
    assert abs(merged.free.shape[0] - plan.free.shape[0]) <= 2
    assert abs(merged.free.shape[1] - plan.free.shape[1]) <= 2
    h, w = (min(s, t) for s, t in zip(merged.free.shape, plan.free.shape, strict=True))
    assert (merged.free[:h, :w] == plan.free[:h, :w]).mean() > 0.97
    png = np.asarray(Image.open(out_dir / "merged.png"))
    assert png.shape == (*merged.free.shape, 3)


def test_yaw_resolution_and_three_maps(tmp_path, capsys):
    plan = building(1)
    a, b, truth = crops(plan)
    # B at half the cell size and its ROS origin turned by 0.3 rad: the transform is into A's
    # map frame, so B's turn is undone in it
    fine = FloorPlan(np.kron(b.free, np.ones((2, 2), bool)),
                     np.kron(b.occupied, np.ones((2, 2), bool)), RES / 2, b.origin, "b", 0.3)
    c = FloorPlan(plan.free[:, 60:200], plan.occupied[:, 60:200], RES, (-1.0, 1.0), "c")
    paths = [save_ros_map(p, tmp_path / f"{p.name}.yaml") for p in (a, fine, c)]
    assert load_input(str(paths[1]))[0].resolution == RES / 2
    assert resampled(load_input(str(paths[1]))[0], RES).resolution == RES
    code, _, _ = run([*paths, "--out", tmp_path / "out"], capsys)
    assert code == EXIT_MERGED
    turn = Rigid2D(0.3, np.asarray(b.origin) - Rigid2D(0.3).apply(np.asarray([b.origin]))[0])
    assert_close(placed(tmp_path / "out", "b"), truth @ turn.inverse(), tol_m=0.2)
    assert_close(placed(tmp_path / "out", "c"), Rigid2D(0.0, (7.0, -1.0)))


def test_maps_with_no_overlap_are_not_merged(tmp_path, capsys):
    a = save_ros_map(building(2), tmp_path / "a.yaml")
    b = save_ros_map(building(3, (150, 150)), tmp_path / "b.yaml")
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    (out_dir / "merged.yaml").write_text("an older run's")
    code, out, _ = run([a, b, "--out", out_dir], capsys)
    assert code == EXIT_NOT_MERGED
    assert "b: not merged: no pair accepted (best: with a, confidence" in out
    assert "(transforms only: no merged map)" in out
    assert not any((out_dir / n).exists() for n in ("merged.yaml", "merged.pgm", "merged.png"))
    assert placed(out_dir, "b")["x"] is None
    assert placed(out_dir, "b")["why"].startswith("no pair accepted")
    assert "colour" not in placed(out_dir, "a")  # no picture drawn
    code, _, _ = run([a, b, "--out", out_dir, "--write-unmerged"], capsys)
    assert code == EXIT_NOT_MERGED
    assert load_ros_map(out_dir / "merged.yaml").free.shape == (160, 240)


def write_yaml(tmp_path, **fields) -> Path:
    Image.fromarray(np.full((8, 8), 254, np.uint8)).save(tmp_path / "m.pgm")
    base = {"image": "m.pgm", "resolution": 0.1, "origin": [0.0, 0.0, 0.0],
            "occupied_thresh": 0.65, "free_thresh": 0.196, "negate": 0}
    (tmp_path / "m.yaml").write_text(yaml.safe_dump({**base, **fields}))
    return tmp_path / "m.yaml"


@pytest.mark.parametrize("case, message", [
    ("text", r"notes\.txt: not a map file \(unknown format '\.txt'; expected a ROS map "
             r"\.yaml"),
    ("missing_image", r"m\.yaml: names image \S*gone\.pgm: map image file not found"),
    ("bad_field", r"m\.yaml: 'origin' must be \[x, y, yaw\] of finite numbers, got 'here'"),
    ("bad_mode", r"m\.yaml: mode must be 'trinary', 'scale' or 'raw', got 'fancy'"),
    ("not_yaml_map", r"m\.yaml: expected a YAML mapping, got list"),
    ("not_an_image", r"bad\.png: cannot read the image"),
    ("all_unknown", r"u\.yaml: empty map \(all unknown\): nothing to align"),
    ("no_walls", r"m\.yaml: empty map \(no occupied cell\): nothing to align"),
    ("plain_no_scale", r"p\.png: a plain image has no scale: give --resolution"),
    ("missing_file", r"nope\.yaml: map YAML file not found"),
    ("one_map", r"need two or more maps to merge, got 1"),
])
def test_bad_input_is_one_clear_line_and_exit_2(tmp_path, capsys, case, message):
    good = save_ros_map(building(4), tmp_path / "good.yaml")
    if case == "text":
        bad = tmp_path / "notes.txt"
        bad.write_text("hello")
    elif case == "missing_image":
        bad = write_yaml(tmp_path, image="gone.pgm")
    elif case == "bad_field":
        bad = write_yaml(tmp_path, origin="here")
    elif case == "bad_mode":
        bad = write_yaml(tmp_path, mode="fancy")
    elif case == "not_yaml_map":
        bad = tmp_path / "m.yaml"
        bad.write_text("- 1\n- 2\n")
    elif case == "not_an_image":
        bad = tmp_path / "bad.png"
        bad.write_bytes(b"not a png at all")
    elif case == "all_unknown":
        empty = np.zeros((6, 6), bool)
        bad = save_ros_map(FloorPlan(empty, empty, 0.1, (0.0, 0.0), "u"), tmp_path / "u.yaml")
    elif case == "no_walls":
        bad = write_yaml(tmp_path)
    elif case == "plain_no_scale":
        bad = tmp_path / "p.png"
        Image.fromarray(np.zeros((8, 8), np.uint8)).save(bad)
    elif case == "missing_file":
        bad = tmp_path / "nope.yaml"
    else:
        bad = None
    argv = [good] + ([bad] if bad is not None else []) + ["--out", tmp_path / "out"]
    code, out, err = run(argv, capsys)
    assert code == EXIT_BAD_INPUT
    assert err.startswith("python -m fusion merge: error: ") and err.count("\n") == 1
    assert re.search(message, err), err
    assert not (tmp_path / "out" / "transforms.json").exists()


def test_plain_images_and_the_module_command(tmp_path, capsys):
    a, b, truth = crops(building(5))
    for p in (a, b):  # map_saver's grey levels, no YAML
        grey = np.where(p.occupied, 0, np.where(p.free, 254, 205)).astype(np.uint8)
        Image.fromarray(np.ascontiguousarray(grey[::-1])).save(tmp_path / f"{p.name}.png")
    code = fusion_main(["merge", str(tmp_path / "a.png"), str(tmp_path / "b.png"),
                        "--resolution", str(RES), "--out", str(tmp_path / "out")])
    assert code == EXIT_MERGED
    # a plain image's origin is (0, 0): B's frame is its image corner
    assert_close(placed(tmp_path / "out", "b"), truth @ Rigid2D(0.0, b.origin))
    code, _, err = run([tmp_path / "a.png", tmp_path / "b.png", "--resolution", "-1",
                        "--out", tmp_path / "out"], capsys)
    assert code == EXIT_BAD_INPUT and "--resolution must be > 0.0, got -1.0" in err
    assert fusion_main(["split"]) == 2
    assert "unknown command 'split'" in capsys.readouterr().err


def test_load_input_refuses_a_bad_pair_selector(tmp_path):
    with pytest.raises(MapFileError, match=r"x\.npz:c: a map-pair file's grid is ':a' or "
                                           r"':b', got 'c'"):
        load_input(str(tmp_path / "x.npz:c"))
    with pytest.raises(MapFileError, match=r"x\.npz: map-pair file not found"):
        load_input(str(tmp_path / "x.npz"))


@pytest.mark.skipif(not (MAPS / "ros" / "depot.yaml").is_file(),
                    reason="shared/maps not beside the repo")
def test_real_map_crops_merge(tmp_path, capsys):
    plan = load_ros_map(MAPS / "ros" / "depot.yaml")
    h, w = plan.free.shape
    a = FloorPlan(plan.free[:, : int(w * 0.65)], plan.occupied[:, : int(w * 0.65)],
                  plan.resolution, (0.0, 0.0), "a")
    c0 = int(w * 0.35)
    b = FloorPlan(np.ascontiguousarray(np.rot90(plan.free[:, c0:])),
                  np.ascontiguousarray(np.rot90(plan.occupied[:, c0:])), plan.resolution,
                  (3.0, -2.0), "b")
    paths = [save_ros_map(p, tmp_path / f"{p.name}.yaml") for p in (a, b)]
    code, _, _ = run([*paths, "--out", tmp_path / "out"], capsys)
    assert code == EXIT_MERGED
    assert_close(placed(tmp_path / "out", "b"),
                 Rigid2D(math.pi / 2, (w * plan.resolution - 2.0, -3.0)), tol_m=0.1)


def test_map_pair_files_give_their_grids(tmp_path, capsys):
    from fusion.evaluation.pairs import GridSnapshot, MapPair, write_pair
    from topo import TopoMap

    a, b, truth = crops(building(6))
    topo = TopoMap.from_arrays(np.array([[0.0, 0.0], [1.0, 0.0]]), np.array([[0, 1]]))

    def snapshot(p):
        return GridSnapshot(np.where(p.occupied, 2, np.where(p.free, 1, 0)).astype(np.int8),
                            p.resolution, p.origin)

    path = write_pair(tmp_path, MapPair(0, topo, topo, snapshot(a), snapshot(b), truth, 0.3,
                                        "test", 0, "none", 0, 0, 0))
    assert [m.name for m in load_input(str(path))] == ["pair_000000:a", "pair_000000:b"]
    assert [m.name for m in load_input(f"{path}:b")] == ["pair_000000:b"]
    code, _, _ = run([f"{path}:a", f"{path}:b", "--out", tmp_path / "out"], capsys)
    assert code == EXIT_MERGED
    assert_close(placed(tmp_path / "out", "pair_000000:b"), truth)
    (tmp_path / "junk.npz").write_bytes(b"PK junk")
    code, _, err = run([path, tmp_path / "junk.npz", "--out", tmp_path / "out"], capsys)
    assert code == EXIT_BAD_INPUT and "junk.npz: corrupt or not a map-pair file" in err


def test_a_turned_reference_frame_round_trips(tmp_path, capsys):
    """With the first map's ROS origin turned, transforms and the merged map are in its map
    frame: the merged map merged again with the first map lands on it (identity)."""
    a, b, truth = crops(building(7))
    turned = FloorPlan(a.free, a.occupied, RES, (1.0, 2.0), "a", 0.4)
    ya, yb = save_ros_map(turned, tmp_path / "a.yaml"), save_ros_map(b, tmp_path / "b.yaml")
    code, _, _ = run([ya, yb, "--out", tmp_path / "out"], capsys)
    assert code == EXIT_MERGED
    frame_a = Rigid2D(0.4, np.asarray(turned.origin)
                      - Rigid2D(0.4).apply(np.asarray([turned.origin]))[0])
    assert_close(placed(tmp_path / "out", "b"), frame_a @ Rigid2D(0.0, (1.0, 2.0)) @ truth)
    assert load_ros_map(tmp_path / "out" / "merged.yaml", allow_yaw=True).yaw == 0.4
    code, _, _ = run([ya, tmp_path / "out" / "merged.yaml", "--out", tmp_path / "again"], capsys)
    assert code == EXIT_MERGED
    assert_close(placed(tmp_path / "again", "merged"), Rigid2D.identity(), tol_m=0.06,
                 tol_deg=0.3)


def test_out_resolution_and_maps_too_large_for_the_alignment(tmp_path, capsys, monkeypatch):
    a, b, _ = crops(building(8))
    paths = [save_ros_map(p, tmp_path / f"{p.name}.yaml") for p in (a, b)]
    code, _, _ = run([*paths, "--out", tmp_path / "out", "--out-resolution", "0.2"], capsys)
    assert code == EXIT_MERGED
    assert load_ros_map(tmp_path / "out" / "merged.yaml").resolution == 0.2
    import fusion.inputs

    monkeypatch.setattr(fusion.inputs, "MAX_POOLED_CELLS", 100)
    code, _, err = run([*paths, "--out", tmp_path / "out2"], capsys)
    assert code == EXIT_BAD_INPUT
    assert re.search(r"a\.yaml and \S*b\.yaml: grid_a: .* above MAX_POOLED_CELLS=100", err)
