"""Behaviour over many steps: determinism, rewards, maps and frames, episode end."""

import dataclasses
import hashlib
import math

import numpy as np
import pytest
from conftest import SMALL

from envs import two_robot_explore_v0
from envs.explore.env import MERGE_METHODS
from envs.explore.mapping import compose_pose


def _flatten(par, obs, rewards, terms, truncs, infos):
    """Everything a step returns, as comparable bytes and reprs, and both robots' maps."""
    out = []
    for agent in sorted(obs):
        out += [obs[agent][k].tobytes() for k in sorted(obs[agent])]
    for d in (rewards, terms, truncs):
        out.append(repr(sorted(d.items())))
    for agent in sorted(infos):
        info = infos[agent]
        out.append(repr([(k, info[k]) for k in sorted(info) if not isinstance(info[k], np.ndarray)]))
        out += [info[k].tobytes() for k in sorted(info) if isinstance(info[k], np.ndarray)]
    for agent in par.possible_agents:
        snap = par.robot_map(agent)
        out += [snap.topomap.xy.tobytes(), hashlib.sha1(snap.grid.log_odds.tobytes()).digest()]
    return out


def _episode(seed, steps, **kw):
    """A seeded episode of ``steps`` steps: its trace (:func:`_flatten` of every step), the
    env, and the last step's observations and infos."""
    par = two_robot_explore_v0.parallel_env(**{**SMALL, "max_cycles": steps, **kw})
    rng = np.random.default_rng(seed + 100)
    obs, infos = par.reset(seed=seed)
    trace = [_flatten(par, obs, {}, {}, {}, infos)]
    while par.agents:
        act = {a: rng.uniform(-1, 1, 2) for a in par.agents}
        # change course only every 5 steps so the robots get somewhere
        if len(trace) % 5:
            act = {a: np.array([0.8, 0.1]) for a in par.agents}
        obs, rewards, terms, truncs, infos = par.step(act)
        trace.append(_flatten(par, obs, rewards, terms, truncs, infos))
    return trace, par, (obs, infos)


def test_same_seed_same_episode_for_520_steps():
    noise = {"robot": {"odometry_noise": (0.05, 0.05)}, "sonar": {"measure_every": 0.05}}
    a, *_ = _episode(11, 520, **noise)
    b, *_ = _episode(11, 520, **noise)
    assert len(a) == len(b) == 521
    for k, (x, y) in enumerate(zip(a, b, strict=True)):
        assert x == y, f"episodes diverge at step {k}"


def test_other_seed_other_episode():
    a, *_ = _episode(1, 5)
    b, *_ = _episode(2, 5)
    assert a[0] != b[0]


def test_reward_is_the_documented_formula():
    par = two_robot_explore_v0.parallel_env(**SMALL)
    _, infos = par.reset(seed=5)
    rng = np.random.default_rng(5)
    cfg = par.config
    for _ in range(60):
        prev_area = infos["robot_0"]["shared_area_m2"]
        prev_coll = infos["robot_0"]["collisions"] + infos["robot_1"]["collisions"]
        _, rewards, _, _, infos = par.step({a: rng.uniform(-1, 1, 2) for a in par.agents})
        coll = infos["robot_0"]["collisions"] + infos["robot_1"]["collisions"]
        expected = (cfg.coverage_reward * (infos["robot_0"]["shared_area_m2"] - prev_area)
                    - cfg.collision_penalty * (coll - prev_coll) - cfg.time_penalty)
        assert rewards["robot_0"] == pytest.approx(expected, abs=1e-9)
        assert rewards["robot_1"] == rewards["robot_0"]


