"""fusion.evaluation.bending: the world alignment of anchors and the share of occupied cells
on true walls."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fusion.evaluation.bending import wall_share, world_alignment
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
