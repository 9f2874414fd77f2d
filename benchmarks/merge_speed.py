"""Merge time against map size for every ``fusion.merge_maps`` method, with ratios to the paper's
exhaustive search measured in the same run.

Pairs are synthetic (:mod:`fusion.evaluation.synthetic`: lattice-like corridor worlds, node noise
0.15 m,
50% overlap, any rotation); each robot explores ``n`` world nodes, so the maps have about ``n``
nodes (the table prints the median real count). Times are medians over the pairs, methods
interleaved pair by pair in this one process, after one warm-up call (compiled kernels load on
the first call), so the ratios are fair on a busy machine; ``auto cpu`` is the process CPU time
of ``auto`` (what the merge costs when it has a core to itself). The exhaustive search is slow
(``n_A × n_B × 181`` placements): it runs up to ``--exhaustive-max`` nodes only.

    python benchmarks/merge_speed.py [--sizes 10,20,40,60,80,120,200] [--pairs 10]

With ``--grids PAIRS_DIR`` (a map-pair dataset that ``python -m agents.dataset generate`` wrote)
it times the occupancy-grid merges the environment runs instead: ``merge_grids`` and
``hybrid_merge`` (with and without ``try_grids``), median and 90th percentile over the pairs;
with ``--reference REV`` also those of that revision, interleaved, and the median ratio.

With ``--reference REV`` (a git revision of this repository) it times ``auto`` against the
``fusion`` package of that revision instead, in this one process, interleaved pair by pair (wall
and CPU medians, and the median over pairs of the ratio of their fastest runs): what a change
costs, fair on a busy machine. With ``--reference REV --env STEPS`` it times, against REV, the
merges the environment makes (``merge_maps`` every 25 steps, ``merge_grids`` every 100 while
unmerged) on the inputs recorded from an env run of seeds 0-2, and counts the results that are
not identical (run with ``PYTHONPATH=.`` from the checkout).

With ``--tool MAP`` (a ROS map YAML or a DungeonMaps PNG) it times the map-merge tool
(:mod:`fusion.mapmerge`) on maps of about ``--cells`` cells a side: the map is enlarged
(nearest cell) to 0.05 m cells until it is 1.4 ``--cells`` on its shorter side, ``--maps``
windows of ``--cells`` × ``--cells`` cells are cut from it at random places and turned by
random angles (each its own frame; occupied cells more than two cells from free space are
made unknown, as a robot sees walls, not solid rock), and it prints the time of every pair's
``merge_grids`` (on fresh grids, and on grids each read once for all its pairs, a
``LayerCache`` per map as ``merge_maps_n`` runs them), of the whole N-map merge
(``merge_maps_n``: all pairs, cycle check, drawing the merged map) and of writing it, and
each placed map's error against the truth; with ``--reference REV`` also those of that
revision, interleaved pair by pair, and the median ratio of the pairs' CPU times.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import math
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from fusion.evaluation.synthetic import SyntheticConfig, make_pair
from fusion.structural import METHODS, merge_maps


def grid_times(pairs_dir: Path, rev: str | None = None) -> None:
    """Print the time of the grid merges on every pair of ``pairs_dir`` (with ``rev``, also
    those of the ``fusion`` package at that git revision, interleaved pair by pair)."""
    from fusion.evaluation.evaluate import load_pair_dir
    from fusion.grid_merge import merge_grids
    from fusion.hybrid import hybrid_merge

    pairs = load_pair_dir(pairs_dir)
    runs = {
        "merge_grids": lambda p: merge_grids(*p.grids),
        "hybrid_merge": lambda p: hybrid_merge(p.map_a, p.map_b, *p.grids, try_grids=True),
        "hybrid (no grids)": lambda p: hybrid_merge(p.map_a, p.map_b, *p.grids,
                                                    try_grids=False),
    }
    with tempfile.TemporaryDirectory() as tmp:
        if rev is not None:
            _reference_merge(rev, Path(tmp))
            ref = importlib.import_module("fusion_ref.grid_merge")
            runs[f"merge_grids@{rev}"] = lambda p: ref.merge_grids(*p.grids)
            ref_hybrid = importlib.import_module("fusion_ref.hybrid")
            runs[f"hybrid_merge@{rev}"] = lambda p: ref_hybrid.hybrid_merge(
                p.map_a, p.map_b, *p.grids, try_grids=True)
        for run in runs.values():  # compiled kernels load on the first call
            run(pairs[0])
        times: dict[str, list[float]] = {name: [] for name in runs}
        accepted = dict.fromkeys(runs, 0)
        for p in pairs:  # interleaved, so a busy machine slows every method alike
            for name, run in runs.items():
                t0 = time.perf_counter()
                accepted[name] += run(p).accepted
                times[name].append(time.perf_counter() - t0)
    print(f"{len(pairs)} pairs from {pairs_dir}")
    print(f"{'method':>26}{'median ms':>11}{'p90 ms':>9}{'accepted':>10}")
    for name, t in times.items():
        p90 = float(np.percentile(t, 90))
        print(f"{name:>26}{1000 * statistics.median(t):>11.1f}{1000 * p90:>9.1f}"
              f"{accepted[name]:>7}/{len(pairs)}")
    if rev is not None:
        for name in ("merge_grids", "hybrid_merge"):
            ratio = statistics.median(a / b for a, b in zip(times[name], times[f"{name}@{rev}"],
                                                            strict=True))
            print(f"{name}: median per-pair time ratio now / {rev}: {ratio:.2f}")


def _reference_merge(rev: str, into: Path):
    """``merge_maps`` of the ``fusion`` package at git revision ``rev``, importable beside the
    current one (copied into ``into`` as ``fusion_ref``, its own imports renamed; its other
    modules then import as ``fusion_ref.*``)."""
    root = Path(__file__).resolve().parent.parent
    names = subprocess.run(["git", "-C", str(root), "ls-tree", "-r", "--name-only", rev,
                            "fusion/"], check=True, capture_output=True, text=True).stdout.split()
    package = into / "fusion_ref"
    for name in names:  # subpackages (fusion/structural) and package data (calibration.json) too
        if not name.endswith((".py", ".json")):
            continue
        text = subprocess.run(["git", "-C", str(root), "show", f"{rev}:{name}"], check=True,
                              capture_output=True, text=True).stdout
        text = text.replace("from fusion ", "from fusion_ref ").replace("from fusion.",
                                                                        "from fusion_ref.")
        target = package / Path(name).relative_to("fusion")
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(text)
    sys.path.insert(0, str(into))
    return importlib.import_module("fusion_ref").merge_maps  # every revision exports it


def reference_times(rev: str, sizes: list[int], n_pairs: int, seed: int,
                    repeats: int = 3) -> None:
    """Print ``auto``'s time now and at revision ``rev`` (module doc)."""
    cfg = SyntheticConfig(noise=0.15)
    with tempfile.TemporaryDirectory() as tmp:
        runs = {"now": merge_maps, rev: _reference_merge(rev, Path(tmp))}
        warm = make_pair(np.random.default_rng(0), cfg, overlap=0.5, nodes=(20, 20))
        for run in runs.values():
            run(warm.map_a, warm.map_b)
        print(f"{'n':>5}" + "".join(f"{k + ' ms':>14}{k + ' cpu':>14}" for k in runs)
              + f"{'ratio':>8}")
        for n in sizes:
            pairs = [make_pair(np.random.default_rng([seed, n, i]), cfg, overlap=0.5,
                               nodes=(n, n)) for i in range(n_pairs)]
            wall = {k: [[] for _ in pairs] for k in runs}
            cpu: dict[str, list[float]] = {k: [] for k in runs}
            for _ in range(repeats):
                for i, p in enumerate(pairs):
                    for k, run in runs.items():
                        t0, c0 = time.perf_counter(), time.process_time()
                        run(p.map_a, p.map_b)
                        wall[k][i].append(time.perf_counter() - t0)
                        cpu[k].append(time.process_time() - c0)
            ratio = statistics.median(min(a) / min(b) for a, b in zip(*wall.values(),
                                                                      strict=True))
            print(f"{n:>5}" + "".join(
                f"{1000 * statistics.median(x for t in wall[k] for x in t):>14.2f}"
                f"{1000 * statistics.median(cpu[k]):>14.2f}" for k in runs) + f"{ratio:>8.2f}")


