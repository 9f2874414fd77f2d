"""The team pose graph: loop closures unbend a drifting map, consistent links merge two robots,
look-alike links are refused, and the answer does not depend on anything but the inputs."""

import math
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fusion import Rigid2D
from fusion.evaluation.bending import ate_rms
from fusion.posegraph import PoseGraph, PoseGraphConfig

pytest.importorskip("gtsam")

ODOM_SIGMAS = (0.02, 0.02, 0.05)
LINK_SIGMAS = (0.05, 0.05, math.radians(2.0))


def square_walk(n_laps: int = 1, side: int = 5, step: float = 1.0,
                start: Rigid2D | None = None) -> list[Rigid2D]:
    """True poses in the world: ``side`` steps of ``step`` m, then a 90° left turn, ``n_laps``
    times round (the last pose is the first one again)."""
    poses = [start or Rigid2D()]
    for k in range(1, 4 * side * n_laps + 1):
        turn = math.pi / 2 if k % side == 0 else 0.0
        poses.append(poses[-1] @ Rigid2D(turn, (step, 0.0)))
    return poses


def odometry(true: list[Rigid2D], bias_deg: float) -> list[Rigid2D]:
    """What a robot whose heading drifts by ``bias_deg`` a step believes, in its own frame
    (its first pose is its frame's origin)."""
    odom = [Rigid2D()]
    for prev, cur in zip(true, true[1:], strict=False):
        rel = prev.inverse() @ cur
        odom.append(odom[-1] @ Rigid2D(rel.theta + math.radians(bias_deg), rel.T))
    return odom


def add_robot(graph: PoseGraph, robot: int, odom: list[Rigid2D]) -> None:
    for pose in odom:
        graph.add_anchor(robot, pose, ODOM_SIGMAS)


def xy(poses: list[Rigid2D]) -> np.ndarray:
    return np.array([p.T for p in poses])


def test_perfect_odometry_without_links_is_the_odometry():
    graph = PoseGraph(2)
    odom = odometry(square_walk(), 0.0)
    add_robot(graph, 0, odom)
    add_robot(graph, 1, odometry(square_walk(side=3), 0.0))
    traj = graph.trajectory(0)
    np.testing.assert_allclose(traj[:, :2], xy(odom), atol=1e-6)
    assert graph.component(0) == frozenset({0})
    assert graph.component(1) == frozenset({1})


def test_a_loop_closure_unbends_a_drifting_map():
    true = square_walk()
    odom = odometry(true, bias_deg=1.5)
    graph = PoseGraph(1)
    add_robot(graph, 0, odom)
    truth = [true[0].inverse() @ p for p in true]
    raw = ate_rms(xy(odom), xy(truth))
    # back at the start: the last anchor is where the first was
    assert graph.add_loop(0, 0, len(odom) - 1, Rigid2D(), LINK_SIGMAS)
    fixed = ate_rms(graph.trajectory(0), xy(truth))
    assert [(m.a, m.b) for m in graph.loops(0)] == [((0, 0), (0, len(odom) - 1))]
    assert raw > 0.4
    assert fixed < raw / 3


def test_a_loop_closure_the_odometry_cannot_explain_is_refused():
    odom = odometry(square_walk(), 0.0)
    graph = PoseGraph(1)
    add_robot(graph, 0, odom)
    assert not graph.add_loop(0, 0, len(odom) - 1, Rigid2D(0.0, (15.0, 0.0)), LINK_SIGMAS)
    assert graph.loops(0) == []
    np.testing.assert_allclose(graph.trajectory(0)[:, :2], xy(odom), atol=1e-6)


