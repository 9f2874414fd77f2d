"""Rigid2D: eq. (1), group laws, validation."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from fusion import Rigid2D, wrap_angle

angles = st.floats(-20.0, 20.0, allow_nan=False)
shifts = st.tuples(st.floats(-100, 100), st.floats(-100, 100))
rigids = st.builds(Rigid2D, angles, shifts)
points = st.lists(st.tuples(st.floats(-50, 50), st.floats(-50, 50)), min_size=1, max_size=8)


@given(rigids, rigids, rigids, points)
def test_compose_is_associative_and_acts_in_order(a, b, c, pts):
    p = np.array(pts)
    np.testing.assert_allclose((a @ b).apply(p), a.apply(b.apply(p)), atol=1e-8)
    assert ((a @ b) @ c).allclose(a @ (b @ c), atol=1e-8)


@given(rigids, points)
def test_inverse_undoes(a, pts):
    p = np.array(pts)
    np.testing.assert_allclose(a.inverse().apply(a.apply(p)), p, atol=1e-8)
    assert (a @ a.inverse()).allclose(Rigid2D.identity(), atol=1e-9)


@given(rigids)
def test_matrix_is_eq1_and_round_trips(a):
    m = a.matrix()
    c, s = math.cos(a.theta), math.sin(a.theta)
    np.testing.assert_allclose(m, [[c, -s, a.T[0]], [s, c, a.T[1]], [0, 0, 1]])
    assert np.isclose(np.linalg.det(a.R), 1.0)
    assert Rigid2D.from_matrix(m).allclose(a, atol=1e-9)
    assert -math.pi < a.theta <= math.pi


@given(st.floats(-100, 100))
def test_trusted_matches_validating_constructor(theta):
    t = np.array([1.0, 2.0])
    assert Rigid2D.trusted(theta, t.copy()).allclose(Rigid2D(theta, t), atol=1e-12)


def test_apply_single_point_and_degrees():
    t = Rigid2D.from_degrees(90.0, (1.0, 0.0))
    np.testing.assert_allclose(t.apply([1.0, 0.0]), [1.0, 1.0], atol=1e-12)
    assert t.degrees == pytest.approx(90.0)


def test_errors_measure_rotation_and_centroid_offset():
    a = Rigid2D.from_degrees(10.0, (0.0, 0.0))
    b = Rigid2D.from_degrees(-350.0, (0.3, 0.4))
    assert a.rotation_error(b) == pytest.approx(0.0, abs=1e-12)
    assert a.translation_error(b) == pytest.approx(0.5)
    assert wrap_angle(3 * math.pi) == pytest.approx(math.pi)


@pytest.mark.parametrize(
    ("args", "error", "match"),
    [
        ((float("nan"), (0, 0)), ValueError, "theta must be finite, got nan"),
        (("ten", (0, 0)), TypeError, "theta must be a real number, got str"),
        ((0.0, (1, 2, 3)), ValueError, r"T must be a 2-vector \(t_x, t_y\), got shape \(3,\)"),
        ((0.0, (1, float("inf"))), ValueError, r"T must be finite, got \[1.0, inf\]"),
        ((0.0, None), TypeError, "T must be a 2-vector"),
    ],
)
def test_bad_input(args, error, match):
    with pytest.raises(error, match=match):
        Rigid2D(*args)


def test_from_matrix_refuses_reflections():
    with pytest.raises(ValueError, match="proper rotation"):
        Rigid2D.from_matrix([[1, 0], [0, -1]])
    with pytest.raises(ValueError, match=r"last row must be \[0, 0, 1\]"):
        Rigid2D.from_matrix([[1, 0, 0], [0, 1, 0], [1, 0, 1]])


def test_from_pose_places_a_frame_at_the_pose():
    t = Rigid2D.from_pose(np.array([2.0, -1.0, math.pi / 2]))
    assert np.allclose(t.apply(np.array([[0.0, 0.0], [1.0, 0.0]])), [[2.0, -1.0], [2.0, 0.0]])
    assert t.allclose(Rigid2D(math.pi / 2, (2.0, -1.0)))
    with pytest.raises(ValueError, match=r"pose must be \(x, y, theta\), got \(1.0, 2.0\)"):
        Rigid2D.from_pose((1.0, 2.0))
    with pytest.raises(ValueError, match="theta must be finite"):
        Rigid2D.from_pose((0.0, 0.0, float("nan")))
