"""Merges inside the env loop: how long each episode runs on a wrong merge transform, and what
the grid alignment costs once a merge is in use; with ``--robots N``, how many robot-steps a
team's fused map places a teammate with a wrong transform, cycle check on and off.

    python benchmarks/merge_in_loop.py [--explorer frontier] [--worlds 20] [--size 20]
        [--steps 3000] [--first-seed 0] [--odometry-noise S] [--odometry-alphas A]
        [--drift-prior] [--drift-correction [KEY=VALUE ...]]
    python benchmarks/merge_in_loop.py --robots N [--quick] [--worlds 10] [--size 20]
        [--steps 3000] [--first-seed 100] [--comm-range R] [--checks on off] [--out FILE]
        [--jobs 1] [--table-only]

**Two robots** (``two_robot_explore_v0``, without ``--robots``).
For each seed ``first_seed .. first_seed + worlds - 1`` (its own procedural ``size`` m
building) one episode of ``--steps`` steps with a scripted team (``agents.scripted``), defaults
otherwise. Every step with a transform in use is checked against the **drift-aware** truth
(``envs.explore.drift.drift_aware_error``: the robots' current odometry frames, the
errors at the robots' current places; with perfect odometry the start-frame truth):
**wrong** is more than 5° or 1 m off — a merge that puts robot 1's rooms on the wrong rooms.
``--odometry-noise S`` drives with ``robot.odometry_noise = (S, S)`` (the ``"increment"``
model), ``--odometry-alphas A`` with the ``"rot_trans_rot"`` model (four numbers or a preset
name); the table then adds the steps wrong against the env's start-frame truth
(``env.merge_errors()``, at robot 1's map centroid), which no rigid transform can match once
the maps are bent, the accepted merge results more than 5° off (drift-aware) at a confidence
of 0.9 or more ("confident wrong"), and the robots' odometry drift at the end (metres, the
larger of the two). ``--drift-correction [KEY=VALUE ...]`` turns on the robots' own drift correction
(``robot.drift_correction``, ``envs.explore.localize``; e.g. ``sigma=1.0`` sets
``robot.drift_correction_sigma``). ``--drift-prior`` gives every merge the grids' ``drift_prior``
(``fusion.grid_merge.drift_prior`` of the odometry noise level — the largest ``sqrt(αk)`` for
the alphas — and the env's steps) by wrapping ``fusion.hybrid``'s ``hybrid_merge`` and
``recheck``: the env's merging has passed that same prior itself since 1dde75e, so the flag
changes nothing at later commits and is kept to run older checkouts as they are measured in
``docs/notes/drift.md``. Per episode: the first step merged, steps
merged, steps wrong (and the first wrong transform's errors), the first step on a right
transform (not wrong), transforms installed (each accepted merge that changed the one in use),
merges dropped (``info["merge_drops"]``), accepted merge results by what supplied them (the
structural merge, checked by the grids, or the grid alignment), steps to 95 % true coverage
(``-`` if not reached). The summary gives the median first merged and first right step over the
episodes (an episode never merged counts as ``steps + 1``). ``--accept-threshold`` sets
``mapping.accept_threshold`` (versions that have it). The summary adds the grid alignment's
calls and seconds with no transform in use (searching) and with one (re-examining it,
``fusion.hybrid.recheck``), per env step.

Seeds 0–19 are the ones the merge was developed on (seeds 11 and 15 were case studies);
``--first-seed 100`` runs worlds it never saw.

**A team of N** (``--robots N``, 2–8: ``multi_robot_explore_v0`` with ``n_robots = N``).
For each seed (from 100 by default: held out) one episode of ``--steps`` steps
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
wrong** is more than 5° or 1 m off, what the two-robot run calls wrong (a teammate's rooms on
the wrong rooms, not a near miss). A **merged robot-step** is one teammate in robot 0's fused
map for one step; the headline is wrong robot-steps / merged robot-steps. Also per episode: the
steps with any teammate wrong, the first step robot 0's map held the whole team, the pair
transforms in use (``merge_state().pairs``, each pair (i, j) against ``env.true_transform(i,
j)``) that were wrong, counted per pair-step, and how many of those the cycle check kept
(``kept``: used for fusion) — with the check off every pair transform is kept, so the
pair-step counts say what the check removes. Each finished episode is one JSON line in
``--out``, the file rewritten atomically after each row: an interrupted run resumes, a run with
more worlds adds only the missing ones; ``--table-only`` prints the tables of what the file
holds.

Run it on two checkouts (``PYTHONPATH=.`` from each) to compare versions on the same seeds.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

from team_size import add_run_arguments, append_row, run_all

import fusion.grid_merge as grid_merge
import fusion.hybrid as hybrid
from agents.base import run_episode
from agents.registry import EXPLORERS, make_team
from envs import multi_robot_explore_v0, two_robot_explore_v0
from envs.explore.config import RobotConfig
from envs.explore.drift import drift_aware_error, odometry_noise_level
from envs.explore.robot import start_frame_pose
from topo.fileio import read_json_lines

WRONG_DEG, WRONG_M = 5.0, 1.0
"""Two robots: wrong is more than this off (a teammate's rooms on the wrong rooms)."""
TEAM_WRONG_DEG, TEAM_WRONG_M = 2.0, 0.3
"""A team: wrong is more than this off (the calibration's "right"); grossly wrong is the
two-robot wrong."""
DEFAULT_OUT = Path(tempfile.gettempdir()) / "topomerge-team_merge_in_loop.jsonl"
QUICK = {"worlds": 4, "steps": 1500}
"""What ``--quick`` sets for a team (explicit ``--worlds`` / ``--steps`` win)."""
TEAM_ONLY = ("quick", "comm_range", "checks", "out", "jobs", "table_only")
PAIR_ONLY = ("explorer", "accept_threshold", "odometry_noise", "odometry_alphas",
             "grid_merge_growth", "drift_prior", "drift_correction")


class _GridClock:
    """Wraps ``fusion.grid_merge.merge_grids`` to count calls and seconds, split by whether
    the env had a transform in use at the time."""

    def __init__(self) -> None:
        self.env = None
        self.calls = {"before": 0, "after": 0}
        self.seconds = {"before": 0.0, "after": 0.0}
        self._real = grid_merge.merge_grids
        grid_merge.merge_grids = self

    def __call__(self, grid_a, grid_b, config=None, **kw):
        t0 = time.perf_counter()
        out = self._real(grid_a, grid_b, config, **kw)
        key = "after" if self.env.shared.transform is not None else "before"
        self.calls[key] += 1
        self.seconds[key] += time.perf_counter() - t0
        return out


class _DriftPrior:
    """Wraps ``fusion.hybrid.hybrid_merge`` and ``recheck`` to give their grid config the
    ``drift_prior`` of odometry noise ``noise`` at the env's current step."""

    def __init__(self, noise: float) -> None:
        self.env = None
        self.noise = noise
        self._hybrid, self._recheck = hybrid.hybrid_merge, hybrid.recheck
        hybrid.hybrid_merge, hybrid.recheck = self.hybrid_merge, self.recheck

    def _config(self, config):
        prior = grid_merge.drift_prior(self.noise, int(self.env.steps))
        return dataclasses.replace(config or grid_merge.GridMergeConfig(), drift_prior=prior)

    def hybrid_merge(self, *args, config=None, **kw):
        return self._hybrid(*args, config=self._config(config), **kw)

    def recheck(self, map_a, map_b, grid_a, grid_b, in_use, config=None):
        return self._recheck(map_a, map_b, grid_a, grid_b, in_use, self._config(config))


def prior_noise(robot: dict) -> float:
    """The odometry noise the drift prior reads from the env's ``robot`` settings."""
    return odometry_noise_level(RobotConfig(**robot))


def robot_kwargs(noise: float, alphas: str | None) -> dict:
    """The env's ``robot`` settings for ``--odometry-noise`` / ``--odometry-alphas``."""
    if alphas is not None:
        value = alphas if "," not in alphas else tuple(float(a) for a in alphas.split(","))
        return {"odometry_model": "rot_trans_rot", "odometry_alphas": value}
    return {"odometry_noise": (noise, noise)} if noise else {}


def episode(seed: int, explorer: str, steps: int, size: float, clock: _GridClock,
            threshold: float | None = None, robot: dict | None = None,
            prior: _DriftPrior | None = None, mapping: dict | None = None) -> dict:
    """One episode's row of the table (module docstring), watched step by step."""
    mapping = dict(mapping or {})
    if threshold is not None:
        mapping["accept_threshold"] = threshold
    env = two_robot_explore_v0.parallel_env(max_cycles=steps, world={"size": (size, size)},
                                            mapping=mapping, robot=robot or {})
    clock.env = env
    if prior is not None:
        prior.env = env
    row = {"seed": seed, "first": None, "merged": 0, "wrong": 0, "first_wrong": None,
           "first_right": None, "installs": 0, "t95": None, "structural": 0, "grid": 0,
           "start_wrong": 0, "confident_wrong": 0, "drift": 0.0}
    last = [None]
    seen = [None]

    def watch(k, _obs, _rewards, infos):
        robots = env.robots
        if env.merge is not seen[0]:  # a new merge result: who supplied an accepted one
            seen[0] = env.merge
            if env.merge is not None and env.merge.accepted:
                row["grid" if getattr(env.merge, "supplied_by", None) == "grid"
                    else "structural"] += 1
                rot, _ = drift_aware_error(env.merge.transform, robots[0], robots[1])
                conf = getattr(env.merge, "confidence", None)
                if rot > WRONG_DEG and conf is not None and conf >= 0.9:
                    row["confident_wrong"] += 1
        t = env.shared.transform
        cov = next(iter(infos.values()))["true_coverage"] if infos else 0.0
        if row["t95"] is None and cov >= 0.95:
            row["t95"] = k
        if t is None:
            last[0] = None
            return
        row["merged"] += 1
        row["first"] = row["first"] or k
        if t is not last[0]:
            row["installs"] += 1
            last[0] = t
        start_rot, start_trans = env.merge_errors()
        row["start_wrong"] += start_rot > WRONG_DEG or start_trans > WRONG_M
        rot, trans = drift_aware_error(t, robots[0], robots[1])
        if rot > WRONG_DEG or trans > WRONG_M:
            row["wrong"] += 1
            row["first_wrong"] = row["first_wrong"] or f"step {k}: {rot:.0f}° / {trans:.1f} m"
        else:
            row["first_right"] = row["first_right"] or k

    out = run_episode(env, make_team(explorer), seed=seed, callback=watch)
    row.update(steps=out["steps"], drops=env.merge_state().drops)
    row["drift"] = max(float(math.dist(start_frame_pose(r.start, r.true_pose())[:2],
                                       r.odometry[:2])) for r in env.robots)
    return row


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
        out = (rot > TEAM_WRONG_DEG or trans > TEAM_WRONG_M, rot, trans)
        if len(xy):
            self._cache[key] = (transform, topomap, truth, out)
        return out


def team_episode(seed: int, n: int, size: float, steps: int, cycle_check: bool,
            comm_range: float | None) -> dict[str, Any]:
    """One team episode's row (module docstring)."""
    from agents.scripted import Frontier

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
            row["gross"] += rot > WRONG_DEG or trans > WRONG_M
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


def _team_key(row: dict[str, Any]) -> tuple:
    return (row["seed"], row["n"], row["size"], row["max_cycles"], row["cycle_check"],
            row["comm_range"])


def team_tables(rows: list[dict[str, Any]]) -> str:
    """A team's per-episode rows, then the summary per cycle-check setting (module docstring)."""
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


def team_main(args: argparse.Namespace) -> None:
    """The team run: the episodes not yet in ``--out``, then the tables."""
    rows = read_json_lines(args.out)
    wanted = [(seed, args.robots, args.size, args.steps, check == "on", args.comm_range)
              for seed in range(args.first_seed, args.first_seed + args.worlds)
              for check in args.checks]
    if not args.table_only:
        done = {_team_key(r) for r in rows}
        todo = [w for w in wanted if w not in done]
        print(f"# {len(todo)} episodes to run, {len(rows)} in {args.out}", flush=True)
        t0 = time.perf_counter()
        for _task, row in run_all(team_episode, todo, args.jobs):
            if isinstance(row, Exception):
                raise row
            append_row(args.out, rows, row)
            print(f"seed {row['seed']} cycle check {row['cycle_check']}: wrong "
                  f"{row['wrong']} / {row['merged']} merged robot-steps, "
                  f"{row['cpu_s']:.0f} s CPU ({time.perf_counter() - t0:.0f} s)", flush=True)
    shown = rows if args.table_only else [r for r in rows if _team_key(r) in set(wanted)]
    if not shown:
        print("no episodes recorded")
        return
    print(f"\n# N-robot merges in the loop ({args.out}): Frontier, wrong = > "
          f"{TEAM_WRONG_DEG:g}° or > {TEAM_WRONG_M:g} m against env.true_transform\n")
    print(team_tables(shown))


def pair_main(args: argparse.Namespace) -> None:
    """The two-robot run: episodes one by one, each row printed as it ends."""
    robot = robot_kwargs(args.odometry_noise, args.odometry_alphas)
    if args.drift_correction is not None:
        robot["drift_correction"] = True
        for item in args.drift_correction:
            key, value = item.split("=")
            robot[f"drift_correction_{key}"] = float(value) if "." in value else int(value)
    prior = _DriftPrior(prior_noise(robot)) if args.drift_prior else None
    mapping = ({} if args.grid_merge_growth is None
               else {"grid_merge_growth": args.grid_merge_growth})
    clock = _GridClock()
    print(f"# merges in the loop: {args.explorer}, {args.worlds} worlds of {args.size:g} m "
          f"(seeds {args.first_seed}-{args.first_seed + args.worlds - 1}), {args.steps} steps, "
          f"accept_threshold {args.accept_threshold or 'default'}, robot {robot or 'default'}, "
          f"drift prior {'on' if prior else 'off'}, mapping {mapping or 'default'}\n")
    print("| seed | first merged | steps merged | steps wrong | first wrong | first right | "
          "installs | drops | accepted: structural / grids | T95 | wrong (start frame) | "
          "confident wrong | drift m |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    rows = []
    t0 = time.perf_counter()
    for seed in range(args.first_seed, args.first_seed + args.worlds):
        r = episode(seed, args.explorer, args.steps, args.size, clock, args.accept_threshold,
                    robot, prior, mapping)
        rows.append(r)
        print(f"| {seed} | {r['first'] or '-'} | {r['merged']} | {r['wrong']} | "
              f"{r['first_wrong'] or ''} | {r['first_right'] or '-'} | {r['installs']} | "
              f"{r['drops']} | {r['structural']} / {r['grid']} | {r['t95'] or '-'} | "
              f"{r['start_wrong']} | {r['confident_wrong']} | {r['drift']:.2f} |", flush=True)
    wall = time.perf_counter() - t0
    steps = sum(r["steps"] for r in rows)
    merged = sum(r["merged"] for r in rows)
    wrong = sum(r["wrong"] for r in rows)
    print(f"\nmerged in {sum(r['first'] is not None for r in rows)} of {len(rows)} episodes; "
          f"a wrong transform in use in {sum(r['wrong'] > 0 for r in rows)}; steps wrong / "
          f"merged: {wrong} / {merged} ({wrong / max(merged, 1):.1%}), of all steps "
          f"{wrong / max(steps, 1):.1%}; drops {sum(r['drops'] for r in rows)}")
    print(f"steps wrong against the start-frame truth: {sum(r['start_wrong'] for r in rows)}; "
          f"accepted results > {WRONG_DEG:g}° off at confidence >= 0.9: "
          f"{sum(r['confident_wrong'] for r in rows)}; median drift "
          f"{statistics.median(r['drift'] for r in rows):.2f} m")
    structural, grid = sum(r["structural"] for r in rows), sum(r["grid"] for r in rows)
    print(f"accepted merges supplied by the structural merge (grid-checked): {structural} of "
          f"{structural + grid} ({structural / max(structural + grid, 1):.0%}); by the grid "
          f"alignment: {grid}")
    never = args.steps + 1
    print(f"median first merged step {statistics.median(r['first'] or never for r in rows):g}, "
          f"median first right step {statistics.median(r['first_right'] or never for r in rows):g}"
          f" (never: {args.steps + 1})")
    for key, label in (("before", "with no transform in use"), ("after", "with one in use")):
        print(f"grid alignments {label}: {clock.calls[key]} calls, "
              f"{clock.seconds[key]:.1f} s = {clock.seconds[key] / steps * 1e6:.0f} µs per env "
              f"step ({clock.seconds[key] / wall:.1%} of the run's {wall:.0f} s)")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The options; those of the other run (two robots or a team) are refused."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=None,
                        help="a team of N (2-8, multi_robot_explore_v0, Frontier robots); "
                             "without it the two-robot env")
    parser.add_argument("--worlds", type=int, default=None,
                        help=f"default 20, a team 10 (--quick {QUICK['worlds']})")
    parser.add_argument("--size", type=float, default=20.0)
    parser.add_argument("--steps", type=int, default=None,
                        help=f"max_cycles (default 3000; a team with --quick {QUICK['steps']})")
    parser.add_argument("--first-seed", type=int, default=None,
                        help="seed of the first world (default 0, a team 100; 100 and on: "
                             "worlds never tuned on)")
    two = parser.add_argument_group("two robots (without --robots)")
    two.add_argument("--explorer", choices=sorted(EXPLORERS), default="frontier")
    two.add_argument("--accept-threshold", type=float, default=None)
    two.add_argument("--odometry-noise", type=float, default=0.0,
                     help="robot.odometry_noise = (S, S), the 'increment' model")
    two.add_argument("--odometry-alphas", default=None,
                     help="the 'rot_trans_rot' model: a preset name or a1,a2,a3,a4")
    two.add_argument("--grid-merge-growth", type=float, default=None,
                     help="mapping.grid_merge_growth (0: re-examine the transform in use "
                          "every grid_merge_every steps, whether or not the maps grew)")
    two.add_argument("--drift-prior", action="store_true",
                     help="give the merges the grids' drift_prior (module docstring)")
    two.add_argument("--drift-correction", nargs="*", default=None, metavar="KEY=VALUE",
                     help="robot.drift_correction = True, with further "
                          "robot.drift_correction_<KEY> = VALUE settings")
    team = parser.add_argument_group("a team (--robots N)")
    team.add_argument("--quick", action="store_true",
                      help=f"{QUICK['worlds']} worlds of {QUICK['steps']} steps")
    team.add_argument("--comm-range", type=float, default=None,
                      help="comm.range in m (default unlimited)")
    team.add_argument("--checks", nargs="+", choices=("on", "off"), default=None,
                      help="mapping.cycle_check settings to run (default on off)")
    add_run_arguments(team, DEFAULT_OUT)
    args = parser.parse_args(argv)
    is_team = args.robots is not None
    defaults = vars(parser.parse_args([]))
    for name in PAIR_ONLY if is_team else TEAM_ONLY:
        if getattr(args, name) != defaults[name]:
            option = "--" + name.replace("_", "-")
            run = "two robots (without --robots)" if is_team else "a team (--robots N)"
            parser.error(f"{option} is an option for {run}, got {option} "
                         f"{getattr(args, name)} with --robots {args.robots}")
    if is_team and not 2 <= args.robots <= 8:
        parser.error(f"--robots must be 2-8 (the env's n_robots), got {args.robots}")
    if is_team and args.jobs < 1:
        parser.error(f"--jobs must be >= 1, got {args.jobs}")
    quick = is_team and args.quick
    args.worlds = args.worlds or (QUICK["worlds"] if quick else 10 if is_team else 20)
    args.steps = args.steps or (QUICK["steps"] if quick else 3000)
    if args.first_seed is None:
        args.first_seed = 100 if is_team else 0
    args.checks = args.checks or ["on", "off"]
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    if args.robots is None:
        pair_main(args)
    else:
        team_main(args)


if __name__ == "__main__":
    main()
