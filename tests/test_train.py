"""train.py: tiny-budget training, reproducibility, resume, SB3Explorer datasets, bad args."""

import re
from pathlib import Path

import numpy as np
import pytest
import torch

from agents.dataset import GenerateArgs, generate
from fusion.evaluation.pairs import load_pairs
from train import Args, main

torch.set_num_threads(1)
TINY = {"total_timesteps": 256, "level": "motion", "n_envs": 1, "n_workers": 1, "n_steps": 64, "batch_size": 64, "n_epochs": 1,
        "eval_every": 0, "eval_episodes": 1, "max_cycles": 40, "world_size": (8.0, 8.0),
        "checkpoint_every": 128, "progress": False, "eval_baselines": ("random_walk",)}


def params(run: Path) -> np.ndarray:
    from stable_baselines3 import PPO

    model = PPO.load(run / "model.zip", device="cpu")
    return torch.nn.utils.parameters_to_vector(model.policy.parameters()).detach().numpy()


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    return main(Args(runs_dir=tmp_path_factory.mktemp("runs"), seed=3, **TINY))


def test_tiny_training_writes_a_run(run_dir):
    assert run_dir.name.startswith("two_robot_explore_v0__3__")
    for name in ("model.zip", "eval.json", "eval.md", "eval_coverage.png", "args.json",
                 "best_model.zip", "best.json"):
        assert (run_dir / name).is_file(), name
    assert sorted(p.name for p in (run_dir / "checkpoints").glob("step_*.zip"))
    assert list((run_dir / "tb").rglob("events.out.tfevents.*"))
    assert "| ppo |" in (run_dir / "eval.md").read_text()


def test_evaluation_runs_longer_episodes_than_training(run_dir):
    import json

    report = json.loads((run_dir / "eval.json").read_text())
    assert report["max_cycles"] == 3 * TINY["max_cycles"]
    (walk,) = json.loads((run_dir / "eval_baselines.json").read_text())["explorers"].values()
    assert len(walk[0]["coverage"]) > TINY["max_cycles"]  # ran past the training horizon


def _report(step, t85, final):
    return {"step": step, "rows": [
        {"explorer": "frontier", "T50": 1.0, "T85": 2.0, "T95": 3.0, "final_coverage": 1.0,
         "reached_T85": 1.0},
        {"explorer": "ppo", "T50": 1.0, "T85": t85, "T95": 3.0, "final_coverage": final,
         "reached_T85": 0.5}]}


def test_keep_best_keeps_lower_t85_then_higher_coverage(tmp_path):
    import json

    from agents.training import keep_best

    saved = []
    for step, t85, final in [(1, 121, 0.5), (2, 121, 0.4), (3, 121, 0.6), (4, 90, 0.3),
                             (5, 95, 0.9), (6, 90, 0.3)]:
        keep_best(_report(step, t85, final), tmp_path, lambda s=step: saved.append(s))
    assert saved == [1, 3, 4]  # ties keep the earlier policy
    best = json.loads((tmp_path / "best.json").read_text())
    assert (best["step"], best["T85"], best["final_coverage"]) == (4, 90, 0.3)


def test_periodic_evaluations_keep_the_best_policy(tmp_path):
    import json

    from stable_baselines3 import PPO

    run = tmp_path / "r"
    (run / "checkpoints").mkdir(parents=True)
    (run / "best.json").write_text(json.dumps({"step": 9, "T85": 0, "final_coverage": 1}))
    (run / "checkpoints" / "step_000000999.zip").write_bytes(b"another run's")
    run = main(Args(runs_dir=tmp_path, run_name="r", overwrite=True, seed=6,
                    **{**TINY, "eval_every": 128}))
    best = json.loads((run / "best.json").read_text())
    assert best["step"] in (128, 256)  # the stale record of an overwritten run is gone
    assert sorted(p.name for p in (run / "checkpoints").iterdir()) == [
        "step_000000128.zip", "step_000000256.zip"]  # and so are its checkpoints
    # the saved policy is the one evaluated at the recorded step (hold 1: a decision a step)
    assert PPO.load(run / "best_model.zip", device="cpu").num_timesteps == best["step"]


