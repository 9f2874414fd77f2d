"""The centralised Gymnasium view: registry, Gymnasium's checker, wrappers and vector envs."""

import dataclasses
import math
import sys
import types
import warnings

import gymnasium
import numpy as np
import pytest
from conftest import SMALL
from gymnasium.utils.env_checker import check_env, data_equivalence
from gymnasium.wrappers import FlattenObservation, RecordVideo, RenderCollection

import envs
from envs import two_robot_explore_v0
from envs.explore.centralised import (
    GYMNASIUM_ID,
    MULTI_GYMNASIUM_ID,
    CentralisedExploreEnv,
    CentralisedMultiRobotEnv,
)

AGENTS = ("robot_0", "robot_1")


def comparable(infos: dict) -> dict:
    """Each robot's info without what two identical episodes do not share (live map objects,
    NaN before a merge, wall-clock times)."""
    def keep(key, value):
        if key == "merge_time_s":
            return False
        if isinstance(value, (bool, int, float, np.number)):
            return math.isfinite(float(value))
        return (isinstance(value, np.ndarray) and value.dtype != object
                and bool(np.isfinite(value).all()))
    return {a: {k: v for k, v in info.items() if keep(k, v)} for a, info in infos.items()}


class _Comparable:
    """Gymnasium's checker compares the infos of two identical steps with ``==``; until the
    env's infos are all small numbers it is given :func:`comparable` infos."""

    def reset(self, *, seed=None, options=None):
        observations, infos = super().reset(seed=seed, options=options)
        return observations, comparable(infos)

    def step(self, action):
        *out, infos = super().step(action)
        return (*out, comparable(infos))


class ComparableInfos(_Comparable, CentralisedExploreEnv):
    """The two-robot view with :func:`comparable` infos."""


class ComparableTeam(_Comparable, CentralisedMultiRobotEnv):
    """The team view with :func:`comparable` infos."""


def test_registered_under_its_gymnasium_id():
    assert GYMNASIUM_ID in envs.GYMNASIUM_IDS and GYMNASIUM_ID in gymnasium.registry
    env = gymnasium.make(GYMNASIUM_ID, **SMALL)
    assert isinstance(env.unwrapped, CentralisedExploreEnv)
    assert env.spec.max_episode_steps is None  # the env truncates itself (max_cycles)
    assert env.action_space == gymnasium.spaces.Box(-1.0, 1.0, (4,), np.float32)
    assert list(env.observation_space.spaces) == list(AGENTS)
    par = env.unwrapped.parallel
    assert all(env.observation_space[a] is par.observation_space(a) for a in AGENTS)
    discrete = gymnasium.make(GYMNASIUM_ID, action_type="discrete", **SMALL)
    assert discrete.action_space == gymnasium.spaces.MultiDiscrete([5, 5])
    env.close()
    discrete.close()


@pytest.mark.parametrize("action_type", ["continuous", "discrete"])
def test_gymnasium_env_checker(action_type):
    kwargs = {**SMALL, "action_type": action_type}
    env = ComparableInfos(render_mode="rgb_array", **kwargs)
    # a spec lets the checker make the env in every render mode ("human" on a dummy display)
    env.spec = dataclasses.replace(gymnasium.spec(GYMNASIUM_ID), kwargs=kwargs)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env)
    assert [str(w.message) for w in caught] == []
    env.close()


@pytest.mark.parametrize("reward_mode", ["shared", "individual"])
def test_same_episode_as_the_parallel_env(reward_mode):
    kwargs = {**SMALL, "max_cycles": 40, "reward_mode": reward_mode}
    single = gymnasium.make(GYMNASIUM_ID, **kwargs)
    par = two_robot_explore_v0.parallel_env(**kwargs)
    rng = np.random.default_rng(3)
    obs_s, info_s = single.reset(seed=7)
    obs_p, info_p = par.reset(seed=7)
    steps = 0
    while True:
        joint = rng.uniform(-1, 1, 4).astype(np.float32)
        obs_s, rew_s, term_s, trunc_s, info_s = single.step(joint)
        obs_p, rew_p, term_p, trunc_p, info_p = par.step({"robot_0": joint[:2],
                                                          "robot_1": joint[2:]})
        steps += 1
        for a in AGENTS:
            for key, value in obs_p[a].items():
                np.testing.assert_array_equal(obs_s[a][key], value)
        team = sum(rew_p.values()) if reward_mode == "individual" else rew_p["robot_0"]
        assert isinstance(rew_s, float) and rew_s == team
        assert data_equivalence(comparable(info_s), comparable(info_p), exact=True)
        assert set(info_s) == set(AGENTS)
        assert (term_s, trunc_s) == (term_p["robot_0"], trunc_p["robot_0"])
        if term_s or trunc_s:
            break
    assert steps == 40 and trunc_s and not par.agents
    single.close()


def test_flatten_observation():
    env = FlattenObservation(gymnasium.make(GYMNASIUM_ID, **SMALL))
    obs, _ = env.reset(seed=0)
    assert obs.shape == env.observation_space.shape and obs.dtype == np.float32
    assert obs in env.observation_space
    obs, *_ = env.step(env.action_space.sample())
    assert obs in env.observation_space
    env.close()


