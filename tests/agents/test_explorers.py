"""Scripted explorers in the real env: episodes run, frontier explores, runs are reproducible."""

import numpy as np
import pytest

from agents.base import run_episode
from agents.frontier_planning import FrontierConfig
from agents.metrics import EpisodeRecorder
from agents.registry import EXPLORERS, make_team
from agents.scripted import RandomWalk, WallFollower
from envs.two_robot_explore_v0 import parallel_env

SMALL = {"world": {"size": (10.0, 10.0)}}


@pytest.mark.parametrize("name", sorted(EXPLORERS))
def test_each_explorer_finishes_an_episode(name):
    env = parallel_env(max_cycles=120, **SMALL)
    rec = EpisodeRecorder()
    out = run_episode(env, make_team(name), seed=5, callback=rec)
    assert out["steps"] == 120 and not env.agents
    s = rec.summary()
    assert 0.0 < s["final_coverage"] <= 1.0 and s["path_length_m"]["robot_0"] > 0.5


def test_frontier_covers_a_small_world():
    env = parallel_env(max_cycles=900, **SMALL)
    rec = EpisodeRecorder()
    run_episode(env, make_team("frontier"), seed=2, callback=rec)
    s = rec.summary()
    assert s["reached_T85"], f"frontier reached only {s['final_coverage']:.2f}"


def actions_of(name: str, seed: int, steps: int = 200) -> list[np.ndarray]:
    env = parallel_env(max_cycles=steps, **SMALL)
    team = make_team(name, env=env)
    seen: list[np.ndarray] = []
    obs, infos = env.reset(seed=seed)
    for a, s in zip(team.values(), np.random.SeedSequence(seed).spawn(2), strict=True):
        a.reset(int(s.generate_state(1)[0]))
    while env.agents:
        actions = {a: team[a].act(obs[a], infos[a]) for a in env.agents}
        seen.append(np.concatenate([np.atleast_1d(v) for v in actions.values()]))
        obs, _, _, _, infos = env.step(actions)
    return seen


@pytest.mark.parametrize("name", ["random_walk", "coordinated_frontier"])
def test_same_seed_same_actions_over_many_steps(name):
    a, b = actions_of(name, 11), actions_of(name, 11)
    assert len(a) == 200
    np.testing.assert_array_equal(np.array(a), np.array(b))
    assert not np.array_equal(np.array(a), np.array(actions_of(name, 12)))


def test_discrete_actions():
    env = parallel_env(max_cycles=30, action_type="discrete", **SMALL)
    out = run_episode(env, make_team("frontier", action_type="discrete"), seed=1)
    assert out["steps"] == 30


def test_bad_arguments():
    with pytest.raises(ValueError, match=r"explorer must be one of \['coordinated_frontier'"):
        make_team("spiral")
    with pytest.raises(ValueError, match="action_type must be one of"):
        make_team("frontier", action_type="joystick")
    with pytest.raises(ValueError, match="FrontierConfig.min_cluster_cells must be >= 1, got 0"):
        FrontierConfig(min_cluster_cells=0)
    with pytest.raises(ValueError, match="FrontierConfig.lookahead must be > 0.0"):
        FrontierConfig(lookahead=-1.0)


PIONEER = (-90.0, -50.0, -30.0, -10.0, 10.0, 30.0, 50.0, 90.0)


def bound_to(explorer, **env_kwargs):
    env = parallel_env(max_cycles=5, **SMALL, **env_kwargs)
    explorer.bind(env, "robot_0")
    explorer.reset(0)
    return explorer


def test_explorers_read_the_sonar_layout_of_the_env_they_are_bound_to():
    # the Pioneer ring listed left to right: the right-hand sonars are the last two
    follower = bound_to(WallFollower(), sonar={"angles": tuple(reversed(PIONEER))})
    right_wall = np.ones(8)
    right_wall[6:] = 0.7 / 5.0  # 0.7 m: the follower's distance
    # following the wall it sees (straight on), not curving right to look for one
    np.testing.assert_allclose(follower.command({"sonar": right_wall}, {}), [0.8, 0.0])
    assert follower.sonar.right.tolist() == [False] * 6 + [True] * 2
    # readings scale with the env's max_range: 0.2 of 3 m is 0.6 m ahead, closer than 0.7 m
    near = bound_to(WallFollower(), sonar={"max_range": 3.0})
    ahead = np.ones(8)
    ahead[3:5] = 0.2
    np.testing.assert_allclose(near.command({"sonar": ahead}, {}), [0.0, 1.0])


@pytest.mark.parametrize("name", ["random_walk", "frontier"])
def test_explorers_run_under_a_non_default_sonar(name):
    env = parallel_env(max_cycles=60, sonar={"angles": (-60.0, 0.0, 60.0), "max_range": 3.0},
                       **SMALL)
    out = run_episode(env, make_team(name), seed=3)
    assert out["steps"] == 60