def test_same_seed_same_policy(run_dir, tmp_path):
    again = main(Args(runs_dir=tmp_path, seed=3, **TINY))
    np.testing.assert_array_equal(params(run_dir), params(again))
    other = main(Args(runs_dir=tmp_path, seed=4, **TINY))
    assert not np.array_equal(params(run_dir), params(other))


def test_resume_finishes_the_budget(run_dir, tmp_path):
    from stable_baselines3 import PPO

    first = main(Args(runs_dir=tmp_path, seed=5, **{**TINY, "total_timesteps": 128}))
    resumed = main(Args(runs_dir=tmp_path, seed=5, resume=first, **{**TINY,
                                                                      "total_timesteps": 256}))
    assert resumed == first
    assert PPO.load(first / "model.zip").num_timesteps >= 256


def test_goal_level_policy_trains_and_drives_the_plain_env(tmp_path):
    from stable_baselines3 import PPO

    from agents.base import run_episode
    from agents.sb3_explorer import SB3Explorer
    from envs import two_robot_explore_v0

    run = main(Args(runs_dir=tmp_path, seed=2, **{**TINY, "level": "goals", "hold": 5,
                                                   "n_workers": 2,  # a worker process
                                                   "n_steps": 16, "batch_size": 16,
                                                   "checkpoint_every": 0}))
    model = PPO.load(run / "model.zip", device="cpu")
    assert model.goal_hold == 5 and model.num_timesteps * 5 >= TINY["total_timesteps"]
    explorer = SB3Explorer(model)
    assert explorer.goal_level and explorer.hold == 5
    env = two_robot_explore_v0.parallel_env(max_cycles=30, world={"size": (8.0, 8.0)})
    decisions = []
    original = explorer.controller.choose_sector
    explorer.controller.choose_sector = lambda k: (decisions.append(k), original(k))
    run_episode(env, {"robot_0": explorer, "robot_1": SB3Explorer(model)}, seed=1)
    assert len(decisions) == 6  # steps 1, 6, ..., 26 of 30
    assert "| ppo |" in (run / "eval.md").read_text()


def test_sampled_actions_repeat_per_seeded_episode(run_dir):
    from stable_baselines3 import PPO

    from agents.base import run_episode
    from agents.sb3_explorer import sb3_team
    from envs import two_robot_explore_v0

    model = PPO.load(run_dir / "model.zip", device="cpu")

    def pose(seed, deterministic=False):
        env = two_robot_explore_v0.parallel_env(max_cycles=25, world={"size": (8.0, 8.0)})
        infos = run_episode(env, sb3_team(model, deterministic=deterministic), seed=seed)
        return np.asarray(infos["infos"]["robot_0"]["odometry"])

    np.testing.assert_array_equal(pose(1), pose(1))
    assert not np.array_equal(pose(1), pose(2))
    assert not np.array_equal(pose(1), pose(1, deterministic=True))