def two_robots(bias_deg: float = 0.3, wrong: int = 0, right: int = 5):
    """Robot 1 starts 70° turned and elsewhere, walks a smaller square inside robot 0's;
    ``right`` true links where their trajectories pass near each other, ``wrong`` look-alikes
    (the true link turned 180° about anchor ``a``)."""
    start1 = Rigid2D(math.radians(70.0), (1.0, 1.0))
    true0, true1 = square_walk(), square_walk(side=3, start=start1)
    graph = PoseGraph(2)
    add_robot(graph, 0, odometry(true0, bias_deg))
    add_robot(graph, 1, odometry(true1, bias_deg))
    pairs = [(1, 2), (4, 5), (7, 8), (9, 10), (12, 3), (15, 6)][:right]
    for a, b in pairs:
        graph.add_link((0, a), (1, b), true0[a].inverse() @ true1[b], LINK_SIGMAS, 0.9)
    for a, b in [(3, 4), (10, 2), (16, 9)][:wrong]:
        z = Rigid2D(math.pi, (0.0, 0.0)) @ true0[a].inverse() @ true1[b]
        graph.add_link((0, a), (1, b), z, LINK_SIGMAS, 0.95)
    # robot 1 in robot 0's frame (robot 0's first pose is its frame's origin)
    truth1 = [true0[0].inverse() @ p for p in true1]
    return graph, truth1


def test_consistent_links_merge_two_robots_in_each_others_frames():
    graph, truth1 = two_robots()
    assert graph.component(0) == frozenset({0, 1})
    kept, rejected = graph.links(0, 1)
    assert len(kept) == 5 and not rejected
    traj = graph.trajectory(1, frame=0)
    err = np.linalg.norm(traj[:, :2] - xy(truth1), axis=1)
    assert err.max() < 0.3
    # and robot 0 in robot 1's frame is the inverse view of the same merge
    back = graph.corrected_poses(0, frame=1)[0]
    forward = graph.corrected_poses(1, frame=0)[0]
    assert (back @ Rigid2D()).allclose((forward.inverse() @ graph.corrected_poses(0)[0]),
                                       atol=1e-6)


def test_look_alike_links_are_refused():
    graph, truth1 = two_robots(wrong=3)
    kept, rejected = graph.links(0, 1)
    assert len(kept) == 5 and len(rejected) == 3
    assert all(m.confidence == 0.95 for m in rejected)
    traj = graph.trajectory(1, frame=0)
    assert np.linalg.norm(traj[:, :2] - xy(truth1), axis=1).max() < 0.3


def test_one_link_alone_does_not_merge():
    graph, _ = two_robots(right=1)
    assert graph.component(0) == frozenset({0})
    with pytest.raises(ValueError, match=r"robot 0 is not in robot 1's component \[1\]"):
        graph.trajectory(1, frame=0)
    assert PoseGraph(2, {"min_links": 1}) is not None


def test_a_third_robot_whose_links_contradict_the_team_is_cut_off():
    """Robots 0–1 and 1–2 agree; robot 2's links to robot 0 are self-consistent but 3 m off
    the others (a shifted look-alike): the optimum cannot explain them and drops them."""
    starts = [Rigid2D(), Rigid2D(math.radians(70.0), (1.0, 1.0)),
              Rigid2D(math.radians(-40.0), (2.0, 0.5))]
    walks = [square_walk(), square_walk(side=3, start=starts[1]),
             square_walk(side=2, start=starts[2])]
    graph = PoseGraph(3)
    for r, w in enumerate(walks):
        add_robot(graph, r, odometry(w, 0.0))

    def link(i, a, j, b, shift=0.0):
        z = walks[i][a].inverse() @ walks[j][b]
        graph.add_link((i, a), (j, b), Rigid2D(0.0, (shift, 0.0)) @ z, LINK_SIGMAS, 0.9)

    for a, b in [(1, 2), (4, 5), (7, 8)]:
        link(0, a, 1, b)
    for a, b in [(2, 1), (5, 4), (8, 6)]:
        link(1, a, 2, b)
    for a, b in [(3, 1), (9, 5), (14, 7)]:
        link(0, a, 2, b, shift=3.0)
    assert graph.component(2) == frozenset({0, 1, 2})
    kept, _ = graph.links(0, 2)
    assert len(kept) < 2
    truth2 = [walks[0][0].inverse() @ p for p in walks[2]]
    assert np.abs(graph.trajectory(2, frame=0)[:, :2] - xy(truth2)).max() < 0.05


