"""Goal-level actions: the FrontierGoalEnv wrapper (PettingZoo API, held rewards, determinism,
bad actions) and GoalFrontier's sector steering."""

import math

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

from agents.base import run_episode
from agents.goals import (
    FRONTIER_FEATURES,
    SECTORS,
    FrontierGoalEnv,
    GoalFrontier,
    SectorRule,
    make_env,
    sector_of,
)
from envs import two_robot_explore_v0

SMALL = {"world": {"size": (8.0, 8.0)}, "max_cycles": 60}


def goal_env(hold=5, **kw):
    return FrontierGoalEnv(two_robot_explore_v0.parallel_env(**{**SMALL, **kw}), hold=hold)


def test_passes_pettingzoo_parallel_api_test():
    parallel_api_test(goal_env(), num_cycles=15)


def test_sector_of_splits_the_circle_in_45_degree_sectors_from_the_heading():
    pose = np.array([1.0, 2.0, math.pi / 2])  # facing +y
    assert sector_of(np.array([1.0, 5.0]), pose) == 0  # ahead
    assert sector_of(np.array([-2.0, 2.0]), pose) == 2  # left
    assert sector_of(np.array([1.0, -1.0]), pose) == 4  # behind
    assert sector_of(np.array([4.0, 2.0]), pose) == 6  # right
    assert sector_of(np.array([0.0, 3.0]), pose) == 1  # ahead-left


def test_a_decision_is_held_and_its_reward_is_the_sum_of_the_held_steps():
    env = goal_env(hold=5)
    inner_rewards = []
    step = env.env.step

    def recording(actions):
        out = step(actions)
        inner_rewards.append(out[1]["robot_0"])
        return out

    env.env.step = recording
    env.reset(seed=4)
    obs, rewards, *_rest, infos = env.step({"robot_0": 0, "robot_1": 3})
    assert infos["robot_0"]["env_steps"] == 5 == len(inner_rewards)
    assert rewards["robot_0"] == pytest.approx(sum(inner_rewards))
    assert obs["robot_0"]["frontiers"].shape == (SECTORS, len(FRONTIER_FEATURES))
    assert env.observation_space("robot_0").contains(obs["robot_0"])


def test_the_last_decision_stops_at_the_episode_end():
    env = goal_env(hold=7, max_cycles=10)
    env.reset(seed=0)
    env.step({"robot_0": 0, "robot_1": 0})
    *_rest, truncs, infos = env.step({"robot_0": 0, "robot_1": 0})
    assert infos["robot_0"]["env_steps"] == 3 and all(truncs.values()) and not env.agents
    with pytest.raises(RuntimeError, match="call reset"):
        env.step({"robot_0": 0, "robot_1": 0})


def test_same_seed_same_episode():
    def trace(seed):
        env = goal_env(hold=4)
        rng = np.random.default_rng(seed)
        obs, _ = env.reset(seed=seed)
        out = [obs["robot_0"]["frontiers"].tobytes()]
        while env.agents:
            obs, rew, *_rest, infos = env.step({a: int(rng.integers(SECTORS))
                                                for a in env.agents})
            out += [obs["robot_1"]["frontiers"].tobytes(), rew["robot_0"],
                    infos["robot_0"]["pose"].tobytes()]
        return out

    assert trace(3) == trace(3)
    assert trace(3) != trace(4)


@pytest.mark.parametrize(("action", "error", "match"), [
    (8, ValueError, r"action of robot_0: sector must be an int in \[0, 8\), got 8"),
    (-1, ValueError, r"sector must be an int in \[0, 8\), got -1"),
    (1.5, ValueError, r"sector must be an int in \[0, 8\), got 1.5"),
])
def test_bad_actions_name_the_problem(action, error, match):
    env = goal_env()
    env.reset(seed=0)
    with pytest.raises(error, match=match):
        env.step({"robot_0": action, "robot_1": 0})
    with pytest.raises(ValueError, match="one sector per agent"):
        env.step({"robot_0": 0})


def looked_around():
    """A small env after both robots turned on the spot for 15 steps (frontiers in several
    directions): ``(env, observations, infos)``."""
    env = two_robot_explore_v0.parallel_env(**SMALL)
    obs, infos = env.reset(seed=2)
    for _ in range(15):
        obs, _r, _t, _u, infos = env.step({a: np.array([0.0, 1.0]) for a in env.agents})
    return env, obs, infos


def bound_robot(env, agent="robot_0", **kwargs):
    """A :class:`GoalFrontier` bound to ``agent`` of ``env`` and reset."""
    robot = GoalFrontier(**kwargs)
    robot.bind(env, agent)
    robot.reset(0)
    return robot


def test_the_chosen_sector_decides_the_goal():
    env, obs, infos = looked_around()
    info = infos["robot_0"]
    robot = bound_robot(env)
    features = robot.frontier_features(info)
    available = np.flatnonzero(features[:, 0])
    assert len(available) >= 2, features
    pose = np.asarray(info["odometry"])[:3]
    for k in available:
        robot.choose_sector(int(k))
        robot.act(obs["robot_0"], info)
        assert robot.plan is not None
        # the goal is the cheapest cell of a cluster whose centroid lies in sector k
        assert robot.plan.cost == pytest.approx(features[k, 1] * 20.0, abs=1e-6)
        assert sector_of(robot.plan.goal, pose) in {(k - 1) % SECTORS, k, (k + 1) % SECTORS}