def test_sb3_explorer_generates_a_pair(run_dir, tmp_path):
    generate(GenerateArgs(out=tmp_path, pairs=1, snapshots=1, max_cycles=30,
                          explorer=f"sb3:{run_dir / 'model.zip'}", world_size=(8.0, 8.0),
                          progress=False))
    (pair,) = load_pairs(tmp_path)
    assert pair.explorer.startswith("sb3:") and pair.step >= 1


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"total_timesteps": -5}, "total_timesteps must be an integer >= 1, got -5"),
        ({"reward_mode": "selfish"}, "reward_mode must be one of"),
        ({"resume": Path("/nowhere/run")}, "resume: no run folder or checkpoint at '/nowhere/run'"),
        ({"learning_rate": 0.0}, r"learning_rate must be in \(0, 1\], got 0.0"),
        ({"eval_baselines": ("oracle",)}, "eval_baselines: unknown explorer 'oracle'"),
        ({"level": "joints"}, r"level must be one of \['goals', 'motion'\], got 'joints'"),
        ({"hold": 0}, "hold must be an integer >= 1, got 0"),
        ({"eval_max_cycles": 0}, "eval_max_cycles must be an integer >= 1, got 0"),
        ({"backend": "jax"}, r"backend must be one of \['sb3', 'rllib'\], got 'jax'"),
        ({"num_env_runners": 2}, "num_env_runners applies to backend='rllib' only, got 2"),
        ({"address": "auto"}, "address applies to backend='rllib' only, got 'auto'"),
        ({"backend": "rllib", "num_env_runners": -1}, "num_env_runners must be an integer >= 0, got -1"),
        ({"backend": "rllib", "n_envs": 2, "num_env_runners": 3}, r"num_env_runners must be <= n_envs \(2\)"),
        ({"backend": "rllib", "address": ""}, "address must be a non-empty string, got ''"),
        ({"world_size_max": 8.0}, r"world_size_max must be a side in metres >= max\(world_size\) "
                                  r"= 10.0, got 8.0"),
        ({"backend": "rllib", "world_size_max": 20.0}, "world_size_max applies to backend='sb3'"),
        ({"cost_prior": -1.0}, "cost_prior must be >= 0.0, got -1.0"),
        ({"level": "motion", "frontier_shaping": -0.5},
         "frontier_shaping must be >= 0.0, got -0.5"),
        ({"motion_commands": "joystick"},
         r"motion_commands must be one of \['continuous', 'arcs'\], got 'joystick'"),
        ({"frontier_shaping": 0.3}, "frontier_shaping applies to level='motion' only"),
        ({"motion_commands": "arcs"}, "motion_commands='arcs' applies to level='motion'"),
        ({"lr_schedule": "cosine"},
         r"lr_schedule must be one of \['constant', 'linear'\], got 'cosine'"),
        ({"backend": "rllib", "lr_schedule": "linear"},
         "lr_schedule='linear' applies to backend='sb3' only"),
        ({"level": "motion", "central_critic": True},
         "central_critic applies to level='goals' with the sector head on backend='sb3' only"),
        ({"ent_coef": float("nan")}, "ent_coef must be finite, got nan"),
        ({"log_std_init": float("inf")}, "log_std_init must be finite, got inf"),
        ({"learning_rate": float("nan")}, "learning_rate must be finite, got nan"),
        ({"world_size": (float("nan"), 10.0)}, r"world_size must be finite, got \(nan, 10.0\)"),
        ({"world_size": (3.0, 3.0)}, r"env settings: world.size\[0\] must be >= 6.0, got 3.0"),
        ({"env_kwargs": {"sonr": {}}}, r"env settings: env_kwargs has unknown keys \['sonr'\]"),
        ({"device": "tpu"}, "device must be 'cpu', 'cuda', 'cuda:N', 'mps' or 'auto', got 'tpu'"),
        ({"device": "cuda:x"}, "device must be 'cpu', 'cuda', 'cuda:N', 'mps' or 'auto', got 'cuda:x'"),
    ],
)
def test_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Args(**kwargs)


@pytest.mark.parametrize(("argv", "match"), [
    (["--world-size", "3", "3"], r"env settings: world.size\[0\] must be >= 6.0, got 3.0"),
    (["--world-size", "nan", "10"], r"world_size must be finite, got \(nan, 10.0\)"),
    (["--ent-coef", "nan"], "ent_coef must be finite, got nan"),
    (["--log-std-init", "nan"], "log_std_init must be finite, got nan"),
    (["--device", "tpu"], "device must be 'cpu', 'cuda', 'cuda:N', 'mps' or 'auto', got 'tpu'"),
])
def test_a_setting_that_cannot_run_is_one_line_and_no_run_folder(tmp_path, capsys, argv, match):
    """Issue 45: settings that used to fail inside the env workers (a traceback per worker and
    a run folder holding only ``args.json``) or halfway inside torch are refused up front."""
    from train import cli

    with pytest.raises(SystemExit) as exit_:
        cli(["--runs-dir", str(tmp_path), "--n-envs", "2", "--no-progress", *argv])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("train.py: error: "), err
    assert re.search(match, err), err
    assert not list(tmp_path.iterdir())


