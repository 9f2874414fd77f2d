"""``benchmarks/_orb.py``: the m-explore (ORB + RANSAC) reference merger recovers a known turn of
a window of a real map, in metres, and refuses maps that do not overlap. Skips without OpenCV
(the ``bench`` extra)."""

import math
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))  # the scripts and their helpers, as when run

pytest.importorskip("cv2", reason="the m-explore reference needs the bench extra (OpenCV)")

import _orb  # noqa: E402
from _maps import MAPS  # noqa: E402

from fusion.mapmerge import InputMap, load_input, rasterise  # noqa: E402
from fusion.rigid import Rigid2D  # noqa: E402

DEPOT = MAPS / "ros" / "depot.yaml"


@pytest.fixture(scope="module")
def depot() -> InputMap:
    if not DEPOT.exists():
        pytest.skip(f"{DEPOT} not present (shared/maps beside the repository)")
    return load_input(str(DEPOT))[0]


def _window(src: InputMap, cols: slice, to_window: Rigid2D) -> InputMap:
    """Columns ``cols`` of ``src`` (all its rows), drawn in the frame ``to_window`` takes the
    map's frame to (a robot's own frame)."""
    sub = InputMap("w", "", src.states[:, cols], src.resolution,
                   (src.origin[0] + cols.start * src.resolution, src.origin[1]))
    plan, _ = rasterise([sub], [to_window], Rigid2D.identity(), src.resolution)
    states = np.where(plan.occupied, 2, np.where(plan.free, 1, 0)).astype(np.int8)
    return InputMap("w", "", states, src.resolution, plan.origin)


@pytest.mark.parametrize("degrees", [0.0, 30.0, 90.0, -135.0, 170.0])
def test_recovers_a_known_turn_of_a_depot_window_pair(depot, degrees):
    to_a = Rigid2D.from_degrees(5.0, (1.0, -2.0))
    to_b = Rigid2D.from_degrees(degrees, (5.0, 3.0))
    a = _window(depot, slice(0, 380), to_a)
    b = _window(depot, slice(220, 604), to_b)  # 160 shared columns of 604
    r = _orb.orb_rigid(a, b)
    truth = to_a @ to_b.inverse()
    assert r.accepted and r.confidence >= 1.0
    assert math.degrees(r.transform.rotation_error(truth)) <= 1.0
    assert r.transform.translation_error(truth, at=b.centre()) <= 0.2
    assert r.pixel.inliers <= r.pixel.matches
    assert r.confidence == pytest.approx(r.pixel.inliers / (8 + 0.3 * r.pixel.matches))


def test_same_inputs_same_result(depot):
    a = _window(depot, slice(0, 380), Rigid2D.identity())
    b = _window(depot, slice(220, 604), Rigid2D.from_degrees(30.0, (5.0, 3.0)))
    first, again = _orb.orb_rigid(a, b, seed=0), _orb.orb_rigid(a, b, seed=0)
    assert np.array_equal(first.pixel.transform, again.pixel.transform)
    assert (first.pixel.matches, first.pixel.inliers) == (again.pixel.matches,
                                                          again.pixel.inliers)


def test_the_pixel_transform_takes_b_pixels_to_a_pixels(depot):
    """A window turned by a quarter turn: pixel ``(u, v)`` of B is ``(v', -u')`` of A."""
    a = InputMap("a", "", depot.states[:, :380].copy(), 0.05, (0.0, 0.0))
    b = InputMap("b", "", np.ascontiguousarray(np.rot90(a.states)), 0.05, (0.0, 0.0))
    r = _orb.orb_merge(_orb.grid_image(a), _orb.grid_image(b))
    assert r.accepted
    # np.rot90: b[i, j] = a[j, W - 1 - i], so B's pixel (u, v) = (j, i) is A's (W - 1 - v, u)
    w = a.states.shape[1]
    expected = np.array([[0.0, -1.0, w - 1.0], [1.0, 0.0, 0.0]])
    assert np.allclose(r.transform[:, :2], expected[:, :2], atol=0.01)
    assert np.allclose(r.transform[:, 2], expected[:, 2], atol=1.0)  # pixels


