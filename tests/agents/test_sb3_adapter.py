"""ParallelVecEnv: SB3 VecEnv semantics (auto-reset, terminal observation, truncation flag,
seeding) on a small scripted ParallelEnv, in-process and across worker processes."""

import functools

import numpy as np
import pytest
from gymnasium import spaces
from pettingzoo import ParallelEnv

from agents.sb3 import ParallelVecEnv


class CountdownEnv(ParallelEnv):
    """Two agents; the episode terminates when the summed actions reach ``goal`` and truncates
    at ``limit`` steps. Observations: {"t": step, "seed": the reset seed or a draw}."""

    metadata = {"name": "countdown_v0"}

    def __init__(self, goal: float = 3.0, limit: int = 5):
        self.possible_agents = ["a", "b"]
        self.goal, self.limit = goal, limit
        self.render_mode = None
        self.rng = np.random.default_rng()

    def observation_space(self, agent):
        return spaces.Dict({"t": spaces.Box(0, 100, (1,), np.float32),
                            "seed": spaces.Box(-1, 2**31, (1,), np.float32)})

    def action_space(self, agent):
        return spaces.Box(0, 1, (1,), np.float32)

    def _obs(self):
        return {a: {"t": np.array([self.t], np.float32), "seed": np.array([self.s], np.float32)}
                for a in self.agents}

    def reset(self, seed=None, options=None):
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        self.s = seed if seed is not None else float(self.rng.integers(1000))
        self.agents = list(self.possible_agents)
        self.t, self.total = 0, 0.0
        return self._obs(), {a: {"reset": True} for a in self.agents}

    def step(self, actions):
        self.t += 1
        self.total += sum(float(np.asarray(v).sum()) for v in actions.values())
        term = self.total >= self.goal
        trunc = self.t >= self.limit and not term
        obs = self._obs()
        rew = {a: float(self.t) for a in self.agents}
        terms = {a: term for a in self.agents}
        truncs = {a: trunc for a in self.agents}
        infos = {a: {"t": self.t, "map": np.zeros((100, 100))} for a in self.agents}
        if term or trunc:
            self.agents = []
        return obs, rew, terms, truncs, infos


def make(goal=3.0, limit=5):
    return functools.partial(CountdownEnv, goal, limit)


def test_termination_auto_resets_with_terminal_observation():
    venv = ParallelVecEnv([make(goal=5.5)])
    assert venv.num_envs == 2
    venv.seed(7)
    obs = venv.reset()
    assert obs["seed"][:, 0].tolist() == [7, 7]
    for t in (1, 2):
        obs, rew, dones, infos = venv.step(np.ones((2, 1)))
        assert not dones.any() and obs["t"][:, 0].tolist() == [t, t]
    obs, rew, dones, infos = venv.step(np.ones((2, 1)))  # total 6 >= 5.5: terminated
    assert dones.tolist() == [True, True] and rew.tolist() == [3.0, 3.0]
    for info in infos:
        assert info["terminal_observation"]["t"][0] == 3
        assert info["TimeLimit.truncated"] is False
    assert obs["t"][:, 0].tolist() == [0, 0]  # already the next episode


def test_truncation_sets_time_limit_flag():
    venv = ParallelVecEnv([make(goal=1e9, limit=2)])
    venv.reset()
    venv.step(np.zeros((2, 1)))
    _, _, dones, infos = venv.step(np.zeros((2, 1)))
    assert dones.all() and all(i["TimeLimit.truncated"] is True for i in infos)


def test_seeding_gives_each_env_its_own_reproducible_seed():
    venv = ParallelVecEnv([make(), make(), make()])
    assert venv.seed(100) == [100 + i for i in range(6)]
    obs = venv.reset()
    assert obs["seed"][:, 0].tolist() == [100, 100, 102, 102, 104, 104]
    unseeded = venv.reset()["seed"][:, 0]  # seeds are used once (SB3 semantics)
    assert unseeded.tolist() != [100, 100, 102, 102, 104, 104]


