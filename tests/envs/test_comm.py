"""Communication (``envs.explore.comm``): who is in contact at a given range (multi-hop, line of
sight), and what a robot holds of a teammate's map in contact, after it and never.

The env tests place the robots by hand (``start_poses``) in empty rooms read from HouseExpo
files, so that who is in range is known without searching seeds."""

from __future__ import annotations

import json
import math

import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from envs import multi_robot_explore_v0
from envs.explore.comm import contact_groups
from envs.explore.config import CommConfig

CORRIDOR = [[0.0, 0.0], [12.0, 0.0], [12.0, 2.0], [0.0, 2.0]]
"""A 12 × 2 m empty room: robots on its axis ``y = 1`` see each other along it."""

ELL = [[0.0, 0.0], [6.0, 0.0], [6.0, 2.0], [2.0, 2.0], [2.0, 6.0], [0.0, 6.0]]
"""An L of two 2 m wide arms: the arms' ends see the corner but not each other."""


def room(tmp_path, verts: list[list[float]] = CORRIDOR) -> str:
    """The path of a HouseExpo JSON file of the polygon ``verts`` (metres) in ``tmp_path``."""
    path = tmp_path / "room.json"
    path.write_text(json.dumps({"verts": verts}), encoding="utf-8")
    return str(path)


def placed_team(tmp_path, xy: list[tuple[float, float]], heading: list[float] | None = None,
                verts: list[list[float]] = CORRIDOR, **kwargs):
    """A ``multi_robot_explore_v0`` env in the room ``verts``, reset with robot ``i`` at
    ``xy[i]`` facing ``heading[i]`` (0: along +x); returns it and the reset's infos."""
    heading = [0.0] * len(xy) if heading is None else heading
    kwargs = {"max_cycles": 200, "sonar": {"rays": 1}, **kwargs}
    env = multi_robot_explore_v0.parallel_env(
        n_robots=len(xy), world={"source": room(tmp_path, verts)}, **kwargs)
    starts = [[x, y, h] for (x, y), h in zip(xy, heading, strict=True)]
    _, infos = env.reset(seed=0, options={"start_poses": starts})
    return env, infos


def _reference_groups(xy: np.ndarray, reach: float) -> set[frozenset[int]]:
    """The connected groups of the graph joining robots at most ``reach`` apart (networkx)."""
    graph = nx.Graph()
    graph.add_nodes_from(range(len(xy)))
    graph.add_edges_from((i, j) for i in range(len(xy)) for j in range(i + 1, len(xy))
                         if math.dist(xy[i], xy[j]) <= reach)
    return {frozenset(c) for c in nx.connected_components(graph)}


def _groups(labels: np.ndarray) -> set[frozenset[int]]:
    return {frozenset(np.flatnonzero(labels == v).tolist()) for v in np.unique(labels)}


positions = st.lists(st.tuples(st.floats(0.0, 20.0), st.floats(0.0, 20.0)), min_size=2,
                     max_size=8).map(np.array)


@settings(max_examples=80, deadline=None)
@given(xy=positions, reach=st.floats(0.5, 12.0))
def test_contact_groups_are_the_connected_groups_of_the_in_range_graph(xy, reach):
    labels = contact_groups(xy, CommConfig(range=reach))
    assert labels.shape == (len(xy),) and labels.dtype == np.int64
    assert _groups(labels) == _reference_groups(xy, reach)


@settings(max_examples=60, deadline=None)
@given(xy=positions, near=st.floats(0.5, 6.0), more=st.floats(0.0, 6.0))
def test_a_longer_range_only_joins_groups(xy, near, more):
    short = _groups(contact_groups(xy, CommConfig(range=near)))
    long = _groups(contact_groups(xy, CommConfig(range=near + more)))
    assert all(any(g <= h for h in long) for g in short)


@settings(max_examples=30, deadline=None)
@given(xy=positions)
def test_unlimited_range_is_one_group(xy):
    np.testing.assert_array_equal(contact_groups(xy, CommConfig()), np.zeros(len(xy)))
    assert len(_groups(contact_groups(xy, CommConfig(range=30.0)))) == 1  # beyond the diagonal


@pytest.mark.parametrize(("reach", "contacts"), [
    (2.0, ((1, 2), (0, 2), (0, 1))),  # 1.5 m hops: robots 0 and 2 (3 m) through robot 1
    (1.4, ((), (), ())),
    (3.5, ((1, 2), (0, 2), (0, 1))),
])
def test_contact_is_multi_hop_along_a_chain_of_robots(tmp_path, reach, contacts):
    env, infos = placed_team(tmp_path, [(1.0, 1.0), (2.5, 1.0), (4.0, 1.0)],
                             comm={"range": reach})
    assert env.merge_state().contacts == contacts
    assert [infos[a]["contacts"] for a in env.possible_agents] == [len(c) for c in contacts]


