"""fusion.team: cycle consistency over pairwise merges and the frames it gives each robot."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fusion.rigid import Rigid2D
from fusion.team import Edge, adjust_frames, consistent_edges, frames_from


def _world_frames(seed: int, n: int) -> list[Rigid2D]:
    rng = np.random.default_rng(seed)
    return [Rigid2D(float(rng.uniform(-math.pi, math.pi)), rng.uniform(-10, 10, 2))
            for _ in range(n)]


def _true_edge(frames, i, j, confidence=0.95, error=None) -> Edge:
    """The true j → i transform (optionally spoiled by ``error`` applied in i's frame)."""
    t = frames[i].inverse() @ frames[j]
    if error is not None:
        t = error @ t
    return Edge(i, j, t, confidence)


def _close(a: Rigid2D, b: Rigid2D) -> bool:
    return math.degrees(a.rotation_error(b)) < 1e-6 and a.translation_error(b) < 1e-6


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(2, 8))
def test_right_merges_are_all_kept_and_frames_compose_to_the_truth(seed, n):
    frames = _world_frames(seed, n)
    edges = [_true_edge(frames, i, j) for i in range(n) for j in range(i + 1, n)]
    check = consistent_edges(edges)
    assert not check.disputed and not check.rejected
    assert len(check.kept) == n - 1  # a spanning tree
    assert len(check.consistent) == n * (n - 1) // 2  # cycles everywhere from three robots
    for root in range(n):
        for edges_used in (check.kept, check.consistent):  # composed, least-squares
            got = frames_from(root, edges_used)
            assert set(got) == set(range(n))
            for j, (to_root, from_root) in got.items():
                assert _close(to_root, frames[root].inverse() @ frames[j])
                assert _close(from_root, frames[j].inverse() @ frames[root])


def test_a_look_alike_among_four_robots_is_left_out():
    frames = _world_frames(1, 4)
    wrong = Rigid2D.from_degrees(180.0, (6.0, 0.0))
    edges = [_true_edge(frames, i, j, 0.9) for i in range(4) for j in range(i + 1, 4)
             if (i, j) != (1, 3)]
    edges.append(_true_edge(frames, 1, 3, confidence=0.99, error=wrong))  # the most confident
    check = consistent_edges(edges)
    assert check.disputed == ((1, 3),) and len(check.kept) == 3
    assert check.votes[(1, 3)] == (0, 2) and check.votes[(0, 1)] == (1, 1)
    fused = frames_from(0, check.kept)
    assert set(fused) == {0, 1, 2, 3}
    for j, (to_0, _) in fused.items():
        assert _close(to_0, frames[0].inverse() @ frames[j])
    # pairwise decisions alone keep the look-alike: it is the most confident edge
    assert (1, 3) in consistent_edges(edges, check=False).kept


def test_an_inconsistent_triangle_of_three_robots_keeps_none_of_its_edges():
    frames = _world_frames(2, 3)
    edges = [_true_edge(frames, 0, 1), _true_edge(frames, 1, 2),
             _true_edge(frames, 0, 2, error=Rigid2D.from_degrees(20.0))]
    check = consistent_edges(edges)
    assert check.disputed == ((0, 1), (0, 2), (1, 2)) and not check.kept


def test_small_errors_within_the_tolerance_are_consistent():
    frames = _world_frames(3, 3)
    edges = [_true_edge(frames, 0, 1), _true_edge(frames, 1, 2),
             _true_edge(frames, 0, 2, error=Rigid2D.from_degrees(1.5, (0.2, 0.1)))]
    check = consistent_edges(edges, {k: np.zeros(2) for k in range(3)})
    assert not check.disputed and len(check.kept) == 2


def test_a_longer_cycle_is_checked_against_the_forest():
    # a square 0-1-2-3 (no triangles): the weakest edge closing the cycle is checked
    frames = _world_frames(4, 4)
    edges = [_true_edge(frames, 0, 1, 0.99), _true_edge(frames, 1, 2, 0.98),
             _true_edge(frames, 2, 3, 0.97),
             _true_edge(frames, 0, 3, 0.9, error=Rigid2D.from_degrees(0.0, (4.0, 0.0)))]
    check = consistent_edges(edges)
    assert check.rejected == ((0, 3),) and len(check.kept) == 3


def test_two_robots_get_the_pairwise_transform_and_its_stored_inverse_exactly():
    t = Rigid2D.from_degrees(37.0, (1.0, -2.0))
    e = Edge(0, 1, t, 0.9)
    f0 = frames_from(0, {(0, 1): e})
    f1 = frames_from(1, {(0, 1): e})
    assert f0[1][0] is t and f0[1][1] is e.inverse
    assert f1[0][0] is e.inverse and f1[0][1] is t


