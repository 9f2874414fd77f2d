"""Team size: how much faster do N robots explore a building than two?

    python benchmarks/team_size.py [--quick] [--ns 2 3 4 6 8] [--sizes 20 40]
        [--explorers frontier coordinated_frontier] [--comms unlimited 5] [--seeds 3]
        [--first-seed 100] [--cycles-per-metre 150] [--out FILE] [--jobs 1] [--table-only]

One episode of ``multi_robot_explore_v0`` per cell × seed: ``n_robots`` N, a procedural
``size`` m building (``world.size = (size, size)``), communication unlimited (``comm.range =
None``) or range-limited (``comm.range`` metres), ``max_cycles = cycles_per_metre · size``
(3000 steps at 20 m, 6000 at 40 m), defaults otherwise, driven by a scripted team: ``frontier``
(one :class:`agents.scripted.Frontier` per robot, each on its own map),
``coordinated_frontier`` (``agents.registry.make_team``) or ``coordinated_frontier@known`` (the
same with the relative start poses known, ``mapping.merge_method="known"``: teammates placed
from the first step instead of by merging). Per episode: T50 / T85 / T95, the first
step the true coverage (``info["true_coverage"]``) reaches 50 / 85 / 95 % (the episode ends at
95 %), the final coverage, the first step robot 0's fused map holds the whole team, and the
CPU seconds.

A :class:`~agents.scripted.Frontier` robot plans on its own map alone, and communication
changes no physics, sensing or random draw, so its team drives exactly the same paths at any
range: Frontier runs with unlimited communication only (a range-limited run would repeat it
step for step); what the range costs is measured on the coordinated team, which reads the
merge.

The seed picks the building (drawn first from the env's generator, so every N explores the same
building for a seed; the start poses differ). Seeds from 100 are held out: the explorers and
the merge were tuned on seeds 0–19 (``merge_in_loop.py``, ``explorers.py``).

N = 1 is not measured: the env needs two robots (``n_robots`` 2–8), and a "team of one" read
off a two-robot run (robot 0's own map) would still have a teammate's body in its sonar and
its path.

Each finished episode is one JSON line in ``--out`` (the file rewritten atomically after each
row), so an interrupted run resumes where it stopped and a later run with more seeds adds only
the missing episodes; ``--table-only`` prints the tables of what the file holds. Episodes run
seed-major (every cell's first seed before any cell's second), so a run cut short still covers
every cell. A team that ``make_team`` cannot build for N robots (a coordinated team of two
only, say) is reported and skipped, not recorded, so a later run fills it in.

Tables: per cell the median T50 / T85 / T95 over its seeds (an episode that never reached the
level counts as ``max_cycles + 1`` and makes the median a lower bound, marked ``>``), the
episodes that reached it, the mean final coverage; then per explorer, size and communication
the per-seed ratio T85(N) / T85(2) (same seed: same building), its median and each seed's (an
unreached level makes a ratio a bound: ``<`` when T85(2) was not reached, ``>`` when T85(N)
was not, ``?`` both; ``~`` marks a median a bound enters); and per explorer, size and N the
ratio T85(range-limited) / T85(unlimited), what the range costs.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

from _poses import split_poses, with_merge_method

from topo.fileio import atomic_write_json_lines, read_json_lines

LEVELS = (0.5, 0.85, 0.95)
"""The coverage levels timed (T50, T85, T95)."""
LEVEL_KEYS = ("t50", "t85", "t95")
EXPLORER_NAMES = ("frontier", "coordinated_frontier", "coordinated_frontier@known")
"""``@known``: the same team with the robots' relative start poses known
(``mapping.merge_method="known"``): what not knowing them costs."""
DEFAULT_OUT = Path(tempfile.gettempdir()) / "topomerge-team_size.jsonl"
QUICK = {"ns": [2, 4, 8], "seeds": 2}
"""What ``--quick`` sets: teams of 2, 4 and 8, two seeds a cell."""


# ----------------------------------------------------------------------------- the results file
def append_row(path: Path, rows: list[dict[str, Any]], row: dict[str, Any]) -> None:
    """Add ``row`` to ``rows`` and rewrite ``path`` with them all, atomically (a crash leaves
    the file as it was before or after, never half a line)."""
    rows.append(row)
    atomic_write_json_lines(path, rows, sort_keys=True)


def run_all(fn: Callable[..., dict[str, Any]], tasks: list[tuple], jobs: int
            ) -> Iterator[tuple[tuple, dict[str, Any] | Exception]]:
    """``fn(*task)`` for every task, ``jobs`` at a time in worker processes (``1``: here, in
    order); yields ``(task, row)`` as each finishes, ``(task, exception)`` for one that raised
    ``ValueError``, ``KeyError`` or ``TypeError`` (the rest propagate)."""
    expected = (ValueError, KeyError, TypeError)
    if jobs == 1:
        for task in tasks:
            try:
                yield task, fn(*task)
            except expected as exc:
                yield task, exc
        return
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        futures = {pool.submit(fn, *task): task for task in tasks}
        for fut in as_completed(futures):
            try:
                yield futures[fut], fut.result()
            except expected as exc:
                yield futures[fut], exc


# ----------------------------------------------------------------------------- one episode
def comm_range(comm: str) -> float | None:
    """``--comms`` value → ``comm.range`` (``"unlimited"``: ``None``)."""
    if comm == "unlimited":
        return None
    value = float(comm)
    if not value > 0:
        raise ValueError(f"--comms values must be 'unlimited' or a range > 0 m, got {comm!r}")
    return value


def build_team(explorer: str, env: Any) -> dict[str, Any]:
    """One explorer per robot of ``env``, bound to it; ``ValueError`` when ``make_team`` cannot
    build the team for this many robots."""
    if explorer == "frontier":
        from agents.scripted import Frontier

        team = {a: Frontier() for a in env.possible_agents}
        for a, x in team.items():
            x.bind(env, a)
        return team
    from agents.registry import make_team

    team = make_team(split_poses(explorer)[0], env=env)
    if sorted(team) != sorted(env.possible_agents):
        raise ValueError(f"make_team({explorer!r}) gave explorers for {sorted(team)}, the env "
                         f"has {env.possible_agents}")
    return team


def cell_key(row: dict[str, Any]) -> tuple:
    """What identifies an episode: explorer, size, communication, N, seed, max_cycles."""
    return (row["explorer"], row["size"], row["comm"], row["n"], row["seed"], row["max_cycles"])


def run_cell(explorer: str, size: float, comm: str, n: int, seed: int,
             max_cycles: int) -> dict[str, Any]:
    """One episode's row (module docstring)."""
    from agents.base import run_episode
    from envs import multi_robot_explore_v0, two_robot_explore_v0

    kwargs = {"world": {"size": (size, size)}, "comm": {"range": comm_range(comm)},
              "max_cycles": max_cycles}
    kwargs = with_merge_method(kwargs, split_poses(explorer)[1])
    row = {"explorer": explorer, "size": size, "comm": comm, "n": n, "seed": seed,
           "max_cycles": max_cycles, "env": "multi_robot_explore_v0", "t50": None,
           "t85": None, "t95": None, "fused_all": None}

    def watch(k: int, _obs, _rewards, infos) -> None:
        info = infos.get("robot_0")
        if info is None:
            return
        cov = info["true_coverage"]
        for level, key in zip(LEVELS, LEVEL_KEYS, strict=True):
            if row[key] is None and cov >= level:
                row[key] = k
        fused = info.get("fused_robots", 2 if info["merge_accepted"] else 1)
        if row["fused_all"] is None and fused == n:
            row["fused_all"] = k

    cpu = time.process_time()
    env = multi_robot_explore_v0.parallel_env(n_robots=n, **kwargs)
    try:
        out = run_episode(env, build_team(explorer, env), seed=seed, callback=watch)
    except KeyError as exc:
        if not (split_poses(explorer)[0] == "coordinated_frontier" and n == 2
                and "teammate" in str(exc)):
            raise
        # a coordinated team that reads the two-robot layout (one ``teammate`` observation):
        # the same env as the N = 2 subclass
        row["env"] = "two_robot_explore_v0"
        env = two_robot_explore_v0.parallel_env(**kwargs)
        cpu = time.process_time()
        out = run_episode(env, build_team(explorer, env), seed=seed, callback=watch)
    row.update(steps=out["steps"], coverage=float(out["infos"]["robot_0"]["true_coverage"]),
               cpu_s=round(time.process_time() - cpu, 2))
    return row


