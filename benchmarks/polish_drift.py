"""How often ``merge._polish`` drifts off a right start: for overlap pairs the oracle gets right
(rotation < 2°, translation < 0.3 m), the refinement is started from the oracle's transform (as
``fusion.diagnose`` does) and the ends beyond 2° / 0.3 m are counted per noise and overlap bin.

    python benchmarks/polish_drift.py [--pairs 450] [--seed 100] [--noise 0.05,0.15] [-v]
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from merge_tradeoff import BINS, OVERLAP_PAIRS  # noqa: E402  (benchmarks/, the same pairs)

from fusion.evaluate import (  # noqa: E402
    is_success,
    oracle_transform,
    synthetic_pairs,
    transform_errors,
)
from fusion.merge import MergeConfig, _evaluate, _polish, _prepare  # noqa: E402


def drift(pairs, cfg: MergeConfig, verbose: bool = False) -> dict:
    """``{(noise, bin): Counter(oracle=, drift=)}``."""
    table: dict = {}
    for p in pairs:
        if p.kind != "overlap":
            continue
        label = next((f"{lo:g}-{hi:g}" for lo, hi in BINS if lo <= p.overlap < hi), None)
        if label is None:
            continue
        row = table.setdefault((p.noise, label), Counter())
        oracle = oracle_transform(p)
        if oracle is None or not is_success(transform_errors(oracle, p)):
            continue
        row["oracle"] += 1
        pa, pb = _prepare(p.map_a, cfg), _prepare(p.map_b, cfg)
        out = _polish(pa, pb, _evaluate(pa, pb, oracle.theta, oracle.T, cfg), cfg)
        err = transform_errors(out.transform, p)
        if not is_success(err):
            row["drift"] += 1
            if verbose:
                print(f"{p.name} overlap {p.overlap:.2f}: {err[0]:.2f} deg {err[1]:.2f} m")
    return table


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=450)
    ap.add_argument("--seed", type=int, default=100)
    ap.add_argument("--noise", default="0.05,0.15")
    ap.add_argument("-v", "--verbose", action="store_true")
    args = ap.parse_args()
    noise = [float(s) for s in args.noise.split(",")]
    table = drift(synthetic_pairs(args.pairs, args.seed, noise, OVERLAP_PAIRS), MergeConfig(),
                  args.verbose)
    print(f"seed {args.seed}: drift / oracle right")
    for (sigma, label), row in sorted(table.items()):
        print(f"  sigma {sigma:g} {label}: {row['drift']} / {row['oracle']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
