"""The motion-level wrapper: PettingZoo API, held commands equal to the plain env's steps,
shaping that telescopes (potential-based), bad arguments; SB3Explorer holds commands too."""

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

from agents.goals import make_env
from agents.motion import MotionEnv, frontier_distance
from envs import two_robot_explore_v0

SMALL = {"world": {"size": (8.0, 8.0)}, "max_cycles": 60}


def motion_env(**kw):
    return MotionEnv(two_robot_explore_v0.parallel_env(**SMALL), **kw)


def commands(n, seed=0):
    rng = np.random.default_rng(seed)
    return [{f"robot_{i}": rng.uniform(-1, 1, 2).astype(np.float32) for i in range(2)}
            for _ in range(n)]


def test_passes_pettingzoo_parallel_api_test():
    parallel_api_test(motion_env(hold=3, frontier_shaping=0.2), num_cycles=10)


def test_a_held_command_is_hold_steps_of_the_plain_env():
    wrapped, plain = motion_env(hold=4), two_robot_explore_v0.parallel_env(**SMALL)
    wrapped.reset(seed=7)
    plain.reset(seed=7)
    for action in commands(5):
        obs, rewards, _, _, infos = wrapped.step(action)
        total = 0.0
        for _ in range(4):
            ref_obs, ref_rewards, _, _, ref_infos = plain.step(action)
            total += ref_rewards["robot_0"]
        assert infos["robot_0"]["env_steps"] == 4
        assert rewards["robot_0"] == pytest.approx(total)
        np.testing.assert_array_equal(obs["robot_1"]["local_map"], ref_obs["robot_1"]["local_map"])
        assert infos["robot_1"]["pose"] == pytest.approx(ref_infos["robot_1"]["pose"])


def test_the_last_decision_takes_the_steps_left():
    env = motion_env(hold=7)
    env.reset(seed=1)
    steps = []
    while env.agents:
        steps.append(env.step(commands(1)[0])[4]["robot_0"]["env_steps"])
    assert sum(steps) == SMALL["max_cycles"] and steps[-1] == 60 - 7 * 8


def test_shaping_telescopes_to_the_change_of_the_frontier_distance():
    k = 0.5
    shaped, plain = motion_env(hold=2, frontier_shaping=k), motion_env(hold=2)
    _, infos = shaped.reset(seed=3)
    plain.reset(seed=3)
    start = infos["robot_0"]["frontier_distance"]
    assert start > 0.0
    gap = 0.0
    for action in commands(20, seed=4):
        _, r_shaped, _, _, infos = shaped.step(action)
        _, r_plain, _, _, _ = plain.step(action)
        gap += r_shaped["robot_0"] - r_plain["robot_0"]
    # sum of k · (Φ(s') − Φ(s)) with Φ = −distance: k · (d_0 − d_T), whatever happened between
    assert gap == pytest.approx(k * (start - infos["robot_0"]["frontier_distance"]))


def test_frontier_distance_is_a_path_length_in_metres():
    env = two_robot_explore_v0.parallel_env(**SMALL)
    env.reset(seed=2)
    d = frontier_distance(env, "robot_0", MotionEnv(env).config)
    assert 0.0 < d < 8.0  # a freshly scanned robot has frontiers within the sonar range


def test_make_env_wraps_only_when_needed():
    assert isinstance(make_env(SMALL, "motion", 3), MotionEnv)
    assert isinstance(make_env(SMALL, "motion", 1, frontier_shaping=0.1), MotionEnv)
    assert not isinstance(make_env(SMALL, "motion"), MotionEnv)


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"hold": 0}, ValueError, "hold must be >= 1, got 0"),
        ({"hold": 2.5}, TypeError, "hold must be an integer, got float"),
        ({"frontier_shaping": -1.0}, ValueError, "frontier_shaping must be >= 0.0, got -1.0"),
    ],
)
def test_bad_arguments(kwargs, error, match):
    with pytest.raises(error, match=match):
        motion_env(**kwargs)


def test_wraps_only_the_exploration_env():
    with pytest.raises(TypeError, match="env must be a two_robot_explore ParallelEnv, got dict"):
        MotionEnv({})