def _env_merge_calls(steps: int) -> list[dict]:
    """The arguments of every merge the environment makes (``merging.run_merge``, default
    config) in ``steps`` steps of seeds 0, 1, 2 under the fixed actions of
    ``benchmarks/_actions.py`` (its :func:`episode`), the grids copied as they were then."""
    from _actions import episode

    from envs.explore import merging
    from fusion.evaluation.pairs import GridSnapshot

    calls: list[dict] = []
    run_merge = merging.run_merge

    def recording(map_a, map_b, method, grid_a=None, grid_b=None, try_grids=False, **kwargs):
        grids = [GridSnapshot(np.array(g.states()), float(g.resolution),
                              tuple(np.asarray(g.origin, dtype=float))) for g in (grid_a, grid_b)]
        calls.append({"maps": (map_a, map_b), "grids": grids, "try_grids": try_grids})
        return run_merge(map_a, map_b, method, grid_a, grid_b, try_grids=try_grids, **kwargs)

    merging.run_merge = recording
    try:
        for seed in (0, 1, 2):
            for _ in episode(seed, steps):
                pass
    finally:
        merging.run_merge = run_merge
    return calls


def _same(a: object, b: object) -> bool:
    """Equal results, times aside (dataclasses field by field, arrays exactly, NaN = NaN)."""
    if dataclasses.is_dataclass(a):
        return type(a).__name__ == type(b).__name__ and all(
            _same(getattr(a, f.name), getattr(b, f.name))
            for f in dataclasses.fields(a) if f.name != "time_s")
    if hasattr(a, "theta") and hasattr(a, "T"):  # Rigid2D of either package
        return a.theta == b.theta and np.array_equal(a.T, b.T)
    if hasattr(a, "xy") and hasattr(a, "edges"):  # TopoMap
        return all(np.array_equal(getattr(a, n), getattr(b, n))
                   for n in ("xy", "kinds", "edges", "lengths"))
    if isinstance(a, np.ndarray):
        return a.shape == b.shape and np.array_equal(a, b, equal_nan=a.dtype.kind == "f")
    if isinstance(a, float) and math.isnan(a):
        return isinstance(b, float) and math.isnan(b)
    return a == b