@settings(max_examples=10, deadline=None)
@given(theta=st.floats(-math.pi, math.pi), tx=st.floats(-20, 20), ty=st.floats(-20, 20))
def test_exact_links_recover_any_relative_frame(theta, tx, ty):
    start1 = Rigid2D(theta, (tx, ty))
    true0, true1 = square_walk(), square_walk(side=3, start=start1)
    graph = PoseGraph(2)
    add_robot(graph, 0, odometry(true0, 0.0))
    add_robot(graph, 1, odometry(true1, 0.0))
    for a, b in [(1, 2), (6, 7), (11, 3)]:
        graph.add_link((0, a), (1, b), true0[a].inverse() @ true1[b], LINK_SIGMAS, 0.9)
    first = graph.corrected_poses(1, frame=0)[0]
    assert first.allclose(start1, atol=1e-5)


def test_same_inputs_same_answer():
    a, _ = two_robots(wrong=2)
    b, _ = two_robots(wrong=2)
    np.testing.assert_array_equal(a.trajectory(1, frame=0), b.trajectory(1, frame=0))


def test_bad_input_names_the_parameter():
    with pytest.raises(ValueError, match=r"n_robots must be >= 1, got 0"):
        PoseGraph(0)
    with pytest.raises(ValueError, match=r"config has unknown keys \['minlinks'\]"):
        PoseGraph(2, {"minlinks": 2})
    with pytest.raises(ValueError, match=r"consistency_quantile must be < 1.0, got 1.0"):
        PoseGraphConfig(consistency_quantile=1.0)
    graph = PoseGraph(2)
    with pytest.raises(ValueError, match=r"robot must be < n_robots=2, got 2"):
        graph.add_anchor(2, Rigid2D())
    with pytest.raises(TypeError, match=r"pose must be a fusion.Rigid2D, got tuple"):
        graph.add_anchor(0, (0.0, 0.0, 0.0))
    graph.add_anchor(0, Rigid2D())
    graph.add_anchor(1, Rigid2D())
    with pytest.raises(ValueError, match=r"b: robot 1 has 1 anchors, got index 3"):
        graph.add_link((0, 0), (1, 3), Rigid2D(), LINK_SIGMAS, 0.9)
    with pytest.raises(ValueError, match=r"sigmas must be > 0, got \(0.0, 0.1, 0.1\)"):
        graph.add_link((0, 0), (1, 0), Rigid2D(), (0.0, 0.1, 0.1), 0.9)
    with pytest.raises(ValueError, match=r"sigmas must be 3 standard deviations"):
        graph.add_link((0, 0), (1, 0), Rigid2D(), (0.1, 0.1), 0.9)
    with pytest.raises(ValueError, match=r"confidence must be <= 1.0, got 1.5"):
        graph.add_link((0, 0), (1, 0), Rigid2D(), LINK_SIGMAS, 1.5)
    with pytest.raises(ValueError, match=r"a link joins two robots' anchors"):
        graph.add_link((0, 0), (0, 0), Rigid2D(), LINK_SIGMAS, 0.9)
    with pytest.raises(ValueError, match=r"sigmas\[2\] must be finite, got nan"):
        graph.add_anchor(0, Rigid2D(), (0.1, 0.1, float("nan")))


def test_without_gtsam_the_error_names_the_extra(monkeypatch):
    graph = PoseGraph(1)
    graph.add_anchor(0, Rigid2D())
    monkeypatch.setitem(sys.modules, "gtsam", None)
    with pytest.raises(ImportError, match=r"pip install 'topomerge\[slam\]'"):
        graph.optimise()


def test_ate_is_zero_for_a_moved_copy_and_checks_shapes():
    pts = np.random.default_rng(0).normal(size=(20, 2))
    moved = Rigid2D(1.0, (3.0, -2.0)).apply(pts)
    assert ate_rms(pts, moved) < 1e-9
    with pytest.raises(ValueError, match=r"same number \(≥ 1\) of rows, got 20 and 19"):
        ate_rms(pts, moved[:19])


def test_one_correction_is_the_list_entry():
    graph, _ = two_robots()
    for r in (0, 1):
        full = graph.corrections(r, frame=0)
        for k in (0, len(full) - 1, -1):
            got, want = graph.correction(r, k, frame=0), full[k]
            assert (got.theta, *got.T) == (want.theta, *want.T)  # the same numbers, bit for bit
    with pytest.raises(ValueError, match="index must be <"):
        graph.correction(0, 10_000)
    with pytest.raises(TypeError, match="index must be an integer"):
        graph.correction(0, 1.5)