def rollout(venv, steps=12):
    venv.seed(3)
    out = [venv.reset()["seed"].copy()]
    rng = np.random.default_rng(0)
    for _ in range(steps):
        obs, rew, dones, infos = venv.step(rng.uniform(0, 1, (venv.num_envs, 1)))
        out += [obs["t"].copy(), obs["seed"].copy(), rew.copy(), dones.copy()]
    return out


def test_worker_processes_match_in_process():
    fns = [make(2.0, 4), make(3.0, 6), make(1.0, 3)]
    local = ParallelVecEnv(fns)
    remote = ParallelVecEnv(fns, n_workers=2)
    try:
        for a, b in zip(rollout(local), rollout(remote), strict=True):
            np.testing.assert_array_equal(a, b)
        assert remote.get_attr("goal") == [2.0, 2.0, 3.0, 3.0, 1.0, 1.0]
        assert remote.env_method("action_space", "a", indices=[5])[0].shape == (1,)
    finally:
        remote.close()


def test_infos_cross_processes_without_their_heavy_values():
    local = ParallelVecEnv([make()])
    remote = ParallelVecEnv([make()], n_workers=2)
    try:
        for venv in (local, remote):
            venv.reset()
        info_local = local.step(np.zeros((2, 1)))[3][0]
        info_remote = remote.step(np.zeros((2, 1)))[3][0]
    finally:
        remote.close()
    assert info_local["t"] == info_remote["t"] == 1
    assert info_local["map"].shape == (100, 100)
    assert "map" not in info_remote


def test_bad_arguments():
    with pytest.raises(TypeError, match="env_fns must be a non-empty sequence"):
        ParallelVecEnv([])
    with pytest.raises(ValueError, match="n_workers must be >= 1, got 0"):
        ParallelVecEnv([make()], n_workers=0)


TEAM = {"world": {"size": (12.0, 12.0)}, "max_cycles": 6, "sonar": {"rays": 1},
        "comm": {"range": 5.0}}
"""A small, fast ``multi_robot_explore_v0`` setting."""


@pytest.mark.parametrize("n_robots", [3, 4])
def test_a_team_of_n_robots_trains_one_shared_policy(n_robots):
    """Every robot of every team is a slot (``N`` per env, ``teammates`` batched), seeded per
    env, ending together; one PPO policy learns on all of them (parameter sharing)."""
    import torch
    from stable_baselines3 import PPO

    from agents.policy import TopoExplorerExtractor
    from envs import multi_robot_explore_v0

    torch.set_num_threads(1)
    fns = [functools.partial(multi_robot_explore_v0.parallel_env, n_robots=n_robots, **TEAM)
           for _ in range(2)]
    venv = ParallelVecEnv(fns)
    assert venv.n_agents == n_robots and venv.num_envs == 2 * n_robots
    assert venv.seed(4)[n_robots] == 4 + n_robots
    obs = venv.reset()
    assert obs["teammates"].shape == (2 * n_robots, n_robots - 1, 7)
    assert obs["sonar"].shape == (2 * n_robots, 8)
    model = PPO("MultiInputPolicy", venv, n_steps=3, batch_size=2 * n_robots, n_epochs=1,
                seed=0, device="cpu",
                policy_kwargs={"features_extractor_class": TopoExplorerExtractor,
                               "net_arch": {"pi": [16], "vf": [16]}})
    model.learn(total_timesteps=3 * venv.num_envs)
    assert model.num_timesteps == 3 * venv.num_envs
    assert model.policy.features_extractor.team
    ended = []
    for _ in range(TEAM["max_cycles"]):  # learn stopped 3 steps into the episodes
        actions, _ = model.predict(obs, deterministic=True)
        obs, rewards, dones, infos = venv.step(actions)
        assert rewards.shape == (2 * n_robots,) and dones.all() == dones.any()
        ended.append(bool(dones.all()))
        if dones.all():
            assert all(i["TimeLimit.truncated"] and "terminal_observation" in i for i in infos)
    assert ended == [False, False, True, False, False, False]
    venv.close()