def env_times(rev: str, steps: int, repeats: int = 3) -> None:
    """Print the environment's merge cost now and at revision ``rev`` on the merges of an env
    run (:func:`_env_merge_calls`), both in this one process, interleaved call by call (the
    fastest of ``repeats`` runs of each), and whether every result is identical."""
    from fusion.grid_merge import merge_grids
    from fusion.hybrid import hybrid_merge

    calls = _env_merge_calls(steps)
    with tempfile.TemporaryDirectory() as tmp:
        _reference_merge(rev, Path(tmp))
        ref = importlib.import_module("fusion_ref.grid_merge")
        ref_hybrid = importlib.import_module("fusion_ref.hybrid")
        versions = {"now": (hybrid_merge, merge_grids),
                    rev: (ref_hybrid.hybrid_merge, ref.merge_grids)}
        first = calls[0]
        for hybrid, _ in versions.values():  # compiled kernels load on the first call
            hybrid(*first["maps"], *first["grids"], try_grids=True)
        topo = {k: [] for k in versions}
        grid = {k: [] for k in versions}
        differ = 0
        for c in calls:
            results = {}
            for _ in range(repeats):
                for k, (hybrid, grids) in versions.items():
                    t0 = time.perf_counter()
                    h = hybrid(*c["maps"], *c["grids"], try_grids=False)
                    t_topo = time.perf_counter() - t0
                    g, t_grid = None, 0.0
                    if c["try_grids"]:
                        t0 = time.perf_counter()
                        g = grids(*c["grids"])
                        t_grid = time.perf_counter() - t0
                    best = results.get(k)
                    results[k] = (h, g, min(t_topo, best[2]) if best else t_topo,
                                  min(t_grid, best[3]) if best else t_grid)
            (h_now, g_now, *_), (h_ref, g_ref, *_) = results["now"], results[rev]
            differ += not (_same(h_now, h_ref) and _same(g_now, g_ref))
            for k, (_, _, t_topo, t_grid) in results.items():
                topo[k].append(t_topo)
                if c["try_grids"]:
                    grid[k].append(t_grid)
    n_steps = 3 * steps
    print(f"{len(calls)} merges ({sum(c['try_grids'] for c in calls)} with grids) in "
          f"{n_steps} env steps; results differing from {rev}: {differ}")
    print(f"{'':>10}{'merge_maps ms':>15}{'merge_grids ms':>16}{'us per env step':>17}")
    for k in versions:
        per_step = 1e6 * (sum(topo[k]) + sum(grid[k])) / n_steps
        print(f"{k:>10}{1000 * statistics.median(topo[k]):>15.3f}"
              f"{1000 * statistics.median(grid[k]):>16.2f}{per_step:>17.1f}")


