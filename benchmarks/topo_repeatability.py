"""Do two robots' topological maps agree, and does the structural merge find the transform?

    python benchmarks/topo_repeatability.py [--split test] [--pairs data/env_pairs]
        [--methods auto,hybrid,grid] [--stored-maps] [--json out.json]

On the env-pair set (``make env-pairs``; ``benchmarks/env_pairs.py``), for every pair: both
robots' topological maps are extracted again from the stored occupancy grids with the current
``topo.extract_topomap`` (``--stored-maps`` uses the maps stored in the pair files instead: the
extraction of the commit that generated them), then

* **node repeatability** (``fusion.repeatability.node_repeatability``) at 0.5 and 1.0 m, its
  chance level, the node count in the shared region and the pairs with at least 3 mutually
  nearest repeatable nodes (a pair with fewer than 3 nodes in the region counts as a miss),
  over pairs with overlap ≥ 0.2;
* **merges** (``fusion.evaluate.evaluate``) per overlap bin: success (accepted, < 2°, < 0.3 m)
  and wrong accepts (accepted and not a success) over all pairs, no-overlap pairs included.

Tables per dataset folder and for the whole split. ``--split tune`` is what the defaults were
chosen on; report ``test``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from fusion.eval_results import EvalPair  # noqa: E402
from fusion.evaluate import evaluate  # noqa: E402
from fusion.pairs import load_pairs  # noqa: E402
from fusion.repeatability import node_repeatability  # noqa: E402
from topo.extract import extract_topomap  # noqa: E402

BINS = ((0.0, 0.2), (0.2, 0.4), (0.4, 0.7), (0.7, 1.01))


def _maps(pair, stored: bool):
    if stored:
        return pair.map_a, pair.map_b
    return tuple(extract_topomap(np.asarray(g.states), g.resolution, g.origin)
                 for g in (pair.grid_a, pair.grid_b))


def measure(folder: Path, methods: list[str], stored: bool) -> list[dict]:
    """One row per pair of the dataset ``folder``: repeatability and each method's result."""
    rows, eval_pairs = [], []
    for pair in load_pairs(folder):
        map_a, map_b = _maps(pair, stored)
        rep = node_repeatability(map_a, map_b, pair.grid_a, pair.grid_b, pair.transform)
        rows.append({
            "set": folder.name, "pair": pair.pair_id, "overlap": float(pair.overlap),
            "rep": rep.repeatability.tolist(), "chance": rep.chance.tolist(),
            "nodes": rep.nodes, "few": min(rep.nodes_a, rep.nodes_b) < 3,
            "mutual": rep.mutual, "methods": {}})
        eval_pairs.append(EvalPair(f"{folder.name}/{pair.pair_id}", map_a, map_b,
                                   pair.transform, None, float(pair.overlap),
                                   "overlap" if pair.overlap > 0 else "no_overlap", None,
                                   (pair.grid_a, pair.grid_b)))
    if methods:
        for rec in evaluate(eval_pairs, methods, progress=False):
            row = rows[[p.name for p in eval_pairs].index(rec.pair)]
            row["methods"][rec.method] = {"accepted": rec.accepted, "success": rec.success,
                                          "time_s": rec.time_s}
    return rows


def _median(values) -> float:
    values = [v for v in values if v == v]
    return float(np.median(values)) if values else float("nan")


def repeatability_table(rows: list[dict]) -> list[str]:
    lines = [f"{'overlap':>10} {'pairs':>5} {'rep 0.5':>8} {'chance':>7} {'rep 1.0':>8} "
             f"{'chance':>7} {'nodes':>6} {'>=3 mutual':>11}"]
    for lo, hi in ((0.2, 1.01), *BINS[1:]):
        sel = [r for r in rows if lo <= r["overlap"] < hi]
        if not sel:
            continue
        mutual = sum(r["mutual"] >= 3 and not r["few"] for r in sel)
        label = f"{lo:.1f}-{min(hi, 1.0):.1f}"
        lines.append(
            f"{label:>10} {len(sel):5d} {100 * _median(r['rep'][0] for r in sel):7.1f}% "
            f"{100 * _median(r['chance'][0] for r in sel):6.1f}% "
            f"{100 * _median(r['rep'][1] for r in sel):7.1f}% "
            f"{100 * _median(r['chance'][1] for r in sel):6.1f}% "
            f"{_median(r['nodes'] for r in sel):6.1f} "
            f"{mutual:4d} ({100 * mutual / len(sel):3.0f}%)")
    return lines


def merge_table(rows: list[dict], methods: list[str]) -> list[str]:
    head = f"{'method':>8} " + " ".join(f"{f'ov {lo:.1f}-{min(hi, 1.0):.1f}':>13}"
                                        for lo, hi in BINS[1:])
    lines = [head + f" {'ov>=0.4':>13} {'wrong accepts':>16} {'median ms':>9}"]
    for m in methods:
        cells = []
        for lo, hi in (*BINS[1:], (0.4, 1.01)):
            sel = [r for r in rows if lo <= r["overlap"] < hi and m in r["methods"]]
            ok = sum(r["methods"][m]["success"] and r["methods"][m]["accepted"] for r in sel)
            cells.append(f"{ok:3d}/{len(sel):<3d}({100 * ok / max(len(sel), 1):3.0f}%)")
        done = [r for r in rows if m in r["methods"]]
        wrong = sum(r["methods"][m]["accepted"] and not r["methods"][m]["success"]
                    for r in done)
        ms = 1000 * _median(r["methods"][m]["time_s"] for r in done)
        lines.append(f"{m:>8} " + " ".join(cells)
                     + f" {wrong:4d}/{len(done):<4d}({100 * wrong / max(len(done), 1):4.1f}%)"
                     + f" {ms:9.1f}")
    return lines


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pairs", type=Path, default=ROOT / "data" / "env_pairs")
    parser.add_argument("--split", default="test", choices=["tune", "test"])
    parser.add_argument("--methods", default="auto,hybrid,grid",
                        help="comma-separated fusion.evaluate methods ('' for none)")
    parser.add_argument("--stored-maps", action="store_true",
                        help="use the maps stored in the pair files (the generating commit's)")
    parser.add_argument("--json", type=Path, help="also write every row here")
    args = parser.parse_args(argv)
    folders = sorted(p for p in (args.pairs / args.split).glob("*") if p.is_dir())
    if not folders:
        parser.error(f"no datasets under {args.pairs / args.split}: run `make env-pairs`")
    methods = [m for m in args.methods.split(",") if m]
    rows = []
    for folder in folders:
        rows += measure(folder, methods, args.stored_maps)
    groups = {"procedural": [r for r in rows if not r["set"].startswith("real_")],
              "real maps": [r for r in rows if r["set"].startswith("real_")],
              "all": rows}
    maps = "stored maps" if args.stored_maps else "maps extracted again"
    print(f"# {args.split} split, {len(rows)} pairs from {len(folders)} datasets ({maps})")
    for name, sel in groups.items():
        if not sel:
            continue
        print(f"\n## {name}: node repeatability (pairs with overlap >= 0.2)")
        print("\n".join(repeatability_table(sel)))
        if methods:
            print(f"\n## {name}: merges (success: accepted, < 2 deg, < 0.3 m)")
            print("\n".join(merge_table(sel, methods)))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
