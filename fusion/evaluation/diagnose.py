"""Why does ``merge_maps(method="auto")`` miss?
``python -m fusion.evaluation.diagnose --synthetic N``.

For every synthetic overlapping pair (overlap ≥ 20%) that the oracle gets right (the SVD fit on
the true node correspondences: rotation < 2°, translation < 0.3 m at B's centroid), the true
alignment is refined as ``auto`` refines its own (:func:`fusion.structural.refine.polish`) and
scored, and a miss of ``auto`` is put in one class:

- ``truth_too_few_matches``: the refined true alignment matches fewer than ``min_inliers``
  nodes (compatible kinds, within ``eps``) or only collinear ones — the pair shares too little
  for any accept rule on these matches (the oracle fits the true correspondences, 2–3 of
  which are enough for it);
- ``truth_below_threshold``: the refined true alignment has the matches but scores below
  ``accept_threshold`` — no search could be accepted there with this evidence;
- ``right_rejected``: ``auto`` found the right alignment and the accept rule refused it;
- ``refine_off``: ``auto`` is near the truth (< 5°, < 1 m) but not within the thresholds;
- ``search_miss``: ``auto`` settled on a wrong alignment that scores below the true one (the
  search never refined the right hypothesis);
- ``score_prefers_wrong``: a wrong alignment scoring at least as well as the true one.

Prints the counts per noise level and overlap bin and the pairs of the fixable classes::

    python -m fusion.evaluation.diagnose --synthetic 300 --noise 0.05,0.15 [--seed 0] [--config
    JSON]
"""

from __future__ import annotations

import argparse
import json
from collections import Counter, defaultdict
from collections.abc import Sequence

from fusion.evaluation.evaluate import synthetic_pairs
from fusion.evaluation.results import EvalPair, is_success, oracle_transform, transform_errors
from fusion.structural import MergeConfig, merge_maps
from fusion.structural.evidence import evaluate
from fusion.structural.prepare import prepare_pair
from fusion.structural.refine import polish

CLASSES = ("truth_too_few_matches", "truth_below_threshold", "right_rejected", "refine_off",
           "search_miss", "score_prefers_wrong")
"""Failure classes, in the order they are tested."""
BINS = ((0.2, 0.4), (0.4, 0.6), (0.6, 1.01))


def classify(pair: EvalPair, config: MergeConfig) -> str | None:
    """``"oracle_fails"`` when the oracle misses too, ``None`` when ``auto`` succeeds, else the
    failure class (:data:`CLASSES`)."""
    oracle = oracle_transform(pair)
    if oracle is None or not is_success(transform_errors(oracle, pair)):
        return "oracle_fails"
    result = merge_maps(pair.map_a, pair.map_b, config=config)
    errors = transform_errors(result.transform, pair)
    if result.accepted and is_success(errors):
        return None
    pa, pb = prepare_pair(pair.map_a, pair.map_b, config)
    truth = polish(pa, pb, evaluate(pa, pb, oracle.theta, oracle.T, config), config).evidence
    if truth.collinear or truth.inliers < config.min_inliers:
        return "truth_too_few_matches"
    if truth.confidence < config.accept_threshold:
        return "truth_below_threshold"
    if is_success(errors):
        return "right_rejected"
    if errors[0] < 5.0 and errors[1] < 1.0:
        return "refine_off"
    return "search_miss" if truth.score > result.score else "score_prefers_wrong"


def diagnose(pairs: Sequence[EvalPair], config: MergeConfig | None = None
             ) -> tuple[dict[tuple[float | None, str], Counter], list[tuple[str, str]]]:
    """Counts per ``(noise, overlap bin)`` (``pairs``, ``oracle``, ``auto`` successes and each
    failure class) and the ``(pair name, class)`` of the fixable failures (not
    ``truth_too_few_matches`` or ``truth_below_threshold``)."""
    cfg = config or MergeConfig()
    table: dict[tuple[float | None, str], Counter] = defaultdict(Counter)
    fixable = []
    for pair in pairs:
        if pair.kind != "overlap":
            continue
        label = next((f"{lo:g}-{min(hi, 1.0):g}" for lo, hi in BINS if lo <= pair.overlap < hi),
                     None)
        if label is None:
            continue
        row = table[(pair.noise, label)]
        row["pairs"] += 1
        cls = classify(pair, cfg)
        if cls == "oracle_fails":
            continue
        row["oracle"] += 1
        if cls is None:
            row["auto"] += 1
            continue
        row[cls] += 1
        if cls not in ("truth_too_few_matches", "truth_below_threshold"):
            fixable.append((pair.name, cls))
    return dict(table), fixable


def main(argv: Sequence[str] | None = None) -> int:
    """The command line (module docstring)."""
    p = argparse.ArgumentParser(prog="python -m fusion.evaluation.diagnose",
                                description=__doc__.split("\n\n")[0])
    p.add_argument("--synthetic", type=int, default=200, metavar="N",
                   help="pairs per noise level")
    p.add_argument("--noise", default="0.05,0.15", help="comma-separated node noise levels")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--config", default=None, metavar="JSON", help="MergeConfig fields")
    args = p.parse_args(argv)
    cfg = MergeConfig.from_dict(json.loads(args.config)) if args.config else MergeConfig()
    noise = [float(s) for s in args.noise.split(",") if s.strip()]
    table, fixable = diagnose(synthetic_pairs(args.synthetic, args.seed, noise), cfg)
    cols = ("pairs", "oracle", "auto") + CLASSES
    print(f"{'noise':>6}{'overlap':>9}" + "".join(f"{c:>{max(8, len(c) + 2)}}" for c in cols))
    for (sigma, label), row in sorted(table.items(), key=lambda kv: (kv[0][0] or 0, kv[0][1])):
        print(f"{sigma:>6g}{label:>9}"
              + "".join(f"{row[c]:>{max(8, len(c) + 2)}}" for c in cols))
    for name, cls in fixable:
        print(f"{name}: {cls}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
