"""Why ``merge_maps(method="auto")`` fails pairs whose maps truly share many nodes: for the
overlap pairs of ``merge_tradeoff.py`` sharing at least ``--min-shared`` nodes that the oracle
gets right and ``auto`` (default rule) does not, the class of each failure per noise level and
overlap bin:

- ``precision``: the final alignment is near the truth (within 5° / 1 m at B's centroid) and at
  least half its matches are true correspondences, but outside 2° / 0.3 m (``+acc``: accepted,
  ``+rej``: also rejected);
- ``rejected``: the final alignment is right (within 2° / 0.3 m) but :func:`fusion.merge.decide`
  refuses it (``weak``: below ``min_score``, too few or collinear matches, possibly ambiguous
  too; ``ambiguous``: the margin alone). ``oracle accepted``: how many of them the rule would
  accept with the evidence at the oracle's own transform (the same runner-up): how many a more
  precise refinement could at most turn into successes;
- ``wrong``: farther than 5° / 1 m (``search``: the evidence at the oracle's transform scores
  higher than auto's best, so the search lost it; else the evidence does);
- ``other``: near but mostly wrong matches.

The last column counts the reverse: pairs ``auto`` gets right and the oracle does not.

A second table asks whether the refinement is less precise than the oracle at all: over every
pair whose best alignment (rule off) is within 5° / 1 m, how many are within 2° / 0.3 m for
the refined transform (``merge._polish``: nodes + paths), a node-only SVD fit on its final
matches, and the oracle (the node-only fit on the true correspondences).

    python benchmarks/shared_failures.py [--pairs 450] [--seed 100] [--min-shared 6]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections import Counter
from pathlib import Path

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from merge_tradeoff import BINS, NOISES, OVERLAP_PAIRS  # noqa: E402  (the same pairs)

from fusion.evaluate import (  # noqa: E402
    is_success,
    oracle_transform,
    synthetic_pairs,
    transform_errors,
)
from fusion.icp import rigid_fit  # noqa: E402
from fusion.merge import MergeConfig, _evaluate, _prepare, decide, merge_maps  # noqa: E402
from fusion.rigid import Rigid2D  # noqa: E402

NEAR_DEG, NEAR_M = 5.0, 1.0
CLASSES = ("precision+acc", "precision+rej", "rejected weak", "rejected ambiguous",
           "wrong search", "wrong evidence", "other")


def _near(err: tuple[float, float]) -> bool:
    return err[0] < NEAR_DEG and err[1] < NEAR_M


def classify(p, res, base: MergeConfig, oracle: Rigid2D) -> tuple[str, bool]:
    """The class of a failure (:data:`CLASSES`) and whether the rule accepts the evidence at
    the oracle's transform (with auto's runner-up)."""
    err = transform_errors(res.transform, p)
    reason = decide(res.evidence, base)
    pa, pb = _prepare(p.map_a, base), _prepare(p.map_b, base)
    ev = _evaluate(pa, pb, oracle.theta, oracle.T, base).evidence
    at_oracle = ev.score
    passes = decide(dataclasses.replace(ev, runner_up=res.evidence.runner_up), base) is None
    if is_success(err):
        weak = res.evidence.score < base.min_score or res.evidence.inliers < base.min_inliers
        return ("rejected weak" if weak or res.evidence.collinear else "rejected ambiguous",
                passes)
    true = {(int(a), int(b)) for a, b in p.correspondences}
    m = res.matches
    right = np.mean([(int(a), int(b)) in true for a, b in m]) if len(m) else 0.0
    if _near(err) and right >= 0.5:
        return ("precision+acc" if reason is None else "precision+rej"), passes
    if not _near(err):
        return ("wrong search" if at_oracle > res.evidence.score else "wrong evidence"), passes
    return "other", passes


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=450, help="overlap pairs per noise level")
    ap.add_argument("--seed", type=int, default=100)
    ap.add_argument("--min-shared", type=int, default=6)
    args = ap.parse_args()
    off, base = MergeConfig(min_score=-1e6, min_margin=0.0), MergeConfig()
    fails: dict = {}
    fits: dict = {}
    for p in tqdm(synthetic_pairs(args.pairs, args.seed, NOISES, OVERLAP_PAIRS), leave=False):
        label = next((f"{lo:.0%}–{hi:.0%}" for lo, hi in BINS if lo <= p.overlap < hi), None)
        if label is None:
            continue
        res = merge_maps(p.map_a, p.map_b, config=off)
        err = transform_errors(res.transform, p)
        oracle = oracle_transform(p)
        oracle_ok = oracle is not None and is_success(transform_errors(oracle, p))
        if _near(err):  # the precision of the refinement, whatever the rule
            row = fits.setdefault(p.noise, Counter())
            row["near"] += 1
            row["refined"] += is_success(err)
            m = res.matches
            node = Rigid2D(*rigid_fit(p.map_b.xy[m[:, 1]], p.map_a.xy[m[:, 0]])) if len(
                m) >= 3 else res.transform
            row["node-only fit"] += is_success(transform_errors(node, p))
            row["oracle"] += oracle_ok
        if p.correspondences is None or len(p.correspondences) < args.min_shared:
            continue
        row = fails.setdefault((p.noise, label), Counter())
        if not oracle_ok:
            row["auto right, oracle not"] += decide(res.evidence, base) is None and is_success(err)
            continue
        row["oracle right"] += 1
        if decide(res.evidence, base) is None and is_success(err):
            row["auto right"] += 1
            continue
        cls, passes = classify(p, res, base, oracle)
        row[cls] += 1
        if cls.startswith("rejected"):
            row["oracle accepted"] += passes

    print(f"# auto's failures on pairs sharing >= {args.min_shared} nodes that the oracle gets "
          f"right (seed {args.seed}, {args.pairs} pairs per σ)\n")
    cols = ("oracle right", "auto right", *CLASSES, "oracle accepted", "auto right, oracle not")
    print("| σ | bin | " + " | ".join(cols) + " |\n|---|---|" + "---|" * len(cols))
    for (noise, label), row in sorted(fails.items()):
        print(f"| {noise:g} | {label} | " + " | ".join(str(row[c]) for c in cols) + " |")
    print("\n# pairs whose best alignment is within 5° / 1 m (rule off): how many each fit "
          "puts within 2° / 0.3 m\n")
    print("| σ | near | refined (nodes + paths) | node-only fit on its matches | oracle |")
    print("|---|---|---|---|---|")
    for noise, row in sorted(fits.items()):
        print(f"| {noise:g} | {row['near']} | {row['refined']} | {row['node-only fit']} | "
              f"{row['oracle']} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