def test_individual_rewards_are_per_robot():
    par = two_robot_explore_v0.parallel_env(reward_mode="individual", **SMALL)
    _, infos = par.reset(seed=6)
    for _ in range(20):
        prev = {a: infos[a]["own_area_m2"] for a in infos}
        _, rewards, _, _, infos = par.step({"robot_0": [1.0, 0.3], "robot_1": [0.0, 0.0]})
        for a in rewards:
            assert rewards[a] == pytest.approx(
                0.1 * (infos[a]["own_area_m2"] - prev[a]) - 0.01, abs=0.5 + 1e-9)
    assert rewards["robot_1"] == pytest.approx(-0.01)  # stands still, sees nothing new


def test_oracle_reward_counts_true_new_area():
    par = two_robot_explore_v0.parallel_env(reward_mode="oracle", **SMALL)
    _, infos = par.reset(seed=6)
    start_area = infos["robot_0"]["true_area_m2"]
    start_coll = infos["robot_0"]["collisions"] + infos["robot_1"]["collisions"]
    total = 0.0
    for _ in range(30):
        _, rewards, _, _, infos = par.step({"robot_0": [1.0, 0.3], "robot_1": [1.0, -0.3]})
        total += rewards["robot_0"] + 0.01
    coll = infos["robot_0"]["collisions"] + infos["robot_1"]["collisions"] - start_coll
    gained = infos["robot_0"]["true_area_m2"] - start_area
    assert gained > 1.0
    assert total == pytest.approx(0.1 * gained - 0.5 * coll, abs=1e-9)


def test_windowed_bookkeeping_matches_the_whole_grid():
    _, par, _ = _episode(4, 120)
    for rmap in par.maps:
        known = rmap.grid.known_mask()
        # every cell the grid knows now was caught by the per-step windows
        assert not (known & ~rmap.ever).any()
        assert rmap.n_ever == int(rmap.ever.sum()) > 0
        r0, r1, c0, c1 = rmap.bbox
        inside = np.zeros_like(rmap.ever)
        inside[r0:r1, c0:c1] = True
        assert not (rmap.ever & ~inside).any()
        assert rmap.ever[r0].any() and rmap.ever[r1 - 1].any()
        assert rmap.ever[:, c0].any() and rmap.ever[:, c1 - 1].any()


def test_true_merge_makes_shared_map_match_the_oracle_and_teammate_exact():
    # without dropouts (a "no echo" belief clears space through walls) and odometry noise, the
    # robots' maps hold what the sonars truly swept: with the true transform in use (known
    # poses) the shared map covers what the oracle counts, up to the range noise and
    # nearest-cell resampling
    _, par, (obs, infos) = _episode(8, 150, sonar={"dropout_prob": 0.0},
                                    mapping={"merge_method": "known"})
    info = infos["robot_0"]
    assert par.merge_state().transform.allclose(par.true_transform(0, 1))
    assert info["merge_accepted"] and info["merge_errors_valid"]
    assert info["shared_area_m2"] == pytest.approx(info["true_area_m2"], rel=0.05)
    truth = np.array([infos[a]["pose"] for a in ("robot_0", "robot_1")])
    dx, dy = truth[1, :2] - truth[0, :2]
    c, s = math.cos(truth[0, 2]), math.sin(truth[0, 2])
    np.testing.assert_allclose(obs["robot_0"]["teammate"][:2],
                               [c * dx + s * dy, -s * dx + c * dy], atol=1e-4)
    dth = truth[1, 2] - truth[0, 2]
    np.testing.assert_allclose(obs["robot_0"]["teammate"][2:],
                               [math.cos(dth), math.sin(dth), 1.0], atol=1e-5)
    # robot 1's pose moved into robot 0's frame is robot 1's true pose seen from robot 0's start
    moved = compose_pose(par.merge_state().transform, infos["robot_1"]["odometry"])
    start0 = par.robots[0].start
    c0, s0 = math.cos(start0[2]), math.sin(start0[2])
    d = truth[1, :2] - start0[:2]
    np.testing.assert_allclose(moved[:2], [c0 * d[0] + s0 * d[1], -s0 * d[0] + c0 * d[1]],
                               atol=1e-6)
    rot_err, trans_err = par.merge_errors()
    assert rot_err == pytest.approx(0.0, abs=1e-9)
    assert trans_err == pytest.approx(0.0, abs=1e-9)
    assert info["merge_rotation_error_deg"] == pytest.approx(0.0, abs=1e-9)
    assert info["merge_translation_error_m"] == pytest.approx(0.0, abs=1e-9)


