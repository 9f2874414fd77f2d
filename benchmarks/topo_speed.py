"""topo speed: one 8-sonar scan into an OccupancyGrid, and extract_topomap on the env's grids.

The extraction is timed on what the env hands it: the windows of known cells of both robots'
sonar grids, recorded every 25 steps of a Frontier episode in a 20 m building (seed 0, 1500
steps), and on crops of a DungeonMaps floor plan. Beside it, in this one process and
interleaved (so a busy machine slows both alike), ``scipy.ndimage.distance_transform_edt`` of
the same window's occupied cells: the one library pass every extraction needs, as a floor.

    python benchmarks/topo_speed.py
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
from _timing import interleaved_medians, median_time
from scipy import ndimage

from topo import OccupancyGrid, load_floor_plan
from topo.extract import extract_topomap

MAPS = Path(__file__).resolve().parents[2] / "shared" / "maps"
SONAR = np.radians([-90, -50, -30, -10, 10, 30, 50, 90])


def main() -> None:
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()
    rng = np.random.default_rng(0)
    print("OccupancyGrid.update, one 8-sonar scan (15° cones, 5 m range), median µs")
    print(f"{'grid':>10} {'µs/scan':>9} {'goal':>6}")
    for n in (200, 400, 800):
        g = OccupancyGrid(0.1, (-n / 20, -n / 20, n / 20, n / 20))
        poses = rng.uniform(-3, 3, (500, 3))
        ranges = rng.uniform(0.3, 5.0, (500, 8))
        k = iter(range(10**9))

        def scan(g=g, poses=poses, ranges=ranges, k=k):
            i = next(k) % 500
            g.update(poses[i], ranges[i], SONAR, 5.0, math.radians(7.5))
        t = median_time(scan, 2000)
        print(f"{n:>4}x{n:<5} {t * 1e6:>9.1f} {'≤100' if n == 200 else '':>6}")

    print("\nextract_topomap on the env's own windows (goal: <= 2 ms a call), median over repeats")
    print(f"{'windows':>22} {'calls':>6} {'nodes':>6} {'extract ms':>11} {'p90 ms':>7} "
          f"{'edt ms':>7} {'ratio':>6}")
    windows = env_windows()
    for label, lo, hi in (("all", 0, 10**9), ("< 150 x 150 cells", 0, 150 * 150),
                          (">= 150 x 150 cells", 150 * 150, 10**9)):
        sel = [w for w in windows if lo <= w[0].size < hi]
        if not sel:
            continue
        ex, edt = [], []
        for states, res, origin in sel:
            t = interleaved_medians(
                {"ex": lambda s=states, r=res, o=origin: extract_topomap(s, r, o),
                 "edt": lambda s=states: ndimage.distance_transform_edt(s != 2)}, 5)
            ex.append(t["ex"])
            edt.append(t["edt"])
        nodes = np.median([extract_topomap(*w).n_nodes for w in sel])
        print(f"{label:>22} {len(sel):>6} {nodes:>6.0f} {np.median(ex) * 1e3:>11.2f} "
              f"{np.percentile(ex, 90) * 1e3:>7.2f} {np.median(edt) * 1e3:>7.2f} "
              f"{np.median(ex) / np.median(edt):>6.1f}")

    plan = load_floor_plan(MAPS / "dungeon" / "1.png", resolution=0.1)
    print("\nextract_topomap on floor-plan crops (DungeonMaps 1, 0.1 m/cell), median ms")
    print(f"{'mask':>10} {'nodes':>6} {'extract':>9}")
    for n in (200, 400):
        free = np.ascontiguousarray(plan.free[:n, :n])
        m = extract_topomap(free, 0.1)
        t = median_time(lambda free=free: extract_topomap(free, 0.1), 10)
        print(f"{n:>4}x{n:<5} {m.n_nodes:>6} {t * 1e3:>9.2f}")


def env_windows(steps: int = 1500, every: int = 25) -> list[tuple[np.ndarray, float, tuple]]:
    """``(states, resolution, origin)`` of both robots' known windows every ``every`` steps of a
    Frontier episode (seed 0, 20 m building), copied."""
    from agents.registry import make_team
    from envs import two_robot_explore_v0

    env = two_robot_explore_v0.parallel_env(max_cycles=steps, mapping={"merge_every": 0,
                                                                        "topo_every": 0})
    team = make_team("frontier", env=env)
    observations, infos = env.reset(seed=0)
    for explorer in team.values():
        explorer.reset(seed=0)
    out = []
    while env.agents:
        observations, _, _, _, infos = env.step(
            {a: team[a].act(observations[a], infos[a]) for a in env.agents})
        if env.steps % every == 0:
            for rmap in env.maps:
                win = rmap.known_window()
                if win is not None:
                    g = rmap.geometry
                    origin = (g.origin[0] + win[1].start * g.resolution,
                              g.origin[1] + win[0].start * g.resolution)
                    out.append((rmap.states[win].copy(), g.resolution, origin))
    return out


if __name__ == "__main__":
    main()
