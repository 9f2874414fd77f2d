"""Where does ``merge_maps(method="auto")``'s search lose the true alignment? For the
``search_miss`` pairs of :mod:`fusion.diagnose` (auto settles on a wrong alignment scoring below
the refined truth; with ``--rule-off``, whatever the truth's score: the misses under the
ceiling of ``merge_tradeoff.py``), on that script's pairs, the first stage of the search where no
hypothesis near the truth survives (:func:`trace` repeats :func:`fusion.merge._auto` step by
step: keep the two in step):

- ``no_true_pair``: no (A pair, B pair) of true correspondences is generated, and why (the first
  filter every pair of true correspondences fails: ``kind`` compatibility, ``min_dist``
  (``min_pair_distance``), ``pair_set`` (neither near in the graph nor among the ``knn``
  nearest, in A or B), ``tolerance`` (``pair_tolerance``));
- ``max_hypotheses``: generated, but every near-truth hypothesis falls to the cut by pair length;
- ``coarse_fit``: kept, but the coarse refit moves every one away from the truth, or scores it
  0 (it lands fewer nodes than the refit needs: before ``sparse_pool``, pairs sharing 3 nodes);
- ``path_pool``: not among the ``path_pool`` (+ ``sparse_pool``) best distinct coarse
  hypotheses (rank shown);
- ``candidates``: in the pool, cut by the path re-ranking to ``candidates``;
- ``refine``: a candidate, moved off the truth by the gated refits;
- ``scored``: refined near the truth but not among the ``scored`` most matched;
- ``argmax``: scored, but a wrong candidate scores higher before the polish;
- ``polish``: the near-truth candidate was best but polishing moved it off.

"Near the truth": within ``NEAR_DEG`` and ``NEAR_M`` at B's centroid.

    python benchmarks/search_stages.py [--pairs 450] [--seed 100] [--config JSON] [--rule-off]
        [--all-misses]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from merge_tradeoff import OVERLAP_PAIRS  # noqa: E402  (benchmarks/, the same pairs)

from fusion import _merge_kernels as K  # noqa: E402
from fusion import merge as M  # noqa: E402
from fusion.diagnose import classify  # noqa: E402
from fusion.evaluate import synthetic_pairs  # noqa: E402
from topo.graph import NodeKind  # noqa: E402

NEAR_DEG = 5.0
NEAR_M = 1.0
STAGES = ("no_true_pair", "max_hypotheses", "coarse_fit", "path_pool", "candidates", "refine",
          "scored", "argmax", "polish", "found")


def _near(pair, theta, tx, ty):
    """Bool array: motions within NEAR_DEG / NEAR_M of the truth at B's centroid."""
    T = pair.transform
    centre = pair.map_b.xy.mean(axis=0)
    gap = np.abs(np.angle(np.exp(1j * (np.asarray(theta) - T.theta))))
    c, s = np.cos(theta), np.sin(theta)
    px = c * centre[0] - s * centre[1] + tx
    py = s * centre[0] + c * centre[1] + ty
    q = T.apply(centre)
    return (gap < math.radians(NEAR_DEG)) & (np.hypot(px - q[0], py - q[1]) < NEAR_M)


def _why_no_pair(pair, pa, pb, cfg):
    """First failing filter over all pairs of true correspondences (the one failed latest)."""
    c = pair.correspondences
    a_set = {(int(i), int(j)) for i, j in zip(pa.pair_i, pa.pair_j, strict=True)}
    b_set = {(int(i), int(j)) for i, j in zip(pb.pair_i, pb.pair_j, strict=True)}
    order = ("kind", "min_dist", "pair_set", "tolerance")
    best = -1
    for u in range(len(c)):
        for v in range(u + 1, len(c)):
            a1, b1 = c[u]
            a2, b2 = c[v]
            if not (M.KIND_COMPATIBLE[pa.kinds[a1], pb.kinds[b1]]
                    and M.KIND_COMPATIBLE[pa.kinds[a2], pb.kinds[b2]]):
                best = max(best, 0)
                continue
            la = np.hypot(*(pa.xy[a1] - pa.xy[a2]))
            lb = np.hypot(*(pb.xy[b1] - pb.xy[b2]))
            if min(la, lb) < cfg.min_pair_distance:
                best = max(best, 1)
                continue
            if (min(a1, a2), max(a1, a2)) not in a_set or (min(b1, b2), max(b1, b2)) not in b_set:
                best = max(best, 2)
                continue
            if abs(la - lb) > cfg.pair_tolerance:
                best = max(best, 3)
                continue
            return None
    return order[best] if best >= 0 else "under_2_correspondences"


