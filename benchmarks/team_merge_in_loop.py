"""Merges inside N-robot episodes: how many robot-steps robot 0's fused map places a teammate
with a wrong transform, with the team's cycle check on and off.

    python benchmarks/team_merge_in_loop.py [--quick] [--n 4] [--worlds 10] [--size 20]
        [--steps 3000] [--first-seed 100] [--comm-range R] [--checks on off] [--out FILE]
        [--jobs 1] [--table-only]

For each seed ``first_seed .. first_seed + worlds - 1`` (its own procedural ``size`` m
building) one episode of ``multi_robot_explore_v0`` with ``n_robots = n``, ``--steps`` steps
(``max_cycles``; it ends earlier at 95 % true coverage), a :class:`agents.scripted.Frontier`
per robot, defaults otherwise, once with ``mapping.cycle_check = True`` and once ``False``
(``--checks``). Frontier robots plan on their own maps, so both runs of a seed drive the same
paths and differ only in which merges robot 0's fused map uses.

Every step, for every teammate ``j`` in robot 0's fused map (``merge_state().frames[0]``: the
transform robot j's frame → robot 0's it uses) the transform is compared with the truth
``env.true_transform(0, j)`` (the robots' start poses; odometry is perfect at the defaults):
**wrong** is more than 2° or more than 0.3 m off (the calibration's "right": rotation < 2°,
translation < 0.3 m), the translation error taken at the centroid of robot j's topological map
(its places; robot j's position while it has none), as ``env.merge_errors()`` does; **grossly
wrong** is more than 5° or 1 m off, what ``merge_in_loop.py`` calls wrong for two robots (a
teammate's rooms on the wrong rooms, not a near miss). A **merged robot-step** is one teammate
in robot 0's fused map for one step; the headline is wrong robot-steps / merged robot-steps
(target ≤ 0.5 %). Also per episode: the steps with any teammate wrong, the first step robot 0's
map held the whole team, the pair transforms in use (``merge_state().pairs``, each pair (i, j)
against ``env.true_transform(i, j)``) that were wrong, counted per pair-step, and how many of
those the cycle check kept (``kept``: used for fusion) — with the check off every pair
transform is kept, so the pair-step counts say what the check removes.

Seeds from 100 are held out (the merge was developed on seeds 0–19). Each finished episode is
one JSON line in ``--out``, the file rewritten atomically after each row: an interrupted run
resumes, a run with more worlds adds only the missing ones; ``--table-only`` prints the tables
of what the file holds.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from team_size import add_run_arguments, append_row, read_rows, run_all  # noqa: E402

WRONG_DEG, WRONG_M = 2.0, 0.3
GROSS_DEG, GROSS_M = 5.0, 1.0
DEFAULT_OUT = Path(tempfile.gettempdir()) / "topomerge-team_merge_in_loop.jsonl"
QUICK = {"worlds": 4, "steps": 1500}
"""What ``--quick`` sets (explicit ``--worlds`` / ``--steps`` win)."""


class _Errors:
    """Errors of transforms against the truth, kept while the transform, the map it is
    measured on and the truth stay the same objects (most steps change none of them)."""

    def __init__(self) -> None:
        self._cache: dict[tuple[int, int], tuple] = {}

    def wrong(self, key: tuple[int, int], transform: Any, truth: Any, topomap: Any,
              fallback: Any) -> tuple[bool, float, float]:
        """Whether ``transform`` is wrong (module docstring), and its errors (°, m)."""
        hit = self._cache.get(key)
        if hit is not None and hit[0] is transform and hit[1] is topomap and hit[2] is truth:
            return hit[3]
        xy = topomap.xy
        at = xy.mean(axis=0) if len(xy) else fallback
        rot = math.degrees(transform.rotation_error(truth))
        trans = transform.translation_error(truth, at)
        out = (rot > WRONG_DEG or trans > WRONG_M, rot, trans)
        if len(xy):
            self._cache[key] = (transform, topomap, truth, out)
        return out


def episode(seed: int, n: int, size: float, steps: int, cycle_check: bool,
            comm_range: float | None) -> dict[str, Any]:
    """One episode's row (module docstring)."""
    from agents.base import run_episode
    from agents.scripted import Frontier
    from envs import multi_robot_explore_v0

    env = multi_robot_explore_v0.parallel_env(
        n_robots=n, max_cycles=steps, world={"size": (size, size)},
        comm={"range": comm_range}, mapping={"cycle_check": cycle_check})
    team = {a: Frontier() for a in env.possible_agents}
    errors = _Errors()
    row = {"seed": seed, "n": n, "size": size, "max_cycles": steps, "cycle_check": cycle_check,
           "comm_range": comm_range, "merged": 0, "wrong": 0, "steps_wrong": 0,
           "first_merged": None, "fused_all": None, "first_wrong": None, "pair_steps": 0,
           "pair_wrong": 0, "pair_wrong_kept": 0, "pair_kept": 0, "worst_deg": 0.0,
           "worst_m": 0.0, "gross": 0}

    def watch(k: int, _obs, _rewards, _infos) -> None:
        state = env.merge_state()
        frames = state.frames[0]
        any_wrong = False
        for j, transform in frames.items():
            if j == 0:
                continue
            robot = env.robots[j]
            bad, rot, trans = errors.wrong((0, j), transform, env.true_transform(0, j),
                                           env.maps[j].topomap, robot.odometry[:2])
            row["merged"] += 1
            row["gross"] += rot > GROSS_DEG or trans > GROSS_M
            if bad:
                row["wrong"] += 1
                any_wrong = True
                row["worst_deg"] = max(row["worst_deg"], round(rot, 2))
                row["worst_m"] = max(row["worst_m"], round(trans, 3))
                if row["first_wrong"] is None:
                    row["first_wrong"] = f"step {k}, robot {j}: {rot:.1f}° / {trans:.2f} m"
        row["steps_wrong"] += any_wrong
        if len(frames) > 1 and row["first_merged"] is None:
            row["first_merged"] = k
        if len(frames) == n and row["fused_all"] is None:
            row["fused_all"] = k
        for (i, j), pair in state.pairs.items():
            if pair.transform is None:
                continue
            row["pair_steps"] += 1
            row["pair_kept"] += pair.kept
            bad = errors.wrong((i, j), pair.transform, env.true_transform(i, j),
                               env.maps[j].topomap, env.robots[j].odometry[:2])[0]
            row["pair_wrong"] += bad
            row["pair_wrong_kept"] += bad and pair.kept

    cpu = time.process_time()
    out = run_episode(env, team, seed=seed, callback=watch)
    row.update(steps=out["steps"], coverage=round(float(
        out["infos"]["robot_0"]["true_coverage"]), 4),
        drops=env.merge_state().drops, cpu_s=round(time.process_time() - cpu, 1))
    return row


