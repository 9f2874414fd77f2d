"""PettingZoo's own test suite, the registry, spaces and bad input."""

import math

import numpy as np
import pettingzoo
import pytest
from conftest import SMALL
from pettingzoo.test import api_test, max_cycles_test, parallel_api_test, render_test

import envs
from envs import two_robot_explore_v0
from envs.explore import EnvConfig, TwoRobotExploreEnv


def test_parallel_api():
    parallel_api_test(two_robot_explore_v0.parallel_env(**SMALL), num_cycles=120)


def test_aec_api():
    api_test(two_robot_explore_v0.env(**SMALL), num_cycles=60)


def test_render_modes_headless():
    def make(render_mode=None):
        return two_robot_explore_v0.env(render_mode=render_mode, **SMALL)

    render_test(make)


def test_rgb_array_frame_shows_something():
    par = two_robot_explore_v0.parallel_env(render_mode="rgb_array", **SMALL)
    par.reset(seed=0)
    frame = par.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 5
    par.close()


class _LastMerge:
    """The env as the renderer reads it, with another last merge result (``merge``)."""

    def __init__(self, env, merge):
        self._env, self.merge = env, merge

    def __getattr__(self, name):
        return getattr(self._env, name)


def test_rgb_array_shows_robot_1_in_the_shared_panel_once_merged():
    """With a transform in use the shared panel draws robot 1's graph too, also when the last
    merge attempt (a re-examination) was rejected and kept the transform; only an accepted
    merge's own fused graph replaces the two graphs."""
    from types import SimpleNamespace

    from envs.explore.render import Renderer

    # known poses: robot 1's true transform is in use from the first step, no merge call
    par = two_robot_explore_v0.parallel_env(render_mode="rgb_array", mapping={
        "merge_method": "known"}, **{**SMALL, "max_cycles": 60})
    par.reset(seed=0)
    for _ in range(50):
        _, _, _, _, infos = par.step({a: np.array([0.8, 0.2]) for a in par.agents})
    assert infos["robot_0"]["merge_accepted"] and par.merge is None
    assert par.robot_map("robot_1").topomap.n_nodes
    both_graphs = par.render()
    own = par.robot_map("robot_0").topomap
    renderer = Renderer("rgb_array", par.metadata["render_fps"])
    own_graph = renderer.draw(_LastMerge(par, SimpleNamespace(accepted=True, merged=own)))
    kept = renderer.draw(_LastMerge(par, SimpleNamespace(accepted=False, merged=own)))
    assert both_graphs.shape == own_graph.shape and not np.array_equal(both_graphs, own_graph)
    np.testing.assert_array_equal(kept, both_graphs)
    renderer.close()
    par.close()


def test_max_cycles():
    max_cycles_test(two_robot_explore_v0)


def test_registry_makes_both_apis():
    assert "topomerge/two_robot_explore_v0" in envs.ENV_IDS
    par = pettingzoo.make("parallel", "topomerge/two_robot_explore_v0", **SMALL)
    assert isinstance(par, TwoRobotExploreEnv)
    assert par.max_cycles == SMALL["max_cycles"]
    aec = pettingzoo.make("aec", "topomerge/two_robot_explore_v0", max_cycles=7, **{
        k: v for k, v in SMALL.items() if k != "max_cycles"})
    assert isinstance(aec, pettingzoo.AECEnv)
    assert aec.unwrapped.max_cycles == 7


def test_spaces_hold_every_observation_and_robots_stay_in_free_space():
    par = two_robot_explore_v0.parallel_env(**{**SMALL, "max_cycles": 150})
    obs, _ = par.reset(seed=3)
    rng = np.random.default_rng(3)
    steps = 0
    while par.agents:
        for agent, o in obs.items():
            space = par.observation_space(agent)
            for key, sub in space.spaces.items():
                assert sub.contains(o[key]), (key, o[key])
        obs, *_ = par.step({a: rng.uniform(-1, 1, 2).astype(np.float32) for a in par.agents})
        poses = np.array([r.true_pose()[:2] for r in par.robots])
        assert par.world.is_free(poses).all()
        steps += 1
    assert steps == 150


