"""Precision of ``fusion.merge_grids`` on fine real maps (0.03–0.05 m cells): does refining on
the grids' own cells (``GridMergeConfig.native_refine``) make them as precise as the env's?

    python benchmarks/fine_maps.py [--pairs 8] [--seed 0]

Pairs are cut from the real maps of ``../shared/maps`` at their own scale: the ROS maps
(depot, tb3_sandbox, turtlebot3_world: 0.05 m/px) and the DungeonMaps PNGs read at 0.03 m/px
(640 × 480 px = 19 × 14 m; the format gives no scale). Each pair is two overlapping windows of
the map (each 55–75 % of its width and height), robot B's turned by a random angle: every cell
of each robot's own grid reads the map cell under its centre (nearest neighbour), walls kept
only next to free space (what a sensor sees). Per map and overall: success (< 2°, < 0.3 m at
B's wall centroid) and median errors of the alignment without and with the refinement on the
grids' own cells, against the best rigid fit (ICP on the full-resolution walls started from
the truth: what any rigid alignment of these grids can reach), and the median time. No
calibration is involved: the numbers are of the transform, accepted or not.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fusion.evaluation.pairs import GridSnapshot  # noqa: E402
from fusion.grid_merge import GridMergeConfig, _native_walls, merge_grids  # noqa: E402
from fusion.icp import icp_svd  # noqa: E402
from fusion.rigid import Rigid2D  # noqa: E402
from topo.maps import load_floor_plan  # noqa: E402

MAPS = Path(__file__).resolve().parents[2] / "shared" / "maps"
SOURCES = ([(MAPS / "ros" / f"{n}.yaml", None) for n in ("depot", "tb3_sandbox",
                                                          "turtlebot3_world")]
           + [(p, 0.03) for p in sorted((MAPS / "dungeon").glob("*.png"))])


def plan_states(path: Path, resolution: float | None) -> tuple[np.ndarray, float]:
    """The map as cell-state codes (1 free, 2 wall next to free space, 0 else) and its cell."""
    plan = load_floor_plan(path, resolution)
    states = np.zeros(plan.free.shape, np.int8)
    states[plan.free] = 1
    near_free = ndimage.binary_dilation(plan.free, iterations=2)
    states[plan.occupied & near_free] = 2
    return states, float(plan.resolution)


def view(states: np.ndarray, res: float, frame: Rigid2D, lo, hi) -> GridSnapshot:
    """What a robot whose frame is ``frame`` (its points → map points) knows of the map box
    ``lo..hi`` (map metres, origin at the map's corner): its own grid at ``res``."""
    corners = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [lo[0], hi[1]], [hi[0], hi[1]]])
    own = frame.inverse().apply(corners)
    o = own.min(axis=0) - 2 * res
    n = np.ceil((own.max(axis=0) + 2 * res - o) / res).astype(int)
    rows, cols = np.mgrid[0: n[1], 0: n[0]]
    pts = np.stack([o[0] + (cols + 0.5) * res, o[1] + (rows + 0.5) * res], -1).reshape(-1, 2)
    p = frame.apply(pts)
    ij = np.floor(p / res).astype(int)
    inside = ((p[:, 0] >= lo[0]) & (p[:, 0] < hi[0]) & (p[:, 1] >= lo[1]) & (p[:, 1] < hi[1])
              & (ij[:, 0] < states.shape[1]) & (ij[:, 1] < states.shape[0]))
    out = np.zeros(len(pts), np.int8)
    out[inside] = states[ij[inside, 1], ij[inside, 0]]
    return GridSnapshot(out.reshape(n[1], n[0]), res, (float(o[0]), float(o[1])))


