"""Does drift correction reduce the robots' own odometry drift? (issue 33, part 1)

    python benchmarks/drift_correction.py [--worlds 10] [--first-seed 0] [--steps 3000]
        [--odometry-noise 0.02] [--set KEY=VALUE ...]

For each seed one episode of a scripted team (``--explorer``, frontier by default) in its own
20 m building, **without merging** (``mapping.merge_method = "none"``: the drift does not depend
on it, and the run is fast), once with ``robot.drift_correction`` off and once on (``--set``
overrides further ``robot.drift_correction_*`` fields, e.g. ``--set age=300``;
``--match-distance`` and ``--fit-scale`` the module's constants). Per robot: the
pose error at the end (odometry against the true pose in the start frame: metres, degrees), its
mean over the episode (sampled every 100 steps), and the corrector's applied / rejected /
skipped fits. Both runs drive the same commands only until their maps differ (the explorers
read the maps), so the paths diverge; the summary gives medians over robots.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from agents.base import run_episode  # noqa: E402
from agents.registry import EXPLORERS, make_team  # noqa: E402
from envs import two_robot_explore_v0  # noqa: E402
from envs.explore import localize  # noqa: E402
from envs.explore.robot import start_frame_pose  # noqa: E402


def pose_errors(env) -> list[tuple[float, float]]:
    """Per robot: metres and degrees between its odometry and its true start-frame pose."""
    out = []
    for r in env.robots:
        true = start_frame_pose(r.start, r.true_pose())
        dth = math.atan2(math.sin(true[2] - r.odometry[2]), math.cos(true[2] - r.odometry[2]))
        out.append((float(math.dist(true[:2], r.odometry[:2])), abs(math.degrees(dth))))
    return out


def episode(seed: int, explorer: str, steps: int, robot: dict) -> list[dict]:
    """One episode's rows, one per robot."""
    env = two_robot_explore_v0.parallel_env(max_cycles=steps, world={"size": (20.0, 20.0)},
                                            mapping={"merge_method": "none"}, robot=robot)
    sums = [0.0, 0.0]
    count = [0]

    def watch(k, *_):
        if k % 100 == 0:
            count[0] += 1
            for i, (m, _deg) in enumerate(pose_errors(env)):
                sums[i] += m

    run_episode(env, make_team(explorer), seed=seed, callback=watch)
    rows = []
    for i, (m, deg) in enumerate(pose_errors(env)):
        c = env._correctors[i]
        rows.append({"seed": seed, "robot": i, "end_m": m, "end_deg": deg,
                     "mean_m": sums[i] / max(count[0], 1),
                     "fits": "-" if c is None else f"{c.applied}/{c.rejected}/{c.skipped}",
                     "travelled": env.robots[i].travelled})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--explorer", choices=sorted(EXPLORERS), default="frontier")
    parser.add_argument("--worlds", type=int, default=10)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--odometry-noise", type=float, default=0.02)
    parser.add_argument("--set", nargs="*", default=[],
                        help="robot.drift_correction_<KEY>=VALUE for the 'on' runs")
    parser.add_argument("--only-on", action="store_true", help="skip the 'off' runs")
    parser.add_argument("--match-distance", type=float, default=localize.MATCH_DISTANCE,
                        help="localize.MATCH_DISTANCE (tuning)")
    parser.add_argument("--fit-scale", type=float, default=localize.FIT_SCALE,
                        help="localize.FIT_SCALE (tuning)")
    parser.add_argument("--heading-only", action="store_true", help="localize.HEADING_ONLY")
    args = parser.parse_args()
    localize.HEADING_ONLY = args.heading_only
    localize.MATCH_DISTANCE, localize.FIT_SCALE = args.match_distance, args.fit_scale
    base = {"odometry_noise": (args.odometry_noise, args.odometry_noise)}
    on = dict(base, drift_correction=True)
    for item in args.set:
        key, value = item.split("=")
        on[f"drift_correction_{key}"] = float(value) if "." in value else int(value)
    print(f"# drift correction: {args.explorer}, seeds {args.first_seed}-"
          f"{args.first_seed + args.worlds - 1}, {args.steps} steps, robot {on}, match "
          f"distance {args.match_distance}, fit scale {args.fit_scale}\n")
    print("| seed | robot | travelled m | off: end m / ° | mean m | on: end m / ° | mean m | "
          "fits applied/rejected/skipped |")
    print("|---|---|---|---|---|---|---|---|")
    ends = {"off": [], "on": []}
    means = {"off": [], "on": []}
    for seed in range(args.first_seed, args.first_seed + args.worlds):
        off_rows = (None, None) if args.only_on else episode(seed, args.explorer, args.steps,
                                                             base)
        on_rows = episode(seed, args.explorer, args.steps, on)
        for a, b in zip(off_rows, on_rows, strict=True):
            if a is not None:
                ends["off"].append(a["end_m"])
                means["off"].append(a["mean_m"])
            ends["on"].append(b["end_m"])
            means["on"].append(b["mean_m"])
            off = "-" if a is None else f"{a['end_m']:.2f} / {a['end_deg']:.1f} | {a['mean_m']:.2f}"
            print(f"| {seed} | {b['robot']} | {b['travelled']:.0f} | {off} | "
                  f"{b['end_m']:.2f} / {b['end_deg']:.1f} | {b['mean_m']:.2f} | {b['fits']} |",
                  flush=True)
    for key in ("off", "on"):
        if ends[key]:
            print(f"{key}: median end error {statistics.median(ends[key]):.2f} m, mean "
                  f"{statistics.fmean(ends[key]):.2f} m; median of the episode means "
                  f"{statistics.median(means[key]):.2f} m")


if __name__ == "__main__":
    main()
