"""agents.rllib: light infos and seed streams, the RLModule on both levels, the missing-extra
error, and one RLlib PPO iteration through ``train.py --backend rllib`` on a Ray env runner."""

import importlib
import json
import sys

import numpy as np
import pytest
import torch
from gymnasium import spaces as gym_spaces

from agents import rllib  # fails naming the extra when it is missing
from agents.goals import SECTORS, make_env

torch.set_num_threads(1)
pytestmark = pytest.mark.rllib

CONFIG = {"max_cycles": 40, "world": {"size": (8.0, 8.0)}}


def module(level: str, sector_head: bool = False, commands: str = "continuous",
           **model_config):
    env = make_env(CONFIG, level, hold=5, commands=commands)
    obs, _ = env.reset(seed=0)
    mod = rllib.TopoExplorerModule(
        observation_space=env.observation_space("robot_0"),
        action_space=env.action_space("robot_0"),
        model_config={"sector_head": sector_head, **model_config})
    return mod, obs


def stacked(obs: dict) -> dict:
    return {"obs": {k: torch.as_tensor(np.stack([obs["robot_0"][k], obs["robot_1"][k]]))
                    for k in obs["robot_0"]}}


def test_light_info_keeps_finite_scalars_only():
    info = {"a": 1, "b": np.float32(0.5), "c": float("nan"), "d": True, "e": np.zeros(3),
            "f": object(), "g": np.int64(4), "h": float("inf"), "i": None}
    out = rllib.light_info(info)
    assert out == {"a": 1, "b": 0.5, "d": True, "g": 4}
    assert all(type(v) in (int, float, bool) for v in out.values())


def test_light_info_env_streams_give_different_worlds_and_repeat():
    def first_obs(stream: int, seed: int) -> np.ndarray:
        env = rllib.LightInfoEnv(make_env(CONFIG), stream=stream)
        obs, infos = env.reset(seed=seed)
        assert all("grid" not in i and "topomap" not in i for i in infos.values())
        return obs["robot_0"]["odometry"], infos["robot_0"]["true_area_m2"]

    a = first_obs(0, 5)
    assert first_obs(0, 5)[1] == a[1]
    assert first_obs(1, 5)[1] != a[1]  # another runner, another world
    with pytest.raises(ValueError, match="stream must be an integer >= 0, got -1"):
        rllib.LightInfoEnv(make_env(CONFIG), stream=-1)


@pytest.mark.parametrize(("level", "sector_head", "commands", "logits"),
                         [("goals", True, "continuous", SECTORS),
                          ("goals", False, "continuous", SECTORS),
                          ("motion", False, "continuous", 4),  # Box(2): mean and log-std
                          ("motion", False, "arcs", 5)])  # one logit per command
def test_module_outputs_and_predict(level, sector_head, commands, logits):
    mod, obs = module(level, sector_head, commands)
    batch = stacked(obs)
    out = mod.forward_train(batch)
    assert out["action_dist_inputs"].shape == (2, logits)
    assert torch.isfinite(out["action_dist_inputs"]).all()
    values = mod.compute_values(batch, embeddings=out["embeddings"])
    assert values.shape == (2,)
    torch.testing.assert_close(values, mod.compute_values(batch))
    assert rllib.RLlibPolicy(mod).motion_hold == (10 if level == "goals" else 1)
    policy = rllib.RLlibPolicy(mod, hold=5)
    action, _ = policy.predict(obs["robot_0"])
    assert policy.action_space.contains(np.asarray(action, dtype=policy.action_space.dtype))
    assert policy.predict(obs["robot_0"])[0] == pytest.approx(action)  # the mode: repeatable
    assert policy.motion_commands == commands
    # sampling with a given generator repeats, and follows the distribution
    draws = [policy.sample(obs["robot_0"], np.random.default_rng(7)) for _ in range(2)]
    np.testing.assert_array_equal(draws[0], draws[1])
    rng = np.random.default_rng(0)
    many = np.array([policy.sample(obs["robot_0"], rng) for _ in range(400)])
    assert all(policy.action_space.contains(np.asarray(a, dtype=policy.action_space.dtype))
               for a in many[:20])
    if isinstance(policy.action_space, gym_spaces.Discrete):
        logits = mod.forward_inference(stacked(obs))["action_dist_inputs"][0].double()
        p = torch.softmax(logits, -1).numpy()
        freq = np.bincount(many, minlength=len(p)) / len(many)
        assert np.abs(freq - p).max() < 0.1
    with pytest.raises(TypeError, match="rng must be a numpy.random.Generator, got int"):
        policy.sample(obs["robot_0"], 3)


