"""TopoMap: validation, encoding table, round trips (dict/JSON, networkx), transforms."""

import json

import networkx as nx
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from motion import Motion

from topo import KIND_LABELS, NodeKind, TopoMap

T_XY = [[0.0, 0.0], [2.0, 0.0], [4.0, 0.0], [2.0, 3.0]]
T_EDGES = [[0, 1], [1, 2], [1, 3]]


@st.composite
def topomaps(draw, with_paths=False):
    n = draw(st.integers(1, 12))
    xy = draw(arrays(np.float64, (n, 2), elements=st.floats(-50, 50, allow_nan=False)))
    pairs = [(i, j) for i in range(n) for j in range(n) if i != j]
    edges = draw(st.lists(st.sampled_from(pairs), max_size=15)) if pairs else []
    kinds = draw(st.lists(st.sampled_from(KIND_LABELS), min_size=n, max_size=n))
    paths = None
    if with_paths:
        paths = [np.array([xy[i], (xy[i] + xy[j]) / 2 + 0.5, xy[j]]) for i, j in edges]
    lengths = None if paths is None else [np.linalg.norm(np.diff(p, axis=0), axis=1).sum()
                                          for p in paths]
    return TopoMap.from_arrays(xy, np.array(edges, dtype=np.int64).reshape(-1, 2), kinds,
                               lengths, paths)


def test_from_arrays_derives_kinds_and_lengths():
    m = TopoMap.from_arrays(T_XY, T_EDGES)
    assert m.kind_labels() == ["dead_end", "junction", "dead_end", "dead_end"]
    np.testing.assert_allclose(m.lengths, [2.0, 2.0, 3.0])
    assert m.degree().tolist() == [1, 3, 1, 1]
    assert "junction=1" in repr(m) and "edges=3" in repr(m)


def test_arrays_are_read_only():
    m = TopoMap.from_arrays(T_XY, T_EDGES)
    with pytest.raises(ValueError):
        m.xy[0, 0] = 1.0


def test_encoding_table_round_trip():
    for kind in NodeKind:
        assert NodeKind.parse(kind.label) is kind
        assert NodeKind.parse(int(kind)) is kind
        assert KIND_LABELS[kind] == kind.label


def test_endpoints_skip_isolated_nodes():
    m = TopoMap.from_arrays([[0, 0], [1, 0], [5, 5]], [[0, 1]])
    np.testing.assert_array_equal(m.endpoints(), [[0, 0], [1, 0]])
    assert TopoMap.empty().endpoints().shape == (0, 2)


@given(topomaps(with_paths=True))
def test_dict_round_trip_through_json(m):
    back = TopoMap.from_dict(json.loads(json.dumps(m.to_dict())))
    assert back.equals(m)
    assert back.paths is not None and all(
        np.array_equal(p, q) for p, q in zip(back.paths, m.paths, strict=True)
    )


@given(topomaps(with_paths=True))
def test_networkx_round_trip(m):
    g = m.to_networkx()
    assert isinstance(g, nx.MultiGraph)
    assert g.number_of_nodes() == m.n_nodes and g.number_of_edges() == m.n_edges
    back = TopoMap.from_networkx(g)
    assert np.array_equal(back.xy, m.xy) and np.array_equal(back.kinds, m.kinds)
    # networkx groups parallel edges: compare edge multisets with their lengths and paths
    def edge_set(t):
        return sorted(
            (min(u, v), max(u, v), round(L, 9), tuple(map(tuple, np.round(
                p if u < v else p[::-1], 9).tolist())))
            for (u, v), L, p in zip(t.edges.tolist(), t.lengths.tolist(), t.paths or (),
                                    strict=True)
        )
    assert edge_set(back) == edge_set(m)


@given(topomaps(with_paths=True), st.floats(-7, 7), st.floats(-20, 20), st.floats(-20, 20))
def test_transformed_is_rigid(m, theta, tx, ty):
    t = Motion(theta, (tx, ty))
    moved = m.transformed(t)
    np.testing.assert_allclose(moved.xy, t.apply(m.xy))
    np.testing.assert_allclose(moved.transformed(t.inverse()).xy, m.xy, atol=1e-9)
    np.testing.assert_array_equal(moved.lengths, m.lengths)
    for p, q in zip(moved.paths, m.paths, strict=True):
        np.testing.assert_allclose(p, t.apply(q))


def test_parallel_paths_allowed():
    m = TopoMap.from_arrays([[0, 0], [4, 0]], [[0, 1], [0, 1]], lengths=[4.0, 9.0])
    assert m.to_networkx().number_of_edges() == 2


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"xy": [[0, 0], [np.nan, 1]]}, ValueError, r"xy must be finite, got \[nan, 1.0\] at row 1"),
        ({"xy": [[0, 0, 0]]}, ValueError, r"xy must have shape \(N, 2\), got shape \(1, 3\)"),
        ({"xy": "nodes"}, TypeError, "xy must be an array of shape"),
        ({"xy": [[0, 0], [1, 0]], "edges": [[0, 2]]}, ValueError,
         r"edges\[0\] = \[0, 2\] has a node index out of range \[0, 2\)"),
        ({"xy": [[0, 0], [1, 0]], "edges": [[1, 1]]}, ValueError,
         r"edges\[0\] = \[1, 1\] is a self-loop"),
        ({"xy": [[0, 0], [1, 0]], "edges": [[0.5, 1]]}, TypeError, "edges must hold integer"),
        ({"xy": [[0, 0], [1, 0]], "edges": [[0, 1]], "kinds": ["junction", "room"]}, ValueError,
         r"kinds has unknown node kind 'room'; allowed: 'junction' \(0\)"),
        ({"xy": [[0, 0], [1, 0]], "kinds": ["junction"]}, ValueError,
         r"kinds must have one entry per node \(2\), got 1"),
        ({"xy": [[0, 0], [3, 0]], "edges": [[0, 1]], "lengths": [1.0]}, ValueError,
         r"lengths\[0\] = 1.0 must be finite and >= the straight-line distance 3.0000"),
        ({"xy": [[0, 0], [3, 0]], "edges": [[0, 1]], "paths": [[[0, 0]]]}, ValueError,
         r"paths\[0\] must have at least 2 points"),
    ],
)
def test_bad_input_is_named(kwargs, error, match):
    with pytest.raises(error, match=match):
        TopoMap.from_arrays(**kwargs)


