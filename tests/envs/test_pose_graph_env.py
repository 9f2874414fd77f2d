"""The env with ``mapping.pose_graph`` (experimental, issue 41): a Pioneer-preset episode
runs, is deterministic, copies and pickles as the env promises; anchors start on schedule."""

from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest

from envs import two_robot_explore_v0

pytest.importorskip("gtsam")

STEPS = 300
PIONEER = {"odometry_model": "rot_trans_rot", "odometry_alphas": "pioneer3dx"}


def _env():
    return two_robot_explore_v0.parallel_env(robot=PIONEER, mapping={"pose_graph": True},
                                             max_cycles=1000)


def _actions(n: int, seed: int = 0) -> list[dict]:
    rng = np.random.default_rng(seed)
    return [{a: rng.uniform(-1, 1, 2).astype(np.float32) for a in ("robot_0", "robot_1")}
            for _ in range(n)]


def _flat(infos: dict) -> list:
    return [(a, k, np.asarray(v).tolist()) for a, d in sorted(infos.items())
            for k, v in sorted(d.items())]


def _run(env, actions) -> list:
    out = []
    for act in actions:
        _, rewards, _, _, infos = env.step(act)
        out.append((_flat(infos), sorted(rewards.items())))
    return out


@pytest.fixture(scope="module")
def stepped():
    env = _env()
    env.reset(seed=4)
    trace = _run(env, _actions(STEPS))
    return env, trace