def test_observation_and_action_spaces_are_the_same_objects():
    par = two_robot_explore_v0.parallel_env(**SMALL)
    assert par.observation_space("robot_0") is par.observation_space("robot_0")
    assert par.action_space("robot_1") is par.action_space("robot_1")
    assert par.observation_space("robot_0")["local_map"].shape == (1, 64, 64)
    with pytest.raises(ValueError, match="agent must be one of"):
        par.action_space("robot_9")


def test_discrete_actions():
    par = two_robot_explore_v0.parallel_env(action_type="discrete", **SMALL)
    par.reset(seed=0)
    start = par.robots[0].true_pose()
    for _ in range(5):
        par.step({"robot_0": 2, "robot_1": np.int64(0)})  # turn left in place; stand still
    pose = par.robots[0].true_pose()
    assert math.dist(pose[:2], start[:2]) < 1e-6
    assert pose[2] != pytest.approx(start[2])
    with pytest.raises(ValueError, match=r"action of robot_0 must be in \[0, 5\), got 7"):
        par.step({"robot_0": 7, "robot_1": 0})
    with pytest.raises(TypeError, match="action of robot_1 must be an int"):
        par.step({"robot_0": 0, "robot_1": 1.5})


def test_bad_actions_are_clear_errors():
    par = two_robot_explore_v0.parallel_env(**SMALL)
    par.reset(seed=0)
    ok = np.zeros(2)
    with pytest.raises(ValueError, match="action of robot_0 must be finite"):
        par.step({"robot_0": [np.nan, 0.0], "robot_1": ok})
    with pytest.raises(ValueError, match="action of robot_1 must be finite"):
        par.step({"robot_0": ok, "robot_1": [0.0, np.inf]})
    with pytest.raises(ValueError, match=r"must have shape \(2,\) \(v, w\), got shape \(3,\)"):
        par.step({"robot_0": [0.0, 0.0, 0.0], "robot_1": ok})
    with pytest.raises(TypeError, match="must be a numeric"):
        par.step({"robot_0": "fast", "robot_1": ok})
    with pytest.raises(ValueError, match=r"missing agents \['robot_1'\]"):
        par.step({"robot_0": ok})
    with pytest.raises(ValueError, match=r"unknown or finished agents \['robot_7'\]"):
        par.step({"robot_0": ok, "robot_1": ok, "robot_7": ok})
    with pytest.raises(TypeError, match="actions must be a dict"):
        par.step([ok, ok])


def test_out_of_range_actions_are_clipped():
    a = two_robot_explore_v0.parallel_env(**SMALL)
    b = two_robot_explore_v0.parallel_env(**SMALL)
    a.reset(seed=4)
    b.reset(seed=4)
    for _ in range(5):
        a.step({"robot_0": [5.0, -3.0], "robot_1": [-9.0, 2.0]})
        b.step({"robot_0": [1.0, -1.0], "robot_1": [-1.0, 1.0]})
    for ra, rb in zip(a.robots, b.robots, strict=True):
        np.testing.assert_array_equal(ra.true_pose(), rb.true_pose())


def test_step_before_reset_and_after_the_end_tell_to_reset():
    par = two_robot_explore_v0.parallel_env(**{**SMALL, "max_cycles": 2})
    with pytest.raises(RuntimeError, match=r"call reset\(\)"):
        par.step({})
    par.reset(seed=0)
    act = {"robot_0": np.zeros(2), "robot_1": np.zeros(2)}
    par.step(act)
    _, _, term, trunc, _ = par.step(act)
    assert trunc == {"robot_0": True, "robot_1": True} and par.agents == []
    with pytest.raises(RuntimeError, match=r"episode ended .* call reset\(\)"):
        par.step(act)


