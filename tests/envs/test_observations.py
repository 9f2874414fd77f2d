"""Observations (``envs.explore.observations``): the space's layout, every observation in it,
what each key holds against the env's public maps (a slow obvious ``local_map`` and
``graph_*`` beside the fast ones), the teammate estimate only after a merge, and reads that
never change an episode."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import SMALL
from hypothesis import given, settings
from hypothesis import strategies as st

from envs import multi_robot_explore_v0, two_robot_explore_v0
from envs.explore.config import EnvConfig
from envs.explore.mapping import compose_pose
from envs.explore.observations import (
    MAX_CLEARANCE,
    MAX_DEGREE,
    N_NODE_FEATURES,
    TEAMMATE_FEATURES,
    observation_space,
)
from topo.graph import NodeKind

IMAGE = np.array([128, 255, 0], dtype=np.uint8)
"""``local_map`` value of each cell state code (unknown, free, occupied), as the manual says."""


@settings(max_examples=40, deadline=None)
@given(n=st.integers(2, 8), max_nodes=st.integers(1, 40), size=st.integers(64, 96),
       radius=st.floats(5.0, 60.0), two_robot=st.booleans())
def test_the_space_layout_and_bounds(n, max_nodes, size, radius, two_robot):
    n = 2 if two_robot else n
    config = EnvConfig.from_kwargs(n_robots=n, mapping={"max_nodes": max_nodes,
                                                        "local_map_size": size})
    space = observation_space(config, radius, two_robot)
    team_key = "teammate" if two_robot else "teammates"
    assert sorted(space.spaces) == sorted(["sonar", "odometry", "graph_nodes", "graph_mask",
                                           "graph_adjacency", "local_map", team_key])
    shapes = {"sonar": (8,), "odometry": (4,), "graph_nodes": (max_nodes, N_NODE_FEATURES),
              "graph_mask": (max_nodes,), "graph_adjacency": (max_nodes, max_nodes),
              "local_map": (1, size, size),
              team_key: (5,) if two_robot else (n - 1, TEAMMATE_FEATURES)}
    assert {k: s.shape for k, s in space.spaces.items()} == shapes
    assert space["local_map"].dtype == np.uint8
    assert all(space[k].dtype == np.float32 for k in shapes if k != "local_map")
    r = np.float32(radius)
    np.testing.assert_array_equal(space["odometry"].high, [r, r, 1, 1])
    nodes = space["graph_nodes"]
    assert N_NODE_FEATURES == 2 + len(NodeKind) + 3
    np.testing.assert_array_equal(nodes.high[0], [2 * r, 2 * r, *[1] * len(NodeKind),
                                                  MAX_DEGREE, MAX_CLEARANCE, 1])
    np.testing.assert_array_equal(nodes.low[0], [-2 * r, -2 * r] + [0] * (N_NODE_FEATURES - 2))
    row = space[team_key].high if two_robot else space[team_key].high[-1]
    np.testing.assert_array_equal(row, [2 * r, 2 * r, 1, 1, 1, 1, 1][:len(row)])


def _local_map(own, pose: np.ndarray, size: int, res: float, others=()) -> np.ndarray:
    """A slow obvious ``local_map``: each pixel's point ahead/left of ``pose`` looked up in the
    grid ``own`` and every ``(grid, pose)`` of ``others``, the largest state code kept."""
    steps = (size / 2.0 - np.arange(size) - 0.5) * res
    fwd, left = np.meshgrid(steps, steps, indexing="ij")
    code = np.zeros((size, size), dtype=np.int8)
    for grid, (x, y, th) in ((own, pose), *others):
        px = x + math.cos(th) * fwd - math.sin(th) * left
        py = y + math.sin(th) * fwd + math.cos(th) * left
        iy = np.floor((py - grid.origin[1]) / grid.resolution).astype(int)
        ix = np.floor((px - grid.origin[0]) / grid.resolution).astype(int)
        h, w = grid.shape
        inside = (iy >= 0) & (iy < h) & (ix >= 0) & (ix < w)
        states = np.zeros((size, size), dtype=np.int8)
        states[inside] = grid.states()[iy[inside], ix[inside]]
        code = np.maximum(code, states)
    return IMAGE[code][None]


def _check_graph(obs: dict, topo, odometry: np.ndarray, radius: float) -> None:
    """``graph_*`` against the robot's own topological map seen from its odometry pose."""
    nodes, mask, adj = obs["graph_nodes"], obs["graph_mask"], obs["graph_adjacency"]
    k = min(topo.n_nodes, len(mask))
    np.testing.assert_array_equal(mask, [1] * k + [0] * (len(mask) - k))
    assert not nodes[k:].any() and not adj[k:].any() and not adj[:, k:].any()
    x, y, th = odometry
    c, s = math.cos(th), math.sin(th)
    d = topo.xy - [x, y]
    rel = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], axis=1)
    order = np.argsort(np.hypot(*rel.T), kind="stable")[:k]  # nearest first
    np.testing.assert_allclose(nodes[:k, :2], np.clip(rel[order], -2 * radius, 2 * radius),
                               atol=1e-4)
    kinds = np.zeros((k, len(NodeKind)))
    kinds[np.arange(k), topo.kinds[order]] = 1
    np.testing.assert_array_equal(nodes[:k, 2:2 + len(NodeKind)], kinds)
    np.testing.assert_allclose(nodes[:k, -3], np.minimum(topo.degree()[order], MAX_DEGREE))
    np.testing.assert_allclose(nodes[:k, -2], np.minimum(topo.clearance[order], MAX_CLEARANCE),
                               rtol=1e-6)
    np.testing.assert_array_equal(nodes[:k, -1], topo.frontier[order])
    slot = {int(q): j for j, q in enumerate(order)}
    expected = np.zeros_like(adj)
    for u, v in topo.edges.tolist():
        if u in slot and v in slot:
            expected[slot[u], slot[v]] = expected[slot[v], slot[u]] = 1
    np.testing.assert_array_equal(adj, expected)