def test_robots_that_cannot_fit_the_world_are_refused_before_the_run(tmp_path):
    """Issue 45: eight robots that fit no 6 x 6 m building at the separation asked for are
    refused when the run starts, naming the settings; nothing is written. (Eight robots at the
    default separation fit: the env retries the start draw.)"""
    kw = {**TINY, "world_size": (6.0, 6.0)}
    with pytest.raises(ValueError, match=r"^env settings: n_robots = 8 do not fit a world.size "
                                         r"\(6.0, 6.0\) building: .* world.min_start_separation 3.0"):
        main(Args(runs_dir=tmp_path, n_robots=8,
                  env_kwargs={"world": {"min_start_separation": 3.0}}, **kw))
    assert not list(tmp_path.iterdir())


def test_an_existing_run_is_refused_unless_overwrite(tmp_path):
    run = tmp_path / "r"
    run.mkdir()
    (run / "model.zip").write_bytes(b"a trained policy")
    with pytest.raises(ValueError, match=r"run_name: the run folder '.*r' exists; pass "
                                         r"--overwrite to replace its run, or --resume"):
        main(Args(runs_dir=tmp_path, run_name="r", **TINY))
    assert (run / "model.zip").read_bytes() == b"a trained policy"


def test_a_run_that_dies_before_training_leaves_no_folder(tmp_path, monkeypatch):
    import agents.training

    def die(*args):
        raise RuntimeError("worker died")

    monkeypatch.setattr(agents.training, "train_sb3", die)
    with pytest.raises(RuntimeError, match="worker died"):
        main(Args(runs_dir=tmp_path, run_name="x", **TINY))
    assert not list(tmp_path.iterdir())


def test_non_numbers_are_type_errors():
    with pytest.raises(TypeError, match="frontier_shaping must be a real number"):
        Args(level="motion", frontier_shaping="1")


def test_motion_commands_choices_are_the_envs():
    import typing

    from agents.motion import COMMANDS

    assert typing.get_args(typing.get_type_hints(Args)["motion_commands"]) == COMMANDS


def test_motion_level_holds_commands_and_shapes(tmp_path):
    from stable_baselines3 import PPO

    assert Args(level="motion").hold == 1 and Args().hold == 10
    run = main(Args(runs_dir=tmp_path, seed=2, **{**TINY, "hold": 4, "frontier_shaping": 0.3,
                                                   "motion_commands": "arcs",
                                                   "n_steps": 16, "batch_size": 16,
                                                   "checkpoint_every": 0,
                                                   "lr_schedule": "linear"}))
    model = PPO.load(run / "model.zip", device="cpu")
    assert model.motion_hold == 4 and model.num_timesteps * 4 >= TINY["total_timesteps"]
    # the rate falls from the start's to 0 with the budget (the last update: none left)
    assert model.lr_schedule(1.0) == pytest.approx(3e-4)
    assert model.lr_schedule(0.25) == pytest.approx(0.25 * 3e-4)
    assert model.policy.optimizer.param_groups[0]["lr"] == 0.0
    assert model.motion_commands == "arcs" and model.action_space.n == 5
    assert "| ppo |" in (run / "eval.md").read_text()


