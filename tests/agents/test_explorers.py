"""Scripted explorers in the real env: episodes run, frontier explores, runs are reproducible."""

import numpy as np
import pytest

from agents.base import run_episode
from agents.metrics import EpisodeRecorder
from agents.scripted import EXPLORERS, FrontierConfig, make_team
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
