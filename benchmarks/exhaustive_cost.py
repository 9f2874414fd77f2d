"""Cost per placement of the paper's exhaustive search, against the constant its refusal uses.

``fusion.exhaustive_search`` refuses more than ``DEFAULT_MAX_EVALUATIONS`` placements and states
an estimated time from ``fusion.search.SECONDS_PER_EVALUATION``; this prints the measured cost
per placement over map sizes so that the constant can be checked on a machine. Maps are
synthetic topological maps (``fusion.evaluation.synthetic.make_pair``, 80 % overlap: many coinciding
endpoints, the dense case) and uniform random points in a 40 m square (sparse); the rotation
step is chosen so that each search scores about ``--placements`` placements (the cost of one
angle does not depend on the step). Times are medians of ``--repeats`` runs after a warm-up.

    PYTHONPATH=. python benchmarks/exhaustive_cost.py [--sizes 20,40,80,160,300] [--repeats 3]
"""

from __future__ import annotations

import argparse

import numpy as np
from _timing import median_time

from fusion.evaluation.synthetic import make_pair
from fusion.search import (
    DEFAULT_MAX_EVALUATIONS,
    SECONDS_PER_EVALUATION,
    exhaustive_evaluations,
    exhaustive_search,
    search_angles,
)


def step_for(n_a: int, n_b: int, placements: int) -> float:
    """The finest of 2°, 3°, ... 180° whose search scores at most ``placements``."""
    for step in range(2, 181):
        if exhaustive_evaluations(n_a, n_b, step) <= placements:
            return float(step)
    return 180.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="20,40,80,160,300",
                        help="nodes per map, comma-separated")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--placements", type=int, default=1_500_000,
                        help="placements per timed search (sets the rotation step)")
    args = parser.parse_args()
    sizes = [int(v) for v in args.sizes.split(",")]
    rng = np.random.default_rng(0)
    print(f"reference: SECONDS_PER_EVALUATION = {SECONDS_PER_EVALUATION * 1e6:g} µs, "
          f"DEFAULT_MAX_EVALUATIONS = {DEFAULT_MAX_EVALUATIONS:,}")
    print(f"{'maps':<10}{'nodes':>6}{'n_A x n_B':>12}{'step °':>8}{'placements':>12}"
          f"{'ms':>9}{'µs/placement':>14}{'/ reference':>13}")
    for n in sizes:
        pair = make_pair(np.random.default_rng(n), overlap=0.8, nodes=(n, n))
        cases = {"synthetic": (pair.map_a.endpoints(), pair.map_b.endpoints()),
                 "uniform": (rng.uniform(0, 40, (n, 2)), rng.uniform(0, 40, (n, 2)))}
        for label, (a, b) in cases.items():
            step = step_for(len(a), len(b), args.placements)
            count = len(a) * len(b) * len(search_angles(step))
            t = median_time(lambda a=a, b=b, step=step: exhaustive_search(
                a, b, step_deg=step, max_evaluations=None), args.repeats)
            per = t / count
            print(f"{label:<10}{n:>6}{f'{len(a)} x {len(b)}':>12}{step:>8g}{count:>12,}"
                  f"{t * 1e3:>9.0f}{per * 1e6:>14.2f}{per / SECONDS_PER_EVALUATION:>13.2f}")


if __name__ == "__main__":
    main()