def tool_maps(source: Path, n_maps: int, cells: int, seed: int) -> tuple[list, list, str]:
    """``n_maps`` turned windows of ``source`` (module docstring), their true frames and a
    line saying what they are."""
    from scipy import ndimage

    from fusion.mapmerge import InputMap, load_input, rasterise
    from fusion.rigid import Rigid2D

    rng = np.random.default_rng(seed)
    src = load_input(str(source), 0.1, "dungeon")[0]
    zoom = int(math.ceil(1.4 * cells / min(src.states.shape)))
    world = ndimage.zoom(src.states, zoom, order=0, grid_mode=True, mode="nearest")
    # a robot maps walls, not solid rock: occupied cells away from free space are unknown
    seen = ndimage.binary_dilation(world == 1, iterations=2)
    world = np.where((world == 2) & ~seen, 0, world).astype(np.int8)
    res = 0.05
    h, w = world.shape
    truth, maps = [], []
    for k in range(n_maps):
        r0, c0 = int(rng.integers(0, max(1, h - cells))), int(rng.integers(0, max(1, w - cells)))
        sub = InputMap(f"w{k}", "", world[r0:r0 + cells, c0:c0 + cells], res,
                       (c0 * res, r0 * res))
        to_k = Rigid2D(float(rng.uniform(-math.pi, math.pi)), rng.uniform(-20, 20, size=2))
        plan, _ = rasterise([sub], [to_k], Rigid2D.identity(), res)
        states = np.where(plan.occupied, 2, np.where(plan.free, 1, 0)).astype(np.int8)
        maps.append(InputMap(f"w{k}", "", states, res, plan.origin))
        truth.append(to_k)
    shapes = [m.states.shape for m in maps]
    return maps, truth, (f"{n_maps} maps from {source.name} x{zoom}, windows of {cells} x "
                         f"{cells} cells (arrays {min(shapes)} .. {max(shapes)} after turning), "
                         f"{res} m cells")


