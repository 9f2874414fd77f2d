"""fusion.evaluation.bending: the world alignment of anchors, the share of occupied cells
on true walls, and a rigid merge of two bent maps judged by its fused trajectory."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fusion.evaluation.bending import PairTrajectories, wall_share, world_alignment
from fusion.rigid import Rigid2D

WALLS = np.array([[0.0, 0.0, 10.0, 0.0], [0.0, 0.0, 0.0, 10.0]])


def test_world_alignment_recovers_a_rigid_motion():
    truth = np.array([[0.0, 0.0], [4.0, 1.0], [2.0, 5.0]])
    motion = Rigid2D(math.radians(25), (1.0, -2.0))
    estimated = motion.inverse().apply(truth)
    assert world_alignment(estimated, truth).allclose(motion, atol=1e-9)


def test_wall_share_counts_cells_near_true_walls():
    pts = np.array([[5.0, 0.1], [0.15, 7.0], [5.0, 5.0], [3.0, -0.3]])
    assert wall_share(pts, Rigid2D.identity(), WALLS) == pytest.approx(0.5)
    # the same cells in a map frame shifted by 1 m: aligned back, they are on the walls again
    shift = Rigid2D(0.0, (1.0, 0.0))
    assert wall_share(shift.inverse().apply(pts), shift, WALLS) == pytest.approx(0.5)
    assert math.isnan(wall_share(np.zeros((0, 2)), Rigid2D.identity(), WALLS))


def test_bad_input_is_named():
    with pytest.raises(ValueError, match=r"segments must be \(M, 4\)"):
        wall_share(np.zeros((1, 2)), Rigid2D.identity(), np.zeros((0, 4)))
    with pytest.raises(ValueError, match="tolerance must be > 0, got 0"):
        wall_share(np.zeros((1, 2)), Rigid2D.identity(), WALLS, tolerance=0)
    with pytest.raises(ValueError, match="same number"):
        world_alignment(np.zeros((2, 2)), np.zeros((3, 2)))


# ------------------------------------------------------------------ a rigid merge of bent maps
def _bent(n: int, bend_deg: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A trajectory's true poses and the odometry of a robot whose heading drifts
    ``bend_deg`` in all (``(n, 3)`` rows each, both from the origin)."""
    rng = np.random.default_rng(seed)
    steps = rng.uniform(0.2, 0.6, n - 1)
    turns = rng.normal(0.0, 0.3, n - 1)
    drift = np.full(n - 1, math.radians(bend_deg) / (n - 1))

    def integrate(turn: np.ndarray) -> np.ndarray:
        theta = np.concatenate([[0.0], np.cumsum(turn)])
        xy = np.vstack([[0.0, 0.0], np.cumsum(np.c_[steps * np.cos(theta[:-1]),
                                                        steps * np.sin(theta[:-1])], axis=0)])
        return np.c_[xy, theta]
    return integrate(turns), integrate(turns + drift)


def _pair(bend_deg: float, seed: int = 0) -> tuple[PairTrajectories, Rigid2D]:
    true_a, odo_a = _bent(40, bend_deg, seed)
    true_b, odo_b = _bent(30, bend_deg, seed + 1)
    start = Rigid2D(math.radians(70), (3.0, -1.0))  # B's start frame in A's
    rows = [np.c_[odo_a, true_a], np.c_[odo_b, true_b]]
    return PairTrajectories.from_start_frames(*rows, start), start


def test_straight_maps_merged_by_the_truth_have_no_error():
    traj, start = _pair(0.0)
    assert traj.ate(start) < 1e-9
    assert traj.floor() < 1e-9
    assert traj.best_merge().allclose(start, atol=1e-9)
    # a merge off by 5° at B's start is judged by where it puts B's whole trajectory
    assert traj.ate(start @ Rigid2D(math.radians(5.0))) > 0.1


@given(st.floats(-math.pi, math.pi), st.floats(-5, 5), st.floats(-5, 5),
       st.floats(0.0, 20.0), st.integers(0, 50))
@settings(max_examples=40, deadline=None)
def test_no_rigid_merge_of_bent_maps_beats_the_floor(theta, tx, ty, bend, seed):
    traj, start = _pair(bend, seed)
    assert traj.floor() <= traj.ate(Rigid2D(theta, (tx, ty))) + 1e-9
    assert traj.floor() <= traj.ate(start) + 1e-9
    assert traj.ate(traj.best_merge()) == pytest.approx(traj.floor(), abs=1e-9)


def test_bent_maps_have_a_floor_the_truth_does_not_reach():
    traj, start = _pair(15.0)
    assert 0.05 < traj.floor() < traj.ate(start)


def test_bad_trajectories_are_named():
    with pytest.raises(ValueError, match=r"rows_b must be \(K, 6\) rows x, y, theta, true x, "
                                         r"true y, true theta with K >= 1, got shape \(3, 5\)"):
        PairTrajectories.from_start_frames(np.zeros((2, 6)), np.zeros((3, 5)), Rigid2D())
    with pytest.raises(ValueError, match=r"odometry_a and truth_a must have the same number "
                                         r"\(≥ 1\) of rows, got 2 and 3"):
        PairTrajectories(np.zeros((2, 2)), np.zeros((1, 2)), np.zeros((3, 2)), np.zeros((1, 2)))
    traj, _ = _pair(0.0)
    with pytest.raises(TypeError, match="transform must be a fusion.Rigid2D, got tuple"):
        traj.ate((0.0, 1.0, 2.0))