def test_sync_vector_env_of_two():
    vec = gymnasium.make_vec(GYMNASIUM_ID, num_envs=2, vectorization_mode="sync",
                             **{**SMALL, "max_cycles": 5})
    obs, infos = vec.reset(seed=[0, 1])
    assert obs["robot_0"]["sonar"].shape == (2, 8)
    assert obs["robot_1"]["local_map"].shape == (2, 1, 64, 64)
    assert not np.array_equal(obs["robot_0"]["sonar"][0], obs["robot_0"]["sonar"][1])
    assert infos["robot_0"]["true_coverage"].shape == (2,)
    vec.action_space.seed(0)
    truncated_at = None
    for t in range(7):
        obs, rewards, terms, truncs, infos = vec.step(vec.action_space.sample())
        assert rewards.shape == (2,) and rewards.dtype == np.float64
        if truncs.all() and truncated_at is None:
            truncated_at = t
    assert truncated_at == 4  # max_cycles = 5; the next step resets (autoreset)
    vec.close()


def test_render_passes_through_to_wrappers():
    env = RenderCollection(gymnasium.make(GYMNASIUM_ID, render_mode="rgb_array", **SMALL))
    env.reset(seed=0)
    for _ in range(3):
        env.step(env.action_space.sample())
    frames = env.render()
    assert len(frames) == 4
    assert all(f.dtype == np.uint8 and f.ndim == 3 and f.shape[2] == 3 for f in frames)
    assert len(np.unique(frames[-1].reshape(-1, 3), axis=0)) > 5
    env.close()


def run_recorded_episode(folder) -> None:
    env = RecordVideo(gymnasium.make(GYMNASIUM_ID, render_mode="rgb_array",
                                     **{**SMALL, "max_cycles": 6}),
                      str(folder), episode_trigger=lambda episode: True, disable_logger=True)
    env.reset(seed=0)
    done = False
    while not done:
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        done = terminated or truncated
    env.close()


def test_record_video_hands_every_frame_to_the_encoder(tmp_path, monkeypatch):
    """RecordVideo captures the env's frames and gives them to moviepy at the env's fps (moviepy
    replaced by a recorder: it is not a dependency)."""
    clips = []

    class ImageSequenceClip:
        def __init__(self, frames, fps):
            clips.append({"frames": list(frames), "fps": fps})

        def write_videofile(self, path, logger=None):
            clips[-1]["path"] = path

    names = ["moviepy", "moviepy.video", "moviepy.video.io", "moviepy.video.io.ImageSequenceClip"]
    for name in names:
        monkeypatch.setitem(sys.modules, name, types.ModuleType(name))
    sys.modules[names[-1]].ImageSequenceClip = ImageSequenceClip
    run_recorded_episode(tmp_path / "videos")
    (clip,) = clips
    assert clip["fps"] == 10 and clip["path"].endswith("rl-video-episode-0.mp4")
    assert len(clip["frames"]) == 7  # the reset and 6 steps
    shapes = {f.shape for f in clip["frames"]}
    assert len(shapes) == 1 and shapes.pop()[2] == 3


def test_record_video_writes_a_video(tmp_path):
    pytest.importorskip("moviepy")
    run_recorded_episode(tmp_path / "videos")
    (video,) = (tmp_path / "videos").glob("*.mp4")
    assert video.stat().st_size > 1000


@pytest.mark.parametrize(
    ("kwargs", "action", "error", "match"),
    [
        ({}, np.zeros(2), ValueError, r"action must have shape \(4,\) \(\[v_0, w_0, v_1, w_1\]\), "
                                      r"got shape \(2,\)"),
        ({}, "fast", TypeError, "action must be numeric"),
        ({"action_type": "discrete"}, np.array([1.5, 2.0]), ValueError,
         r"action must be 2 integers \(robot 0's action, robot 1's\)"),
        ({"action_type": "discrete"}, np.array([1, 9]), ValueError,
         r"action of robot_1 must be in \[0, 5\), got 9"),
    ],
)
def test_bad_actions(kwargs, action, error, match):
    env = CentralisedExploreEnv(**SMALL, **kwargs)
    env.reset(seed=0)
    with pytest.raises(error, match=match):
        env.step(action)


# ------------------------------------------------------------------------ teams of N robots
TEAM = {"world": {"size": (12.0, 12.0)}, "max_cycles": 12, "sonar": {"rays": 1},
        "comm": {"range": 5.0}}
"""A small, fast team setting: a 12 x 12 m building, one ray per sonar cone."""