def test_an_episode_runs_and_anchors_start_on_schedule(stepped):
    env, trace = stepped
    graph = env._graph
    assert [len(s.poses) for s in graph.submaps] == [STEPS // 100 + 1] * 2
    assert len(trace) == STEPS
    state = env.merge_state()
    assert {"fused_ate_m", "own_ate_m", "fused_wall_share", "own_wall_share",
            "links_kept", "loops_kept", "loops_kept_wrong"} <= set(state.bending)
    assert all(np.isfinite(v) or k.endswith("wall_share") for k, v in state.bending.items())


def test_same_seed_same_infos(stepped):
    _, trace = stepped
    env = _env()
    env.reset(seed=4)
    assert _run(env, _actions(STEPS)) == trace


def test_copies_and_pickles_step_alike(stepped):
    env = _env()
    env.reset(seed=4)
    _run(env, _actions(150))
    rest = _actions(STEPS - 150, seed=1)
    deep = copy.deepcopy(env)
    pickled = pickle.loads(pickle.dumps(env))
    want = _run(env, rest)
    assert _run(deep, rest) == want
    assert _run(pickled, rest) == want


def test_setting_off_builds_no_graph():
    env = two_robot_explore_v0.parallel_env(robot=PIONEER)
    env.reset(seed=4)
    assert env._graph is None
    assert env.merge_state().bending == {}
    _, _, _, _, infos = env.step(_actions(1)[0])
    assert "fused_ate_m" not in infos["robot_0"] and "fused_wall_share" not in infos["robot_1"]


def test_infos_carry_the_fused_maps_truth_as_of_the_last_merge_step(stepped):
    """``fused_ate_m`` / ``fused_wall_share`` (pose graph only): robot 0's fused map against
    the truth, what ``merge_state().bending`` says at a merge step, the same for every
    agent."""
    env, _ = stepped
    assert env.steps % env.config.mapping.merge_every == 0
    infos = env._infos()
    bending = env.merge_state().bending
    for agent in env.agents:
        assert infos[agent]["fused_ate_m"] == pytest.approx(bending["fused_ate_m"])
        assert infos[agent]["fused_wall_share"] == pytest.approx(bending["fused_wall_share"])
    assert 0.0 < infos["robot_0"]["fused_wall_share"] <= 1.0


@pytest.mark.parametrize("budget", [1, 2])
def test_each_robot_has_its_own_search_budget(budget):
    """``mapping.window_searches`` is each robot's per merge step: in a team of four in
    contact, every robot with a window searches, none more than its budget."""
    from collections import Counter

    from envs import multi_robot_explore_v0

    env = multi_robot_explore_v0.parallel_env(
        n_robots=4, robot=PIONEER, max_cycles=400, world={"size": (10.0, 10.0)},
        mapping={"pose_graph": True, "anchor_every": 10, "window_anchors": 2,
                 "merge_every": 5, "window_searches": budget})
    env.reset(seed=1)
    graph = env._graph
    calls: list[tuple[int, int]] = []
    align = graph._align
    graph._align = lambda i, ei, j, ej: calls.append((env.steps, i)) or align(i, ei, j, ej)
    rng = np.random.default_rng(0)
    for _ in range(120):
        env.step({a: rng.uniform(-1, 1, 2).astype(np.float32) for a in env.agents})
    per_step = Counter(calls)
    assert per_step and max(per_step.values()) <= budget
    assert {i for _, i in calls} == {0, 1, 2, 3}
    first = min(step for step, _ in calls)
    assert {i for step, i in calls if step == first} == {0, 1, 2, 3}


def test_a_robot_of_a_pair_searches_at_most_twice_a_merge_step():
    """At most one candidate of each kind (the teammate to join or the joined teammate's
    nearest window, and a loop closure): a budget above 2 changes nothing for two robots,
    as ``MappingConfig.window_searches`` says."""
    from collections import Counter

    def calls(budget: int) -> list[tuple[int, int, int, int, int]]:
        env = two_robot_explore_v0.parallel_env(
            robot=PIONEER, max_cycles=400, world={"size": (10.0, 10.0)},
            mapping={"pose_graph": True, "anchor_every": 10, "window_anchors": 2,
                     "merge_every": 5, "window_searches": budget})
        env.reset(seed=1)
        graph, out = env._graph, []
        align = graph._align
        graph._align = lambda i, ei, j, ej: out.append((env.steps, i, ei, j, ej)) or align(
            i, ei, j, ej)
        for act in _actions(150):
            env.step(act)
        return out

    two, five = calls(2), calls(5)
    assert max(Counter((step, i) for step, i, *_ in two).values()) == 2
    assert five == two


def test_a_loop_closure_straightens_the_working_map_and_leaves_fused_maps_alone():
    """``GraphMerging.straighten``: a loop closure that turns robot 0's older anchors moves
    them in its own grid (its working map) and keeps the newest anchor's cells where they
    were scanned; fused maps, made of the unchanged patches, do not move; the next closed
    patch holds only what its scans added (but where evidence saturates)."""
    from fusion import Rigid2D

    env = two_robot_explore_v0.parallel_env(
        robot=PIONEER, world={"size": (10.0, 10.0)}, max_cycles=400,
        mapping={"pose_graph": True, "anchor_every": 20, "merge_every": 5})
    env.reset(seed=1)
    for act in _actions(100, seed=1):
        env.step(act)
    graph, rmap = env._graph, env.maps[0]
    sub = graph.submaps[0]
    assert not graph.straighten(0, env.maps)  # no loop closure yet: left as scanned
    odo = sub.poses[4].inverse() @ sub.poses[0]
    assert graph.add_alignment(0, 4, 0, 0, odo @ Rigid2D.from_degrees(6.0), 1.0)
    fused = graph.fused_log_odds(0, env.maps, env.views)
    live = sub.live_patch(rmap.grid.log_odds)
    before = rmap.grid.states().copy()
    assert graph.straighten(0, env.maps)
    after = rmap.grid.states()
    assert np.count_nonzero(before != after) > 20  # the older anchors' cells moved
    moved_live = sub.live_patch(rmap.grid.log_odds)
    assert (moved_live.r0, moved_live.c0) == (live.r0, live.c0)
    assert moved_live.delta.shape == live.delta.shape
    differ = ~np.isclose(moved_live.delta, live.delta, atol=1e-5)
    h, w = live.delta.shape
    at = rmap.grid.log_odds[live.r0:live.r0 + h, live.c0:live.c0 + w]
    assert np.all(np.abs(at[differ]) >= rmap.grid.model.clamp - 1e-5)  # only where it clamps
    moved_fused = graph.fused_log_odds(0, env.maps, env.views)
    assert np.count_nonzero(~np.isclose(moved_fused, fused, atol=1e-5)) <= np.count_nonzero(differ)
    assert not graph.straighten(0, env.maps)  # nothing moved since: not drawn again
    closed = len(sub.patches)
    for act in _actions(25, seed=2):
        env.step(act)
    assert len(sub.patches) > closed
    delta = sub.patches[closed].delta  # the scans' change, no rounding residue of the rest
    assert delta.any() and not np.any((delta != 0) & (np.abs(delta) < 1e-3))