def test_frontier_features_mark_the_cheapest_sector_and_the_current_goal():
    env, obs, infos = looked_around()
    robot = bound_robot(env)
    features = robot.frontier_features(infos["robot_0"])
    reachable = features[:, 0] == 1
    assert features.shape == (SECTORS, len(FRONTIER_FEATURES))
    # cost gap: 0 where the cheapest frontier is, the cost difference elsewhere, 1 if none
    assert features[reachable, 3].min() == 0.0
    np.testing.assert_allclose(features[reachable, 3],
                               features[reachable, 1] - features[reachable, 1].min(), atol=1e-6)
    assert np.all(features[~reachable][:, [1, 3]] == 1.0)
    assert features[:, 4].sum() == 0  # no goal yet
    k = int(np.flatnonzero(reachable)[0])
    robot.choose_sector(k)
    robot.act(obs["robot_0"], infos["robot_0"])
    features = robot.frontier_features(infos["robot_0"])
    pose = np.asarray(infos["robot_0"]["odometry"])[:3]
    assert np.flatnonzero(features[:, 4]).tolist() == [sector_of(robot.plan.goal, pose)]


def test_teammate_column_marks_frontiers_near_the_teammates_goal_once_merged():
    from agents.scripted import Blackboard
    from fusion.rigid import Rigid2D

    env, obs, infos = looked_around()
    board = Blackboard()
    robots = {a: bound_robot(env, a, blackboard=board) for a in env.agents}
    me, info = robots["robot_0"], infos["robot_0"]
    before = me.frontier_features(info)
    assert before[:, 5].sum() == 0  # no merge: the teammate's place is unknown
    # as if merged (robot 1's frame = robot 0's) and in contact
    board.frames[0] = {0: Rigid2D.identity(), 1: Rigid2D.identity()}
    board.contacts[0] = (1,)
    fmap = me._frontier_map(info, np.asarray(info["odometry"])[:3])
    target = fmap.clusters(me.cfg.min_cluster_cells)[0]["centroid"]
    board.goals[1] = target  # the teammate heads there (its frame = this one)
    features = me.frontier_features(info)
    k = sector_of(target, np.asarray(info["odometry"])[:3])
    assert features[k, 5] == pytest.approx(1.0)
    assert np.all((features[:, 5] >= 0) & (features[:, 5] <= 1))
    with pytest.raises(ValueError, match=r"agent must be 'robot_<k>' \(k = 0, 1, ...\), got 'r2'"):
        GoalFrontier().bind(env, "r2")


def test_bad_wrapper_arguments_name_the_problem():
    with pytest.raises(ValueError, match="hold must be >= 1, got 0"):
        goal_env(hold=0)
    with pytest.raises(TypeError, match="env must be a two_robot_explore ParallelEnv, got dict"):
        FrontierGoalEnv({})
    with pytest.raises(RuntimeError, match=r"call reset\(\) before step\(\)"):
        goal_env().step({"robot_0": 0, "robot_1": 0})


def test_sector_rules_hold_their_choice_and_repeat_with_a_seed():
    def trace(rule, seed):
        team = {a: SectorRule(rule, hold=5) for a in ("robot_0", "robot_1")}
        chosen = []
        env = two_robot_explore_v0.parallel_env(**SMALL)
        run_episode(env, team, seed=seed,
                    callback=lambda *_: chosen.append(team["robot_0"].controller.sector))
        return chosen

    ahead = trace("ahead", 1)
    assert len(ahead) == SMALL["max_cycles"] and set(ahead) == {0}
    random = trace("random", 1)
    # one choice per 5 steps, several sectors over the episode, the same for the same seed
    assert all(len(set(random[k:k + 5])) == 1 for k in range(0, len(random), 5))
    assert len(set(random)) >= 3
    assert random == trace("random", 1) and random != trace("random", 2)


def test_bad_sector_rule_arguments_name_the_problem():
    with pytest.raises(ValueError, match=r"rule must be one of \['ahead', 'random'\], got 'left'"):
        SectorRule("left")
    with pytest.raises(ValueError, match="hold must be >= 1, got 0"):
        SectorRule("ahead", hold=0)


def test_make_env_builds_either_level_and_names_bad_levels():
    assert isinstance(make_env({"max_cycles": 5}, "goals", hold=3), FrontierGoalEnv)
    assert not isinstance(make_env({"max_cycles": 5}), FrontierGoalEnv)
    with pytest.raises(ValueError, match=r"level must be one of \['goals', 'motion'\], got 'x'"):
        make_env({}, "x")


def test_global_state_adds_the_envs_state_for_a_central_critic():
    env = FrontierGoalEnv(two_robot_explore_v0.parallel_env(**SMALL), hold=3, global_state=True)
    obs, _ = env.reset(seed=2)
    assert env.observation_space("robot_0").contains(obs["robot_0"])
    np.testing.assert_array_equal(obs["robot_0"]["state"], env.unwrapped.state())
    obs, *_ = env.step({"robot_0": 0, "robot_1": 1})
    np.testing.assert_array_equal(obs["robot_1"]["state"], env.unwrapped.state())
    assert "state" not in goal_env().observation_space("robot_0").spaces
    with pytest.raises(ValueError, match="global_state applies to level='goals' only"):
        make_env(SMALL, "motion", global_state=True)