def _key(row: dict[str, Any]) -> tuple:
    return (row["seed"], row["n"], row["size"], row["max_cycles"], row["cycle_check"],
            row["comm_range"])


def tables(rows: list[dict[str, Any]]) -> str:
    """Per-episode rows, then the summary per cycle-check setting (module docstring)."""
    lines = ["| seed | cycle check | steps | first merged | all fused | merged robot-steps | "
             "wrong | steps any wrong | first wrong | worst ° / m | pair-steps wrong (kept) "
             "/ in use | drops | coverage |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in sorted(rows, key=lambda r: (r["seed"], not r["cycle_check"])):
        lines.append(
            f"| {r['seed']} | {'on' if r['cycle_check'] else 'off'} | {r['steps']} | "
            f"{r['first_merged'] or '-'} | {r['fused_all'] or '-'} | {r['merged']} | "
            f"{r['wrong']} | {r['steps_wrong']} | {r['first_wrong'] or ''} | "
            f"{r['worst_deg']:.1f} / {r['worst_m']:.2f} | {r['pair_wrong']} "
            f"({r['pair_wrong_kept']}) / {r['pair_steps']} | {r['drops']} | "
            f"{r['coverage']:.3f} |")
    lines += ["", "| cycle check | episodes | merged robot-steps | wrong robot-steps | wrong / "
              "merged | episodes with a wrong step | wrong pair-steps, kept / all | grossly wrong "
              "(> 5° or > 1 m) / merged |",
              "|---|---|---|---|---|---|---|---|"]
    for check in (True, False):
        rs = [r for r in rows if r["cycle_check"] == check]
        if not rs:
            continue
        merged = sum(r["merged"] for r in rs)
        wrong = sum(r["wrong"] for r in rs)
        # rows written before the gross count existed have none
        if any("gross" not in r for r in rs):
            gross = "–"
        else:
            n_gross = sum(r["gross"] for r in rs)
            gross = f"{n_gross} ({n_gross / max(merged, 1):.2%})"
        lines.append(
            f"| {'on' if check else 'off'} | {len(rs)} | {merged} | {wrong} | "
            f"{wrong / max(merged, 1):.2%} | {sum(r['wrong'] > 0 for r in rs)} | "
            f"{sum(r['pair_wrong_kept'] for r in rs)} / {sum(r['pair_wrong'] for r in rs)} | "
            f"{gross} |")
    return "\n".join(lines)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help=f"{QUICK['worlds']} worlds of {QUICK['steps']} steps")
    parser.add_argument("--n", type=int, default=4, help="robots, 2-8")
    parser.add_argument("--worlds", type=int, default=None, help="default 10")
    parser.add_argument("--size", type=float, default=20.0)
    parser.add_argument("--steps", type=int, default=None, help="max_cycles (default 3000)")
    parser.add_argument("--first-seed", type=int, default=100,
                        help="seed of the first world (100 and on: never tuned on)")
    parser.add_argument("--comm-range", type=float, default=None,
                        help="comm.range in m (default unlimited)")
    parser.add_argument("--checks", nargs="+", choices=("on", "off"), default=["on", "off"],
                        help="mapping.cycle_check settings to run")
    add_run_arguments(parser, DEFAULT_OUT)
    args = parser.parse_args(argv)
    args.worlds = args.worlds or (QUICK["worlds"] if args.quick else 10)
    args.steps = args.steps or (QUICK["steps"] if args.quick else 3000)
    if not 2 <= args.n <= 8:
        parser.error(f"--n must be 2-8 (the env's n_robots), got {args.n}")
    if args.jobs < 1:
        parser.error(f"--jobs must be >= 1, got {args.jobs}")
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    rows = read_rows(args.out)
    wanted = [(seed, args.n, args.size, args.steps, check == "on", args.comm_range)
              for seed in range(args.first_seed, args.first_seed + args.worlds)
              for check in args.checks]
    if not args.table_only:
        done = {_key(r) for r in rows}
        todo = [w for w in wanted if w not in done]
        print(f"# {len(todo)} episodes to run, {len(rows)} in {args.out}", flush=True)
        t0 = time.perf_counter()
        for _task, row in run_all(episode, todo, args.jobs):
            if isinstance(row, Exception):
                raise row
            append_row(args.out, rows, row)
            print(f"seed {row['seed']} cycle check {row['cycle_check']}: wrong "
                  f"{row['wrong']} / {row['merged']} merged robot-steps, "
                  f"{row['cpu_s']:.0f} s CPU ({time.perf_counter() - t0:.0f} s)", flush=True)
    shown = rows if args.table_only else [r for r in rows if _key(r) in set(wanted)]
    if not shown:
        print("no episodes recorded")
        return
    print(f"\n# N-robot merges in the loop ({args.out}): Frontier, wrong = > {WRONG_DEG:g}° or "
          f"> {WRONG_M:g} m against env.true_transform\n")
    print(tables(shown))


if __name__ == "__main__":
    main()
