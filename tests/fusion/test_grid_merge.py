"""merge_grids / hybrid_merge: recovery on grids of a known plan, ambiguity and no-overlap
rejection, degenerate input."""

import math

import numpy as np
import pytest
from scipy import ndimage

from fusion import Rigid2D
from fusion.grid_merge import GridMergeConfig, check_with_grids, hybrid_merge, merge_grids
from fusion.pairs import GridSnapshot
from topo import TopoMap

RES = 0.1


def plan(seed: int = 0) -> np.ndarray:
    """An asymmetric indoor plan (cell states: 1 free, 2 wall) of 30 x 30 m."""
    rng = np.random.default_rng(seed)
    s = np.full((300, 300), 2, np.int8)
    for _ in range(14):  # rooms and corridors of random sizes
        r, c = rng.integers(10, 230, 2)
        h, w = rng.integers(15, 70, 2)
        s[r: r + h, c: c + w] = 1
    s[:3], s[-3:], s[:, :3], s[:, -3:] = 2, 2, 2, 2
    # a sensor sees walls, not the inside of solid blocks: keep wall cells next to free space
    near_free = ndimage.binary_dilation(s == 1, iterations=2)
    s[(s == 2) & ~near_free] = 0
    return s


def view(states: np.ndarray, frame: Rigid2D, lo, hi) -> GridSnapshot:
    """What a robot whose frame is ``frame`` (its points → plan points) knows of the plan box
    ``lo..hi`` (plan metres): its own grid, sampled from the plan, unknown elsewhere."""
    corners = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [lo[0], hi[1]], [hi[0], hi[1]]])
    own = frame.inverse().apply(corners)
    o = own.min(axis=0) - 1.0
    n = np.ceil((own.max(axis=0) + 1.0 - o) / RES).astype(int)
    rows, cols = np.mgrid[0: n[1], 0: n[0]]
    pts = np.stack([o[0] + (cols + 0.5) * RES, o[1] + (rows + 0.5) * RES], -1).reshape(-1, 2)
    p = frame.apply(pts)
    ij = np.floor(p / RES).astype(int)
    inside = ((p[:, 0] >= lo[0]) & (p[:, 0] < hi[0]) & (p[:, 1] >= lo[1]) & (p[:, 1] < hi[1]))
    out = np.zeros(len(pts), np.int8)
    out[inside] = states[ij[inside, 1], ij[inside, 0]]
    return GridSnapshot(out.reshape(n[1], n[0]), RES, (float(o[0]), float(o[1])))


def overlapping_views(deg: float, frame_a: Rigid2D | None = None,
                      shift=(10.0, 4.0)) -> tuple[GridSnapshot, GridSnapshot, Rigid2D]:
    """Two robots' grids of plan 1 overlapping on (8..20, 6..22) m, and the true B → A."""
    frame_a = frame_a or Rigid2D.identity()
    frame_b = Rigid2D(frame_a.theta + math.radians(deg), shift)
    states = plan(1)
    a = view(states, frame_a, (1, 1), (20, 22))
    b = view(states, frame_b, (8, 6), (28, 28))
    return a, b, frame_a.inverse() @ frame_b


@pytest.mark.parametrize("deg", [0.0, 37.0, 133.0, 251.0])
def test_recovers_the_transform_of_overlapping_views(deg):
    a, b, truth = overlapping_views(deg, Rigid2D.from_degrees(20.0, (3.0, 2.0)), (12.0, 5.0))
    res = merge_grids(a, b)
    centre = np.array([0.0, 0.0])
    assert res.accepted, res.reason
    assert math.degrees(res.transform.rotation_error(truth)) < 1.0
    assert res.transform.translation_error(truth, at=centre) < 0.15


def test_disjoint_views_are_rejected():
    states = plan(2)
    frame = Rigid2D.from_degrees(10.0, (0.0, 0.0))
    a = view(states, frame, (1, 1), (12, 12))
    b = view(states, frame, (17, 17), (29, 29))
    assert not merge_grids(a, b).accepted


def test_a_symmetric_room_is_ambiguous():
    s = np.zeros((120, 120), np.int8)
    s[18:102, 28:92] = 2
    s[20:100, 30:90] = 1  # a plain rectangle looks the same after a half turn
    g = GridSnapshot(s, RES, (0.0, 0.0))
    res = merge_grids(g, g)
    assert not res.accepted and "ambiguous" in res.reason


def test_nothing_known_is_a_reason_not_an_error():
    empty = GridSnapshot(np.zeros((10, 10), np.int8), RES, (0.0, 0.0))
    res = merge_grids(empty, empty)
    assert not res.accepted and res.reason == "a grid has no known cells"


def test_hybrid_falls_back_to_the_grids_and_fuses_the_maps():
    a, b, truth = overlapping_views(90.0)
    tiny = TopoMap.from_arrays([[0, 0], [1, 0]], [[0, 1]])  # too small for the structural merge
    res = hybrid_merge(tiny, tiny, a, b)
    assert res.accepted and res.method == "hybrid"
    assert math.degrees(res.transform.rotation_error(truth)) < 1.0
    rejected = hybrid_merge(tiny, tiny, a, b, try_grids=False)
    assert not rejected.accepted


def test_bad_config():
    with pytest.raises(ValueError, match="GridMergeConfig.resolution must be > 0.0"):
        GridMergeConfig(resolution=0.0)
    with pytest.raises(ValueError, match="GridMergeConfig.min_wall_agreement must be <= 1.0"):
        GridMergeConfig(min_wall_agreement=2.0)
    with pytest.raises(ValueError, match="GridMergeConfig.coarse_factor must be >= 1, got 0"):
        GridMergeConfig(coarse_factor=0)
    with pytest.raises(TypeError, match="GridMergeConfig.refine_top must be an integer"):
        GridMergeConfig(refine_top=2.5)


def test_coarse_sweep_finds_what_the_full_resolution_sweep_finds():
    # the coarse-to-fine search must not lose the alignment the exhaustive sweep finds
    a, b, truth = overlapping_views(133.0, Rigid2D.from_degrees(20.0, (3.0, 2.0)), (12.0, 5.0))
    full = merge_grids(a, b, GridMergeConfig(coarse_factor=1, refine_top=1))
    fast = merge_grids(a, b, GridMergeConfig(coarse_factor=3))
    assert full.accepted and fast.accepted
    assert math.degrees(fast.transform.rotation_error(full.transform)) < 1.0
    assert fast.transform.translation_error(full.transform, at=np.zeros(2)) < 0.15


def test_grids_refute_a_wrong_transform():
    a, b, truth = overlapping_views(60.0)
    assert check_with_grids(a, b, truth) is None
    why = check_with_grids(a, b, Rigid2D.from_degrees(90.0) @ truth)
    assert why is not None and "wall agreement" in why