@pytest.mark.parametrize(("kwargs", "error", "match"), [
    ({"colour": "red"}, ValueError, r"unknown config keys \['colour'\]"),
    ({"max_cycles": 0}, ValueError, "max_cycles must be >= 1, got 0"),
    ({"max_cycles": 2.5}, TypeError, "max_cycles must be an integer"),
    ({"reward_mode": "greedy"}, ValueError, r"reward_mode must be one of \['shared'"),
    ({"action_type": "joystick"}, ValueError, "action_type must be one of"),
    ({"target_coverage": 1.5}, ValueError, "target_coverage must be <= 1.0, got 1.5"),
    ({"sonar": {"max_range": -1}}, ValueError, "sonar.max_range must be > 0.0, got -1.0"),
    ({"sonar": {"min_range": 6.0}}, ValueError, "sonar.min_range must be < sonar.max_range"),
    ({"sonar": {"beams": 3}}, ValueError, r"sonar has unknown keys \['beams'\]"),
    ({"sonar": 3}, TypeError, "sonar must be a SonarConfig, a dict of its fields or None"),
    ({"robot": {"radius": float("nan")}}, ValueError, "robot.radius must be finite"),
    ({"robot": {"substeps": 0}}, ValueError, "robot.substeps must be >= 1, got 0"),
    ({"robot": {"max_speed": 9.0, "substeps": 1}}, ValueError, "cannot tunnel"),
    ({"world": {"size": (3, 20)}}, ValueError, r"world.size\[0\] must be >= 6.0, got 3.0"),
    ({"world": {"source": "house.obj"}}, ValueError, "world.source must be 'procedural' or"),
    ({"world": {"source": "/nonexistent/map.yaml"}}, FileNotFoundError, "does not exist"),
    ({"world": {"door_width": 0.4}}, ValueError, "world.door_width must be > 2 \\* robot"),
    ({"mapping": {"local_map_size": 32}}, ValueError, "mapping.local_map_size must be >= 64"),
    ({"mapping": {"merge_method": "magic"}}, ValueError, "mapping.merge_method must be one of"),
    ({"mapping": {"topo": {"spur": 1}}}, ValueError, r"mapping.topo has unknown keys \[.spur.\]"),
    ({"mapping": {"grid_merge_growth": -0.1}}, ValueError,
     "mapping.grid_merge_growth must be >= 0.0, got -0.1"),
    ({"mapping": {"accept_threshold": 1.5}}, ValueError,
     "mapping.accept_threshold must be <= 1.0, got 1.5"),
    ({"render_mode": "ansi"}, ValueError, "render_mode must be one of"),
])
def test_bad_config_names_the_problem(kwargs, error, match):
    with pytest.raises(error, match=match):
        two_robot_explore_v0.parallel_env(**kwargs)


def test_config_object_and_overrides():
    cfg = EnvConfig.from_kwargs(max_cycles=33, sonar={"rays": 1})
    par = two_robot_explore_v0.parallel_env(cfg, world={"size": (10.0, 10.0)})
    assert par.config.sonar.rays == 1 and par.config.max_cycles == 33
    assert par.config.world.size == (10.0, 10.0)
    with pytest.raises(TypeError, match="config must be an EnvConfig"):
        two_robot_explore_v0.parallel_env({"max_cycles": 3})
    with pytest.raises(ValueError, match="max_cycles must be >= 1"):
        par.max_cycles = 0


def test_reset_options():
    par = two_robot_explore_v0.parallel_env(**SMALL)
    par.reset(seed=1)
    starts = np.array([r.true_pose() for r in par.robots])
    par.reset(seed=2, options={"start_poses": starts})
    np.testing.assert_allclose([r.true_pose() for r in par.robots], starts, atol=1e-12)
    with pytest.warns(UserWarning, match=r"reset options \['speed'\] are not used"):
        par.reset(seed=0, options={"speed": 1})
    with pytest.raises(ValueError, match=r"start_poses'\]\[0\] = \[-5.0, -5.0\] is not a drivable"):
        par.reset(seed=0, options={"start_poses": [[-5, -5, 0], [1, 1, 0]]})
    with pytest.raises(ValueError, match=r"shape \(2, 3\)"):
        par.reset(seed=0, options={"start_poses": [[1, 1, 0]]})


def test_grid_merge_every_must_be_a_multiple_of_merge_every():
    from envs.explore.config import MappingConfig

    with pytest.raises(ValueError, match=r"mapping.grid_merge_every must be 0 or a multiple of "
                                         r"mapping.merge_every \(25\), got 30"):
        MappingConfig(grid_merge_every=30)
    assert MappingConfig(merge_every=0).grid_merge_every == 100
