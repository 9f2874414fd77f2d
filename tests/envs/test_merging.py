"""Merging in the loop (``envs.explore.merging``), through the env: pairs are merged only while
in contact, what ``merge_state()`` reports agrees with itself and with the infos, known poses
and no merging."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import SMALL
from test_comm import placed_team

from envs import multi_robot_explore_v0, two_robot_explore_v0
from envs.explore.merging import MERGE_METHODS, MERGE_SOURCES
from fusion.rigid import Rigid2D

TEAM = {**SMALL, "world": {"size": (12.0, 12.0)}, "sonar": {"rays": 1},
        "mapping": {"merge_every": 5, "grid_merge_every": 10, "topo_every": 5}}
"""A small team world with frequent merges (every 5 steps, the grids every 10)."""


def _walk(env, steps: int, seed: int):
    """Step ``env`` (already reset) ``steps`` times with seeded commands changed every 10
    steps; yields each step's observations, infos and ``merge_state()``."""
    rng = np.random.default_rng(seed)
    for k in range(steps):
        if not env.agents:
            return
        if k % 10 == 0:
            act = {a: np.array([rng.uniform(0.3, 1.0), rng.uniform(-1, 1)], dtype=np.float32)
                   for a in env.agents}
        obs, _, _, _, infos = env.step(act)
        yield obs, infos, env.merge_state()


def _check_state(env, infos, state) -> None:
    """What one step's ``merge_state()`` says agrees with itself and with the infos."""
    n = env.n_robots
    assert sorted(state.pairs) == [(i, j) for i in range(n) for j in range(i + 1, n)]
    for pair in state.pairs.values():
        assert 0.0 <= pair.confidence <= 1.0
        assert pair.method in MERGE_METHODS and pair.source in MERGE_SOURCES
        assert (pair.transform is None) == (pair.method == "none") == (pair.source == "none")
        assert not pair.kept or pair.transform is not None
    for i in range(n):
        assert state.frames[i][i].allclose(Rigid2D.identity())
        assert state.fused[i] == tuple(sorted(state.frames[i]))
        assert all(i in state.contacts[j] for j in state.contacts[i])  # symmetric
        info = infos[f"robot_{i}"]
        assert info["contacts"] == len(state.contacts[i])
        assert info["fused_robots"] == len(state.fused[i])
    info = infos["robot_0"]
    assert info["merge_accepted"] == (len(state.fused[0]) > 1) == info["merge_errors_valid"]
    assert info["merges"] == state.merges == sum(p.calls for p in state.pairs.values())
    assert info["merge_drops"] == state.drops == sum(p.drops for p in state.pairs.values())
    assert MERGE_METHODS[info["merge_method"]] == state.method == state.pairs[(0, 1)].method
    assert MERGE_SOURCES[info["merge_source"]] == state.source == state.pairs[(0, 1)].source
    if 1 in state.frames[0]:
        assert state.transform.allclose(state.frames[0][1])
    else:
        assert state.transform is None


@pytest.mark.parametrize(("method", "reach", "seed"), [
    ("hybrid", 5.0, 2), ("hybrid", None, 5), ("known", 5.0, 2)])
def test_merges_only_in_contact_and_the_state_agrees_with_the_infos(method, reach, seed):
    # every merge accepted (thresholds 0), so that transforms come and go in 150 steps
    mapping = {**TEAM["mapping"], "merge_method": method, "accept_threshold": 0.0,
               "team_accept_threshold": 0.0}
    env = multi_robot_explore_v0.parallel_env(n_robots=3, comm={"range": reach},
                                              **{**TEAM, "mapping": mapping})
    env.reset(seed=seed)
    calls = dict.fromkeys(env.merge_state().pairs, 0)
    seen = set()
    for _, infos, state in _walk(env, 150, seed):
        _check_state(env, infos, state)
        seen.add((state.contacts, state.fused))
        for (i, j), pair in state.pairs.items():
            if pair.calls > calls[(i, j)]:
                assert j in state.contacts[i], (i, j, env.steps)  # merged only in contact
                assert env.steps % TEAM["mapping"]["merge_every"] == 0
            calls[(i, j)] = pair.calls
    # the episode shows something: contacts made and lost, robots fused
    assert reach is None or len({c for c, _ in seen}) > 1
    assert any(len(members) > 1 for _, fused in seen for members in fused)
    assert (state.merges > 0) == (method == "hybrid")  # known poses: nothing is merged


def test_a_pair_far_apart_is_never_merged(tmp_path):
    """Robots 0 and 1 turn on the spot side by side; robot 2, 7.5 m down the corridor, is out
    of range: only pair (0, 1) is merged; with no range limit every pair is."""
    xy = [(1.0, 1.0), (2.5, 1.0), (10.0, 1.0)]
    turn = {"robot_0": np.array([0.0, 0.5]), "robot_1": np.array([0.0, -0.5]),
            "robot_2": np.array([0.0, 0.5])}
    for reach, merged in ((2.0, {(0, 1)}), (None, {(0, 1), (0, 2), (1, 2)})):
        env, _ = placed_team(tmp_path, xy, [0.0, math.pi, 0.0], comm={"range": reach},
                             mapping=TEAM["mapping"])
        for _ in range(60):
            env.step(turn)
        assert {p for p, s in env.merge_state().pairs.items() if s.calls} == merged


def test_known_poses_put_the_true_transform_in_use_from_the_first_step():
    par = two_robot_explore_v0.parallel_env(mapping={"merge_method": "known"}, **SMALL)
    _, infos = par.reset(seed=2)
    assert not infos["robot_0"]["merge_accepted"] and par.merge_state().transform is None
    for _ in range(3):
        _, _, _, _, infos = par.step({a: np.array([0.6, 0.3]) for a in par.agents})
        state = par.merge_state()
        info = infos["robot_0"]
        assert state.transform.allclose(par.true_transform(0, 1))
        assert state.merges == 0 and state.last is None and math.isnan(state.time_s)
        assert state.method == state.source == "known"
        assert info["merge_accepted"] and info["merge_rotation_error_deg"] == 0.0
        assert info["merge_translation_error_m"] == pytest.approx(0.0, abs=1e-9)
        assert MERGE_SOURCES[info["merge_source"]] == "known"


def test_no_merging_never_merges():
    env = multi_robot_explore_v0.parallel_env(n_robots=3, mapping={
        **TEAM["mapping"], "merge_method": "none"}, **{k: v for k, v in TEAM.items()
                                                        if k != "mapping"})
    env.reset(seed=1)
    for obs, infos, state in _walk(env, 60, 1):
        assert state.merges == 0 and state.fused == ((0,), (1,), (2,))
        assert infos["robot_0"]["merge_method"] == infos["robot_0"]["merge_source"] == 0
        for a in env.possible_agents:
            np.testing.assert_array_equal(obs[a]["teammates"][:, :5], 0.0)


def test_known_poses_fuse_a_teammate_met_later(tmp_path):
    env, _ = placed_team(tmp_path, [(1.0, 1.0), (2.5, 1.0), (10.0, 1.0)], [0.0, 0.0, math.pi],
                         comm={"range": 2.0}, mapping={"merge_method": "known"})
    still = np.zeros(2, dtype=np.float32)
    for _ in range(100):  # robot 2 comes into range of robot 1 at about step 80
        env.step({"robot_0": still, "robot_1": still, "robot_2": np.array([1.0, 0.0])})
    state = env.merge_state()
    assert state.contacts == ((1, 2), (0, 2), (0, 1))
    assert state.fused == ((0, 1, 2),) * 3
