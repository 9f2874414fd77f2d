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
