"""Explorers compared: exploration metrics over seeded worlds, frontier decision time, map-pair
dataset generation speed (process pool vs Ray), team speed in large buildings, and T85 on the
held-out worlds (two commits compared).

    python benchmarks/explorers.py [--worlds 20] [--sizes 10 20] [--workers 1] [--skip-ray]
        [--only metrics|decision|dataset] [--explorers NAME ...] [--json rows.json]
        [--from-json rows.json]
    python benchmarks/explorers.py --only speed [--sizes 20 40 80] [--steps 2000 6000 6000]
        [--explorers frontier coordinated_frontier] [--seed 100] [--robots N] [--json F]
    python benchmarks/explorers.py --only heldout --out rows.json [--explorers frontier ...]
        [--worlds 20] [--skip-real] [--workers 1]
    python benchmarks/explorers.py --compare before.json after.json

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

Steps 1–3 run without ``--only``; the two below are asked for by name.

``--only speed``: how fast a scripted team explores large buildings, against the raw env
stepped with the same actions in the same run. For each building size and explorer one episode
of ``--steps`` steps (``max_cycles``), the team's ``act()`` timed per robot and the env's
``step()`` timed; then a fresh env reset with the same seed is stepped with the recorded actions
alone (the env floor: what the env costs without explorers). Columns: team steps/s and ms/step
(explorers + env), the explorers' share of that time, the env floor (steps/s of the replay), the
true coverage reached, and per robot the planning cost: ``act()`` ms per step, plans, ms per
plan and the robot's known area at the end (so that cost per plan can be read against the area
it plans over). The CPU columns are the same from the process's CPU time
(``time.process_time``): on a machine shared with other jobs they move less than wall time.

``--only heldout``: the scripted explorers on the held-out worlds of ``training_eval.py``
(:func:`training_eval.heldout_worlds`: 20 procedural buildings, sides 10–20 m, plus the real
maps); an episode is :func:`training_eval.episode`, so the numbers are the ones
``training_eval.py`` reports for the scripted explorers. Rows are saved (atomically) to
``--out`` after each episode and reused, so an interrupted run resumes. ``--compare BEFORE
AFTER`` prints, per explorer, the median, mean and interquartile mean of T85 (and T95) over the
worlds of two such files (two commits), the relative change, and how many worlds got faster,
tied or slower.
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
TEAM_EXPLORERS = ("frontier", "coordinated_frontier")
"""The default of ``--only speed`` and ``--only heldout``."""
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


def _env(size: float, steps: int, robots: int | None):
    from envs import two_robot_explore_v0

    kwargs = {"max_cycles": steps, "world": {"size": (size, size)}}
    if robots is not None and robots != 2:
        from envs import multi_robot_explore_v0  # the N-robot env (issue 32)

        return multi_robot_explore_v0.parallel_env(n_robots=robots, **kwargs)
    return two_robot_explore_v0.parallel_env(**kwargs)


def speed_row(explorer: str, size: float, steps: int, seed: int,
            robots: int | None = None) -> dict:
    """One timed episode and its replay on the raw env (``--only speed``, module docstring)."""
    from agents.registry import make_team

    env = _env(size, steps, robots)
    team = make_team(explorer, env=env)
    obs, infos = env.reset(seed=seed)
    for explorer_, s in zip(team.values(), np.random.SeedSequence(seed).spawn(len(team)),
                            strict=True):
        explorer_.reset(int(s.generate_state(1)[0]))
    act_s = dict.fromkeys(team, 0.0)
    act_cpu = 0.0
    env_s = env_cpu = 0.0
    log = []
    coverage = 0.0
    while env.agents:
        actions = {}
        c0 = time.process_time()
        for a in env.agents:
            t0 = time.perf_counter()
            actions[a] = team[a].act(obs[a], infos[a])
            act_s[a] += time.perf_counter() - t0
        c1 = time.process_time()
        act_cpu += c1 - c0
        log.append(actions)
        t0 = time.perf_counter()
        obs, _r, _t, _u, infos = env.step(actions)
        env_s += time.perf_counter() - t0
        env_cpu += time.process_time() - c1
        if infos:
            coverage = float(next(iter(infos.values()))["true_coverage"])
    raw = env.unwrapped
    robots_out = {}
    for a, e in team.items():
        snap = raw.robot_map(a)
        plans = getattr(e, "events", {}).get("plans", 0)
        robots_out[a] = {"act_ms_per_step": act_s[a] / len(log) * 1e3, "plans": plans,
                         "ms_per_plan": act_s[a] / plans * 1e3 if plans else float("nan"),
                         "known_m2": snap.known_cells * snap.grid.resolution ** 2}
    replay = _env(size, steps, robots)
    replay.reset(seed=seed)
    t0, c0 = time.perf_counter(), time.process_time()
    for actions in log:
        replay.step(actions)
    floor_s, floor_cpu = time.perf_counter() - t0, time.process_time() - c0
    total = sum(act_s.values()) + env_s
    return {"explorer": explorer, "size": size, "steps": len(log),
            "steps_per_s": len(log) / total, "ms_per_step": total / len(log) * 1e3,
            "explorer_share": sum(act_s.values()) / total,
            "env_floor_steps_per_s": len(log) / floor_s, "env_in_run_ms": env_s / len(log) * 1e3,
            "cpu_steps_per_s": len(log) / (act_cpu + env_cpu),
            "cpu_explorer_ms": act_cpu / len(log) * 1e3,
            "cpu_env_floor_steps_per_s": len(log) / floor_cpu,
            "coverage": coverage, "robots": robots_out}


def print_speed_table(rows: list[dict]) -> None:
    """The team speed table and the per-robot planning cost table (markdown)."""
    print("| explorer | building | steps | team steps/s | ms/step | explorer share | "
          "env floor steps/s | env ms/step in run | CPU: team steps/s | CPU: explorers "
          "ms/step | CPU: env floor steps/s | true coverage |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['explorer']} | {r['size']:g} m | {r['steps']} | {r['steps_per_s']:.0f} | "
              f"{r['ms_per_step']:.2f} | {r['explorer_share']:.0%} | "
              f"{r['env_floor_steps_per_s']:.0f} | {r['env_in_run_ms']:.2f} | "
              f"{r['cpu_steps_per_s']:.0f} | {r['cpu_explorer_ms']:.2f} | "
              f"{r['cpu_env_floor_steps_per_s']:.0f} | {r['coverage']:.2f} |")
    print("\n| explorer | building | robot | act() ms/step | plans | ms/plan | known m² | "
          "ms/plan per 100 m² known |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        for a, p in r["robots"].items():
            print(f"| {r['explorer']} | {r['size']:g} m | {a} | {p['act_ms_per_step']:.3f} | "
                  f"{p['plans']} | {p['ms_per_plan']:.2f} | {p['known_m2']:.0f} | "
                  f"{p['ms_per_plan'] / max(p['known_m2'], 1e-9) * 100:.3f} |")


def team_speed(parser: argparse.ArgumentParser, args: argparse.Namespace,
               explorers: list[str]) -> None:
    """``--only speed``: every size × explorer row, printed as it ends, then the tables."""
    import torch

    torch.set_num_threads(1)
    sizes = args.sizes or [20.0, 40.0, 80.0]
    steps = args.steps if len(args.steps) > 1 else args.steps * len(sizes)
    if len(steps) != len(sizes):
        parser.error(f"--steps must give one value or one per size ({len(sizes)}), "
                     f"got {len(steps)}")
    rows = []
    for size, n in zip(sizes, steps, strict=True):
        for e in explorers:
            rows.append(speed_row(e, size, n, args.seed, args.robots))
            r = rows[-1]
            print(f"{e} {size:g} m: {r['steps_per_s']:.0f} steps/s, floor "
                  f"{r['env_floor_steps_per_s']:.0f}", flush=True)
    print()
    print_speed_table(rows)
    if args.json is not None:
        from topo.fileio import atomic_write_json

        atomic_write_json(args.json, rows)


def heldout_run(out: Path, explorers: list[str], n_worlds: int, real: bool, workers: int) -> None:
    """Every (explorer, held-out world) episode not yet in ``out``, saved after each."""
    from training_eval import episode as heldout_episode
    from training_eval import heldout_worlds

    from topo.fileio import atomic_write_json

    rows = json.loads(out.read_text()) if out.exists() else {}
    todo = [(e, w) for e in explorers for w in heldout_worlds(n_worlds, real)
            if f"{e}|{w.id}" not in rows]
    print(f"{len(todo)} episodes to run", flush=True)

    def keep(e, w, r, seconds):
        r.pop("curve", None)
        rows[f"{e}|{w.id}"] = {**r, "seconds": seconds}
        atomic_write_json(out, rows)
        print(f"{e} {w.id}: T85 {r['T85']:.0f} ({seconds:.1f} s)", flush=True)

    if workers == 1:
        for e, w in todo:
            t0 = time.perf_counter()
            keep(e, w, heldout_episode(e, w), time.perf_counter() - t0)
        return
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(workers) as pool:
        results = pool.map(heldout_episode, *zip(*todo, strict=True))
        for (e, w), r in zip(todo, results, strict=True):
            keep(e, w, r, float("nan"))


def heldout_compare(before: Path, after: Path) -> None:
    """The T85 (and T95) comparison table of two row files (common worlds only)."""
    from training_eval import iqm

    a, b = json.loads(before.read_text()), json.loads(after.read_text())
    common = sorted(set(a) & set(b))
    print("| explorer | worlds | metric | before median | after median | before mean | "
          "after mean | before IQM | after IQM | IQM change | faster / tied / slower | "
          "wall s before → after |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for e in dict.fromkeys(k.split("|")[0] for k in common):
        keys = [k for k in common if k.startswith(f"{e}|")]
        for m in ("T85", "T95"):
            x = np.array([a[k][m] for k in keys])
            y = np.array([b[k][m] for k in keys])
            secs = (sum(a[k].get("seconds", 0.0) for k in keys),
                    sum(b[k].get("seconds", 0.0) for k in keys))
            print(f"| {e} | {len(keys)} | {m} | {np.median(x):.0f} | {np.median(y):.0f} | "
                  f"{x.mean():.0f} | {y.mean():.0f} | {iqm(x):.0f} | {iqm(y):.0f} | "
                  f"{iqm(y) / iqm(x) - 1:+.1%} | {(y < x).sum()} / {(y == x).sum()} / "
                  f"{(y > x).sum()} | {secs[0]:.0f} → {secs[1]:.0f} |")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", choices=("metrics", "decision", "dataset", "speed", "heldout"),
                        default=None, help="one part (default: metrics, decision, dataset)")
    parser.add_argument("--worlds", type=int, default=20)
    parser.add_argument("--sizes", type=float, nargs="+", default=None,
                        help="building sides in m (default 10 20; --only speed 20 40 80)")
    parser.add_argument("--workers", type=int, default=1,
                        help="episode processes for the metrics and heldout (1: the machine is "
                             "shared); the dataset comparison uses 2")
    parser.add_argument("--skip-ray", action="store_true")
    parser.add_argument("--skip-real", action="store_true", help="procedural worlds only")
    parser.add_argument("--explorers", nargs="+", default=None,
                        help=f"explorers (default: the metrics all of {', '.join(EXPLORERS)}; "
                             f"speed and heldout {' '.join(TEAM_EXPLORERS)})")
    parser.add_argument("--pairs", type=int, default=90, help="pairs per dataset run")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", type=Path, default=None,
                        help="write the episode rows (metrics) or the speed rows here")
    parser.add_argument("--from-json", type=Path, default=None,
                        help="print the table of earlier metrics rows instead of running")
    parser.add_argument("--steps", type=int, nargs="+", default=[2000, 6000, 6000],
                        help="--only speed: episode length per size (one value: the same for all)")
    parser.add_argument("--seed", type=int, default=100, help="--only speed: the world's seed")
    parser.add_argument("--robots", type=int, default=None,
                        help="--only speed: team size (default: the two-robot env)")
    parser.add_argument("--out", type=Path, default=None,
                        help="--only heldout: rows file (JSON) to fill")
    parser.add_argument("--compare", type=Path, nargs=2, metavar=("BEFORE", "AFTER"),
                        help="compare two --only heldout row files")
    args = parser.parse_args(argv)
    if args.from_json is not None:
        print_table(json.loads(args.from_json.read_text()))
        return
    if args.compare:
        heldout_compare(*args.compare)
        return
    if args.only in ("speed", "heldout"):
        explorers = args.explorers or list(TEAM_EXPLORERS)
    else:
        explorers = args.explorers or list(EXPLORERS)
        unknown = [e for e in explorers if e not in EXPLORERS]
        if unknown:
            parser.error(f"--explorers of the metrics table must be among {', '.join(EXPLORERS)}"
                         f", got {' '.join(unknown)}")
    if args.only == "speed":
        team_speed(parser, args, explorers)
        return
    if args.only == "heldout":
        if args.out is None:
            parser.error("--only heldout needs --out FILE (the rows, resumed if it exists)")
        heldout_run(args.out, explorers, args.worlds, not args.skip_real, args.workers)
        return
    if args.only in (None, "metrics"):
        metrics_table(args.worlds, args.sizes or [10.0, 20.0], args.workers, args.json,
                      not args.skip_real, tuple(explorers))
    if args.only in (None, "decision"):
        decision_time()
    if args.only in (None, "dataset"):
        dataset_speed(2, args.skip_ray, args.pairs, args.repeats)


if __name__ == "__main__":
    main()
