"""``benchmarks/real_pairs.py`` on a tiny synthetic CARMEN log (a robot in a 6 × 4 m box):
the reader, the rasteriser (walls at the right cells once the map is read back the way the
merge tool reads it) and the truth convention (B's walls land on A's)."""

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))  # the scripts and their helpers, as when run

import real_pairs as rp  # noqa: E402

from fusion.mapmerge import load_input  # noqa: E402
from topo.grid import CellState  # noqa: E402
from topo.maps import save_ros_map  # noqa: E402

BOX = (0.0, 0.0, 6.0, 4.0)
NO_ECHO_BEAM = 45  # this beam of every scan reads 81.91 m: no echo


def _ranges(x, y, theta, n=180):
    """Distances from (x, y) inside BOX to its walls along the FLASER beams of ``n`` readings."""
    a = theta - math.pi / 2 + np.arange(n) * math.pi / 180
    dx, dy = np.cos(a), np.sin(a)
    with np.errstate(divide="ignore"):
        tx = np.where(dx > 0, (BOX[2] - x) / dx, np.where(dx < 0, (BOX[0] - x) / dx, np.inf))
        ty = np.where(dy > 0, (BOX[3] - y) / dy, np.where(dy < 0, (BOX[1] - y) / dy, np.inf))
    return np.minimum(tx, ty)


def _poses():
    out = [(x, 1.0, 0.0) for x in np.arange(1.0, 5.01, 0.25)]  # along the bottom, facing east
    out += [(x, 3.0, math.pi) for x in np.arange(5.0, 0.99, -0.25)]  # back along the top
    return out


def _log(poses=None):
    lines = ["# message formats defined: PARAM SYNC ODOM FLASER",
             "PARAM robot_front_laser_max 80.99 nohost 0"]
    for k, (x, y, t) in enumerate(poses or _poses()):
        r = _ranges(x, y, t)
        r[NO_ECHO_BEAM] = 81.91
        lines.append(f"ODOM {x} {y} {t} 0 0 0 {k} pippo {k}")
        lines.append("FLASER 180 " + " ".join(f"{v:.3f}" for v in r)
                     + f" {x} {y} {t} {x} {y} {t} {k}.5 pippo {k}.5")
    return "\n".join(lines) + "\n"


def _walls_distance(xy):
    """Distance of points (N, 2) to BOX's boundary."""
    x, y = xy[:, 0], xy[:, 1]
    return np.minimum.reduce([np.abs(x - BOX[0]), np.abs(x - BOX[2]),
                              np.abs(y - BOX[1]), np.abs(y - BOX[3])])


def _cells(m, state, transform=None):
    """World (or, with a 3 × 3 ``transform``, moved) centres of ``m``'s cells in ``state``."""
    rows, cols = np.nonzero(m.states == state)
    xy = np.stack([m.origin[0] + (cols + 0.5) * m.resolution,
                   m.origin[1] + (rows + 0.5) * m.resolution, np.ones(rows.size)])
    return ((transform if transform is not None else np.eye(3)) @ xy)[:2].T


def test_reader_takes_the_flaser_lines_and_their_poses():
    scans = rp.read_carmen(_log(), "box")
    assert len(scans) == len(_poses())
    first = scans[0]
    assert first.pose == (1.0, 1.0, 0.0)
    assert first.ranges.shape == (180,) and first.ranges[NO_ECHO_BEAM] == 81.91
    assert first.angles[0] == pytest.approx(-math.pi / 2)
    assert np.diff(first.angles) == pytest.approx(np.full(179, math.pi / 180))
    assert first.ranges[90] == pytest.approx(5.0, abs=1e-3)  # straight ahead to x = 6


def test_flaser_spacing_follows_the_sick_modes():
    assert rp.flaser_step(181) == pytest.approx(math.radians(1.0))
    assert rp.flaser_step(360) == pytest.approx(math.radians(0.5))
    assert rp.flaser_step(100) == pytest.approx(math.pi / 99)


def test_reader_rejects_malformed_logs():
    with pytest.raises(ValueError, match="box line 1: malformed FLASER line"):
        rp.read_carmen("FLASER 180 1.0 2.0\n", "box")
    with pytest.raises(ValueError, match="empty: no FLASER or ROBOTLASER1 line"):
        rp.read_carmen("ODOM 0 0 0 0 0 0 0 pippo 0\n", "empty")


def test_missing_log_says_where_to_get_it(tmp_path):
    with pytest.raises(FileNotFoundError, match="no intel-corrected.log.gz in it .*acschaefer"):
        rp.log_text("intel", tmp_path, None)


def test_walls_land_on_the_right_cells_after_the_merge_tool_reads_them(tmp_path):
    scans = rp.read_carmen(_log(), "box")
    plan = rp.rasterise(scans, np.eye(3), name="box")
    yaml = save_ros_map(plan, tmp_path / "box.yaml")
    (m,) = load_input(str(yaml))
    walls = _cells(m, CellState.OCCUPIED)
    assert len(walls) > 300
    assert _walls_distance(walls).max() <= 1.5 * m.resolution  # every wall cell on a wall
    for point in ((6.0, 2.0), (3.0, 4.0), (0.0, 2.0), (3.0, 0.0)):  # each wall is seen
        assert np.linalg.norm(walls - point, axis=1).min() <= m.resolution
    free = _cells(m, CellState.FREE)
    outside = free[_walls_distance(free) > m.resolution]
    outside = outside[(outside[:, 0] < 0) | (outside[:, 0] > 6)
                      | (outside[:, 1] < 0) | (outside[:, 1] > 4)]
    assert len(outside) > 0  # the no-echo beams pass the walls: free space only, no wall
    poses = np.array([p[:2] for p in _poses()])
    reach = np.linalg.norm(outside[:, None] - poses[None], axis=2).min(axis=1)
    assert reach.max() <= 8.0 + m.resolution  # and only up to no_echo_free