def test_central_critic_trains_and_its_policy_drives_without_the_state(tmp_path):
    from stable_baselines3 import PPO

    from agents.base import run_episode
    from agents.sb3_explorer import sb3_team
    from envs import two_robot_explore_v0

    run = main(Args(runs_dir=tmp_path, seed=2, **{**TINY, "level": "goals", "hold": 5,
                                                   "central_critic": True, "n_steps": 16,
                                                   "batch_size": 16, "checkpoint_every": 0}))
    model = PPO.load(run / "model.zip", device="cpu")
    assert "state" in model.observation_space.spaces and model.policy.mlp_extractor.n_state
    env = two_robot_explore_v0.parallel_env(max_cycles=20, world={"size": (8.0, 8.0)})
    run_episode(env, sb3_team(model), seed=1)  # SB3Explorer fills the critic-only state


def test_world_size_max_spreads_the_training_envs():
    configs = Args(n_envs=3, world_size=(10.0, 12.0), world_size_max=20.0).train_env_configs()
    assert [c["world"]["size"] for c in configs] == [(10.0, 12.0), (15.0, 16.0), (20.0, 20.0)]
    assert [c["max_cycles"] for c in configs] == [500, 667, 833]
    one = Args(n_envs=2, world_size_max=10.0)  # one size: world_size's
    assert one.train_env_configs() == [one.env_config()] * 2


def test_training_spreads_sizes_to_20_m_by_default_where_it_can():
    """The default is the measured recipe (10–20 m buildings) on SB3; RLlib and buildings of
    20 m or more train on ``world_size`` alone."""
    assert [c["world"]["size"] for c in Args(n_envs=3).train_env_configs()] == [
        (10.0, 10.0), (15.0, 15.0), (20.0, 20.0)]
    for args in (Args(backend="rllib", n_envs=2), Args(n_envs=2, world_size=(25.0, 25.0))):
        assert args.size_range_top is None
        assert args.train_env_configs() == [args.env_config()] * 2


def test_rllib_defaults_split_the_envs_between_runners():
    import os

    args = Args(backend="rllib", n_envs=4)
    assert args.num_env_runners == max(1, min(os.cpu_count() or 1, 4))
    assert Args(backend="rllib", n_envs=5, num_env_runners=2).envs_per_runner == 3
    assert Args(backend="rllib", n_envs=3, num_env_runners=0).envs_per_runner == 3


def test_resume_folder_without_checkpoints(tmp_path):
    with pytest.raises(ValueError, match="has no checkpoints"):
        main(Args(runs_dir=tmp_path, resume=tmp_path, **TINY))


# ------------------------------------------------------------------------ teams of N robots
TEAM_TINY = {**TINY, "n_robots": 3, "comm_range": 5.0, "total_timesteps": 48, "n_steps": 16,
             "batch_size": 24, "checkpoint_every": 0, "max_cycles": 12,
             "world_size": (12.0, 12.0), "env_kwargs": {"sonar": {"rays": 1}}}
"""One rollout of 16 decisions of a team of three in one env (48 agent-steps), across an
episode end."""


def test_team_env_config_and_two_robot_config_unchanged():
    two = Args().env_config()
    assert "n_robots" not in two and "comm" not in two  # a two-robot run as before
    team = Args(n_robots=4, comm_range=5.0).env_config()
    assert team["n_robots"] == 4 and team["comm"] == {"range": 5.0}
    assert Args(comm_range=3).env_config()["comm"] == {"range": 3.0}
    assert Args(known_poses=True).env_config()["mapping"] == {"merge_method": "known"}
    assert "mapping" not in Args().env_config()


@pytest.mark.parametrize(("kwargs", "error", "match"), [
    ({"n_robots": 1}, ValueError, "n_robots must be between 2 and 8, got 1"),
    ({"n_robots": 9}, ValueError, "n_robots must be between 2 and 8, got 9"),
    ({"n_robots": 2.5}, TypeError, "n_robots must be an integer, got"),
    ({"comm_range": -1.0}, ValueError, "comm.range must be"),
    ({"known_poses": 1}, TypeError, "known_poses must be True or False, got 1"),
])
def test_bad_team_arguments_name_the_field(kwargs, error, match):
    with pytest.raises(error, match=match):
        Args(**kwargs)


