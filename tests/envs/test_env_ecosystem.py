"""The env as RL libraries use it: PettingZoo's seed tests, small comparable infos, map snapshots,
pickle and deepcopy (a restored env continues exactly), the global state."""

import copy
import dataclasses
import json
import math
import pickle
import warnings

import numpy as np
import pytest
from conftest import SMALL
from gymnasium import spaces
from pettingzoo.test import parallel_seed_test, seed_test

from envs import two_robot_explore_v0
from envs.explore.env import (
    MERGE_METHODS,
    MERGE_SOURCES,
    STATE_MAP_SIZE,
    STATE_SCALARS,
)


def test_pettingzoo_seed_tests():
    parallel_seed_test(lambda: two_robot_explore_v0.parallel_env(**SMALL))
    seed_test(lambda: two_robot_explore_v0.env(**{**SMALL, "max_cycles": 120}), num_cycles=120)


def _scripted_merges(monkeypatch, env_ref):
    """Make every grid alignment return the true transform, accepted: a merge within the first
    grid alignment (``env_ref[0]``: the env whose truth is used)."""
    import fusion.grid_merge as gm

    real = gm.merge_grids

    def truth(grid_a, grid_b, config=None):
        res = real(grid_a, grid_b, config)
        return dataclasses.replace(res, transform=env_ref[0].true_merge, accepted=True,
                                   reason=None)

    monkeypatch.setattr(gm, "merge_grids", truth)


MERGING = {"mapping": {"merge_every": 5, "grid_merge_every": 10, "topo_every": 5}}


def _drive(env, rng):
    return {a: np.array([0.8, rng.uniform(-0.6, 0.6)], dtype=np.float32)
            for a in env.possible_agents}


def test_infos_are_small_numeric_comparable_and_nan_free(monkeypatch):
    env = two_robot_explore_v0.parallel_env(max_cycles=60, **MERGING)  # default 20 m world
    _scripted_merges(monkeypatch, [env])
    rng = np.random.default_rng(0)
    _, infos = env.reset(seed=1)
    seen_merged = False
    while env.agents:
        assert len(pickle.dumps(infos)) <= 10_000
        for info in infos.values():
            for key, value in info.items():
                if isinstance(value, np.ndarray):
                    assert value.dtype.kind == "f" and value.size <= 3, key
                    assert np.isfinite(value).all(), key
                else:
                    assert type(value) in (bool, int, float), (key, type(value))
                    assert not (isinstance(value, float) and math.isnan(value)), key
        info = infos["robot_0"]
        assert info["merge_errors_valid"] == info["merge_accepted"]
        if not info["merge_accepted"]:
            assert info["merge_rotation_error_deg"] == 0.0 == info["merge_translation_error_m"]
            assert info["merge_method"] == 0 == info["merge_source"]
        else:
            seen_merged = True
            assert MERGE_METHODS[info["merge_method"]] == "hybrid"
            # the scripted grid alignment supplies it, unless the structural merge came first
            assert MERGE_SOURCES[info["merge_source"]] in ("structural", "grid")
            assert MERGE_SOURCES[info["merge_source"]] == env.merge_state().source
            assert info["merge_rotation_error_deg"] == pytest.approx(0.0, abs=1e-6)
        _, _, _, _, infos = env.step(_drive(env, rng))
    assert seen_merged, "the scripted merge was never accepted"
    assert math.isfinite(env.merge_state().time_s)  # the wall time lives in merge_state()


def test_robot_map_is_a_read_only_snapshot_later_steps_do_not_change():
    env = two_robot_explore_v0.parallel_env(**SMALL)
    with pytest.raises(RuntimeError, match=r"call reset\(\)"):
        env.robot_map("robot_0")
    env.reset(seed=2)
    with pytest.raises(ValueError, match=r"agent must be one of \['robot_0', 'robot_1'\], got 'robot_2'"):
        env.robot_map("robot_2")
    snap = env.robot_map("robot_0")
    assert env.robot_map("robot_0") is snap  # one copy per step
    before = snap.grid.log_odds.copy()
    assert snap.step == 0 and snap.known_cells == env.maps[0].n_ever > 0
    with pytest.raises(ValueError, match="read-only"):
        snap.grid.log_odds[0, 0] = 1.0
    with pytest.raises(ValueError, match="read-only"):
        snap.odometry[0] = 1.0
    rng = np.random.default_rng(2)
    for _ in range(20):
        env.step(_drive(env, rng))
    np.testing.assert_array_equal(snap.grid.log_odds, before)
    now = env.robot_map("robot_0")
    assert now is not snap and now.step == 20
    np.testing.assert_array_equal(now.grid.log_odds, env.maps[0].grid.log_odds)
    np.testing.assert_array_equal(now.grid.states(), env.maps[0].grid.states())
    assert now.topomap is env.maps[0].topomap and not np.array_equal(now.grid.log_odds, before)