def test_from_dict_refuses_foreign_and_unknown_keys():
    good = TopoMap.from_arrays(T_XY, T_EDGES).to_dict()
    with pytest.raises(ValueError, match="not a topomerge.TopoMap version 1 or 2 dict"):
        TopoMap.from_dict({**good, "version": 99})
    with pytest.raises(ValueError, match=r"unknown keys \['colour'\]"):
        TopoMap.from_dict({**good, "colour": "red"})
    with pytest.raises(TypeError, match="data must be a dict, got list"):
        TopoMap.from_dict([1, 2])


def test_from_networkx_needs_positions():
    g = nx.Graph()
    g.add_node("a")
    with pytest.raises(ValueError, match="'xy' attribute"):
        TopoMap.from_networkx(g)
    with pytest.raises(ValueError, match="undirected"):
        TopoMap.from_networkx(nx.DiGraph())


@given(st.integers(0, 2**32 - 1), st.integers(1, 12), st.integers(0, 15))
def test_descriptors_survive_every_round_trip(seed, n, n_edges):
    """Clearances and frontier flags go through dicts, networkx and rigid motions unchanged."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-5, 5, (n, 2))
    pairs = [(u, v) for u, v in rng.integers(0, n, (n_edges, 2)).tolist() if u != v]
    m = TopoMap.from_arrays(xy, np.asarray(pairs, dtype=np.int64).reshape(-1, 2),
                            clearance=rng.uniform(0, 3, n), frontier=rng.random(n) < 0.5)
    assert TopoMap.from_dict(m.to_dict()).equals(m)
    back = TopoMap.from_networkx(m.to_networkx())  # same nodes; networkx orders the edges
    for f in ("xy", "kinds", "clearance", "frontier"):
        np.testing.assert_array_equal(getattr(back, f), getattr(m, f))
    moved = m.transformed(_Shift((1.0, -2.0)))
    np.testing.assert_array_equal(moved.clearance, m.clearance)
    np.testing.assert_array_equal(moved.frontier, m.frontier)
    assert not m.clearance.flags.writeable and not m.frontier.flags.writeable


class _Shift:
    def __init__(self, t):
        self.t = np.asarray(t)

    def apply(self, points):
        return np.asarray(points) + self.t


def test_version_1_dicts_still_read_and_descriptors_are_checked():
    m = TopoMap.from_arrays([[0, 0], [1, 0]], [[0, 1]])
    old = {k: v for k, v in m.to_dict().items() if k not in ("clearance", "frontier")}
    old["version"] = 1
    back = TopoMap.from_dict(old)
    assert back.equals(m) and not back.frontier.any() and (back.clearance == 0).all()
    with pytest.raises(ValueError, match=r"clearance\[1\] = -1.0 must be finite and >= 0"):
        TopoMap.from_arrays([[0, 0], [1, 0]], clearance=[0.5, -1.0])
    with pytest.raises(ValueError, match=r"clearance must have one entry per node \(2\), got 3"):
        TopoMap.from_arrays([[0, 0], [1, 0]], clearance=[0.5, 1.0, 2.0])
    with pytest.raises(TypeError, match="frontier must hold booleans, got dtype float64"):
        TopoMap.from_arrays([[0, 0], [1, 0]], frontier=[0.5, 1.0])


def test_path_directions_leave_each_node_along_its_paths():
    """An L path with its polyline: at the corner node the path heads east (0); at the far end
    of a 1 m reach it heads back along the polyline; straight edges use the segment."""
    xy = [[0.0, 0.0], [4.0, 0.0], [4.0, 3.0]]
    m = TopoMap.from_arrays(xy, [[0, 1], [1, 2]], paths=[np.array([[0, 0], [2, 0], [4, 0.0]]),
                                                         np.array([[4, 0], [4, 3.0]])])
    d = m.path_directions()
    np.testing.assert_allclose(d[0], [0.0])
    np.testing.assert_allclose(sorted(d[1]), sorted([np.pi, np.pi / 2]))
    np.testing.assert_allclose(d[2], [-np.pi / 2])
    turned = m.transformed(_Turn(np.pi / 2))
    np.testing.assert_allclose(turned.path_directions()[0], [np.pi / 2])
    with pytest.raises(ValueError, match="reach must be a positive number of metres, got 0"):
        m.path_directions(0)


class _Turn:
    def __init__(self, a):
        self.r = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])

    def apply(self, points):
        return np.asarray(points) @ self.r.T
