"""The TorchRL MAPPO example trains on a tiny budget, reproducibly (the ``torchrl`` extra)."""

import math

import pytest

pytest.importorskip("torchrl", reason="needs the torchrl extra: pip install 'topomerge[torchrl]'")

import torch  # noqa: E402

from agents.torchrl_mappo import MappoArgs, main  # noqa: E402

torch.set_num_threads(1)
TINY = {"frames": 200, "frames_per_batch": 100, "minibatch": 50, "epochs": 2, "cells": 16,
        "max_cycles": 40, "world_size": (8.0, 8.0)}


def test_tiny_mappo_run_is_finite_and_reproducible():
    first = main(MappoArgs(**TINY))
    rows = first["iterations"]
    assert [r["frames"] for r in rows] == [100, 200]
    assert all(math.isfinite(r["loss"]) and math.isfinite(r["mean_reward"]) for r in rows)
    assert not math.isnan(rows[0]["episode_reward"])  # 40-step episodes end within a batch
    assert first["agent_steps_per_s"] > 0
    again = main(MappoArgs(**TINY))
    assert again["iterations"] == rows
    for p, q in zip(first["actor"].parameters(), again["actor"].parameters(), strict=True):
        assert torch.equal(p, q)


def test_bad_arguments_name_the_problem():
    with pytest.raises(ValueError, match=r"frames_per_batch \(100\) must be a multiple of minibatch, got minibatch=30"):
        MappoArgs(frames_per_batch=100, minibatch=30)
    with pytest.raises(ValueError, match="gamma must be <= 1.0"):
        MappoArgs(gamma=1.5)


def test_tiny_mappo_run_of_a_team_of_three():
    """Three robots: the actor reads the flattened ``teammates`` (44 + 7 · 2 inputs), one value
    per robot."""
    from agents.torchrl_mappo import make_env

    args = MappoArgs(**{**TINY, "frames": 60, "frames_per_batch": 60, "minibatch": 30,
                        "max_cycles": 20, "world_size": (12.0, 12.0)}, n_robots=3,
                     comm_range=5.0)
    env = make_env(args)
    assert env.group_map == {"robot": ["robot_0", "robot_1", "robot_2"]}
    assert env.observation_spec["robot", "observation_vector"].shape == (3, 44 + 7 * 2)
    env.close()
    (row,) = main(args)["iterations"]
    assert row["frames"] == 60 and math.isfinite(row["loss"])
    assert not math.isnan(row["episode_reward"])  # 20-step episodes end within the batch


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"n_robots": 9}, "n_robots must be between 2 and 8, got 9"),
    ({"comm_range": -2.0}, "comm.range must be"),
])
def test_bad_team_arguments_name_the_field(kwargs, match):
    with pytest.raises(ValueError, match=match):
        MappoArgs(**kwargs)