def test_local_map_is_egocentric_and_heading_up():
    par = two_robot_explore_v0.parallel_env(**SMALL)
    obs, _ = par.reset(seed=9)
    img = obs["robot_0"]["local_map"][0]
    size = img.shape[0]
    # the robot stands on free space it has just seen (the centre), unknown behind it
    centre = img[size // 2 - 2:size // 2 + 2, size // 2 - 2:size // 2 + 2]
    assert (centre != 0).all()
    sonar = par.sonars[0]
    ahead = img[: size // 2 - 4, size // 2 - 3: size // 2 + 3]  # straight ahead: ±10° sonars
    behind = img[size // 2 + 8:, :]
    assert (ahead == 255).mean() > (behind == 255).mean()
    assert (behind == 128).mean() > 0.9
    assert sonar.fresh


def test_coverage_target_terminates_both_robots():
    par = two_robot_explore_v0.parallel_env(**{**SMALL, "target_coverage": 0.02})
    par.reset(seed=0)
    _, _, term, trunc, infos = par.step({a: np.array([0.5, 0.0]) for a in par.agents})
    assert term == {"robot_0": True, "robot_1": True}
    assert trunc == {"robot_0": False, "robot_1": False}
    assert infos["robot_0"]["true_coverage"] >= 0.02
    assert par.agents == []


def test_true_coverage_ignores_echoes_lost_through_walls():
    # same seed, same actions: dropouts change only the readings, never the motion
    runs = []
    for drop in (0.0, 1.0):
        par = two_robot_explore_v0.parallel_env(
            **{**SMALL, "max_cycles": 60},
            sonar={"dropout_prob": drop, "dropout_incidence": 0.0},
            mapping={"topo_every": 0, "merge_every": 0})
        par.reset(seed=12)
        k = 0
        while par.agents:
            par.step({"robot_0": [0.7, math.sin(k / 9)], "robot_1": [0.6, -0.4]})
            k += 1
        runs.append(par)
    clean, lossy = runs
    np.testing.assert_array_equal(clean.oracle.union, lossy.oracle.union)
    # the robots themselves believe they see far beyond the walls when every echo is lost
    assert lossy.maps[0].n_ever > 1.5 * clean.maps[0].n_ever
    assert 0 < clean.oracle.fraction < 1


@pytest.mark.parametrize(("growth", "expect_retries"), [(0.0, True), (10.0, False)])
def test_rejected_grid_alignment_waits_for_the_maps_to_grow(monkeypatch, growth,
                                                            expect_retries):
    import fusion.grid_merge as gm

    calls = []
    real = gm.merge_grids

    def refusing(grid_a, grid_b, config=None):
        calls.append(int(grid_a.known_mask().sum() + grid_b.known_mask().sum()))
        return dataclasses.replace(real(grid_a, grid_b, config), accepted=False, reason="test")

    monkeypatch.setattr(gm, "merge_grids", refusing)
    _episode(3, 200, mapping={"merge_every": 5, "grid_merge_every": 10,
                              "grid_merge_growth": growth})
    assert calls, "the grid alignment never ran"
    if expect_retries:
        assert len(calls) >= 5  # on schedule: every 10 steps while the maps are non-empty
    else:
        assert len(calls) == 1  # the maps never grow 11-fold in 200 steps


def test_grids_keep_checking_a_merge_and_drop_one_they_refute(monkeypatch):
    """Once merged, the grid alignment keeps running: its accepted alignment replaces the
    transform in use, and a rejected one far from it that the grids support better drops it
    (robot 0's map alone again)."""
    import fusion.grid_merge as gm
    from fusion import Rigid2D

    par = two_robot_explore_v0.parallel_env(
        **{**SMALL, "max_cycles": 400},
        mapping={"merge_every": 5, "grid_merge_every": 10, "grid_merge_growth": 0.0})
    real = gm.merge_grids
    calls = []

    def scripted(grid_a, grid_b, config=None):
        # 1st: a wrong transform, accepted; 2nd: it turned 2°, accepted; then: the truth,
        # rejected (the grids support it better than the wrong one in use)
        res = real(grid_a, grid_b, config)
        n = len(calls)
        calls.append(n)
        truth = par.true_transform(0, 1)
        wrong = Rigid2D.from_degrees(90.0, (5.0, 0.0)) @ truth
        transform = [wrong, Rigid2D.from_degrees(2.0) @ wrong][n] if n < 2 else truth
        return dataclasses.replace(res, transform=transform, accepted=n < 2,
                                   reason=None if n < 2 else "test", centre=(0.0, 0.0))

    monkeypatch.setattr(gm, "merge_grids", scripted)
    par.reset(seed=3)
    seen = []
    while par.agents and len(calls) < 4:
        obs, rewards, _, _, infos = par.step({a: np.array([0.8, 0.3]) for a in par.agents})
        state = par.merge_state()
        seen.append((len(calls), state.transform, infos["robot_0"], rewards["robot_0"], state))
    assert len(calls) == 4, "the grid alignment did not keep running after the merge"
    in_use = {n: t for n, t, *_ in seen}
    truth = par.true_transform(0, 1)
    assert math.degrees(in_use[1].rotation_error(truth)) == pytest.approx(90.0)
    assert math.degrees(in_use[2].rotation_error(in_use[1])) == pytest.approx(2.0)
    # the third alignment is rejected and 92° / 8 m away: the merge is dropped
    assert in_use[3] is None and seen[-1][1] is None
    info, reward, state = next((i, r, m) for n, _, i, r, m in seen if n == 3)
    assert info["merge_drops"] == 1 and not info["merge_accepted"]
    assert not info["merge_errors_valid"] and info["merge_method"] == 0
    assert reward < 0  # robot 1's cells left the shared map at that step
    assert "the grids refute the transform in use" in state.last.reason
    assert state.transform is None and state.drops == 1 and state.method == "none"
    merged = next(i for n, _, i, _, _ in seen if n == 2)
    assert merged["merge_errors_valid"] and merged["merge_rotation_error_deg"] == pytest.approx(92.0)
    assert MERGE_METHODS[merged["merge_method"]] == "hybrid"
    # robot 1's cells left the shared map, and robot 0 no longer sees where robot 1 is
    assert infos["robot_0"]["shared_area_m2"] == infos["robot_0"]["own_area_m2"]
    assert obs["robot_0"]["teammate"][4] == 0.0


def test_the_accept_threshold_reaches_the_grid_alignment(monkeypatch):
    """``mapping.accept_threshold`` is the threshold the env's merges are decided with, and
    its default is the library's."""
    import fusion.grid_merge as gm
    from envs.explore.config import MappingConfig

    assert MappingConfig().accept_threshold == gm.DEFAULT_ACCEPT_THRESHOLD
    seen = []
    real = gm.merge_grids

    def watched(grid_a, grid_b, config=None):
        seen.append(config.accept_threshold)
        out = real(grid_a, grid_b, config)
        assert out.accepted == (out.confidence >= config.accept_threshold
                                and out.overlap_m2 >= config.min_overlap_m2)
        return out

    monkeypatch.setattr(gm, "merge_grids", watched)
    _episode(3, 60, mapping={"merge_every": 5, "grid_merge_every": 10,
                             "grid_merge_growth": 0.0, "accept_threshold": 0.42})
    assert seen and set(seen) == {0.42}
