"""Explorers compared: exploration metrics over seeded worlds, frontier decision time, and
map-pair dataset generation speed (process pool vs Ray).

    python benchmarks/explorers.py [--worlds 20] [--sizes 10 20] [--workers 1] [--skip-ray]
        [--only metrics|decision|dataset] [--explorers NAME ...] [--json rows.json]
        [--from-json rows.json]

1. For each explorer, episodes on ``--worlds`` procedural buildings per size (seeds 0..N-1;
   ``max_cycles`` 150 steps per metre of building side: 1500 for 10 m, 3000 for 20 m) and on
   the real maps of shared/maps (ROS maps, one DungeonMaps PNG at 0.05 m/pixel; 2000 steps).
   Per explorer: **median** T50/T85/T95 (steps to that true coverage) with the share of
   episodes that never got there (*censored*: counted as ``max_cycles + 1``, so a median
   with more than half censored is only a lower bound, printed ``>N``), mean final coverage,
   overlap of the two robots' explored areas, path length, collisions and the median first
   step a merge was accepted. The Frontier/RandomWalk T85 ratio is of medians; when
   RandomWalk's median is censored the ratio is an upper bound (``≤``). CoordinatedFrontier vs
   Frontier is also compared world by world (same seeds, same starts).
2. ``Frontier`` decision time on a 200 × 200 grid: the median ``act()`` and the median re-plan.
3. Dataset generation: pairs/min with the process backend and with Ray on the same settings,
   alternating, ``--repeats`` times each (Ray's start-up included in its time).

Team speed in large buildings against the raw env is ``explorer_speed.py``; T85 on the
held-out worlds of ``training_eval.py``, and two commits compared, ``explorers_heldout.py``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from _maps import REAL_MAX_CYCLES, real_worlds

EXPLORERS = ("random_walk", "wall_follower", "frontier", "coordinated_frontier")
STEPS_PER_METRE = 150


def worlds(n: int, sizes: list[float], real: bool = True) -> list[tuple[str, str, dict, int]]:
    """``(group, world id, spec, max_cycles)`` of every benchmark world."""
    out = []
    for size in sizes:
        for s in range(n):
            out.append((f"procedural {size:g} m", f"procedural{size:g}:{s}",
                        {"seed": s, "world": {"size": (size, size)}},
                        int(STEPS_PER_METRE * size)))
    if not real:
        return out
    for world_id, world in real_worlds():
        out.append(("real", world_id, {"seed": 0, "world": world}, REAL_MAX_CYCLES))
    return out


def episode(job: tuple[str, str, str, dict, int]) -> dict:
    import torch

    torch.set_num_threads(1)
    from agents.base import run_episode
    from agents.metrics import EpisodeRecorder
    from agents.registry import make_team
    from envs.two_robot_explore_v0 import parallel_env

    explorer, group, world_id, spec, max_cycles = job
    env = parallel_env(max_cycles=max_cycles, world=spec["world"])
    rec = EpisodeRecorder()
    team = make_team(explorer)
    t0 = time.perf_counter()
    run_episode(env, team, seed=spec["seed"], callback=rec)
    s = rec.summary()
    s.pop("coverage")
    s.update(explorer=explorer, group=group, world=world_id, max_cycles=max_cycles,
             seconds=time.perf_counter() - t0, path=sum(s.pop("path_length_m").values()),
             events=[getattr(t, "events", {}) for t in team.values()])
    return s


def _median_cell(rows: list[dict], key: str) -> str:
    """Median steps with the censored share, e.g. ``812 (10%)``; ``>N`` if the median is
    censored."""
    values = [r[key] for r in rows]
    censored = float(np.mean([not r[f"reached_{key}"] for r in rows]))
    med = float(np.median(values))
    text = f">{rows[0]['max_cycles']}" if censored >= 0.5 else f"{med:.0f}"
    return f"{text} ({censored:.0%})"


def print_table(rows: list[dict]) -> None:
    """The metrics table per world group, the T85 ratio and the coordinated comparison."""
    for group in dict.fromkeys(r["group"] for r in rows):
        sel = [r for r in rows if r["group"] == group]
        cycles = sorted({r["max_cycles"] for r in sel})
        n_worlds = len({r["world"] for r in sel})
        print(f"\n{group} worlds ({n_worlds}, max_cycles {cycles}); T: median steps "
              f"(censored share)")
        print(f"{'explorer':<22}{'T50':>13}{'T85':>13}{'T95':>13}{'final':>7}{'overlap':>8}"
              f"{'path m':>8}{'coll.':>7}{'merge@':>8}")
        med: dict[str, dict[str, float]] = {}
        for e in EXPLORERS:
            rs = [r for r in sel if r["explorer"] == e]
            if not rs:
                continue
            mean = {k: float(np.mean([r[k] for r in rs])) for k in
                    ("final_coverage", "overlap", "path", "collisions")}
            merges = [r["merge_first_accept_step"] for r in rs if r["merge_first_accept_step"]]
            merge = f"{np.median(merges):.0f}" if merges else "-"
            med[e] = {k: float(np.median([r[k] for r in rs])) for k in ("T85", "T95")}
            med[e]["censored85"] = float(np.mean([not r["reached_T85"] for r in rs]))
            med[e].update(mean)
            print(f"{e:<22}{_median_cell(rs, 'T50'):>13}{_median_cell(rs, 'T85'):>13}"
                  f"{_median_cell(rs, 'T95'):>13}{mean['final_coverage']:>7.2f}"
                  f"{mean['overlap']:>8.2f}{mean['path']:>8.1f}{mean['collisions']:>7.1f}"
                  f"{merge:>8}")
        if "frontier" in med and "random_walk" in med:
            f, rw = med["frontier"], med["random_walk"]
            bound = "≤" if rw["censored85"] >= 0.5 else "="
            print(f"Frontier T85 / RandomWalk T85 (medians) {bound} {f['T85'] / rw['T85']:.2f} "
                  f"(goal ≤ 0.50; RandomWalk censored in {rw['censored85']:.0%} of worlds, "
                  f"Frontier in {f['censored85']:.0%})")
        if "frontier" in med and "coordinated_frontier" in med:
            c, f = med["coordinated_frontier"], med["frontier"]
            by_world = {(r["world"], r["explorer"]): r for r in sel}
            ids = sorted({r["world"] for r in sel})
            pairs = [(by_world[(w, "coordinated_frontier")], by_world[(w, "frontier")])
                     for w in ids if (w, "coordinated_frontier") in by_world
                     and (w, "frontier") in by_world]
            t95_wins = sum(a["T95"] < b["T95"] for a, b in pairs)
            t95_ties = sum(a["T95"] == b["T95"] for a, b in pairs)
            ov_wins = sum(a["overlap"] < b["overlap"] for a, b in pairs)
            print(f"Coordinated vs Frontier: median T95 {c['T95']:.0f} vs {f['T95']:.0f} "
                  f"(faster in {t95_wins}/{len(pairs)} worlds, tied {t95_ties}); mean overlap "
                  f"{c['overlap']:.2f} vs {f['overlap']:.2f} (lower in {ov_wins}/{len(pairs)}); "
                  f"final coverage {c['final_coverage']:.2f} vs {f['final_coverage']:.2f}")


def metrics_table(n_worlds: int, sizes: list[float], workers: int, json_out: Path | None,
                  real: bool = True, explorers: tuple[str, ...] = EXPLORERS) -> None:
    jobs = [(e, *w) for w in worlds(n_worlds, sizes, real) for e in explorers]
    print(f"1. {len(jobs)} episodes ({len(explorers)} explorers × {len(jobs) // len(explorers)} "
          f"worlds, {workers} worker(s))", flush=True)
    if workers == 1:
        rows = [episode(j) for j in jobs]
    else:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(workers) as pool:
            rows = list(pool.map(episode, jobs))
    if json_out is not None:
        from topo.fileio import atomic_write_bytes

        atomic_write_bytes(json_out, json.dumps(rows, indent=1, default=float).encode())
    print_table(rows)


def decision_time() -> None:
    from agents.frontier_planning import frontier_map
    from agents.scripted import Frontier
    from envs.two_robot_explore_v0 import parallel_env

    env = parallel_env(max_cycles=400, world={"size": (20.0, 20.0)})
    team = {a: Frontier() for a in ("robot_0", "robot_1")}
    obs, infos = env.reset(seed=1)
    for i, (agent, a) in enumerate(team.items()):
        a.bind(env, agent)
        a.reset(i)
    acts, plans = [], []
    while env.agents:
        t0 = time.perf_counter()
        actions = {a: team[a].act(obs[a], infos[a]) for a in env.agents}
        acts.append((time.perf_counter() - t0) / 2)
        obs, _, _, _, infos = env.step(actions)
    grid = env.robot_map("robot_0").grid
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


def dataset_speed(workers: int, skip_ray: bool, pairs: int, repeats: int) -> None:
    from agents.dataset import GenerateArgs, generate

    print(f"\n3. Dataset generation (frontier, procedural 20x20 m, 3 snapshots, max_cycles 600, "
          f"{pairs} pairs, {workers} workers; backends alternating, {repeats} repeats; goal "
          f"≥ 60 pairs/min, ray ≥ 0.80 × process)")
    backends = ("process",) + (() if skip_ray else ("ray",))
    results: dict[str, list[float]] = {b: [] for b in backends}
    for r in range(repeats):
        for backend in backends:
            with tempfile.TemporaryDirectory() as d:
                s = generate(GenerateArgs(out=Path(d), pairs=pairs, workers=workers,
                                          backend=backend, max_cycles=600, progress=False))
            results[backend].append(s["pairs_per_s"] * 60)
            print(f"  repeat {r + 1} {backend:<8} {results[backend][-1]:7.1f} pairs/min "
                  f"({s['seconds']:.1f} s)", flush=True)
    for backend in backends:
        print(f"  {backend:<8} median {statistics.median(results[backend]):7.1f} pairs/min")
    if "ray" in results:
        ratios = [a / b for a, b in zip(results["ray"], results["process"], strict=True)]
        print(f"  ray / process per repeat: {', '.join(f'{x:.2f}' for x in ratios)}; of medians "
              f"{statistics.median(results['ray']) / statistics.median(results['process']):.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worlds", type=int, default=20)
    parser.add_argument("--sizes", type=float, nargs="+", default=[10.0, 20.0])
    parser.add_argument("--workers", type=int, default=1,
                        help="episode processes for the metrics (1: the machine is shared); "
                             "the dataset comparison uses 2")
    parser.add_argument("--skip-ray", action="store_true")
    parser.add_argument("--skip-real", action="store_true", help="procedural worlds only")
    parser.add_argument("--explorers", nargs="+", choices=EXPLORERS, default=list(EXPLORERS),
                        help="explorers of the metrics table (default: all)")
    parser.add_argument("--pairs", type=int, default=90, help="pairs per dataset run")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--only", choices=("metrics", "decision", "dataset"), default=None)
    parser.add_argument("--json", type=Path, default=None, help="write the episode rows here")
    parser.add_argument("--from-json", type=Path, default=None,
                        help="print the table of earlier rows instead of running episodes")
    args = parser.parse_args()
    if args.from_json is not None:
        print_table(json.loads(args.from_json.read_text()))
        return
    if args.only in (None, "metrics"):
        metrics_table(args.worlds, args.sizes, args.workers, args.json, not args.skip_real,
                      tuple(args.explorers))
    if args.only in (None, "decision"):
        decision_time()
    if args.only in (None, "dataset"):
        dataset_speed(2, args.skip_ray, args.pairs, args.repeats)


if __name__ == "__main__":
    main()