def _trace(env, actions):
    """What ``env`` returns for each of ``actions`` (stopping at the episode end), as bytes."""
    out = []
    for act in actions:
        if not env.agents:
            break
        obs, rewards, terms, truncs, infos = env.step(act)
        row = [repr((sorted(rewards.items()), sorted(terms.items()), sorted(truncs.items())))]
        for a in sorted(obs):
            row += [obs[a][k].tobytes() for k in sorted(obs[a])]
            row.append(repr([(k, v.tobytes() if isinstance(v, np.ndarray) else v)
                             for k, v in sorted(infos[a].items())]))
        row.append(env.state().tobytes())
        out.append(row)
    return out


@pytest.mark.parametrize("how", ["pickle", "deepcopy"])
def test_a_restored_env_continues_exactly_as_the_original_across_a_merge(monkeypatch, how):
    env = two_robot_explore_v0.parallel_env(**{**SMALL, "max_cycles": 300}, **MERGING)
    ref = [env]
    _scripted_merges(monkeypatch, ref)
    rng = np.random.default_rng(7)
    actions = [_drive(env, rng) for _ in range(140)]
    env.reset(seed=7)
    for act in actions[:6]:
        env.step(act)
    assert env.merge_state().transform is None

    def restore(e):
        return pickle.loads(pickle.dumps(e)) if how == "pickle" else copy.deepcopy(e)

    restored = restore(env)
    assert restored is not env and restored.maps[0].grid is not env.maps[0].grid
    original = _trace(env, actions[6:120])
    again = _trace(restored, actions[6:120])
    assert len(original) == len(again) == 114
    for k, (x, y) in enumerate(zip(original, again, strict=True)):
        assert x == y, f"the restored env diverges {k} steps after the copy"
    assert env.merge_state().transform is not None, "no merge happened after the copy"
    assert restored.merge_state().merges == env.merge_state().merges
    assert restored.robots[0].collisions == env.robots[0].collisions
    # a copy taken with the merge in use replays it
    late = restore(env)
    assert late.merge_state().transform.allclose(env.merge_state().transform)
    assert _trace(late, actions[120:]) == _trace(env, actions[120:])


def test_pickle_before_reset_and_with_a_render_window():
    fresh = two_robot_explore_v0.parallel_env(render_mode="rgb_array", **SMALL)
    twin = pickle.loads(pickle.dumps(fresh))
    a, _ = fresh.reset(seed=4)
    b, _ = twin.reset(seed=4)
    for agent in a:
        for key in a[agent]:
            np.testing.assert_array_equal(a[agent][key], b[agent][key])
    fresh.render()  # the renderer (pygame surfaces) is left behind by copies
    copied = copy.deepcopy(fresh)
    assert copied._renderer is None and copied.render().shape == fresh.render().shape
    fresh.close()
    copied.close()


def test_a_copy_after_the_episode_end_is_ended_and_resets_as_the_original():
    env = two_robot_explore_v0.parallel_env(**{**SMALL, "max_cycles": 30})
    env.reset(seed=5)
    rng = np.random.default_rng(5)
    while env.agents:
        env.step(_drive(env, rng))
    data = pickle.dumps(env)
    assert len(data) < 20_000  # config, commands, generator states: no maps, no physics
    restored = pickle.loads(data)
    assert restored.agents == [] and restored.steps == 30
    with pytest.raises(RuntimeError, match="after the episode ended"):
        restored.step(_drive(env, rng))
    # the generator continues where the original's is: the next unseeded episode is the same
    a, _ = env.reset()
    b, _ = restored.reset()
    for agent in a:
        for key in a[agent]:
            np.testing.assert_array_equal(a[agent][key], b[agent][key])


def test_a_copy_replays_start_poses_and_max_cycles_changes_without_warnings():
    env = two_robot_explore_v0.parallel_env(**SMALL)
    env.reset(seed=6)
    starts = np.array([r.true_pose() for r in env.robots]) + [[0.0, 0.0, 0.5], [0.0, 0.0, -0.5]]
    with pytest.warns(UserWarning, match=r"reset options \['speed'\] are not used"):
        env.reset(seed=6, options={"start_poses": starts, "speed": 1})
    rng = np.random.default_rng(6)
    for _ in range(5):
        env.step(_drive(env, rng))
    env.max_cycles = 3  # the next step truncates
    twin = copy.deepcopy(env)
    _, _, _, truncs, _ = env.step(_drive(env, rng))
    assert all(truncs.values()) and env.agents == []
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the restored env shows no warning again
        restored = pickle.loads(pickle.dumps(env))
    assert restored.steps == 6 and restored.agents == [] and restored.max_cycles == 3
    for r1, r2 in zip(env.robots, restored.robots, strict=True):
        assert r1.true_pose().tobytes() == r2.true_pose().tobytes()
    np.testing.assert_array_equal(restored.robots[0].start, starts[0])
    assert twin.max_cycles == 3 and twin.agents == list(env.possible_agents)
    _, _, _, truncs, _ = twin.step({a: np.array([0.1, 0.0]) for a in twin.agents})
    assert all(truncs.values())