def test_arcs_reach_the_env_runners_and_drive_through_sb3_explorer():
    from agents.base import run_episode
    from agents.motion import ARCS
    from agents.sb3_explorer import SB3Explorer

    config = rllib.ppo_config(env_config=CONFIG, level="motion", hold=4, commands="arcs")
    env = rllib.env_creator(config.env_config)
    assert env.action_space["robot_0"].n == len(ARCS)
    mod, obs = module("motion", commands="arcs")
    explorer = SB3Explorer(rllib.RLlibPolicy(mod, hold=4))
    assert explorer.commands == "arcs"

    from envs import two_robot_explore_v0

    def sampled_episode() -> np.ndarray:  # a sampled episode repeats for its seed
        env = two_robot_explore_v0.parallel_env(max_cycles=24, world={"size": (8.0, 8.0)})
        policy = rllib.RLlibPolicy(mod, hold=4)
        team = {a: SB3Explorer(policy, deterministic=False) for a in ("robot_0", "robot_1")}
        run_episode(env, team, seed=4)
        return np.array([r.true_pose() for r in env.unwrapped.robots])

    np.testing.assert_array_equal(sampled_episode(), sampled_episode())
    with pytest.raises(ValueError, match="commands='arcs' applies to level='motion' only"):
        rllib.ppo_config(env_config=CONFIG, level="goals", commands="arcs")
    with pytest.raises(ValueError, match=r"commands must be one of \['continuous', 'arcs'\]"):
        rllib.ppo_config(env_config=CONFIG, level="motion", commands="wheels")


def test_module_rejects_bad_model_config():
    with pytest.raises(ValueError, match=r"model_config has unknown keys \['hiddens'\]"):
        module("goals", hiddens=[64])
    with pytest.raises(ValueError, match="sector_head=True needs a Discrete action space"):
        module("motion", sector_head=True)


def test_missing_extra_is_named(monkeypatch):
    monkeypatch.setitem(sys.modules, "tree", None)  # dm-tree absent, as with plain `ray`
    monkeypatch.delitem(sys.modules, "agents.rllib")
    with pytest.raises(ImportError, match=r"needs the 'rllib' extra.*topomerge\[rllib\]"):
        importlib.import_module("agents.rllib")


def test_one_ppo_iteration_on_a_ray_env_runner_then_resume(tmp_path):
    from agents.base import run_episode
    from agents.sb3_explorer import SB3Explorer
    from envs import two_robot_explore_v0
    from train import Args, main

    # 2 envs × 16 decisions = one iteration of 32 env steps, 64 robot decisions, 320 agent-steps
    args = Args(backend="rllib", num_env_runners=1, n_envs=2, level="goals", hold=5,
                total_timesteps=300, n_steps=16, batch_size=32, n_epochs=1, max_cycles=40,
                world_size=(8.0, 8.0), eval_every=0, eval_episodes=1, checkpoint_every=300,
                eval_baselines=("random_walk",), progress=False, runs_dir=tmp_path, seed=3)
    run = main(args)
    for name in ("eval.json", "eval.md", "eval_coverage.png", "args.json",
                 f"rllib/{rllib.POLICY_FILE}"):
        assert (run / name).is_file(), name
    assert "| ppo |" in (run / "eval.md").read_text()
    assert json.loads((run / "eval.json").read_text())["step"] == 320
    assert [p.name for p in (run / "checkpoints").iterdir()] == ["step_000000320"]
    # the only evaluation was the final one: the best policy is a copy of the final one
    assert json.loads((run / "best.json").read_text())["step"] == 320
    assert (run / "rllib_best" / rllib.POLICY_FILE).is_file()

    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    (events,) = {p.parent for p in (run / "tb").rglob("events.out.tfevents.*")}
    acc = EventAccumulator(str(events))
    acc.Reload()
    tags = set(acc.Tags()["scalars"])
    assert {"time/agent_steps_per_s", "explore/true_coverage", "train/policy_loss",
            "rollout/ep_rew_mean"} <= tags
    assert acc.Scalars("time/agent_steps_per_s")[-1].step == 320

    policy = rllib.RLlibPolicy.load(run / "rllib")
    assert policy.goal_hold == 5
    explorer = SB3Explorer(policy)
    assert explorer.goal_level and explorer.hold == 5
    decisions = []
    original = explorer.controller.choose_sector
    explorer.controller.choose_sector = lambda k: (decisions.append(k), original(k))
    env = two_robot_explore_v0.parallel_env(max_cycles=12, world={"size": (8.0, 8.0)})
    run_episode(env, {"robot_0": explorer, "robot_1": SB3Explorer(policy)}, seed=1)
    assert len(decisions) == 3 and all(0 <= k < SECTORS for k in decisions)  # steps 1, 6, 11

    # resuming the run folder restores the step count and trains the rest of the budget
    args.total_timesteps, args.resume = 600, run
    assert main(args) == run
    assert json.loads((run / "eval.json").read_text())["step"] == 640
    assert sorted(p.name for p in (run / "checkpoints").iterdir()) == [
        "step_000000320", "step_000000640"]