def test_step_before_reset_is_an_error():
    with pytest.raises(RuntimeError, match="before reset"):
        motion_env().step(commands(1)[0])


def test_sb3_explorer_holds_a_motion_policys_command():
    from agents.base import run_episode
    from agents.sb3_explorer import SB3Explorer

    class Policy:
        observation_space = two_robot_explore_v0.parallel_env(**SMALL).observation_space("robot_0")
        motion_hold = 4

        def __init__(self):
            self.calls = 0

        def predict(self, observation, deterministic=True):
            self.calls += 1
            return np.array([0.5, 0.1], dtype=np.float32), None

    policy = Policy()
    explorers = {"robot_0": SB3Explorer(policy), "robot_1": SB3Explorer(policy)}
    run_episode(two_robot_explore_v0.parallel_env(**{**SMALL, "max_cycles": 30}), explorers,
                seed=1)
    assert policy.calls == 2 * 8  # steps 1, 5, ..., 29 of 30, per robot


def test_arcs_are_a_few_velocity_commands():
    from agents.motion import ARCS

    wrapped = motion_env(hold=2, commands="arcs")
    plain = two_robot_explore_v0.parallel_env(**SMALL)
    assert wrapped.action_space("robot_0").n == len(ARCS)
    wrapped.reset(seed=5)
    plain.reset(seed=5)
    for k in [0, 1, 2, 3, 4, 0]:
        obs, *_ = wrapped.step({"robot_0": k, "robot_1": np.int64(4 - k)})
        for _ in range(2):
            ref, *_ = plain.step({"robot_0": ARCS[k], "robot_1": ARCS[4 - k]})
        np.testing.assert_array_equal(obs["robot_0"]["odometry"], ref["robot_0"]["odometry"])
    with pytest.raises(ValueError, match=r"action of robot_0 must be an index in \[0, 5\)"):
        wrapped.step({"robot_0": 5, "robot_1": 0})
    with pytest.raises(ValueError, match=r"commands must be one of \['continuous', 'arcs'\]"):
        motion_env(commands="joystick")
    with pytest.raises(ValueError, match="commands='arcs' needs an env with action_type"):
        MotionEnv(two_robot_explore_v0.parallel_env(action_type="discrete"), commands="arcs")


# ------------------------------------------------------------------------ teams of N robots
TEAM = {"world": {"size": (12.0, 12.0)}, "max_cycles": 20, "sonar": {"rays": 1},
        "comm": {"range": 5.0}}


def test_make_env_builds_the_two_robot_env_or_a_team_alike():
    from agents.goals import FrontierGoalEnv

    two = make_env(SMALL, "motion", hold=2)
    assert isinstance(two, MotionEnv) and two.unwrapped.metadata["name"] == (
        "two_robot_explore_v0")
    assert type(make_env(SMALL, "motion").unwrapped) is type(make_env(SMALL, "motion"))
    three = make_env({**TEAM, "n_robots": 3}, "motion", hold=2, frontier_shaping=0.1)
    assert isinstance(three, MotionEnv) and three.possible_agents == [
        "robot_0", "robot_1", "robot_2"]
    assert three.unwrapped.metadata["name"] == "multi_robot_explore_v0"
    plain = make_env({**TEAM, "n_robots": 3}, "motion")
    assert plain.metadata["name"] == "multi_robot_explore_v0"
    goals = make_env({**TEAM, "n_robots": 4}, "goals", hold=3, global_state=True)
    assert isinstance(goals, FrontierGoalEnv) and goals.hold == 3
    assert goals.observation_space("robot_3")["teammates"].shape == (3, 7)
    with pytest.raises(ValueError, match="n_robots must be between 2 and 8, got 9"):
        make_env({**TEAM, "n_robots": 9})
    with pytest.raises(ValueError, match="global_state applies to level='goals' only"):
        make_env({**TEAM, "n_robots": 3}, "motion", global_state=True)
    with pytest.raises(ValueError, match=r"level must be one of \['goals', 'motion'\]"):
        make_env({**TEAM, "n_robots": 3}, "wheels")


def test_team_of_three_passes_the_parallel_api_test():

    parallel_api_test(make_env({**TEAM, "n_robots": 3}, "motion", hold=2, commands="arcs"),
                      num_cycles=8)