def test_a_copy_keeps_the_loaded_world_file(tmp_path):
    path = tmp_path / "house.json"
    verts = [[0, 0], [8, 0], [8, 3], [3, 3], [3, 6], [0, 6]]
    path.write_text(json.dumps({"id": "x", "verts": verts, "bbox": {}}))
    env = two_robot_explore_v0.parallel_env(world={"source": str(path)}, max_cycles=50,
                                            mapping={"merge_every": 0})
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(10):
        env.step(_drive(env, rng))
    data = pickle.dumps(env)
    path.unlink()  # a copy does not read the file again
    restored = pickle.loads(data)
    assert restored.world.name == env.world.name
    act = _drive(env, rng)
    assert _trace(restored, [act]) == _trace(env, [act])


def test_a_copy_of_an_env_changed_from_outside_is_refused():
    env = two_robot_explore_v0.parallel_env(**SMALL)
    env.reset(seed=8)
    rng = np.random.default_rng(8)
    for _ in range(5):
        env.step(_drive(env, rng))
    env.robots[0].body.position += (0.01, 0.0)  # not something step() or reset() did
    with pytest.raises(RuntimeError, match="does not reproduce the original"):
        copy.deepcopy(env)


def test_the_aec_env_copies():
    aec = two_robot_explore_v0.env(**SMALL)
    aec.reset(seed=9)
    for _ in range(8):
        aec.step(np.array([0.7, 0.2], dtype=np.float32))
    twin = copy.deepcopy(aec)
    for _ in range(8):
        agent = aec.agent_selection
        assert twin.agent_selection == agent
        np.testing.assert_array_equal(twin.observe(agent)["sonar"], aec.observe(agent)["sonar"])
        aec.step(np.array([0.5, -0.3], dtype=np.float32))
        twin.step(np.array([0.5, -0.3], dtype=np.float32))
    assert np.array_equal(twin.state(), aec.state())


def test_state_is_a_global_view_in_its_space(monkeypatch):
    env = two_robot_explore_v0.parallel_env(**SMALL, **MERGING)
    _scripted_merges(monkeypatch, [env])
    space = env.state_space
    n = STATE_MAP_SIZE ** 2
    assert isinstance(space, spaces.Box) and space.shape == (STATE_SCALARS + 3 * n,)
    with pytest.raises(RuntimeError, match=r"call reset\(\)"):
        env.state()
    env.reset(seed=3)
    rng = np.random.default_rng(3)
    for _ in range(40):
        env.step(_drive(env, rng))
    assert env.merge_state().transform is not None
    state = env.state()
    assert state.dtype == np.float32 and space.contains(state)
    x0, y0, x1, y1 = env.world.extent
    for i, robot in enumerate(env.robots):
        x, y, th = robot.true_pose()
        np.testing.assert_allclose(state[4 * i: 4 * i + 4], [(x - x0) / (x1 - x0), (y - y0) / (
            y1 - y0), math.cos(th), math.sin(th)], atol=1e-6)
    np.testing.assert_allclose(state[8:12], [env.oracle.fraction, env.oracle.overlap, 1.0,
                                             40 / SMALL["max_cycles"]], atol=1e-6)
    # each map block is the share of its area that is swept / in the shared map / reachable
    block = (x1 - x0) * (y1 - y0) / n
    swept, shared, reach = (state[STATE_SCALARS + k * n: STATE_SCALARS + (k + 1) * n]
                            for k in range(3))
    assert swept.sum() * block == pytest.approx(env.oracle.area, rel=0.1)
    assert reach.sum() * block == pytest.approx(env.world.reachable_area, rel=0.1)
    # the true merge puts the shared map where the robots swept (up to phantom space)
    assert shared.sum() * block == pytest.approx(env.shared.area, rel=0.15)
    assert (shared[swept > 0.5] > 0).mean() > 0.9
    aec = two_robot_explore_v0.env(**SMALL)
    aec.reset(seed=3)
    assert aec.state_space == space and aec.state().shape == space.shape


def test_copies_taken_in_contact_continue_exactly():
    """Copies taken while a robot presses into a wall (bias velocities, joint impulses and
    contacts carried over) and elsewhere, each checked for 30 steps against the original."""
    env = two_robot_explore_v0.parallel_env(world={"size": (8.0, 8.0)}, max_cycles=400,
                                            mapping={"merge_every": 0, "topo_every": 0})
    rng = np.random.default_rng(0)
    actions = [{a: rng.uniform(-1, 1, 2).astype(np.float32) for a in env.possible_agents}
               for _ in range(400)]
    env.reset(seed=0)
    copies, in_contact = [], 0
    for k, act in enumerate(actions):
        if k % 10 == 5:
            touching = []
            for robot in env.robots:
                robot.body.each_arbiter(touching.append)
            in_contact += bool(touching)
            copies.append((k, pickle.loads(pickle.dumps(env)) if k % 20 == 5
                           else copy.deepcopy(env)))
        env.step(act)
        for start, twin in list(copies):
            twin.step(act)
            for r1, r2 in zip(env.robots, twin.robots, strict=True):
                assert np.array_equal(r1.true_pose(), r2.true_pose()), (
                    f"the copy taken at step {start} diverges at step {k}")
                assert r1.collisions == r2.collisions
            if k - start >= 30:
                copies.remove((start, twin))
    assert in_contact >= 3, "too few copies were taken in contact to test them"
