"""topo speed: one 8-sonar scan into an OccupancyGrid, and extract_topomap vs skeletonize alone.

Masks are crops of a DungeonMaps floor plan (real corridors and rooms) at 0.1 m/cell, and a
400x400 sonar grid built by scanning that plan (ragged free space, ``ExtractConfig.for_sonar``);
medians over repeats, all in this one process, so the ratio to ``skeletonize`` is fair on a busy
machine. The last row ("env sonar") extracts the env's own grids (the nodes column there is the
number of masks); then the clean-up after thinning on those masks, compiled against the Python
passes it reproduces.

    python benchmarks/topo_speed.py
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
from _timing import interleaved_medians, median_time
from skimage.morphology import skeletonize

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's packages

from topo import OccupancyGrid, load_floor_plan  # noqa: E402
from topo.extract import ExtractConfig, extract_topomap  # noqa: E402

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
        t = interleaved_medians({"ex": lambda free=free: extract_topomap(free, 0.1),
                                 "sk": lambda free=free: skeletonize(free)}, reps)
        t_ex, t_sk = t["ex"], t["sk"]
        print(f"{n:>4}x{n:<5} {m.n_nodes:>6} {t_ex * 1e3:>9.2f} {t_sk * 1e3:>9.2f} "
              f"{t_ex / t_sk:>6.2f} {goal:>12}")
    sonar_row(plan.free)
    env_row()


def sonar_grid(free: np.ndarray, res: float, rng: np.random.Generator,
               scans: int = 400) -> OccupancyGrid:
    """A robot-frame grid filled by ``scans`` 8-sonar scans from random free poses, ranges ray
    marched on ``free`` (cell steps), 5 m range, 15° cones."""
    h, w = free.shape
    g = OccupancyGrid(res, (0.0, 0.0, w * res, h * res))
    cells = np.argwhere(free)
    steps = np.arange(1, int(5.0 / res) + 1) * res
    for _ in range(scans):
        iy, ix = cells[rng.integers(len(cells))]
        x, y, th = (ix + 0.5) * res, (iy + 0.5) * res, rng.uniform(-math.pi, math.pi)
        ranges = np.full(len(SONAR), 5.0)
        for k, a in enumerate(th + SONAR):
            px = ((x + steps * math.cos(a)) / res).astype(int)
            py = ((y + steps * math.sin(a)) / res).astype(int)
            inside = (px >= 0) & (px < w) & (py >= 0) & (py < h)
            hit = ~inside
            hit[inside] = ~free[py[inside], px[inside]]
            if hit.any():
                ranges[k] = steps[int(np.argmax(hit))]
        g.update((x, y, th), ranges, SONAR, 5.0, math.radians(7.5))
    return g


def sonar_row(plan_free: np.ndarray) -> None:
    grid = sonar_grid(np.ascontiguousarray(plan_free[:400, 100:500]), 0.1,
                      np.random.default_rng(1))
    cfg = ExtractConfig.for_sonar()
    free = grid.free_mask()
    m = extract_topomap(grid, config=cfg)
    t = interleaved_medians({"ex": lambda: extract_topomap(grid, config=cfg),
                             "sk": lambda: skeletonize(free)}, 20)
    print(f"{'sonar 400':>10} {m.n_nodes:>6} {t['ex'] * 1e3:>9.2f} {t['sk'] * 1e3:>9.2f} "
          f"{t['ex'] / t['sk']:>6.2f} {'≤20 ms, ≤2×':>12}")


def env_row(steps: int = 1000) -> None:
    """The env's own extractions: the free masks of both robots' sonar grids every 50 steps of a
    default episode (seed 0, random commands), against ``skeletonize`` of the same raw masks."""
    from envs import two_robot_explore_v0
    from topo.grid import CellState

    par = two_robot_explore_v0.parallel_env(max_cycles=steps)
    par.reset(seed=0)
    rng = np.random.default_rng(0)
    masks = []
    for k in range(steps - 1):
        par.step({a: np.array([rng.uniform(0.2, 1.0), rng.uniform(-1, 1)]) for a in par.agents})
        if k % 50 == 49:
            for rmap in par.maps:
                win = rmap.known_window()
                masks.append(np.ascontiguousarray(rmap.states[win] == CellState.FREE))
    cfg = ExtractConfig.for_sonar()
    t = interleaved_medians({"ex": lambda: [extract_topomap(m, 0.1, config=cfg) for m in masks],
                             "sk": lambda: [skeletonize(m) for m in masks]}, 5)
    side = np.mean([np.sqrt(m.size) for m in masks])
    print(f"{'env sonar':>10} {len(masks):>6} {t['ex'] / len(masks) * 1e3:>9.2f} "
          f"{t['sk'] / len(masks) * 1e3:>9.2f} {t['ex'] / t['sk']:>6.2f} "
          f"{'(masks ~' + format(side, '.0f') + ' cells)':>12}")
    clean_up_row(masks, cfg)


def clean_up_row(masks: list[np.ndarray], cfg: ExtractConfig) -> None:
    """The clean-up after thinning (steps 3-7 and the output) on the env masks: the compiled
    passes against the Python ones they reproduce (``_graph_topomap_reference``)."""
    from topo import extract

    inputs = []
    orig = extract._graph_topomap

    def record(*args):
        inputs.append(args)
        return orig(*args)

    extract._graph_topomap = record
    try:
        for m in masks:
            extract_topomap(m, 0.1, config=cfg)
    finally:
        extract._graph_topomap = orig
    t = interleaved_medians(
        {"compiled": lambda: [extract._graph_topomap(*a) for a in inputs],
         "python": lambda: [extract._graph_topomap_reference(*a) for a in inputs]}, 5)
    print(f"\nclean-up after thinning on the {len(inputs)} env masks, median ms per mask")
    print(f"{'compiled':>9} {'python':>9} {'ratio':>6}")
    print(f"{t['compiled'] / len(inputs) * 1e3:>9.3f} {t['python'] / len(inputs) * 1e3:>9.3f} "
          f"{t['python'] / t['compiled']:>6.2f}")


if __name__ == "__main__":
    main()