def test_missing_rllib_checkpoint(tmp_path):
    with pytest.raises(FileNotFoundError, match="no RLlib checkpoint of train.py"):
        rllib.RLlibPolicy.load(tmp_path)


# ------------------------------------------------------------------------ teams of N robots
TEAM_CONFIG = {"max_cycles": 12, "world": {"size": (12.0, 12.0)}, "sonar": {"rays": 1},
               "comm": {"range": 5.0}}


@pytest.mark.parametrize(("n_robots", "level"), [(3, "motion"), (4, "goals")])
def test_env_creator_and_module_serve_a_team(n_robots, level):
    """The env runners' env is the team's (every robot an agent of the one shared module),
    and the module reads the ``teammates`` rows."""
    config = rllib.ppo_config(env_config={**TEAM_CONFIG, "n_robots": n_robots}, level=level,
                              hold=3)
    env = rllib.env_creator(config.env_config)
    agents = [f"robot_{i}" for i in range(n_robots)]
    assert sorted(env.get_agent_ids()) == agents
    obs, infos = env.reset(seed=2)
    assert sorted(obs) == agents and obs["robot_1"]["teammates"].shape == (n_robots - 1, 7)
    space = env.observation_space["robot_0"]
    mod = rllib.TopoExplorerModule(observation_space=space,
                                   action_space=env.action_space["robot_0"],
                                   model_config={"sector_head": level == "goals"})
    batch = {"obs": {k: torch.as_tensor(np.stack([obs[a][k] for a in agents]))
                     for k in obs["robot_0"]}}
    out = mod.forward_train(batch)
    assert out["action_dist_inputs"].shape[0] == n_robots
    assert torch.isfinite(out["action_dist_inputs"]).all()
    assert mod.compute_values(batch).shape == (n_robots,)
    action, _ = rllib.RLlibPolicy(mod, hold=3).predict(obs["robot_2"])
    obs, rewards, terms, truncs, infos = env.step({a: action for a in agents})
    assert sorted(rewards) == agents


@pytest.mark.parametrize("level", ["motion", "goals"])
def test_train_rllib_team_of_three(tmp_path, level):
    """``train.py --backend rllib --n-robots 3``: one PPO iteration sampled in the driver, the
    policy evaluated on teams of three."""
    from train import Args, main

    hold = {"hold": 2} if level == "goals" else {}
    args = Args(backend="rllib", num_env_runners=0, n_envs=1, level=level, n_robots=3, **hold,
                comm_range=5.0, total_timesteps=40, n_steps=16, batch_size=16, n_epochs=1,
                max_cycles=12, world_size=(12.0, 12.0), env_kwargs={"sonar": {"rays": 1}},
                eval_every=0, eval_episodes=1, eval_max_cycles=12, checkpoint_every=0,
                eval_baselines=("random_walk",), progress=False, runs_dir=tmp_path, seed=3)
    run = main(args)
    assert run.name.startswith("multi_robot_explore_v0_n3__3__")
    report = json.loads((run / "eval.json").read_text())
    assert report["step"] >= 40 and [r["explorer"] for r in report["rows"]] == [
        "ppo", "random_walk"]
    policy = rllib.RLlibPolicy.load(run / "rllib")
    assert policy.observation_space["teammates"].shape == (2, 7)
    assert ("frontiers" in policy.observation_space.spaces) == (level == "goals")