def tool_times(source: Path, n_maps: int, cells: int, seed: int, rev: str | None = None
               ) -> None:
    """Print the map-merge tool's times on ``n_maps`` turned windows of ``source`` (module
    docstring); with ``rev``, also those of the ``fusion`` package at that git revision,
    interleaved pair by pair, and the ratios of the CPU times."""
    import fusion.grid_merge
    import fusion.mapmerge

    maps, truth, what = tool_maps(source, n_maps, cells, seed)
    print(what)
    versions = {"now": (fusion.grid_merge, fusion.mapmerge)}
    with tempfile.TemporaryDirectory() as tmp:
        if rev is not None:
            _reference_merge(rev, Path(tmp))
            versions[rev] = (importlib.import_module("fusion_ref.grid_merge"),
                             importlib.import_module("fusion_ref.mapmerge"))
        for grid_merge, _ in versions.values():  # compiled kernels load on the first call
            grid_merge.merge_grids(maps[0], maps[1])
        # each pair on fresh grids, and on grids each read once for all its pairs (a
        # LayerCache per map, as merge_maps_n runs them; revisions without one: fresh)
        runs = [(k, fresh) for fresh in (True, False) for k in versions]
        caches = {k: [_layer_cache(grid_merge, m) for m in maps]
                  for k, (grid_merge, _) in versions.items()}
        pair_t = {run: [] for run in runs}
        pair_cpu = {run: [] for run in runs}
        pair_ok = dict.fromkeys(runs, 0)
        for i in range(n_maps):
            for j in range(i + 1, n_maps):
                true = truth[i] @ truth[j].inverse()
                for k, fresh in runs:
                    grids = maps if fresh else caches[k]
                    t0, c0 = time.perf_counter(), time.process_time()
                    r = versions[k][0].merge_grids(grids[i], grids[j])
                    pair_t[k, fresh].append(time.perf_counter() - t0)
                    pair_cpu[k, fresh].append(time.process_time() - c0)
                    pair_ok[k, fresh] += r.accepted and r.transform.translation_error(
                        true, at=maps[j].centre()) <= 0.3
        for k, (grid_merge, mapmerge) in versions.items():
            # the revision's own classes (its Rigid2D composes only with its own)
            rigid = importlib.import_module(grid_merge.__name__.replace("grid_merge", "rigid"))
            its_maps = [mapmerge.InputMap(m.name, m.source, m.states, m.resolution, m.origin)
                        for m in maps]
            its_truth = [rigid.Rigid2D(t.theta, t.T) for t in truth]
            t0, c0 = time.perf_counter(), time.process_time()
            team = mapmerge.merge_maps_n(its_maps)
            t_team, cpu_team = time.perf_counter() - t0, time.process_time() - c0
            with tempfile.TemporaryDirectory() as out:
                t0 = time.perf_counter()
                mapmerge.write_outputs(team, Path(out))
                t_write = time.perf_counter() - t0
            for fresh in (True, False):
                run = k, fresh
                print(f"[{k}] pairs ({'fresh grids' if fresh else 'a cache per map'}): "
                      f"{len(pair_t[run])}, median {1000 * statistics.median(pair_t[run]):.0f} "
                      f"ms, max {1000 * max(pair_t[run]):.0f} ms (CPU median "
                      f"{1000 * statistics.median(pair_cpu[run]):.0f} ms, max "
                      f"{1000 * max(pair_cpu[run]):.0f} ms), accepted within 0.3 m: "
                      f"{pair_ok[run]}")
            print(f"[{k}] merge_maps_n of {n_maps} maps: {t_team:.2f} s (CPU {cpu_team:.2f} s); "
                  f"writing: {t_write:.2f} s; merged "
                  f"{sum(p.merged for p in team.placements)}/{n_maps}, grid "
                  f"{team.merged.free.shape}"
                  if team.merged is not None else f"merge_maps_n: {t_team:.2f} s, nothing merged")
            ref = team.reference
            for m, p in enumerate(team.placements):
                if p.merged:
                    true = its_truth[ref] @ its_truth[m].inverse()
                    err = p.transform.translation_error(true, at=maps[m].centre())
                    print(f"  {p.name}: error {err:.3f} m, "
                          f"{math.degrees(p.transform.rotation_error(true)):.2f} deg, "
                          f"confidence {p.confidence:.2f}")
                else:
                    print(f"  {p.name}: not merged: {p.why}")
    if rev is not None:
        for fresh in (True, False):
            ratio = statistics.median(a / b for a, b in zip(
                pair_cpu["now", fresh], pair_cpu[rev, fresh], strict=True))
            print(f"merge_grids ({'fresh grids' if fresh else 'a cache per map'}): median "
                  f"per-pair CPU time ratio now / {rev}: {ratio:.2f}")


