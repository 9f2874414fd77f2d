"""Merges inside the env loop: how long each episode runs on a wrong merge transform, and what
the grid alignment costs once a merge is in use.

    python benchmarks/merge_in_loop.py [--explorer frontier] [--worlds 20] [--size 20]
        [--steps 3000] [--first-seed 0] [--odometry-noise S] [--odometry-alphas A]
        [--drift-prior] [--drift-correction [KEY=VALUE ...]]

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
``benchmarks/drift.md``. Per episode: the first step merged, steps
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

Run it on two checkouts (``PYTHONPATH=.`` from each) to compare versions on the same seeds.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import fusion.grid_merge as grid_merge  # noqa: E402
import fusion.hybrid as hybrid  # noqa: E402
from agents.base import run_episode  # noqa: E402
from agents.registry import EXPLORERS, make_team  # noqa: E402
from envs import two_robot_explore_v0  # noqa: E402
from envs.explore.config import RobotConfig  # noqa: E402
from envs.explore.drift import drift_aware_error, odometry_noise_level  # noqa: E402
from envs.explore.robot import start_frame_pose  # noqa: E402

WRONG_DEG, WRONG_M = 5.0, 1.0


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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--explorer", choices=sorted(EXPLORERS), default="frontier")
    parser.add_argument("--worlds", type=int, default=20)
    parser.add_argument("--size", type=float, default=20.0)
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--accept-threshold", type=float, default=None)
    parser.add_argument("--first-seed", type=int, default=0,
                        help="seed of the first world (100 and on: worlds never tuned on)")
    parser.add_argument("--odometry-noise", type=float, default=0.0,
                        help="robot.odometry_noise = (S, S), the 'increment' model")
    parser.add_argument("--odometry-alphas", default=None,
                        help="the 'rot_trans_rot' model: a preset name or a1,a2,a3,a4")
    parser.add_argument("--grid-merge-growth", type=float, default=None,
                        help="mapping.grid_merge_growth (0: re-examine the transform in use "
                             "every grid_merge_every steps, whether or not the maps grew)")
    parser.add_argument("--drift-prior", action="store_true",
                        help="give the merges the grids' drift_prior (module docstring)")
    parser.add_argument("--drift-correction", nargs="*", default=None, metavar="KEY=VALUE",
                        help="robot.drift_correction = True, with further "
                             "robot.drift_correction_<KEY> = VALUE settings")
    args = parser.parse_args()
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


if __name__ == "__main__":
    main()
