"""Floor-plan loaders: the real maps in shared/maps, orientation, and named file errors."""

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from topo.maps import MapFileError, load_dungeon_png, load_floor_plan, load_ros_map

MAPS = Path(__file__).resolve().parents[3] / "shared" / "maps"
ROS = sorted((MAPS / "ros").glob("*.yaml"))
DUNGEON = sorted((MAPS / "dungeon").glob("*.png"))[:3]

pytestmark = pytest.mark.skipif(not MAPS.is_dir(), reason="shared/maps not beside the repo")


@pytest.mark.parametrize("path", ROS, ids=lambda p: p.stem)
def test_ros_maps_load(path):
    plan = load_ros_map(path)
    assert plan.resolution == pytest.approx(0.05)
    assert plan.free.any() and plan.occupied.any()
    assert not (plan.free & plan.occupied).any()
    assert plan.free_area_m2() > 5.0


@pytest.mark.parametrize("path", DUNGEON, ids=lambda p: p.stem)
def test_dungeon_maps_load(path):
    plan = load_floor_plan(path, resolution=0.1)
    assert plan.shape == (480, 640) and plan.resolution == 0.1
    assert 0.05 < plan.free.mean() < 0.9
    assert (plan.free ^ plan.occupied).all()  # no unknown in DungeonMaps


def write_pgm_map(tmp_path, pixels: np.ndarray, **yaml_fields) -> Path:
    Image.fromarray(pixels.astype(np.uint8), mode="L").save(tmp_path / "m.pgm")
    fields = {"image": "m.pgm", "resolution": 0.5, "origin": "[1.0, 2.0, 0.0]",
              "occupied_thresh": 0.65, "free_thresh": 0.196, "negate": 0, **yaml_fields}
    text = "".join(f"{k}: {v}\n" for k, v in fields.items() if v is not None)
    (tmp_path / "m.yaml").write_text(text)
    return tmp_path / "m.yaml"


def test_ros_orientation_and_thresholds(tmp_path):
    img = np.full((3, 4), 254)  # free
    img[0, 0] = 0    # occupied, top-left of the image
    img[2, 3] = 205  # unknown, bottom-right
    plan = load_ros_map(write_pgm_map(tmp_path, img))
    assert plan.occupied[2, 0] and plan.occupied.sum() == 1  # row 0 is now the bottom
    assert not plan.free[0, 3] and not plan.occupied[0, 3]
    assert plan.origin == (1.0, 2.0) and plan.extent == (1.0, 2.0, 3.0, 3.5)
    negated = load_ros_map(write_pgm_map(tmp_path, img, negate=1))
    assert negated.free[2, 0]


def test_missing_and_broken_files_are_named(tmp_path):
    with pytest.raises(MapFileError, match=r"nope\.yaml: map YAML file not found"):
        load_ros_map(tmp_path / "nope.yaml")
    yml = write_pgm_map(tmp_path, np.full((4, 4), 254))
    (tmp_path / "m.pgm").write_bytes((tmp_path / "m.pgm").read_bytes()[:12])
    with pytest.raises(MapFileError, match=r"m\.pgm: cannot read the image"):
        load_ros_map(yml)
    (tmp_path / "m.pgm").write_bytes(b"P9 this is not a pgm")
    with pytest.raises(MapFileError, match=r"m\.pgm: cannot read the image"):
        load_ros_map(yml)
    yml = write_pgm_map(tmp_path, np.full((4, 4), 254), resolution=None)
    with pytest.raises(MapFileError, match=r"m\.yaml: missing key 'resolution'"):
        load_ros_map(yml)
    yml = write_pgm_map(tmp_path, np.full((4, 4), 254), resolution=-1)
    with pytest.raises(MapFileError, match=r"m\.yaml: resolution must be > 0.0, got -1.0"):
        load_ros_map(yml)
    yml = write_pgm_map(tmp_path, np.full((4, 4), 254), origin="[0, 0, 1.57]")
    with pytest.raises(MapFileError, match="origin yaw must be 0"):
        load_ros_map(yml)
    (tmp_path / "bad.yaml").write_text("image: [unclosed")
    with pytest.raises(MapFileError, match=r"bad\.yaml: not valid YAML"):
        load_ros_map(tmp_path / "bad.yaml")
    with pytest.raises(MapFileError, match=r"x\.png: DungeonMaps PNG file not found"):
        load_dungeon_png(tmp_path / "x.png")
    with pytest.raises(MapFileError, match=r"unknown map format '\.bmp'"):
        load_floor_plan(tmp_path / "x.bmp")
    with pytest.raises(ValueError, match="resolution is set by the ROS map's YAML"):
        load_floor_plan(yml, resolution=0.1)