def test_multi_robot_ids_are_registered():
    import pettingzoo

    from envs import multi_robot_explore_v0

    assert "topomerge/multi_robot_explore_v0" in envs.ENV_IDS
    assert MULTI_GYMNASIUM_ID in envs.GYMNASIUM_IDS and MULTI_GYMNASIUM_ID in gymnasium.registry
    par = pettingzoo.make("parallel", "topomerge/multi_robot_explore_v0", n_robots=3, **TEAM)
    assert isinstance(par, multi_robot_explore_v0.raw_env)
    assert par.possible_agents == ["robot_0", "robot_1", "robot_2"]
    aec = pettingzoo.make("aec", "topomerge/multi_robot_explore_v0", n_robots=4, **TEAM)
    assert aec.possible_agents == [f"robot_{i}" for i in range(4)]
    env = gymnasium.make(MULTI_GYMNASIUM_ID, n_robots=3, **TEAM)
    assert isinstance(env.unwrapped, CentralisedMultiRobotEnv)
    assert env.spec.max_episode_steps is None
    assert env.action_space == gymnasium.spaces.Box(-1.0, 1.0, (6,), np.float32)
    assert env.observation_space["robot_2"]["teammates"].shape == (2, 7)
    discrete = gymnasium.make(MULTI_GYMNASIUM_ID, n_robots=4, action_type="discrete", **TEAM)
    assert discrete.action_space == gymnasium.spaces.MultiDiscrete([5] * 4)
    for e in (par, aec, env, discrete):
        e.close()


def test_parallel_env_for_picks_the_version_by_n_robots():
    two = envs.parallel_env_for(dict(SMALL))
    assert two.metadata["name"] == "two_robot_explore_v0"
    assert "teammate" in two.observation_space("robot_0").spaces
    assert envs.parallel_env_for({**SMALL, "n_robots": 2}).metadata["name"] == (
        "two_robot_explore_v0")
    three = envs.parallel_env_for({**TEAM, "n_robots": 3})
    assert three.metadata["name"] == "multi_robot_explore_v0"
    assert three.possible_agents == ["robot_0", "robot_1", "robot_2"]
    with pytest.raises(TypeError, match="config must be a mapping of EnvConfig fields, got list"):
        envs.parallel_env_for([("n_robots", 3)])


@pytest.mark.parametrize("n_robots", [1, 9, "3"])
def test_bad_team_size_names_the_field(n_robots):
    match = "n_robots must be" + (" between 2 and 8, got" if n_robots != "3" else "")
    with pytest.raises((ValueError, TypeError), match=match):
        gymnasium.make(MULTI_GYMNASIUM_ID, n_robots=n_robots, **TEAM)
    with pytest.raises((ValueError, TypeError), match=match):
        envs.parallel_env_for({"n_robots": n_robots})


@pytest.mark.parametrize("n_robots", [3, 4])
def test_team_is_the_same_episode_as_the_parallel_env(n_robots):
    from envs import multi_robot_explore_v0

    kwargs = {**TEAM, "n_robots": n_robots, "reward_mode": "individual"}
    single = gymnasium.make(MULTI_GYMNASIUM_ID, **kwargs)
    par = multi_robot_explore_v0.parallel_env(**kwargs)
    agents = par.possible_agents
    rng = np.random.default_rng(3)
    obs_s, _ = single.reset(seed=5)
    obs_p, _ = par.reset(seed=5)
    steps = 0
    while True:
        joint = rng.uniform(-1, 1, 2 * n_robots).astype(np.float32)
        obs_s, rew_s, term_s, trunc_s, info_s = single.step(joint)
        obs_p, rew_p, term_p, trunc_p, info_p = par.step(
            {a: joint[2 * i:2 * i + 2] for i, a in enumerate(agents)})
        steps += 1
        for a in agents:
            for key, value in obs_p[a].items():
                np.testing.assert_array_equal(obs_s[a][key], value)
        assert rew_s == sum(rew_p.values())
        assert data_equivalence(comparable(info_s), comparable(info_p), exact=True)
        assert (term_s, trunc_s) == (term_p["robot_0"], trunc_p["robot_0"])
        if term_s or trunc_s:
            break
    assert steps == TEAM["max_cycles"] and trunc_s
    single.close()


def test_team_gymnasium_env_checker():
    kwargs = {**TEAM, "n_robots": 3, "action_type": "discrete"}
    env = ComparableTeam(**kwargs)
    env.spec = dataclasses.replace(gymnasium.spec(MULTI_GYMNASIUM_ID), kwargs=kwargs)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env, skip_render_check=True)
    assert [str(w.message) for w in caught] == []
    env.close()


@pytest.mark.parametrize(
    ("kwargs", "action", "error", "match"),
    [
        ({}, np.zeros(4), ValueError, r"action must have shape \(6,\) "
                                      r"\(\[v_0, w_0, \.\.\., v_2, w_2\]\), got shape \(4,\)"),
        ({"action_type": "discrete"}, np.array([1, 2]), ValueError,
         r"action must be 3 integers \(robot 0's action, \.\.\., robot 2's\)"),
        ({"action_type": "discrete"}, np.array([1, 2, 7]), ValueError,
         r"action of robot_2 must be in \[0, 5\), got 7"),
    ],
)
def test_team_bad_actions(kwargs, action, error, match):
    env = CentralisedMultiRobotEnv(n_robots=3, **TEAM, **kwargs)
    env.reset(seed=0)
    with pytest.raises(error, match=match):
        env.step(action)