def _layer_cache(grid_merge, grid):
    """``grid`` read once for all its pairs by the ``LayerCache`` of ``grid_merge``'s revision
    (``grid`` itself for revisions without one)."""
    layers = importlib.import_module(grid_merge.__name__.replace("grid_merge", "grid_layers"))
    return layers.LayerCache(grid) if hasattr(layers, "LayerCache") else grid


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="10,20,40,60,80,120,200")
    parser.add_argument("--pairs", type=int, default=10, help="pairs per size")
    parser.add_argument("--exhaustive-max", type=int, default=80,
                        help="largest size the exhaustive search runs at")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--grids", type=Path, default=None, metavar="PAIRS_DIR",
                        help="time the grid merges on a map-pair dataset instead")
    parser.add_argument("--reference", default=None, metavar="REV",
                        help="time auto against the fusion package of this git revision")
    parser.add_argument("--env", type=int, default=0, metavar="STEPS",
                        help="with --reference: time the merges of STEPS env steps per seed "
                             "(seeds 0-2) against REV instead, checking identical results")
    parser.add_argument("--tool", type=Path, default=None, metavar="MAP",
                        help="time the map-merge tool on turned windows of this map instead")
    parser.add_argument("--maps", type=int, default=6, help="with --tool: how many maps")
    parser.add_argument("--cells", type=int, default=1500,
                        help="with --tool: the windows' side in cells")
    args = parser.parse_args()
    if args.tool is not None:
        tool_times(args.tool, args.maps, args.cells, args.seed, args.reference)
        return
    if args.grids is not None:
        grid_times(args.grids, args.reference)
        return
    sizes = [int(s) for s in args.sizes.split(",")]
    if args.env:
        if args.reference is None:
            parser.error("--env needs --reference REV")
        env_times(args.reference, args.env)
        return
    if args.reference is not None:
        reference_times(args.reference, sizes, args.pairs, args.seed)
        return
    cfg = SyntheticConfig(noise=0.15)

    warm = make_pair(np.random.default_rng(0), cfg, overlap=0.5, nodes=(20, 20))
    for m in METHODS:
        merge_maps(warm.map_a, warm.map_b, method=m)

    head = f"{'n':>5}{'nodes A/B':>11}" + "".join(f"{m + ' ms':>18}" for m in METHODS)
    print(head + f"{'auto cpu ms':>13}{'exhaustive/auto':>17}{'auto accepted':>15}")
    for n in sizes:
        pairs = [make_pair(np.random.default_rng([args.seed, n, i]), cfg, overlap=0.5,
                           nodes=(n, n)) for i in range(args.pairs)]
        methods = [m for m in METHODS if m != "exhaustive" or n <= args.exhaustive_max]
        times: dict[str, list[float]] = {m: [] for m in methods}
        cpu: list[float] = []
        accepted = 0
        for p in pairs:
            for m in methods:
                t0, c0 = time.perf_counter(), time.process_time()
                r = merge_maps(p.map_a, p.map_b, method=m)
                times[m].append(time.perf_counter() - t0)
                if m == "auto":
                    cpu.append(time.process_time() - c0)
                    accepted += r.accepted
        med = {m: 1000 * statistics.median(v) for m, v in times.items()}
        nodes = (f"{statistics.median(len(p.map_a) for p in pairs):.0f}/"
                 f"{statistics.median(len(p.map_b) for p in pairs):.0f}")
        ratio = f"{med['exhaustive'] / med['auto']:.0f}x" if "exhaustive" in med else "-"
        print(f"{n:>5}{nodes:>11}" + "".join(
            f"{med[m]:>18.2f}" if m in med else f"{'-':>18}" for m in METHODS)
            + f"{1000 * statistics.median(cpu):>13.2f}{ratio:>17}{accepted:>10}/{len(pairs)}")


if __name__ == "__main__":
    main()
