"""Generate the env-pair benchmark set (``make env-pairs``): map pairs made by the env itself.

    python benchmarks/env_pairs.py [--out data/env_pairs] [--workers 2] [--only tune|test]
    python benchmarks/env_pairs.py --odometry-noise 0.01 0.02 0.05 [--episodes 20]

Two splits, so that what is tuned on is never what is reported:

* ``tune`` (seed 0) and ``test`` (seed 1), each with
  - ``frontier`` and ``coordinated_frontier``: 60 pairs each (20 episodes × 3 snapshots) in
    procedural 20 × 20 m buildings, 1500 steps (``tune`` also ``frontier_seed2`` and
    ``coordinated_frontier_seed3``: 120 pairs each from seeds 2 and 3, for fitting the merges'
    calibrated confidences; ``test`` also ``frontier_seed4`` and ``coordinated_frontier_seed5``,
    60 pairs each: worlds of their own, as the two sets of the split's seed share theirs);
  - ``real_<map>``: 6 pairs (2 episodes × 3 snapshots) on each real map of ``../shared/maps``
    (DungeonMaps at 0.1 m/pixel, ROS maps at their own resolution), split between the two.

Each folder is a ``fusion.evaluation.pairs`` dataset written by ``python -m agents.dataset
generate``, so an
interrupted run resumes with the same command. ``benchmarks/topo_repeatability.py`` reads it.

``--odometry-noise σ …`` instead makes, per σ, ``drift/<split>/sigma_<σ>`` (apart from the
split folders, which ``python -m fusion.calibration fit`` reads by default): frontier pairs
(``--episodes`` × 3 snapshots, 1500 steps, 20 m buildings, the dataset CLI's episode seeds and
snapshot rule) driven with ``robot.odometry_noise = (σ, σ)``, whose ``transform`` is the
**drift-aware** truth at the snapshot (``envs.explore.drift.drift_aware_truth``: the
robots' current odometry frames), not the start-frame one the dataset CLI stores — with drift no
rigid transform matches the start frames, and the current frames are where the maps are right
now. Finished episodes are skipped, so a rerun resumes. The ``tune`` split (seed 0) unless
``--only test``: seed 1's worlds, a held-out set for ``python -m fusion.calibration fit
--held-out``.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from agents.dataset import coverage_levels, episode_seed  # noqa: E402
from agents.dataset import main as dataset_main  # noqa: E402
from fusion.evaluation.pairs import (  # noqa: E402
    FORMAT,
    FORMAT_VERSION,
    GridSnapshot,
    MapPair,
    pair_path,
    write_pair,
)
from topo.fileio import atomic_write_json  # noqa: E402

MAPS = ROOT.parent / "shared" / "maps"
SPLIT_SEEDS = {"tune": 0, "test": 1}
REAL_MAPS = {
    "tune": ["dungeon/1.png", "dungeon/10.png", "dungeon/100.png", "dungeon/101.png",
             "ros/tb3_sandbox.yaml"],
    "test": ["dungeon/102.png", "dungeon/103.png", "dungeon/104.png", "dungeon/105.png",
             "ros/depot.yaml", "ros/turtlebot3_world.yaml"],
}
PROCEDURAL = ("frontier", "coordinated_frontier")
EXTRA_SEEDS = {"tune": (("2", "3"), "120"), "test": (("4", "5"), "60")}
"""Per split: the seeds of one more set per explorer, and its pair count. The two explorers'
sets of the split's own seed share worlds and their early snapshots (the teams act alike until
their first merge); these do not."""


def jobs(out: Path, split: str) -> list[list[str]]:
    """The ``agents.dataset generate`` argument lists of one split."""
    seed = str(SPLIT_SEEDS[split])
    common = ["--snapshots", "3", "--max-cycles", "1500", "--seed", seed, "--no-progress"]
    out_jobs = [["generate", "--explorer", explorer, "--pairs", "60", "--world-size", "20", "20",
                 "--out", str(out / split / explorer), *common] for explorer in PROCEDURAL]
    seeds, pairs = EXTRA_SEEDS[split]
    for explorer, extra_seed in zip(PROCEDURAL, seeds, strict=True):
        out_jobs.append(["generate", "--explorer", explorer, "--pairs", pairs,
                         "--world-size", "20", "20", "--out",
                         str(out / split / f"{explorer}_seed{extra_seed}"),
                         *common[:4], "--seed", extra_seed, "--no-progress"])
    for name in REAL_MAPS[split]:
        path = MAPS / name
        if not path.is_file():
            print(f"skipping {name}: {path} not found", file=sys.stderr)
            continue
        tag = "real_" + Path(name).stem.replace(".", "_")
        if name.startswith("dungeon/"):
            tag = "real_dungeon_" + Path(name).stem
        out_jobs.append(["generate", "--explorer", "frontier", "--pairs", "6", "--world",
                         str(path), "--out", str(out / split / tag), *common])
    return out_jobs


DRIFT_STEPS, DRIFT_SNAPSHOTS = 1500, 3


def drift_folder(out: Path, split: str, noise: float) -> Path:
    """Where the pairs of odometry noise ``noise`` of ``split`` go."""
    return out / "drift" / split / f"sigma_{noise:g}"


def drift_episode(root: Path, episode: int, noise: float, seed: int) -> int:
    """Run frontier episode ``episode`` with ``robot.odometry_noise = (noise, noise)`` and write
    its snapshots (pair ids ``episode · 3 + k``) with the drift-aware truth; returns how many."""
    from agents.base import run_episode
    from agents.registry import make_team
    from envs.explore.drift import drift_aware_truth
    from envs.two_robot_explore_v0 import parallel_env

    ep_seed = episode_seed(seed, episode)
    env = parallel_env(max_cycles=DRIFT_STEPS, world={"size": (20.0, 20.0)},
                       robot={"odometry_noise": (noise, noise)})
    levels = coverage_levels(DRIFT_SNAPSHOTS)
    deadlines = [math.ceil((k + 1) / DRIFT_SNAPSHOTS * DRIFT_STEPS)
                 for k in range(DRIFT_SNAPSHOTS)]
    taken: list[MapPair] = []

    def grid(snap) -> GridSnapshot:
        g = snap.grid
        return GridSnapshot(np.asarray(g.states(), dtype=np.int8).copy(), float(g.resolution),
                            tuple(float(v) for v in g.origin))

    def callback(step: int, _obs: dict, _rew: dict, infos: dict) -> None:
        if len(infos) < 2:
            return
        a = infos["robot_0"]
        cov = float(a["true_coverage"])
        while len(taken) < DRIFT_SNAPSHOTS and (cov >= levels[len(taken)]
                                                or step >= deadlines[len(taken)]):
            raw = env.unwrapped
            snap_a, snap_b = raw.robot_map("robot_0"), raw.robot_map("robot_1")
            taken.append(MapPair(
                pair_id=episode * DRIFT_SNAPSHOTS + len(taken), map_a=snap_a.topomap,
                map_b=snap_b.topomap, grid_a=grid(snap_a), grid_b=grid(snap_b),
                transform=drift_aware_truth(raw.robots[0], raw.robots[1]),
                overlap=float(a["overlap"]), world_id=f"procedural:{ep_seed}", seed=ep_seed,
                explorer="frontier", step=step, episode=episode, snapshot=len(taken),
                extra={"true_coverage": cov, "odometry_noise": noise,
                       "truth": "drift-aware"}))

    try:
        run_episode(env, make_team("frontier"), seed=ep_seed, callback=callback)
    finally:
        env.close()
    for pair in taken:
        write_pair(root, pair)
    return len(taken)


def drift_pairs(out: Path, split: str, noise: float, episodes: int) -> Path:
    """Make (or finish) the drift-aware pairs of one noise level (module docstring)."""
    root = drift_folder(out, split, noise)
    (root / "pairs").mkdir(parents=True, exist_ok=True)
    seed = SPLIT_SEEDS[split]
    atomic_write_json(root / "dataset.json", {
        "format": FORMAT, "version": FORMAT_VERSION,
        "settings": {"explorer": "frontier", "max_cycles": DRIFT_STEPS, "seed": seed,
                     "snapshots": DRIFT_SNAPSHOTS, "world": "procedural",
                     "world_size": [20.0, 20.0], "odometry_noise": [noise, noise],
                     "truth": "drift-aware", "script": "benchmarks/env_pairs.py"}})
    for episode in range(episodes):
        if pair_path(root, episode * DRIFT_SNAPSHOTS).exists():
            continue
        n = drift_episode(root, episode, noise, seed)
        print(f"{root.name}: episode {episode}: {n} pairs", flush=True)
    return root


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=ROOT / "data" / "env_pairs")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--only", choices=sorted(SPLIT_SEEDS))
    parser.add_argument("--odometry-noise", type=float, nargs="*", default=None,
                        help="make drift-aware pairs at these noise levels instead")
    parser.add_argument("--episodes", type=int, default=20,
                        help="episodes per noise level (--odometry-noise)")
    args = parser.parse_args(argv)
    if args.odometry_noise:
        for split in ([args.only] if args.only else ["tune"]):
            for noise in args.odometry_noise:
                drift_pairs(args.out, split, noise, args.episodes)
        return
    for split in ([args.only] if args.only else list(SPLIT_SEEDS)):
        for job in jobs(args.out, split):
            print(" ".join(["agents.dataset", *job]), flush=True)
            dataset_main([*job, "--workers", str(args.workers)])


if __name__ == "__main__":
    main()
