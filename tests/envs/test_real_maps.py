"""Every real map in ``shared/maps`` (and a HouseExpo JSON plan) loads and runs an episode."""

import json
from pathlib import Path

import numpy as np
import pytest

from envs import two_robot_explore_v0

MAPS = Path(__file__).resolve().parents[3] / "shared" / "maps"
FILES = sorted(MAPS.glob("ros/*.yaml")) + sorted(MAPS.glob("dungeon/*.png"))


def _episode(source, steps=25, **world):
    par = two_robot_explore_v0.parallel_env(
        world={"source": str(source), **world}, max_cycles=steps,
        mapping={"topo_every": 10, "merge_every": 0})
    obs, infos = par.reset(seed=0)
    rng = np.random.default_rng(0)
    while par.agents:
        obs, rewards, _, _, infos = par.step({a: rng.uniform(-1, 1, 2) for a in par.agents})
        for agent in obs:
            assert par.observation_space(agent).contains(obs[agent])
    poses = np.array([r.true_pose()[:2] for r in par.robots])
    assert par.world.is_free(poses).all()
    assert infos["robot_0"]["true_coverage"] > 0
    return par


def test_the_shared_maps_are_there():
    assert len(FILES) >= 8, f"expected the ROS and DungeonMaps files in {MAPS}"


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_real_map_loads_and_runs(path):
    par = _episode(path, png_resolution=0.1)
    world = par.world
    assert world.reachable_area > 10.0
    assert len(world.segments) > 4


def test_houseexpo_json_runs(tmp_path):
    plan = {"id": "toy", "verts": [[0, 0], [12, 0], [12, 5], [5, 5], [5, 10], [0, 10]]}
    path = tmp_path / "toy.json"
    path.write_text(json.dumps(plan))
    par = _episode(path, steps=40)
    assert par.world.reachable_area == pytest.approx(12 * 5 + 5 * 5, rel=0.05)