def test_truth_maps_b_onto_a():
    scans = rp.read_carmen(_log(), "box")
    a_part, b_part = rp.segments(scans, 4.5)
    assert len(a_part) + len(b_part) == len(scans) and len(b_part) >= 10
    rng = np.random.default_rng(2)  # a turn of about 1 rad: the box looks alike turned by π
    fa, fb = rp.random_frame(a_part, rng, 3.0), rp.random_frame(b_part, rng, 3.0)
    a, b = rp.rasterise(a_part, fa), rp.rasterise(b_part, fb)
    truth = rp.matrix(*rp.as_xyt(fa @ np.linalg.inv(fb)))
    assert 0.5 < abs(rp.as_xyt(truth)[2]) < 2.5
    near = ndimage.binary_dilation(a.occupied, iterations=1)
    seen = near | a.free  # where A can tell a wall from no wall

    def on_a_walls(transform):
        """The share of B's walls moved by ``transform`` into what A saw that are A's walls."""
        rows, cols = np.nonzero(b.occupied)
        xy = np.stack([b.origin[0] + (cols + 0.5) * b.resolution,
                       b.origin[1] + (rows + 0.5) * b.resolution, np.ones(rows.size)])
        ij = np.floor(((transform @ xy)[:2].T - a.origin) / a.resolution).astype(int)
        ok = (ij >= 0).all(axis=1) & (ij[:, 0] < a.shape[1]) & (ij[:, 1] < a.shape[0])
        ij = ij[ok][seen[ij[ok, 1], ij[ok, 0]]]
        return near[ij[:, 1], ij[:, 0]].mean() if len(ij) else 0.0

    assert on_a_walls(truth) > 0.95
    assert on_a_walls(np.linalg.inv(truth)) < 0.5  # the other direction is wrong
    share, area = rp.known_overlap(a, b, truth)
    assert rp.known_overlap(b, b, np.eye(3))[0] == 1.0
    # the box is shared; the no-echo beams of B reach outside it where A's do not
    assert 0.4 < share < 1.0 and area == pytest.approx(share * (b.free | b.occupied).sum()
                                                        * b.resolution ** 2)


def test_main_writes_the_manifest(tmp_path):
    logs = tmp_path / "logs"
    logs.mkdir()
    for name in ("intel", "aces"):
        (logs / f"{name}-corrected.log").write_text(_log())
    out = tmp_path / "set"
    rp.main(["--logs", str(logs), "--out", str(out), "--buildings", "intel", "aces",
             "--segment-m", "4.5", "--cross", "2"])
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["format"] == "topomerge.real_pairs" and manifest["version"] == 1
    assert manifest["resolution"] == 0.05
    keys = {"id", "building", "split", "a", "b", "truth", "overlap", "overlap_m2"}
    pairs = manifest["pairs"]
    assert all(set(p) == keys for p in pairs)
    same = [p for p in pairs if p["truth"] is not None]
    assert {p["building"] for p in same} == {"intel", "aces"}
    assert all(p["split"] == "test" and (out / p["a"]).exists() for p in pairs)
    cross = [p for p in pairs if p["truth"] is None]
    assert len(cross) == 2 and cross[0]["building"] in ("aces+intel", "intel+aces")
    for pair in same:  # the recorded truth, on the maps as the merge tool reads them
        (a,), (b,) = load_input(str(out / pair["a"])), load_input(str(out / pair["b"]))
        moved = _cells(b, CellState.OCCUPIED, rp.matrix(*pair["truth"]))
        a_walls = _cells(a, CellState.OCCUPIED)
        gap = np.linalg.norm(moved[:, None] - a_walls[None], axis=2).min(axis=1)
        assert np.median(gap) <= a.resolution
    again = tmp_path / "again"
    rp.main(["--logs", str(logs), "--out", str(again), "--buildings", "intel", "aces",
             "--segment-m", "4.5", "--cross", "2"])
    assert (again / "manifest.json").read_text() == (out / "manifest.json").read_text()


def test_show_draws_a_pair_and_bad_options_are_named(tmp_path, capsys):
    logs = tmp_path / "logs"
    logs.mkdir()
    (logs / "seattle-corrected.log").write_text(_log())
    out = tmp_path / "set"
    rp.main(["--logs", str(logs), "--out", str(out), "--buildings", "seattle",
             "--segment-m", "4.5"])
    rp.main(["--out", str(out), "--show", "seattle_00_01"])
    assert (out / "seattle_00_01.png").stat().st_size > 0
    for argv, message in ((["--out", str(out), "--show", "nope"], "--show nope: no such pair"),
                          (["--logs", str(logs), "--segment-m", "0"], "--segment-m 0.0: must be")):
        with pytest.raises(SystemExit):
            rp.main(argv)
        assert message in capsys.readouterr().err
