"""Generate the env-pair benchmark set (``make env-pairs``): map pairs made by the env itself.

    python benchmarks/env_pairs.py [--out data/env_pairs] [--workers 2] [--only tune|test]

Two splits, so that what is tuned on is never what is reported:

* ``tune`` (seed 0) and ``test`` (seed 1), each with
  - ``frontier`` and ``coordinated_frontier``: 60 pairs each (20 episodes × 3 snapshots) in
    procedural 20 × 20 m buildings, 1500 steps (``tune`` also ``frontier_seed2`` and
    ``coordinated_frontier_seed3``: 120 pairs each from seeds 2 and 3, for fitting the merges'
    calibrated confidences; ``test`` also ``frontier_seed4`` and ``coordinated_frontier_seed5``,
    60 pairs each: worlds of their own, as the two sets of the split's seed share theirs);
  - ``real_<map>``: 6 pairs (2 episodes × 3 snapshots) on each real map of ``../shared/maps``
    (DungeonMaps at 0.1 m/pixel, ROS maps at their own resolution), split between the two.

Each folder is a ``fusion.pairs`` dataset written by ``python -m agents.dataset generate``, so an
interrupted run resumes with the same command. ``benchmarks/topo_repeatability.py`` reads it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from agents.dataset import main as dataset_main  # noqa: E402

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


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=ROOT / "data" / "env_pairs")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--only", choices=sorted(SPLIT_SEEDS))
    args = parser.parse_args(argv)
    for split in ([args.only] if args.only else list(SPLIT_SEEDS)):
        for job in jobs(args.out, split):
            print(" ".join(["agents.dataset", *job]), flush=True)
            dataset_main([*job, "--workers", str(args.workers)])


if __name__ == "__main__":
    main()
