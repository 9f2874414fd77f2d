"""agents.evaluation: fixed worlds, summary rows, the files an evaluation writes."""

import json

import pytest

from agents.evaluation import eval_seeds, eval_worlds, evaluate, summarise
from agents.registry import make_team


def test_eval_seeds_are_fixed_per_run_seed_and_differ_between_seeds():
    assert eval_seeds(3, 4) == eval_seeds(3, 4)
    assert eval_seeds(3, 2) == eval_seeds(3, 4)[:2]
    assert not set(eval_seeds(3, 4)) & set(eval_seeds(4, 4))
    with pytest.raises(ValueError, match="episodes must be >= 1, got 0"):
        eval_seeds(3, 0)


def test_eval_worlds_sets_the_episode_length_and_keys_the_cache():
    config, seeds, key = eval_worlds({"max_cycles": 40, "world": {"size": (8.0, 8.0)}}, 1, 2, 90)
    assert config["max_cycles"] == 90 and config["world"] == {"size": (8.0, 8.0)}
    assert key == {"seeds": seeds, "config": {"max_cycles": 90, "world": {"size": [8.0, 8.0]}}}


def test_summarise_averages_and_refuses_no_episodes():
    eps = [{"T50": 10, "T85": 30, "T95": 41, "final_coverage": 0.9, "overlap": 0.2,
            "collisions": 1, "reached_T85": True},
           {"T50": 20, "T85": 41, "T95": 41, "final_coverage": 0.8, "overlap": 0.4,
            "collisions": 0, "reached_T85": False}]
    row = summarise("x", eps)
    assert row["T50"] == 15 and row["reached_T85"] == 0.5 and row["episodes"] == 2
    with pytest.raises(ValueError, match=r"summarise\('x'\): episodes is empty"):
        summarise("x", [])


def test_evaluate_writes_the_run_files_and_caches_baselines(tmp_path):
    config = {"max_cycles": 20, "world": {"size": (8.0, 8.0)}}
    kwargs = {"env_config": config, "seed": 0, "episodes": 1, "max_cycles": 25,
              "baselines": ("random_walk",)}
    report = evaluate(make_team("frontier"), tmp_path, 7, name="policy", **kwargs)
    assert [r["explorer"] for r in report["rows"]] == ["policy", "random_walk"]
    for name in ("eval.json", "eval.md", "eval_coverage.png", "eval_baselines.json"):
        assert (tmp_path / name).is_file(), name
    assert "| policy |" in (tmp_path / "eval.md").read_text()
    cached = json.loads((tmp_path / "eval_baselines.json").read_text())
    assert len(cached["explorers"]["random_walk"][0]["coverage"]) == 25
    again = evaluate(make_team("frontier"), tmp_path, 8, name="policy", **kwargs)
    assert again["rows"] == report["rows"]  # same worlds, same seeds, baselines from the cache


def test_evaluate_a_team_of_three(tmp_path):
    """With ``n_robots`` 3 every explorer drives three robots of ``multi_robot_explore_v0``, the
    baselines too."""
    from agents.evaluation import run_explorer
    from envs import parallel_env_for

    config = {"max_cycles": 20, "world": {"size": (12.0, 12.0)}, "n_robots": 3,
              "sonar": {"rays": 1}}
    env = parallel_env_for(config)
    team = make_team("frontier", env=env)
    assert list(team) == ["robot_0", "robot_1", "robot_2"]
    assert all(e.bound_env() is env.unwrapped for e in team.values())
    report = evaluate(team, tmp_path, 3, env_config=config, seed=0, episodes=1, max_cycles=15,
                      baselines=("random_walk",))
    assert [r["explorer"] for r in report["rows"]] == ["ppo", "random_walk"]
    (episode,) = run_explorer("random_walk", {**config, "max_cycles": 15}, [0])
    assert sorted(episode["path_length_m"]) == ["robot_0", "robot_1", "robot_2"]
    with pytest.raises(ValueError, match="n_robots must be between 2 and 8, got 9"):
        run_explorer("random_walk", {**config, "n_robots": 9}, [0])


class _Policy:
    """The least a policy needs for ``SB3Explorer``: ``predict``."""

    def predict(self, observation, deterministic=True):
        return [0.0, 0.0], None


@pytest.mark.parametrize("n_robots", [2, 4])
def test_sb3_team_drives_every_robot_with_one_policy(n_robots):
    from agents.sb3_explorer import sb3_team

    policy = _Policy()
    team = sb3_team(policy, n_robots=n_robots)
    assert list(team) == [f"robot_{i}" for i in range(n_robots)]
    assert {id(e.policy) for e in team.values()} == {id(policy)}


@pytest.mark.parametrize(("n_robots", "error"), [(1, ValueError), (9, ValueError),
                                                 (2.0, TypeError)])
def test_sb3_team_size_is_checked(n_robots, error):
    from agents.sb3_explorer import sb3_team

    with pytest.raises(error, match="n_robots must be"):
        sb3_team(_Policy(), n_robots=n_robots)