def make_pair(states: np.ndarray, res: float, rng: np.random.Generator):
    """Two overlapping windows, A's frame the map's, B's turned and shifted; the truth B → A."""
    h, w = states.shape[0] * res, states.shape[1] * res
    fa, fb = rng.uniform(0.55, 0.75, 2), rng.uniform(0.55, 0.75, 2)
    a_lo = np.array([0.0, 0.0])
    a_hi = np.array([w * fa[0], h * fa[1]])
    b_hi = np.array([w, h])
    b_lo = b_hi - np.array([w * fb[0], h * fb[1]])
    if rng.random() < 0.5:  # A at the other corner
        a_lo, a_hi, b_lo, b_hi = b_lo, b_hi, a_lo, a_hi
    frame_b = Rigid2D(rng.uniform(-math.pi, math.pi), rng.uniform(-5, 5, 2))
    a = view(states, res, Rigid2D.identity(), a_lo, a_hi)
    b = view(states, res, frame_b, b_lo, b_hi)
    return a, b, frame_b


def errors(t: Rigid2D, truth: Rigid2D, centre: np.ndarray) -> tuple[float, float]:
    return math.degrees(t.rotation_error(truth)), t.translation_error(truth, at=centre)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=8, help="pairs per map")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    variants = {"pooled": GridMergeConfig(native_refine=False), "native": GridMergeConfig()}
    print("| map | cell | pairs | right pooled / native / best fit | median rotation error ° "
          "(pooled / native / best) | median translation error m | median ms pooled / "
          "native |\n|---|---|---|---|---|---|---|")
    total = {k: [] for k in (*variants, "best")}
    times = {k: [] for k in variants}
    for path, res in SOURCES:
        states, cell = plan_states(path, res)
        rows = {k: [] for k in (*variants, "best")}
        for _ in range(args.pairs):
            a, b, truth = make_pair(states, cell, rng)
            walls_a, _ = _native_walls(a)
            walls_b, _ = _native_walls(b)
            if len(walls_a) < 10 or len(walls_b) < 10:
                continue
            centre = walls_b.mean(axis=0)
            best = icp_svd(walls_a, walls_b[:: max(1, len(walls_b) // 6000)], tau=None,
                           rel_tol=1e-7, max_iter=60, init=truth, max_distance=3 * cell,
                           trim=0.9).transform
            rows["best"].append(errors(best, truth, centre))
            for k, cfg in variants.items():
                t0 = time.perf_counter()
                r = merge_grids(a, b, cfg)
                times[k].append(time.perf_counter() - t0)
                rows[k].append(errors(r.transform, truth, centre))
        for k in rows:
            total[k] += rows[k]

        def ok(v):
            return sum(e[0] < 2 and e[1] < 0.3 for e in v)

        def med(v, i):
            return statistics.median(e[i] for e in v) if v else math.nan

        n = len(rows["best"])
        print(f"| {path.stem} | {cell:g} | {n} | {ok(rows['pooled'])} / {ok(rows['native'])} / "
              f"{ok(rows['best'])} | {med(rows['pooled'], 0):.2f} / {med(rows['native'], 0):.2f}"
              f" / {med(rows['best'], 0):.2f} | {med(rows['pooled'], 1):.3f} / "
              f"{med(rows['native'], 1):.3f} / {med(rows['best'], 1):.3f} | "
              f"{1000 * statistics.median(times['pooled'][-n:]):.0f} / "
              f"{1000 * statistics.median(times['native'][-n:]):.0f} |", flush=True)
    n = len(total["best"])
    near = [i for i in range(n) if total["pooled"][i][0] < 10 and total["pooled"][i][1] < 2]
    right = {k: sum(e[0] < 2 and e[1] < 0.3 for e in v) for k, v in total.items()}
    print(f"\nall: {n} pairs; right (< 2°, < 0.3 m): pooled {right['pooled']}, native "
          f"{right['native']}, best fit {right['best']}")
    for k in variants:
        gap = [total[k][i][1] - total["best"][i][1] for i in near]
        print(f"{k}: on the {len(near)} pairs found (< 10°, < 2 m), translation error beyond the "
              f"best fit's: median {statistics.median(gap):.3f} m, 90th percentile "
              f"{np.percentile(gap, 90):.3f} m, more than 0.1 m on {sum(g > 0.1 for g in gap)}")


if __name__ == "__main__":
    main()
