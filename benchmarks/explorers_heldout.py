"""Scripted explorers on the held-out worlds of ``training_eval.py``: T50/T85/T95 per world,
and two such runs (two commits) compared.

    python benchmarks/explorers_heldout.py --out rows.json [--explorers frontier ...]
        [--worlds 20] [--skip-real] [--workers 1]
    python benchmarks/explorers_heldout.py --compare before.json after.json

The worlds are :func:`training_eval.heldout_worlds` (20 procedural buildings, sides 10–20 m,
plus the real maps); an episode is :func:`training_eval.episode`, so the numbers are the
ones ``training_eval.py`` reports for the scripted explorers. Rows are saved (atomically)
after each episode and reused, so an interrupted run resumes. ``--compare`` prints, per
explorer, the median, mean and interquartile mean of T85 over the worlds of both files, the
relative change, and how many worlds got faster, tied or slower.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from training_eval import episode, heldout_worlds, iqm  # noqa: E402

from topo.fileio import atomic_write_json  # noqa: E402

EXPLORERS = ("frontier", "coordinated_frontier")


def run(out: Path, explorers: list[str], n_worlds: int, real: bool, workers: int) -> None:
    """Every (explorer, held-out world) episode not yet in ``out``, saved after each."""
    rows = json.loads(out.read_text()) if out.exists() else {}
    todo = [(e, w) for e in explorers for w in heldout_worlds(n_worlds, real)
            if f"{e}|{w.id}" not in rows]
    print(f"{len(todo)} episodes to run", flush=True)

    def keep(e, w, r, seconds):
        r.pop("curve", None)
        rows[f"{e}|{w.id}"] = {**r, "seconds": seconds}
        atomic_write_json(out, rows)
        print(f"{e} {w.id}: T85 {r['T85']:.0f} ({seconds:.1f} s)", flush=True)

    if workers == 1:
        for e, w in todo:
            t0 = time.perf_counter()
            keep(e, w, episode(e, w), time.perf_counter() - t0)
        return
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(workers) as pool:
        for (e, w), r in zip(todo, pool.map(episode, *zip(*todo, strict=True)), strict=True):
            keep(e, w, r, float("nan"))


def compare(before: Path, after: Path) -> None:
    """The T85 (and T95) comparison table of two row files (common worlds only)."""
    a, b = json.loads(before.read_text()), json.loads(after.read_text())
    common = sorted(set(a) & set(b))
    print("| explorer | worlds | metric | before median | after median | before mean | "
          "after mean | before IQM | after IQM | IQM change | faster / tied / slower | "
          "wall s before → after |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for e in dict.fromkeys(k.split("|")[0] for k in common):
        keys = [k for k in common if k.startswith(f"{e}|")]
        for m in ("T85", "T95"):
            x = np.array([a[k][m] for k in keys])
            y = np.array([b[k][m] for k in keys])
            secs = (sum(a[k].get("seconds", 0.0) for k in keys),
                    sum(b[k].get("seconds", 0.0) for k in keys))
            print(f"| {e} | {len(keys)} | {m} | {np.median(x):.0f} | {np.median(y):.0f} | "
                  f"{x.mean():.0f} | {y.mean():.0f} | {iqm(x):.0f} | {iqm(y):.0f} | "
                  f"{iqm(y) / iqm(x) - 1:+.1%} | {(y < x).sum()} / {(y == x).sum()} / "
                  f"{(y > x).sum()} | {secs[0]:.0f} → {secs[1]:.0f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, help="rows file (JSON) to fill")
    parser.add_argument("--explorers", nargs="+", default=list(EXPLORERS))
    parser.add_argument("--worlds", type=int, default=20)
    parser.add_argument("--skip-real", action="store_true")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--compare", type=Path, nargs=2, metavar=("BEFORE", "AFTER"))
    opts = parser.parse_args()
    if opts.compare:
        compare(*opts.compare)
    elif opts.out is None:
        parser.error("--out or --compare is required")
    else:
        run(opts.out, opts.explorers, opts.worlds, not opts.skip_real, opts.workers)


if __name__ == "__main__":
    main()