def _check_step(env, obs: dict, infos: dict) -> None:
    """Every observation in its space and what each key holds (the manual, Observations)."""
    state = env.merge_state()
    for i, agent in enumerate(env.agents):
        o = obs[agent]
        space = env.observation_space(agent)
        for key, sub in space.spaces.items():
            assert sub.contains(o[key]), (agent, key)
        x, y, th = infos[agent]["odometry"]
        np.testing.assert_array_equal(o["odometry"], np.array(
            [x, y, math.cos(th), math.sin(th)], dtype=np.float32))
        snap = env.robot_map(agent)
        _check_graph(o, snap.topomap, snap.odometry, env.frame_radius)
        assert set(np.unique(o["local_map"])) <= {0, 128, 255}
        rows = o["teammates"]
        others = [j for j in range(env.n_robots) if j != i]
        np.testing.assert_array_equal(rows[:, 4], [j in state.frames[i] for j in others])
        np.testing.assert_array_equal(rows[:, 5], [j in state.contacts[i] for j in others])
        assert not rows[rows[:, 4] == 0, :4].any()  # no estimate without a merge
        assert (rows[rows[:, 5] == 1, 6] == 0).all()  # in contact: age 0


@pytest.mark.parametrize(("n", "reach", "method", "seed", "max_nodes"), [
    (2, None, "hybrid", 4, 32), (3, 4.0, "known", 1, 32), (4, 5.0, "hybrid", 0, 3)])
def test_every_observation_is_in_its_space_and_holds_what_the_manual_says(n, reach, method,
                                                                            seed, max_nodes):
    # every merge accepted (thresholds 0): estimates appear within 80 steps; with 3 graph
    # nodes observed the maps have more than that
    env = multi_robot_explore_v0.parallel_env(
        n_robots=n, comm={"range": reach}, sonar={"rays": 1}, mapping={
            "merge_method": method, "merge_every": 5, "grid_merge_every": 10,
            "topo_every": 5, "accept_threshold": 0.0, "team_accept_threshold": 0.0,
            "max_nodes": max_nodes}, **{**SMALL, "max_cycles": 80})
    obs, infos = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    valid = set()
    while True:
        _check_step(env, obs, infos)
        valid |= {bool(o["teammates"][:, 4].any()) for o in obs.values()}
        if not env.agents:
            break
        obs, _, _, _, infos = env.step({a: np.array([rng.uniform(0.2, 1), rng.uniform(-1, 1)])
                                        for a in env.agents})
    assert valid == {False, True}  # before and after a merge