def trace(pair, cfg):
    """The stage where the truth is lost (:data:`STAGES`) and details."""
    pa, pb = M._prepare(pair.map_a, cfg), M._prepare(pair.map_b, cfg)
    info = {}
    b_i = np.concatenate([pb.pair_i, pb.pair_j])
    b_j = np.concatenate([pb.pair_j, pb.pair_i])
    b_len = np.concatenate([pb.pair_len, pb.pair_len])
    order = np.argsort(b_len, kind="stable")
    b_i, b_j = b_i[order], b_j[order]
    hyp_p, hyp_q, weight = K.pair_candidates(pa.kinds, pa.pair_i, pa.pair_j, pa.pair_len,
                                             pb.kinds, b_i, b_j, b_len[order],
                                             cfg.pair_tolerance, M.KIND_COMPATIBLE)
    n_hyp = len(hyp_p)
    info["n_hyp"] = n_hyp
    why = _why_no_pair(pair, pa, pb, cfg)
    th_all, tx_all, ty_all, _, _ = K.pair_motions(pa.xy, pa.pair_i, pa.pair_j, pb.xy, b_i, b_j,
                                                  hyp_p, hyp_q)
    near_all = _near(pair, th_all, tx_all, ty_all)
    info["near_generated"] = int(near_all.sum())
    if why is not None and not near_all.any():
        return "no_true_pair", why, info
    if n_hyp > cfg.max_hypotheses:
        keep = np.sort(np.argpartition(-weight, cfg.max_hypotheses - 1)[:cfg.max_hypotheses])
        hyp_p, hyp_q = hyp_p[keep], hyp_q[keep]
    theta, tx, ty, cos_t, sin_t = K.pair_motions(pa.xy, pa.pair_i, pa.pair_j, pb.xy, b_i, b_j,
                                                 hyp_p, hyp_q)
    near0 = _near(pair, theta, tx, ty)
    if not near0.any():
        return "max_hypotheses", f"{int(near_all.sum())} near of {n_hyp} all cut", info
    table, x0, y0, inv_cell = M._hit_grid(pa, cfg.coarse_tolerance, cfg.eps)
    landed = np.zeros(len(theta), dtype=np.int64)
    min_pairs = max(cfg.min_inliers, M._COARSE_MIN_PAIRS)
    reserve = cfg.sparse_pool if cfg.min_inliers < min_pairs else 0
    coarse = K.refined_scores(theta, tx, ty, cos_t, sin_t, pa.xy, pb.xy, pb.kinds, table, x0,
                              y0, inv_cell, cfg.eps, int(NodeKind.DEAD_END),
                              cfg.min_inliers if reserve else min_pairs, landed)
    few = landed < min_pairs
    near1 = _near(pair, theta, tx, ty) & (coarse > 0) & (~few if not reserve else True)
    if not near1.any():
        return "coarse_fit", f"{int(near0.sum())} near before", info
    centre = pb.xy.mean(axis=0)
    cx, cy = M._centroid_image(theta, tx, ty, centre)
    ranked = np.argsort(np.where(few, 0.0, -coarse), kind="stable")
    info["coarse_rank"] = int(np.flatnonzero(near1[ranked])[0])
    chosen = K.select_distinct(ranked, theta, cx, cy, math.radians(cfg.distinct_angle_deg),
                               cfg.distinct_distance, max(cfg.path_pool, cfg.candidates))
    if reserve:
        small = np.flatnonzero(few & (coarse > M._SPARSE_MIN * landed))
        small = small[np.argsort(-coarse[small], kind="stable")]
        chosen = K.select_distinct(np.concatenate([chosen, small]), theta, cx, cy,
                                   math.radians(cfg.distinct_angle_deg), cfg.distinct_distance,
                                   len(chosen) + reserve)
    if not near1[chosen].any():
        # rank among distinct ones, had the pool been unlimited
        allc = K.select_distinct(ranked, theta, cx, cy, math.radians(cfg.distinct_angle_deg),
                                 cfg.distinct_distance, len(ranked))
        hit = np.flatnonzero(near1[allc])
        return "path_pool", f"distinct rank {int(hit[0]) if len(hit) else -1}", info
    if len(chosen) > cfg.candidates:
        w = M.CONFIDENCE_WEIGHTS
        paths = M._path_evidence(pa, pb, theta[chosen], tx[chosen], ty[chosen], both=False)
        gain = coarse[chosen] + paths @ M._PATH_WEIGHTS / (w["closeness"] + w["inliers"])
        pos = int(np.flatnonzero(near1[chosen])[0])
        new_rank = int(np.flatnonzero(np.argsort(-gain, kind="stable") == pos)[0])
        info["pool_pos"], info["gain_rank"] = pos, new_rank
        chosen = chosen[np.argsort(-gain, kind="stable")[:cfg.candidates]]
        if not near1[chosen].any():
            return "candidates", f"pool position {pos} -> gain rank {new_rank}", info
    th, txc, tyc = theta[chosen].copy(), tx[chosen].copy(), ty[chosen].copy()
    gates = np.array([cfg.coarse_tolerance, cfg.eps])
    counts = K.refine_batch(th, txc, tyc, pa.xy, pa.kinds, pb.xy, pb.kinds, M.KIND_COMPATIBLE,
                            gates)
    near2 = _near(pair, th, txc, tyc)
    if not near2.any():
        return "refine", "", info
    keep = np.sort(np.argsort(-counts, kind="stable")[:cfg.scored])
    if not near2[keep].any():
        cut = np.sort(counts)[::-1][cfg.scored - 1]
        return "scored", f"count {counts[near2].max()} vs cut {cut}", info
    th, txc, tyc = th[keep], txc[keep], tyc[keep]
    near3 = near2[keep]
    features = K.evidence_batch(*M._evidence_args(pa, pb), th, txc, tyc, cfg.eps,
                                M.KIND_COMPATIBLE, int(NodeKind.DEAD_END), M._BRANCH_TOL,
                                M._MIN_CROSSING_SIN, cfg.near_miss)
    scores = M._scores(features, M._path_evidence(pa, pb, th, txc, tyc), len(pa.xy), len(pb.xy))
    k = int(np.argmax(scores))
    if not near3[k]:
        return "argmax", f"near {scores[near3].max():.2f} vs best {scores[k]:.2f}", info
    best = M._polish(pa, pb, M._evaluate(pa, pb, th[k], np.array([txc[k], tyc[k]]), cfg), cfg)
    if not _near(pair, np.array([best.theta]), best.t[0], best.t[1])[0]:
        return "polish", "", info
    return "found", "", info


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--pairs", type=int, default=450)
    p.add_argument("--seed", type=int, default=100)
    p.add_argument("--noise", default="0.05,0.15")
    p.add_argument("--config", default=None)
    p.add_argument("--all-misses", action="store_true",
                   help="trace every fixable miss, not only search_miss")
    p.add_argument("--rule-off", action="store_true",
                   help="classify with the accept rule off (min_score -1e6, min_margin 0): "
                        "search misses whatever the truth's score, the ceiling's misses")
    args = p.parse_args()
    cfg = M.MergeConfig.from_dict(json.loads(args.config)) if args.config else M.MergeConfig()
    noises = [float(s) for s in args.noise.split(",")]
    off = dataclasses.replace(cfg, min_score=-1e6, min_margin=0.0)
    pairs = synthetic_pairs(args.pairs, args.seed, noises, OVERLAP_PAIRS)
    table = Counter()
    classes = Counter()
    why = Counter()
    for pair in pairs:
        cls = classify(pair, off if args.rule_off else cfg)
        lo = 0.2 if pair.overlap < 0.4 else 0.4 if pair.overlap < 0.6 else 0.6
        classes[(pair.noise, lo, cls)] += 1
        if cls != "search_miss" and not (args.all_misses and cls in (
                "right_rejected", "refine_off", "score_prefers_wrong")):
            continue
        stage, detail, info = trace(pair, cfg)
        table[(pair.noise, lo, stage)] += 1
        if stage == "no_true_pair":
            why[detail] += 1
        print(f"{pair.name} ov {pair.overlap:.2f} {cls}: {stage} {detail} {info}", flush=True)
    print()
    print("| σ | bin | search_miss | " + " | ".join(STAGES) + " |")
    print("|---|---|---|" + "---|" * len(STAGES))
    for noise in noises:
        for lo in (0.2, 0.4, 0.6):
            n = classes[(noise, lo, "search_miss")]
            print(f"| {noise:g} | {lo:.0%}– | {n} | "
                  + " | ".join(str(table[(noise, lo, s)]) for s in STAGES) + " |")
    print("no_true_pair reasons:", dict(why))
    succ = Counter()
    for (noise, lo, cls), v in classes.items():
        succ[(noise, lo, cls)] += v
    print("classes:", {f"{k[0]:g}/{k[1]:g}/{k[2]}": v for k, v in sorted(
        classes.items(), key=lambda kv: (kv[0][0], kv[0][1], str(kv[0][2])))})


if __name__ == "__main__":
    main()
