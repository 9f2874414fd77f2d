"""Floor-plan loaders: the real maps in shared/maps, orientation, and named file errors."""

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from topo.maps import (
    FloorPlan,
    MapFileError,
    load_dungeon_png,
    load_floor_plan,
    load_ros_map,
    save_ros_map,
)

MAPS = Path(__file__).resolve().parents[3] / "shared" / "maps"
ROS = sorted((MAPS / "ros").glob("*.yaml"))
DUNGEON = sorted((MAPS / "dungeon").glob("*.png"))[:3]

needs_maps = pytest.mark.skipif(not MAPS.is_dir(), reason="shared/maps not beside the repo")
"""On the tests that read shared/maps; the others make their maps in ``tmp_path``."""


@needs_maps
@pytest.mark.parametrize("path", ROS, ids=lambda p: p.stem)
def test_ros_maps_load(path):
    plan = load_ros_map(path)
    assert plan.resolution == pytest.approx(0.05)
    assert plan.free.any() and plan.occupied.any()
    assert not (plan.free & plan.occupied).any()
    assert plan.free_area_m2() > 5.0


@needs_maps
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


@needs_maps
def test_more_broken_files_are_named(tmp_path):
    png = MAPS / "dungeon" / "1.png"
    (tmp_path / "cut.png").write_bytes(png.read_bytes()[:5000])
    with pytest.raises(MapFileError, match=r"cut\.png: cannot read the image"):
        load_dungeon_png(tmp_path / "cut.png")
    (tmp_path / "empty.png").write_bytes(b"")
    with pytest.raises(MapFileError, match=r"empty\.png: cannot read the image"):
        load_floor_plan(tmp_path / "empty.png")
    yml = write_pgm_map(tmp_path, np.full((4, 4), 254))
    (tmp_path / "m.pgm").write_bytes(b"P5\n4 4x\n255\n" + bytes(16))  # bad size in the header
    with pytest.raises(MapFileError, match=r"m\.pgm: cannot read the image"):
        load_ros_map(yml)
    (tmp_path / "m.pgm").unlink()
    with pytest.raises(MapFileError, match=r"m\.pgm: map image file not found"):
        load_ros_map(yml)
    cases = [
        ({"free_thresh": 0.9}, r"free_thresh \(0.9\) must be <= occupied_thresh \(0.65\)"),
        ({"origin": "[0.0, .nan, 0.0]"}, r"'origin' must be \[x, y, yaw\] of finite numbers"),
        ({"image": 7}, "'image' must be the map image file name, got 7"),
        ({"image": None}, "missing key 'image'"),
        ({"negate": 2}, "negate must be 0 or 1, got 2"),
        ({"mode": "fancy"}, "mode must be 'trinary', 'scale' or 'raw', got 'fancy'"),
        ({"occupied_thresh": "high"}, "occupied_thresh must be a real number"),
    ]
    for fields, match in cases:
        yml = write_pgm_map(tmp_path, np.full((4, 4), 254), **fields)
        with pytest.raises(MapFileError, match=r"m\.yaml: " + match):
            load_ros_map(yml)
    (tmp_path / "m.yaml").write_text("")
    with pytest.raises(MapFileError, match=r"m\.yaml: expected a YAML mapping, got NoneType"):
        load_ros_map(tmp_path / "m.yaml")


def test_sixteen_bit_pgm_is_scaled_not_clipped(tmp_path):
    """A 16-bit PGM (maxval 65535): 0 is occupied, 65535 free, 32768 (p = 0.5) unknown."""
    pixels = np.array([[0, 32768, 65535], [65535, 65535, 65535]], dtype=">u2")
    yml = write_pgm_map(tmp_path, np.full((2, 3), 254))  # the YAML; the image is replaced
    (tmp_path / "m.pgm").write_bytes(b"P5\n3 2\n65535\n" + pixels.tobytes())
    plan = load_ros_map(yml)
    top = 1  # image row 0 is the grid's top row
    assert plan.occupied[top, 0] and not plan.free[top, 0]
    assert not plan.occupied[top, 1] and not plan.free[top, 1]
    assert plan.free[top, 2] and plan.free[0].all()


def test_image_over_the_pixel_limit_is_refused_before_decoding(tmp_path, monkeypatch):
    import topo.maps

    yml = write_pgm_map(tmp_path, np.full((4, 5), 254))
    monkeypatch.setattr(topo.maps, "MAX_MAP_PIXELS", 19)
    with pytest.raises(MapFileError, match=r"m\.pgm: map image of 5 x 4 pixels is larger than "
                                           r"MAX_MAP_PIXELS = 19"):
        load_ros_map(yml)
    Image.fromarray(np.full((4, 5), 200, dtype=np.uint8)).save(tmp_path / "d.png")
    with pytest.raises(MapFileError, match=r"d\.png: DungeonMaps PNG of 5 x 4 pixels"):
        load_dungeon_png(tmp_path / "d.png")
    monkeypatch.setattr(topo.maps, "MAX_MAP_PIXELS", 20)
    assert load_ros_map(yml).shape == (4, 5)


def test_save_ros_map_round_trip(tmp_path):
    """map_saver's trinary PGM + YAML, read back as the same masks, origin and yaw."""
    rng = np.random.default_rng(0)
    codes = rng.integers(0, 3, size=(7, 9))
    plan = FloorPlan(codes == 1, codes == 2, 0.05, (-1.25, 3.5), "m", 0.25)
    yml = save_ros_map(plan, tmp_path / "sub" / "m.yaml")
    assert (tmp_path / "sub" / "m.pgm").read_bytes().startswith(b"P5")
    grey = np.asarray(Image.open(tmp_path / "sub" / "m.pgm"))
    assert set(np.unique(grey).tolist()) <= {0, 205, 254}
    assert grey[0, 0] == {0: 205, 1: 254, 2: 0}[int(codes[-1, 0])]  # image row 0 = top
    with pytest.raises(MapFileError, match="origin yaw must be 0"):
        load_ros_map(yml)
    back = load_ros_map(yml, allow_yaw=True)
    assert (back.free == plan.free).all() and (back.occupied == plan.occupied).all()
    assert back.origin == (-1.25, 3.5) and back.yaw == 0.25 and back.resolution == 0.05
    assert load_floor_plan(save_ros_map(FloorPlan(plan.free, plan.occupied, 0.05, (0.0, 0.0),
                                                  "flat"), tmp_path / "flat.yaml")).yaw == 0.0
    with pytest.raises(ValueError, match="plan.free and plan.occupied overlap"):
        save_ros_map(FloorPlan(plan.free, plan.free, 0.05, (0.0, 0.0), "x"), tmp_path / "x.yaml")


def test_raw_mode_reads_occupancy_values_and_255_as_unknown(tmp_path):
    img = np.array([[0, 100, 255], [10, 90, 50]])
    plan = load_ros_map(write_pgm_map(tmp_path, img, mode="raw"))
    top = 1
    assert plan.free[top, 0] and plan.occupied[top, 1]
    assert not plan.free[top, 2] and not plan.occupied[top, 2]  # 255: map_server's -1
    assert plan.free[0, 0] and plan.occupied[0, 1] and not plan.free[0, 2]


def test_missing_image_names_the_yaml(tmp_path):
    yml = write_pgm_map(tmp_path, np.full((4, 4), 254))
    (tmp_path / "m.pgm").unlink()
    with pytest.raises(MapFileError, match=r"m\.yaml: names image \S*m\.pgm: map image file "
                                           r"not found"):
        load_ros_map(yml)
