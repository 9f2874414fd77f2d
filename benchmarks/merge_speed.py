"""Merge time against map size for every ``fusion.merge_maps`` method, with ratios to the paper's
exhaustive search measured in the same run.

Pairs are synthetic (:mod:`fusion.synthetic`: lattice-like corridor worlds, node noise 0.15 m,
50% overlap, any rotation); each robot explores ``n`` world nodes, so the maps have about ``n``
nodes (the table prints the median real count). Times are medians over the pairs, methods
interleaved pair by pair in this one process, after one warm-up call (compiled kernels load on
the first call), so the ratios are fair on a busy machine; ``auto cpu`` is the process CPU time
of ``auto`` (what the merge costs when it has a core to itself). The exhaustive search is slow
(``n_A × n_B × 181`` placements): it runs up to ``--exhaustive-max`` nodes only.

    python benchmarks/merge_speed.py [--sizes 10,20,40,60,80,120,200] [--pairs 10]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from fusion.merge import METHODS, merge_maps
from fusion.synthetic import SyntheticConfig, make_pair


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="10,20,40,60,80,120,200")
    parser.add_argument("--pairs", type=int, default=10, help="pairs per size")
    parser.add_argument("--exhaustive-max", type=int, default=80,
                        help="largest size the exhaustive search runs at")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")]
    cfg = SyntheticConfig(noise=0.15)

    warm = make_pair(np.random.default_rng(0), cfg, overlap=0.5, nodes=(20, 20))
    for m in METHODS:
        merge_maps(warm.map_a, warm.map_b, method=m)

    head = f"{'n':>5}{'nodes A/B':>11}" + "".join(f"{m + ' ms':>18}" for m in METHODS)
    print(head + f"{'auto cpu ms':>13}{'exhaustive/auto':>17}{'auto accepted':>15}")
    for n in sizes:
        pairs = [make_pair(np.random.default_rng([args.seed, n, i]), cfg, overlap=0.5,
                           nodes=(n, n)) for i in range(args.pairs)]
        methods = [m for m in METHODS if m != "exhaustive" or n <= args.exhaustive_max]
        times: dict[str, list[float]] = {m: [] for m in methods}
        cpu: list[float] = []
        accepted = 0
        for p in pairs:
            for m in methods:
                t0, c0 = time.perf_counter(), time.process_time()
                r = merge_maps(p.map_a, p.map_b, method=m)
                times[m].append(time.perf_counter() - t0)
                if m == "auto":
                    cpu.append(time.process_time() - c0)
                    accepted += r.accepted
        med = {m: 1000 * statistics.median(v) for m, v in times.items()}
        nodes = (f"{statistics.median(len(p.map_a) for p in pairs):.0f}/"
                 f"{statistics.median(len(p.map_b) for p in pairs):.0f}")
        ratio = f"{med['exhaustive'] / med['auto']:.0f}x" if "exhaustive" in med else "-"
        print(f"{n:>5}{nodes:>11}" + "".join(
            f"{med[m]:>18.2f}" if m in med else f"{'-':>18}" for m in METHODS)
            + f"{1000 * statistics.median(cpu):>13.2f}{ratio:>17}{accepted:>10}/{len(pairs)}")


if __name__ == "__main__":
    main()