# ----------------------------------------------------------------------------- tables
def _fmt_median(values: list[tuple[int | None, int]]) -> str:
    """Median of ``(step or None, max_cycles + 1)`` pairs, an unreached level counted as
    ``max_cycles + 1``; ``>`` when that makes the median a lower bound."""
    filled = sorted((never if v is None else v, v is None) for v, never in values)
    k = len(filled) // 2
    middle = filled[k - 1:k + 1] if len(filled) % 2 == 0 else filled[k:k + 1]
    med = statistics.median(f for f, _ in filled)
    return (">" if any(c for _, c in middle) else "") + f"{med:.0f}"


def _group(rows: Iterable[dict[str, Any]]) -> dict[tuple, list[dict[str, Any]]]:
    cells: dict[tuple, list[dict[str, Any]]] = defaultdict(list)
    for r in rows:
        cells[(r["explorer"], r["size"], r["comm"], r["n"])].append(r)
    return cells


def _comm_order(comm: str) -> float:
    return math.inf if comm == "unlimited" else float(comm)


def _sort_key(cell: tuple) -> tuple:
    explorer, size, comm, n = cell
    return (EXPLORER_NAMES.index(explorer) if explorer in EXPLORER_NAMES else 9, size,
            -_comm_order(comm), n)


def cell_table(rows: list[dict[str, Any]]) -> str:
    """The per-cell table (module docstring)."""
    lines = ["| explorer | size m | comm | N | seeds | T50 | T85 | T95 | reached 50/85/95 % | "
             "final coverage | all fused (median step) | CPU s / episode |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    cells = _group(rows)
    for cell in sorted(cells, key=_sort_key):
        rs = cells[cell]
        reached = "/".join(str(sum(r[k] is not None for r in rs)) for k in LEVEL_KEYS)
        fused = _fmt_median([(r["fused_all"], r["max_cycles"] + 1) for r in rs])
        explorer, size, comm, n = cell
        lines.append(
            f"| {explorer} | {size:g} | {comm} | {n} | {len(rs)} | "
            + " | ".join(_fmt_median([(r[k], r["max_cycles"] + 1) for r in rs])
                         for k in LEVEL_KEYS)
            + f" | {reached} | {statistics.mean(r['coverage'] for r in rs):.3f} | {fused} | "
            f"{statistics.mean(r['cpu_s'] for r in rs):.0f} |")
    return "\n".join(lines)


def _paired(a: list[dict[str, Any]], b: list[dict[str, Any]], key: str
            ) -> list[tuple[float, str]]:
    """Per-seed ``a[key] / b[key]`` over the seeds both have, by seed, each with a mark: ``""``
    exact; an unreached level counts as ``max_cycles + 1``, which makes the ratio an upper
    bound ``"<"`` (the denominator's), a lower bound ``">"`` (the numerator's) or unknown
    ``"?"`` (both)."""
    bs = {r["seed"]: r for r in b}
    out = []
    for r in sorted(a, key=lambda r: r["seed"]):
        other = bs.get(r["seed"])
        if other is None:
            continue
        num = r[key] if r[key] is not None else r["max_cycles"] + 1
        den = other[key] if other[key] is not None else other["max_cycles"] + 1
        mark = {(False, False): "", (False, True): "<", (True, False): ">",
                (True, True): "?"}[(r[key] is None, other[key] is None)]
        out.append((num / den, mark))
    return out


def _fmt_ratios(ratios: list[tuple[float, str]]) -> str:
    """The median of the per-seed ratios (``~`` when a bound enters it; unknown ones left
    out) and each seed's."""
    if not ratios:
        return "-"
    known = [(v, m) for v, m in ratios if m != "?"]
    each = ", ".join(f"{m}{v:.2f}" if m != "?" else "?" for v, m in ratios)
    if not known:
        return f"? ({each})"
    approx = "~" if any(m for _, m in known) else ""
    return f"{approx}{statistics.median(v for v, _ in known):.2f} ({each})"


def ratio_tables(rows: list[dict[str, Any]], key: str = "t85") -> str:
    """T85(N) / T85(2) per explorer, size and communication; T85(limited) / T85(unlimited)
    per explorer, size and N (module docstring)."""
    cells = _group(rows)
    ns = sorted({c[3] for c in cells if c[3] != 2})
    name = key.upper()
    lines = [f"{name}(N) / {name}(2), median (each seed's; same seed, same building):", "",
             "| explorer | size m | comm | " + " | ".join(f"N = {n}" for n in ns) + " |",
             "|---|---|---|" + "---|" * len(ns)]
    for explorer, size, comm in sorted({c[:3] for c in cells},
                                       key=lambda c: _sort_key((*c, 0))):
        base = cells.get((explorer, size, comm, 2), [])
        lines.append(f"| {explorer} | {size:g} | {comm} | " + " | ".join(
            _fmt_ratios(_paired(cells.get((explorer, size, comm, n), []), base, key))
            for n in ns) + " |")
    limited = sorted({c[2] for c in cells if c[2] != "unlimited"}, key=_comm_order)
    if limited:
        all_ns = sorted({c[3] for c in cells})
        lines += ["", f"{name}(range-limited) / {name}(unlimited), median (each seed's):",
                  "", "| explorer | size m | comm | " + " | ".join(
                      f"N = {n}" for n in all_ns) + " |",
                  "|---|---|---|" + "---|" * len(all_ns)]
        for explorer, size in sorted({c[:2] for c in cells},
                                     key=lambda c: _sort_key((*c, "unlimited", 0))):
            for comm in limited:
                ratios = [_fmt_ratios(_paired(cells.get((explorer, size, comm, n), []),
                                              cells.get((explorer, size, "unlimited", n), []),
                                              key)) for n in all_ns]
                if any(r != "-" for r in ratios):
                    lines.append(f"| {explorer} | {size:g} | {comm} m | " + " | ".join(ratios)
                                 + " |")
    return "\n".join(lines)


# ----------------------------------------------------------------------------- main
def planned(args: argparse.Namespace) -> list[tuple]:
    """Every episode asked for, seed-major: ``(explorer, size, comm, n, seed, max_cycles)``."""
    out = []
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        for explorer in args.explorers:
            for size in args.sizes:
                for comm in args.comms:
                    if explorer == "frontier" and comm != "unlimited":
                        continue  # the same paths at any range (module docstring)
                    for n in args.ns:
                        out.append((explorer, size, comm, n, seed,
                                    int(round(args.cycles_per_metre * size))))
    return out


def add_run_arguments(parser: argparse.ArgumentParser, out: Path) -> None:
    """The options every resumable team benchmark shares: ``--out`` (default ``out``),
    ``--jobs``, ``--table-only``."""
    parser.add_argument("--out", type=Path, default=out,
                        help="JSON-lines results, resumed if it exists")
    parser.add_argument("--jobs", type=int, default=1, help="episodes run in parallel")
    parser.add_argument("--table-only", action="store_true",
                        help="print the tables of --out, run nothing")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help=f"teams {QUICK['ns']}, {QUICK['seeds']} seeds a cell "
                             "(explicit --ns / --seeds win)")
    parser.add_argument("--ns", type=int, nargs="+", default=None,
                        help="team sizes, 2-8 (default 2 3 4 6 8)")
    parser.add_argument("--sizes", type=float, nargs="+", default=[20.0, 40.0],
                        help="building sides, m")
    parser.add_argument("--explorers", nargs="+", choices=EXPLORER_NAMES,
                        default=list(EXPLORER_NAMES[:2]))
    parser.add_argument("--comms", nargs="+", default=["unlimited", "5"],
                        help="'unlimited' or comm.range in m")
    parser.add_argument("--seeds", type=int, default=None, help="seeds a cell (default 3)")
    parser.add_argument("--first-seed", type=int, default=100,
                        help="first seed (100 and on: held out from tuning)")
    parser.add_argument("--cycles-per-metre", type=float, default=150.0,
                        help="max_cycles = this × size")
    add_run_arguments(parser, DEFAULT_OUT)
    args = parser.parse_args(argv)
    if args.ns is None:
        args.ns = QUICK["ns"] if args.quick else [2, 3, 4, 6, 8]
    if args.seeds is None:
        args.seeds = QUICK["seeds"] if args.quick else 3
    for n in args.ns:
        if not 2 <= n <= 8:
            parser.error(f"--ns values must be 2-8 (the env's n_robots), got {n}")
    if args.seeds < 1 or args.jobs < 1:
        parser.error(f"--seeds and --jobs must be >= 1, got {args.seeds}, {args.jobs}")
    try:
        for comm in args.comms:
            comm_range(comm)
    except ValueError as exc:
        parser.error(str(exc))
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    rows = read_json_lines(args.out)
    if not args.table_only:
        done = {cell_key(r) for r in rows}
        todo = [c for c in planned(args) if c not in done]
        print(f"# team size: {len(todo)} episodes to run, {len(rows)} in {args.out}",
              flush=True)
        t0 = time.perf_counter()
        for c, row in run_all(run_cell, todo, args.jobs):
            if isinstance(row, Exception):
                print(f"skipped {c}: {type(row).__name__}: {row}", flush=True)
                continue
            append_row(args.out, rows, row)
            print(f"{c}: steps {row['steps']}, T85 {row['t85']}, coverage "
                  f"{row['coverage']:.3f}, {row['cpu_s']:.0f} s CPU "
                  f"({time.perf_counter() - t0:.0f} s)", flush=True)
    wanted = set(planned(args))
    shown = rows if args.table_only else [r for r in rows if cell_key(r) in wanted]
    if not shown:
        print("no episodes recorded")
        return
    print(f"\n# team size, seeds {args.first_seed}+ ({args.out}, pid {os.getpid()})\n")
    print(cell_table(shown))
    print()
    print(ratio_tables(shown))


if __name__ == "__main__":
    main()