def test_motion_level_team_of_three_trains_one_policy(tmp_path):
    """SB3 at the motion level with three robots: one policy over the 3 robots' slots, which
    then drives a team of three through SB3Explorer; the evaluation ran three robots too."""
    import json

    from stable_baselines3 import PPO

    from agents.base import run_episode
    from agents.sb3_explorer import sb3_team
    from envs import multi_robot_explore_v0

    run = main(Args(runs_dir=tmp_path, seed=4, **TEAM_TINY))
    assert run.name.startswith("multi_robot_explore_v0_n3__4__")
    model = PPO.load(run / "model.zip", device="cpu")
    assert model.observation_space["teammates"].shape == (2, 7)
    assert model.num_timesteps == 48 and model.n_envs == 3
    report = json.loads((run / "eval.json").read_text())
    assert [r["explorer"] for r in report["rows"]] == ["ppo", "random_walk"]
    cached = json.loads((run / "eval_baselines.json").read_text())
    assert cached["key"]["config"]["n_robots"] == 3
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    (events,) = {p.parent for p in (run / "tb").rglob("events.out.tfevents.*")}
    acc = EventAccumulator(str(events))
    acc.Reload()
    assert {"explore/contacts", "explore/fused_robots"} <= set(acc.Tags()["scalars"])
    assert cached["key"]["config"]["comm"] == {"range": 5.0}
    env = multi_robot_explore_v0.parallel_env(n_robots=3, max_cycles=10,
                                              world={"size": (12.0, 12.0)})
    out = run_episode(env, sb3_team(model, n_robots=3), seed=1)
    assert out["steps"] == 10 and sorted(out["infos"]) == ["robot_0", "robot_1", "robot_2"]


def test_goal_level_team_of_three_trains_one_policy(tmp_path):
    from stable_baselines3 import PPO

    run = main(Args(runs_dir=tmp_path, seed=4, **{**TEAM_TINY, "level": "goals", "hold": 2,
                                                   "n_steps": 8, "batch_size": 12,
                                                   "total_timesteps": 48}))
    model = PPO.load(run / "model.zip", device="cpu")
    assert model.observation_space["teammates"].shape == (2, 7) and model.goal_hold == 2
    assert "| ppo |" in (run / "eval.md").read_text()
    # its teammates are a set: the same weights drive a team of five, or of two
    import torch

    from agents.base import run_episode
    from agents.registry import make_team
    from agents.sb3_explorer import SB3Explorer, sb3_team
    from envs import multi_robot_explore_v0

    with pytest.raises(ValueError, match=r"n_robots=5: the policy's observations are for a "
                                         r"team of 3; load it with SB3Explorer.load_policy"):
        sb3_team(model, n_robots=5)
    for n in (5, 2):
        resized = SB3Explorer.load_policy(run / "model.zip", n_robots=n)
        assert resized.observation_space["teammates"].shape == (n - 1, 7)
        for name, value in model.policy.state_dict().items():
            assert torch.equal(value, resized.policy.state_dict()[name]), name
        env = multi_robot_explore_v0.parallel_env(n_robots=n, max_cycles=6,
                                                  world={"size": (12.0, 12.0)})
        out = run_episode(env, make_team(f"sb3:{run / 'model.zip'}", env=env), seed=1)
        assert out["steps"] == 6 and len(out["infos"]) == n
    assert SB3Explorer.load_policy(run / "model.zip", n_robots=3).observation_space == (
        model.observation_space)


def test_a_two_robot_policy_refuses_other_team_sizes():
    from gymnasium import spaces

    from agents.sb3_explorer import team_space

    two = spaces.Dict({"teammate": spaces.Box(-1, 1, (5,))})
    assert team_space(two, 2) is two
    with pytest.raises(ValueError, match="n_robots=4: this policy was trained on "
                                         "two_robot_explore_v0"):
        team_space(two, 4)
    with pytest.raises(ValueError, match="n_robots must be between 2 and 8, got 9"):
        team_space(two, 9)
