"""topo speed: one 8-sonar scan into an OccupancyGrid, and extract_topomap vs skeletonize alone.

Masks are crops of a DungeonMaps floor plan (real corridors and rooms) at 0.1 m/cell; medians
over repeats, all in this one process, so the ratio to ``skeletonize`` is fair on a busy machine.

    python benchmarks/topo_speed.py
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from _timing import median_time
from skimage.morphology import skeletonize

from topo import OccupancyGrid, load_floor_plan
from topo.extract import extract_topomap

MAPS = Path(__file__).resolve().parents[2] / "shared" / "maps"
SONAR = np.radians([-90, -50, -30, -10, 10, 30, 50, 90])


def main() -> None:
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

    plan = load_floor_plan(MAPS / "dungeon" / "1.png", resolution=0.1)
    big = np.tile(plan.free, (2, 2))  # 960 x 1280 of real rooms and corridors
    print("\nextract_topomap vs skeletonize alone on the same free mask (0.1 m/cell), median ms")
    print(f"{'mask':>10} {'nodes':>6} {'extract':>9} {'skeleton':>9} {'ratio':>6} {'goal':>12}")
    for n, goal in ((200, "≤5 ms, ≤2×"), (400, "≤20 ms, ≤2×"), (800, "")):
        free = np.ascontiguousarray(big[:n, :n])
        m = extract_topomap(free, 0.1)
        reps = 20 if n < 800 else 5
        t_ex = median_time(lambda free=free: extract_topomap(free, 0.1), reps)
        t_sk = median_time(lambda free=free: skeletonize(free), reps)
        print(f"{n:>4}x{n:<5} {m.n_nodes:>6} {t_ex * 1e3:>9.2f} {t_sk * 1e3:>9.2f} "
              f"{t_ex / t_sk:>6.2f} {goal:>12}")


if __name__ == "__main__":
    main()