@pytest.mark.parametrize("method", ["none", "known"])
def test_the_local_map_shows_the_own_map_and_the_fused_teammates(method):
    """Before a merge, a robot's ``local_map`` is its own map around it; once merged, also the
    teammate's map moved into its frame (checked against a slow obvious sampler)."""
    par = two_robot_explore_v0.parallel_env(mapping={"merge_method": method},
                                            **{**SMALL, "max_cycles": 40})
    obs, _ = par.reset(seed=7)
    cfg = par.config.mapping
    size, res = cfg.local_map_size, cfg.local_map_resolution
    differs = 0
    while par.agents:
        state = par.merge_state()
        for i, agent in enumerate(par.possible_agents):
            own = par.robot_map(agent)
            moved = [(par.robot_map(f"robot_{j}").grid,
                      compose_pose(to_i.inverse(), own.odometry)) for j, to_i in
                     state.frames[i].items() if j != i]
            assert bool(moved) == (method == "known" and par.steps > 0)
            expected = _local_map(own.grid, own.odometry, size, res, moved)
            mismatch = (obs[agent]["local_map"] != expected).mean()
            assert mismatch < 0.002, (agent, par.steps, mismatch)  # nearest-cell rounding
            differs += not np.array_equal(expected, _local_map(own.grid, own.odometry, size,
                                                               res))
        obs, *_ = par.step({"robot_0": np.array([0.8, 0.3]), "robot_1": np.array([0.8, -0.3])})
    assert (differs > 0) == (method == "known")


def test_the_two_robot_layout_is_the_team_of_two_with_one_teammate_row():
    """``two_robot_explore_v0`` and ``multi_robot_explore_v0`` with two robots and no range
    limit play the same episode; ``teammate`` is the first five entries of ``teammates``."""
    kw = {**SMALL, "max_cycles": 80, "mapping": {"merge_method": "known"}}
    two = two_robot_explore_v0.parallel_env(**kw)
    team = multi_robot_explore_v0.parallel_env(n_robots=2, **kw)
    o2, i2 = two.reset(seed=4)
    ot, it = team.reset(seed=4)
    rng = np.random.default_rng(4)
    while True:
        for a in two.possible_agents:
            for key in o2[a]:
                if key != "teammate":
                    np.testing.assert_array_equal(o2[a][key], ot[a][key])
            np.testing.assert_array_equal(o2[a]["teammate"], ot[a]["teammates"][0, :5])
            np.testing.assert_array_equal(ot[a]["teammates"][0, 5:], [1, 0])
            assert repr(i2[a]) == repr({k: v for k, v in it[a].items()
                                        if k not in ("contacts", "fused_robots")})
        if not two.agents:
            break
        act = {a: rng.uniform(-1, 1, 2) for a in two.agents}
        o2, r2, *_, i2 = two.step(act)
        ot, rt, *_, it = team.step(act)
        assert r2 == rt


def test_reading_the_maps_and_state_never_changes_the_episode():
    """Same seed, same actions: an env whose maps, teammates' maps, merge state and global
    state are read every step gives the same observations as one never read."""
    kw = {"n_robots": 3, "comm": {"range": 4.0}, "robot": {"odometry_noise": (0.03, 0.03)},
          "mapping": {"merge_every": 5, "topo_every": 5}, **{**SMALL, "max_cycles": 120}}
    quiet = multi_robot_explore_v0.parallel_env(**kw)
    read = multi_robot_explore_v0.parallel_env(**kw)
    oq, _ = quiet.reset(seed=9)
    orr, _ = read.reset(seed=9)
    rng = np.random.default_rng(9)
    while quiet.agents:
        for a in read.possible_agents:
            read.robot_map(a)
            for b in read.possible_agents:
                read.teammate_map(a, b)
        read.merge_state()
        read.state()
        for a in quiet.possible_agents:
            for key in oq[a]:
                np.testing.assert_array_equal(oq[a][key], orr[a][key])
        act = {a: rng.uniform(-1, 1, 2) for a in quiet.agents}
        oq, *_ = quiet.step(act)
        orr, *_ = read.step(act)
    assert read.steps == 120
