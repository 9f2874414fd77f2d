"""TorchRL's ``PettingZooWrapper`` around the env: specs, rollouts with the global state and
every info as a tensor, auto-reset across an episode end (the ``torchrl`` extra)."""

import pytest
from conftest import SMALL

torch = pytest.importorskip("torch")
pytest.importorskip("torchrl", reason="needs the torchrl extra: pip install 'topomerge[torchrl]'")

from torchrl.envs.libs.pettingzoo import PettingZooWrapper  # noqa: E402
from torchrl.envs.utils import check_env_specs  # noqa: E402

from envs import two_robot_explore_v0  # noqa: E402
from envs.explore.env import STATE_MAP_SIZE, STATE_SCALARS  # noqa: E402

torch.set_num_threads(1)


def wrapped(max_cycles):
    return PettingZooWrapper(
        env=two_robot_explore_v0.parallel_env(**{**SMALL, "max_cycles": max_cycles}),
        return_state=True, seed=0)


def test_pettingzoo_wrapper_rollout_has_observations_state_and_infos():
    env = wrapped(30)
    assert env.group_map == {"robot": ["robot_0", "robot_1"]}
    check_env_specs(env)
    td = env.rollout(8)
    assert td.batch_size == torch.Size([8])
    obs = td["robot", "observation"]
    assert obs["sonar"].shape == (8, 2, 8) and obs["local_map"].shape == (8, 2, 1, 64, 64)
    assert td["state"].shape == (8, STATE_SCALARS + 3 * STATE_MAP_SIZE ** 2)
    info = td["next", "robot", "info"]
    assert info["true_coverage"].shape == (8, 2) and (info["true_coverage"] > 0).all()
    assert info["pose"].shape == (8, 2, 3) and not info["merge_errors_valid"].any()
    # the robots move: their true poses change over the rollout
    assert not torch.equal(info["pose"][0], info["pose"][-1])
    env.close()


def test_rollout_resets_across_episode_ends():
    env = wrapped(5)
    td = env.rollout(12, break_when_any_done=False)
    done = td["next", "done"].squeeze(-1)
    assert done.tolist() == [False] * 4 + [True] + [False] * 4 + [True] + [False] * 2
    env.close()


@pytest.mark.parametrize("n_robots", [3, 4])
def test_pettingzoo_wrapper_groups_a_team(n_robots):
    from envs import multi_robot_explore_v0
    from envs.explore.env import state_scalars

    env = PettingZooWrapper(
        env=multi_robot_explore_v0.parallel_env(
            n_robots=n_robots, world={"size": (12.0, 12.0)}, max_cycles=6,
            sonar={"rays": 1}, comm={"range": 5.0}),
        return_state=True, seed=0)
    assert env.group_map == {"robot": [f"robot_{i}" for i in range(n_robots)]}
    check_env_specs(env)
    td = env.rollout(8, break_when_any_done=False)
    obs = td["robot", "observation"]
    assert obs["teammates"].shape == (8, n_robots, n_robots - 1, 7)
    assert td["state"].shape == (8, state_scalars(n_robots) + 3 * STATE_MAP_SIZE ** 2)
    info = td["next", "robot", "info"]
    assert info["contacts"].shape == (8, n_robots) and info["pose"].shape == (8, n_robots, 3)
    assert td["next", "done"].squeeze(-1).tolist() == [False] * 5 + [True] + [False] * 2
    env.close()