def test_bad_edges_are_refused():
    t = Rigid2D()
    with pytest.raises(ValueError, match=r"robots 0 <= i < j, got i=2, j=1"):
        Edge(2, 1, t, 0.5)
    with pytest.raises(TypeError, match="transform must be a Rigid2D, got tuple"):
        Edge(0, 1, (0, 0), 0.5)
    with pytest.raises(ValueError, match=r"two edges for robots \(0, 1\)"):
        consistent_edges([Edge(0, 1, t, 0.5), Edge(0, 1, t, 0.6)])
    with pytest.raises(ValueError, match="tolerances must be > 0"):
        consistent_edges([], tolerance_deg=0.0)


def test_an_unconfirmed_edge_needs_the_higher_confidence():
    frames = _world_frames(5, 4)
    # robots 0, 1, 2 confirm each other; robot 3 hangs on one edge (a bridge, no triangle)
    edges = [_true_edge(frames, 0, 1), _true_edge(frames, 1, 2), _true_edge(frames, 0, 2),
             _true_edge(frames, 2, 3, confidence=0.91)]
    check = consistent_edges(edges, min_unconfirmed=0.97)
    assert check.unconfirmed == ((2, 3),) and set(frames_from(0, check.kept)) == {0, 1, 2}
    edges[-1] = _true_edge(frames, 2, 3, confidence=0.98)
    check = consistent_edges(edges, min_unconfirmed=0.97)
    assert not check.unconfirmed and set(frames_from(0, check.kept)) == {0, 1, 2, 3}
    # without the check, no edge is held back
    assert not consistent_edges(edges[:3] + [_true_edge(frames, 2, 3, 0.5)], check=False,
                                min_unconfirmed=0.97).unconfirmed


def _errors(got, truth):
    return math.degrees(got.rotation_error(truth)), got.translation_error(truth)


def test_cycles_spread_one_pairs_error_instead_of_handing_it_to_one_robot():
    frames = _world_frames(6, 3)
    small = Rigid2D.from_degrees(1.5, (0.4, 0.0))  # within the tolerance: consistent
    edges = [_true_edge(frames, 0, 1, 0.99), _true_edge(frames, 1, 2, 0.98),
             _true_edge(frames, 0, 2, 0.9, error=small)]
    check = consistent_edges(edges)
    assert len(check.kept) == 2 and len(check.consistent) == 3
    tree = frames_from(0, check.kept)[2][0]
    assert tree is not edges[2].transform  # the forest reaches robot 2 through robot 1
    adjusted = frames_from(0, check.consistent)
    truth = [frames[0].inverse() @ frames[k] for k in range(3)]
    rot2, trans2 = _errors(adjusted[2][0], truth[2])
    rot1, trans1 = _errors(adjusted[1][0], truth[1])
    # one edge of three carries 1.5 deg / 0.4 m: the fit spreads it over both placements
    assert 0 < rot2 < 1.5 and 0 < rot1 < 1.5 and trans2 < 0.4
    assert max(rot1, rot2) < 1.0
    for k in range(3):  # from_root is to_root's inverse
        assert _close(adjusted[k][1], adjusted[k][0].inverse())


def test_adjusted_frames_beat_composed_ones_under_noise_on_average():
    """Four robots, every pairwise merge off by up to 1 deg / 0.15 m: the least-squares frames
    are closer to the truth than the frames composed along the confidence forest, over many
    draws (each robot's error at its map centre)."""
    rng = np.random.default_rng(3)
    tree_err, adjusted_err = [], []
    for trial in range(40):
        frames = _world_frames(100 + trial, 4)
        centres = {k: rng.uniform(-5, 5, 2) for k in range(4)}
        edges = [_true_edge(frames, i, j, float(rng.uniform(0.9, 1.0)),
                            Rigid2D.from_degrees(rng.uniform(-1, 1), rng.uniform(-0.15, 0.15, 2)))
                 for i in range(4) for j in range(i + 1, 4)]
        check = consistent_edges(edges, centres)
        assert len(check.consistent) == 6
        tree = frames_from(0, check.kept)
        adjusted = frames_from(0, check.consistent, centres)
        for k in range(1, 4):
            truth = frames[0].inverse() @ frames[k]
            tree_err.append(tree[k][0].translation_error(truth, centres[k]))
            adjusted_err.append(adjusted[k][0].translation_error(truth, centres[k]))
    assert np.mean(adjusted_err) < 0.8 * np.mean(tree_err)


def test_adjust_frames_refuses_robots_it_was_not_given():
    frames = _world_frames(2, 3)
    edge = _true_edge(frames, 0, 2)
    with pytest.raises(ValueError, match="root 5 is not among the robots"):
        adjust_frames(5, {0: Rigid2D.identity()}, [edge])
    with pytest.raises(ValueError, match=r"edge \(0, 2\) leaves the robots \[0, 1\]"):
        adjust_frames(0, {0: Rigid2D.identity(), 1: Rigid2D.identity()}, [edge])