def test_a_robot_leaving_the_chain_breaks_it(tmp_path):
    """Robot 1 relays between 0 and 2; once it drives out of the line, 0 and 2 lose contact
    though neither moved."""
    env, _ = placed_team(tmp_path, [(1.0, 1.0), (2.5, 1.0), (4.0, 1.0)], [0.0, math.pi / 2, 0.0],
                         verts=[[0.0, 0.0], [5.0, 0.0], [5.0, 1.6], [3.0, 1.6], [3.0, 8.0],
                                [2.0, 8.0], [2.0, 1.6], [0.0, 1.6]],
                         comm={"range": 2.0})
    assert env.merge_state().contacts == ((1, 2), (0, 2), (0, 1))
    still = np.zeros(2, dtype=np.float32)
    for _ in range(40):
        _, _, _, _, infos = env.step({"robot_0": still, "robot_1": np.array([1.0, 0.0]),
                                      "robot_2": still})
    assert infos["robot_1"]["pose"][1] > 3.5  # up the side arm
    assert env.merge_state().contacts == ((), (), ())


@pytest.mark.parametrize(("line_of_sight", "contacts"), [
    (False, ((1,), (0,))),
    (True, ((), ())),
])
def test_line_of_sight_needs_no_wall_between_the_robots(tmp_path, line_of_sight, contacts):
    # the two arms' ends are 5.7 m apart in a straight line that leaves the L
    env, _ = placed_team(tmp_path, [(5.0, 1.0), (1.0, 5.0)], verts=ELL,
                         comm={"range": 10.0, "line_of_sight": line_of_sight})
    assert env.merge_state().contacts == contacts


def test_a_robot_at_the_corner_relays_round_it(tmp_path):
    env, _ = placed_team(tmp_path, [(5.0, 1.0), (1.0, 5.0), (1.0, 1.0)], verts=ELL,
                         comm={"range": 10.0, "line_of_sight": True})
    assert env.merge_state().contacts == ((1, 2), (0, 2), (0, 1))


def test_a_teammate_map_is_live_in_contact_frozen_after_and_live_again(tmp_path):
    env, infos = placed_team(tmp_path, [(1.0, 1.0), (2.5, 1.0)], comm={"range": 2.0})
    cells = [env.robot_map("robot_1").known_cells]  # cells[k], contact[k]: after step k
    contact = [infos["robot_0"]["contacts"] == 1]
    still = np.zeros(2, dtype=np.float32)
    for k in range(1, 61):  # robot 1 drives away for 30 steps, then back
        v = 1.0 if k <= 30 else -1.0
        obs, _, _, _, infos = env.step({"robot_0": still, "robot_1": np.array([v, 0.0])})
        contact.append(infos["robot_0"]["contacts"] == 1)
        live = env.robot_map("robot_1")
        cells.append(live.known_cells)
        held = env.teammate_map("robot_0", "robot_1")
        row = obs["robot_0"]["teammates"][0]
        if contact[k]:
            assert held.step == k and held.known_cells == live.known_cells
            assert row[5] == 1.0 and row[6] == 0.0
        else:
            # the copy from the end of the last step in contact; nothing streams since
            last = k - contact[::-1].index(True)
            assert held.step == last and held.known_cells == cells[last]
            assert row[5] == 0.0 and row[6] == pytest.approx((k - last) / env.max_cycles)
    lost, back = contact.index(False), len(contact) - contact[::-1].index(False)
    assert all(contact[:lost]) and not any(contact[lost:back]) and all(contact[back:])
    assert 0 < lost < 30 < back <= 60  # lost, then met again
    assert cells[back - 1] > cells[lost - 1]  # robot 1 mapped meanwhile: the copy stayed behind


def test_robots_that_never_met_hold_nothing_of_each_other(tmp_path):
    env, infos = placed_team(tmp_path, [(1.0, 1.0), (8.0, 1.0), (11.0, 1.0)],
                             comm={"range": 3.5})
    assert env.merge_state().contacts == ((), (2,), (1,))
    assert env.teammate_map("robot_0", "robot_1") is None
    assert env.teammate_map("robot_1", "robot_2").step == 0
    own = env.teammate_map("robot_0", "robot_0")
    assert own.known_cells * env.config.mapping.grid_resolution ** 2 == pytest.approx(
        infos["robot_0"]["own_area_m2"])
    obs, *_ = env.step({a: np.zeros(2, dtype=np.float32) for a in env.agents})
    np.testing.assert_array_equal(obs["robot_0"]["teammates"][:, 4:], [[0, 0, 1], [0, 0, 1]])
    np.testing.assert_array_equal(obs["robot_1"]["teammates"][:, 5:], [[0, 1], [1, 0]])