def test_unrelated_maps_are_refused(depot):
    """Observed: a depot window against other maps gives 0-5 matches (no transform,
    confidence 0); two depot windows that share nothing give a few matches whose confidence
    stays below m-explore's threshold of 1."""
    a = _window(depot, slice(0, 380), Rigid2D.identity())
    for other in ("turtlebot3_world", "tb3_sandbox"):
        path = MAPS / "ros" / f"{other}.yaml"
        if path.exists():
            r = _orb.orb_rigid(a, load_input(str(path))[0])
            assert not r.accepted and r.confidence < 1.0
    left = _window(depot, slice(0, 250), Rigid2D.identity())
    right = _window(depot, slice(350, 604), Rigid2D.from_degrees(40.0, (1.0, 1.0)))
    r = _orb.orb_rigid(left, right)
    assert not r.accepted and r.confidence < 1.0


def test_a_lower_threshold_accepts_what_the_default_refuses(depot):
    left = _window(depot, slice(0, 250), Rigid2D.identity())
    right = _window(depot, slice(350, 604), Rigid2D.from_degrees(40.0, (1.0, 1.0)))
    r = _orb.orb_rigid(left, right)
    assert r.transform is not None and 0.0 < r.confidence < 1.0
    low = _orb.orb_rigid(left, right, confidence_threshold=r.confidence)
    assert low.accepted and low.confidence == r.confidence


def test_grid_images_are_ros_values_read_as_uint8():
    """Unknown −1 → 255, free 0 → 0, occupied 100 → 100; row 0 stays the bottom row."""
    states = np.array([[0, 1, 2], [2, 2, 0]], dtype=np.int8)
    image = _orb.grid_image(InputMap("m", "", states, 0.05, (0.0, 0.0)))
    assert image.dtype == np.uint8
    assert image.tolist() == [[255, 0, 100], [100, 100, 255]]


def test_blank_images_give_no_transform():
    blank = np.full((64, 64), 255, dtype=np.uint8)
    r = _orb.orb_merge(blank, blank)
    assert (r.transform, r.confidence, r.accepted, r.matches, r.inliers) == (None, 0.0, False,
                                                                             0, 0)


def test_resolution_of_b_is_brought_to_a(depot):
    to_b = Rigid2D.from_degrees(30.0, (5.0, 3.0))
    a = _window(depot, slice(0, 380), Rigid2D.identity())
    b = _window(depot, slice(220, 604), to_b)
    fine = InputMap("b", "", np.repeat(np.repeat(b.states, 2, axis=0), 2, axis=1), 0.025,
                    b.origin)
    r = _orb.orb_rigid(a, fine)
    assert r.accepted
    assert r.transform.translation_error(to_b.inverse(), at=b.centre()) <= 0.2


@pytest.mark.parametrize(("kwargs", "error", "match"), [
    ({"image_a": [[0]]}, TypeError, "image_a must be a numpy array"),
    ({"image_b": np.zeros((4, 4), np.float32)}, ValueError, "image_b must be a 2-D uint8"),
    ({"confidence_threshold": -1.0}, ValueError, "confidence_threshold must be >= 0"),
    ({"seed": -1}, ValueError, "seed must be >= 0"),
    ({"features": "surf"}, ValueError, r"features must be one of \('orb', 'akaze'\), got 'surf'"),
])
def test_bad_arguments_are_named(kwargs, error, match):
    args = {"image_a": np.zeros((4, 4), np.uint8), "image_b": np.zeros((4, 4), np.uint8)}
    args.update(kwargs)
    with pytest.raises(error, match=match):
        _orb.orb_merge(args.pop("image_a"), args.pop("image_b"), **args)


def test_maps_must_be_input_maps(depot):
    with pytest.raises(TypeError, match="map_b must be a fusion.mapmerge.InputMap, got ndarray"):
        _orb.orb_rigid(depot, depot.states)