def test_an_unbound_explorer_says_to_bind_it():
    walker = RandomWalk()
    walker.reset(0)
    with pytest.raises(RuntimeError, match=r"RandomWalk reads its robot's sonar layout"):
        walker.act({"sonar": np.ones(8)}, {})


# ---------------------------------------------------------------------------- teams of N
def team_env(n, steps=60, **kwargs):
    from envs import multi_robot_explore_v0

    return multi_robot_explore_v0.parallel_env(n_robots=n, max_cycles=steps,
                                               comm={"range": 6.0}, **SMALL, **kwargs)


@pytest.mark.parametrize("name", sorted(EXPLORERS))
def test_make_team_sizes_the_team_by_the_env(name):
    env = team_env(4)
    team = make_team(name, env=env)
    assert list(team) == ["robot_0", "robot_1", "robot_2", "robot_3"]
    assert all(e.agent == a for a, e in team.items())
    out = run_episode(env, team, seed=2)
    assert out["steps"] == 60 and not env.agents
    assert list(make_team(name, n_robots=3)) == ["robot_0", "robot_1", "robot_2"]
    assert list(make_team(name)) == ["robot_0", "robot_1"]


def test_a_coordinated_team_shares_one_blackboard_and_repeats_with_a_seed():
    def trace(seed):
        env = team_env(3, steps=150)
        team = make_team("coordinated_frontier", env=env)
        assert len({id(e.board) for e in team.values()}) == 1
        seen = []
        run_episode(env, team, seed=seed, callback=lambda _k, _o, _r, infos: seen.append(
            np.concatenate([infos[a]["pose"] for a in sorted(infos)])))
        return np.array(seen)

    a = trace(4)
    assert a.shape[0] == 150
    np.testing.assert_array_equal(a, trace(4))
    assert not np.array_equal(a, trace(5))


def test_make_team_names_a_bad_team_size():
    with pytest.raises(ValueError, match="n_robots must be >= 1, got 0"):
        make_team("frontier", n_robots=0)
    with pytest.raises(TypeError, match="n_robots must be an integer, got"):
        make_team("frontier", n_robots=2.5)
    with pytest.raises(ValueError, match="n_robots must match the env's team of 3 robots, got 2"):
        make_team("frontier", env=team_env(3), n_robots=2)


def test_goal_frontier_drives_any_robot_of_a_team():
    from agents.goals import GoalFrontier
    from agents.scripted import robot_index

    env = team_env(4, steps=20)
    robot = GoalFrontier()
    robot.bind(env, "robot_3")
    assert robot.index == 3
    obs, infos = env.reset(seed=1)
    robot.reset(0)
    robot.choose_sector(0)
    for _ in range(10):
        action = robot.act(obs["robot_3"], infos["robot_3"])
        obs, _r, _t, _u, infos = env.step({a: action if a == "robot_3" else np.zeros(2)
                                           for a in env.agents})
    assert robot.events["plans"] >= 1
    for bad in ("robot_x", "robot_", "robot_01", "r2", 3):
        with pytest.raises(ValueError, match=r"agent must be 'robot_<k>' \(k = 0, 1, ...\)"):
            robot_index(bad)


class WithoutTeams:
    """The two-robot env as explorers saw it before teams: ``merge_state()`` with the
    transform only, no ``teammate_map``."""

    def __init__(self, env):
        self._env = env.unwrapped

    @property
    def unwrapped(self):
        return self

    def merge_state(self):
        from types import SimpleNamespace

        return SimpleNamespace(transform=self._env.merge_state().transform)

    def __getattr__(self, name):
        if name == "teammate_map":
            raise AttributeError(name)
        return getattr(self._env, name)


def test_two_coordinated_robots_act_the_same_with_or_without_the_team_interface():
    def actions(hide):
        env = parallel_env(max_cycles=400, world={"size": (10.0, 10.0)})
        team = make_team("coordinated_frontier", env=WithoutTeams(env) if hide else env)
        obs, infos = env.reset(seed=2)
        for e, s in zip(team.values(), np.random.SeedSequence(2).spawn(2), strict=True):
            e.reset(int(s.generate_state(1)[0]))
        seen = []
        while env.agents:
            acts = {a: team[a].act(obs[a], infos[a]) for a in env.agents}
            seen.append(np.concatenate(list(acts.values())))
            obs, _r, _t, _u, infos = env.step(acts)
        return np.array(seen), team["robot_0"].events

    with_frames, events = actions(hide=False)
    assert events.get("assigned", 0) >= 1  # merged and coordinating within the episode
    np.testing.assert_array_equal(with_frames, actions(hide=True)[0])
