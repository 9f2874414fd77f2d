"""Explorers compared: exploration metrics over seeded worlds, frontier decision time, and
map-pair dataset generation speed (process pool vs Ray).

    python benchmarks/explorers.py [--worlds 16] [--max-cycles 1000] [--workers 2] [--skip-ray]

1. For each explorer, episodes on ``--worlds`` procedural buildings (seeds 0..N-1) and on the
   real maps of shared/maps (ROS maps, one DungeonMaps PNG at 0.05 m/pixel): mean T50/T85/T95
   (steps to that true coverage; an episode that never gets there counts as max_cycles + 1),
   share of episodes reaching 85 %, final coverage, overlap of the two robots' explored areas,
   path length, collisions and the first step a merge was accepted.
2. ``Frontier`` decision time on a 200 × 200 grid: the median ``act()`` and the median re-plan.
3. Dataset generation: pairs/min with the process backend and with Ray on the same settings.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

MAPS = Path(__file__).resolve().parents[2] / "shared" / "maps"
EXPLORERS = ("random_walk", "wall_follower", "frontier", "coordinated_frontier")


def worlds(n: int) -> list[tuple[str, dict]]:
    out = [(f"procedural:{s}", {"seed": s, "world": {}}) for s in range(n)]
    for path in sorted((MAPS / "ros").glob("*.yaml")):
        out.append((f"ros/{path.stem}", {"seed": 0, "world": {"source": str(path)}}))
    png = MAPS / "dungeon" / "1.png"
    if png.exists():
        out.append(("dungeon/1", {"seed": 0, "world": {"source": str(png),
                                                       "png_resolution": 0.05}}))
    return out


def episode(job: tuple[str, str, dict, int]) -> dict:
    import torch

    torch.set_num_threads(1)
    from agents.base import run_episode
    from agents.metrics import EpisodeRecorder
    from agents.scripted import make_team
    from envs.two_robot_explore_v0 import parallel_env

    explorer, world_id, spec, max_cycles = job
    env = parallel_env(max_cycles=max_cycles, world=spec["world"])
    rec = EpisodeRecorder()
    t0 = time.perf_counter()
    run_episode(env, make_team(explorer), seed=spec["seed"], callback=rec)
    s = rec.summary()
    s.pop("coverage")
    s.update(explorer=explorer, world=world_id, seconds=time.perf_counter() - t0,
             path=sum(s.pop("path_length_m").values()))
    return s


def metrics_table(n_worlds: int, max_cycles: int, workers: int) -> None:
    jobs = [(e, w, spec, max_cycles) for e in EXPLORERS for w, spec in worlds(n_worlds)]
    print(f"1. {len(jobs)} episodes ({len(EXPLORERS)} explorers × {len(jobs) // len(EXPLORERS)} "
          f"worlds, max_cycles={max_cycles}, {workers} workers)")
    with ProcessPoolExecutor(workers) as pool:
        rows = list(pool.map(episode, jobs))
    for group in ("procedural", "real"):
        sel = [r for r in rows if r["world"].startswith("procedural") == (group == "procedural")]
        if not sel:
            continue
        print(f"\n{group} worlds ({len(sel) // len(EXPLORERS)})")
        print(f"{'explorer':<22}{'T50':>7}{'T85':>7}{'T95':>7}{'≥85%':>6}{'final':>7}"
              f"{'overlap':>8}{'path m':>8}{'coll.':>7}{'merge@':>8}")
        base = {}
        for e in EXPLORERS:
            rs = [r for r in sel if r["explorer"] == e]
            mean = {k: float(np.mean([r[k] for r in rs])) for k in
                    ("T50", "T85", "T95", "final_coverage", "overlap", "path", "collisions")}
            reached = np.mean([r["reached_T85"] for r in rs])
            merges = [r["merge_first_accept_step"] for r in rs if r["merge_first_accept_step"]]
            merge = f"{np.median(merges):.0f}" if merges else "-"
            base[e] = mean
            print(f"{e:<22}{mean['T50']:>7.0f}{mean['T85']:>7.0f}{mean['T95']:>7.0f}"
                  f"{reached:>6.0%}{mean['final_coverage']:>7.2f}{mean['overlap']:>8.2f}"
                  f"{mean['path']:>8.1f}{mean['collisions']:>7.1f}{merge:>8}")
        ratio = base["frontier"]["T85"] / base["random_walk"]["T85"]
        coord, front = base["coordinated_frontier"], base["frontier"]
        print(f"Frontier T85 / RandomWalk T85 = {ratio:.2f} (goal ≤ 0.50); Coordinated vs "
              f"Frontier: T95 {coord['T95']:.0f} vs {front['T95']:.0f}, overlap "
              f"{coord['overlap']:.2f} vs {front['overlap']:.2f}")


def decision_time() -> None:
    from agents.scripted import Frontier, frontier_map
    from envs.two_robot_explore_v0 import parallel_env

    env = parallel_env(max_cycles=400, world={"size": (20.0, 20.0)})
    team = {a: Frontier() for a in ("robot_0", "robot_1")}
    obs, infos = env.reset(seed=1)
    for i, a in enumerate(team.values()):
        a.reset(i)
    acts, plans = [], []
    while env.agents:
        t0 = time.perf_counter()
        actions = {a: team[a].act(obs[a], infos[a]) for a in env.agents}
        acts.append((time.perf_counter() - t0) / 2)
        obs, _, _, _, infos = env.step(actions)
    grid = infos and next(iter(infos.values()))["grid"]
    if not grid:
        _, infos = env.reset(seed=1)
        grid = infos["robot_0"]["grid"]
    # re-plans on a 200 x 200 crop of a grid explored for 400 steps
    from topo.grid import OccupancyGrid

    crop = OccupancyGrid(grid.resolution, (-10.0, -10.0, 10.0, 10.0))
    cy, cx = grid.world_to_cell([[-10.0, -10.0]])[0]
    crop.log_odds[:] = grid.log_odds[cy: cy + 200, cx: cx + 200]
    crop._states[:] = grid.states()[cy: cy + 200, cx: cx + 200]
    cfg = Frontier().cfg
    for _ in range(30):
        t0 = time.perf_counter()
        fmap = frontier_map(crop, np.zeros(2), cfg)
        if fmap is not None:
            fmap.clusters(cfg.min_cluster_cells)
        plans.append(time.perf_counter() - t0)
    print(f"\n2. Frontier on a 200x200 grid: median act() {statistics.median(acts) * 1e3:.3f} ms "
          f"(re-plans included, every {cfg.replan_every} steps or on arrival); median re-plan "
          f"{statistics.median(plans) * 1e3:.2f} ms (goal: decision ≤ 2 ms median)")


def dataset_speed(workers: int, skip_ray: bool) -> None:
    from agents.dataset import GenerateArgs, generate

    print("\n3. Dataset generation (frontier, procedural 20x20 m, 3 snapshots, max_cycles 600)")
    results = {}
    for backend in ("process",) + (() if skip_ray else ("ray",)):
        with tempfile.TemporaryDirectory() as d:
            s = generate(GenerateArgs(out=Path(d), pairs=24, workers=workers, backend=backend,
                                      max_cycles=600, progress=False))
        results[backend] = s["pairs_per_s"] * 60
        print(f"  {backend:<8} {results[backend]:7.1f} pairs/min ({s['seconds']:.1f} s, "
              f"{workers} workers; goal ≥ 60)")
    if "ray" in results:
        print(f"  ray / process = {results['ray'] / results['process']:.2f} (goal ≥ 0.80)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worlds", type=int, default=16)
    parser.add_argument("--max-cycles", type=int, default=1000)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--skip-ray", action="store_true")
    parser.add_argument("--only", choices=("metrics", "decision", "dataset"), default=None)
    args = parser.parse_args()
    if args.only in (None, "metrics"):
        metrics_table(args.worlds, args.max_cycles, args.workers)
    if args.only in (None, "decision"):
        decision_time()
    if args.only in (None, "dataset"):
        dataset_speed(args.workers, args.skip_ray)


if __name__ == "__main__":
    main()
