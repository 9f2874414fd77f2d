"""Merge accuracy on real sensor-map pairs: how often each merge method's estimate is right, how
often it is accepted, how often it is accepted wrongly, on a ``topomerge.real_pairs`` manifest
(``benchmarks/real_pairs.py`` makes one from public laser logs).

    python benchmarks/real_maps.py --pairs data/real_pairs/manifest.json [--methods grid,orb]
        [--split dev|test|all] [--out data/real_maps]

Methods:

* ``grid``: what ``topomerge merge A.yaml B.yaml`` does for one pair — both maps read by
  :func:`fusion.mapmerge.load_input` (cropped to their known cells), B resampled to A's
  resolution (:func:`fusion.mapmerge.resampled`), :func:`fusion.grid_merge.merge_grids` with
  the tool's settings. Its estimate and evidence do not depend on the confidence model, so the
  table judges every stored model on the same rows: ``grid [sim]`` is the env's model at its
  threshold, ``grid [real]`` the model fitted on real maps (:data:`fusion.decision.
  REAL_MAP_MODEL`, the tool's default) at its own.
* ``orb``: ``benchmarks/_orb.py``'s ``orb_rigid`` (m-explore's ORB + RANSAC estimate and
  confidence rule), skipped with a message when that module or OpenCV is missing.

Per pair and method one JSON line in ``OUT/<method>.jsonl`` (rewritten atomically after each
pair; a rerun skips the pairs done): the estimate (B's map frame → A's, ``[x, y, θ]``),
accepted, confidence, seconds, the rotation and translation errors against the truth (the
translation error at B's known-cells centroid, in B's map frame), whether it is right (< 2°
and < 0.3 m: :func:`fusion.evaluation.results.is_success`), and for ``grid`` the evidence
features of :meth:`fusion.grid_merge.GridMergeResult.features` — the rows ``python -m
fusion.calibration fit --model grid_real --rows OUT/grid.jsonl --split dev`` fits on.

The table (also ``OUT/table.md``), per method: pairs; those that *should merge* (a true
overlap of at least :data:`SHOULD_MERGE_M2` m² of B's known area: enough shared walls that a
right merge is expected); accepted (% of all pairs); right (accepted and right, % of the
should-merge pairs); wrong accepts (accepted and not right, % of all pairs, and % of the pairs
with no overlap at all: other places of the building, other buildings); the estimate's own
right rate on the should-merge pairs (what a perfect accept rule could reach); the most right
accepts any threshold on the method's confidence reaches with at most 1 % wrong accepts of
all pairs; the median seconds per pair.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from fusion.calibration import load_model, read_table  # noqa: E402
from fusion.decision import REAL_MAP_MODEL, MergeRule, model_threshold  # noqa: E402
from fusion.evaluation.results import is_success  # noqa: E402
from fusion.grid_merge import GridMergeConfig, merge_grids  # noqa: E402
from fusion.mapmerge import InputMap, load_input, resampled  # noqa: E402
from fusion.rigid import Rigid2D  # noqa: E402
from topo.fileio import (  # noqa: E402
    atomic_write_bytes,
    atomic_write_json_lines,
    read_json_lines,
)

FORMAT = "topomerge.real_pairs"
"""The manifest's ``format`` (version 1)."""

SHOULD_MERGE_M2 = 20.0
"""A pair should merge when its true overlap covers at least this much (m²) of B's known
area: a few metres of corridor and a room's walls, enough for a right merge to be expected
of any method (smaller overlaps are counted in the wrong accepts only)."""

MAX_WRONG = 0.01
"""Most wrong accepts (of all pairs) the best-threshold column allows."""

METHODS = ("grid", "orb")
"""The methods ``--methods`` chooses from."""

MODELS = {"sim": "grid", "real": REAL_MAP_MODEL}
"""The grid method's confidence models the table judges (those present in the table)."""


class ManifestError(ValueError):
    """A manifest that is not a ``topomerge.real_pairs`` version 1 file (the message says
    what is wrong)."""


def read_manifest(path: str | Path, split: str = "all") -> list[dict]:
    """The pairs of the manifest at ``path`` in ``split`` (``"dev"``, ``"test"`` or
    ``"all"``), their ``a``/``b`` resolved against the manifest's folder.

    Raises:
        ManifestError: a missing file, another format or version, a pair without its keys.
        ValueError: an unknown ``split``.
    """
    if split not in ("dev", "test", "all"):
        raise ValueError(f"split must be 'dev', 'test' or 'all', got {split!r}")
    path = Path(path)
    if not path.is_file():
        raise ManifestError(f"{path}: manifest not found (benchmarks/real_pairs.py makes it)")
    doc = json.loads(path.read_text())
    if doc.get("format") != FORMAT or doc.get("version") != 1:
        raise ManifestError(f"{path}: not a {FORMAT} version 1 manifest")
    pairs = []
    for p in doc["pairs"]:
        missing = [k for k in ("id", "building", "split", "a", "b", "truth", "overlap",
                               "overlap_m2") if k not in p]
        if missing:
            raise ManifestError(f"{path}: pair {p.get('id')!r} lacks {missing}")
        if split in ("all", p["split"]):
            pairs.append({**p, "a": str(path.parent / p["a"]), "b": str(path.parent / p["b"])})
    return pairs


def load_pair(pair: dict) -> tuple[InputMap, InputMap]:
    """A pair's maps as the tool reads them: cropped, B at A's resolution."""
    a = load_input(pair["a"])[0]
    b = load_input(pair["b"])[0]
    return a, resampled(b, a.resolution)


def map_frames(a: InputMap, b: InputMap, grid_t: Rigid2D) -> Rigid2D:
    """A transform of B's grid frame into A's, as one of B's map frame into A's (the frame
    the manifest's truth is in; the ROS origins' yaw)."""
    return a.frame @ grid_t @ b.frame.inverse()


def judged(pair: dict, b: InputMap, estimate: Rigid2D | None) -> dict:
    """The estimate's errors against the pair's truth, at B's known-cells centroid (B's map
    frame), and whether it is right (``None`` errors: no truth or no estimate)."""
    out = {"rotation_error_deg": None, "translation_error_m": None, "right": False,
           "estimate": None if estimate is None else [float(estimate.T[0]),
                                                      float(estimate.T[1]),
                                                      float(estimate.theta)]}
    if pair["truth"] is None or estimate is None:
        return out
    truth = Rigid2D.from_pose(pair["truth"])
    centre = b.frame.apply(b.centre()[None])[0]
    rot = math.degrees(estimate.rotation_error(truth))
    trans = float(estimate.translation_error(truth, at=centre))
    out.update(rotation_error_deg=rot, translation_error_m=trans,
               right=bool(pair["overlap"] > 0 and is_success((rot, trans))))
    return out


def run_grid(pair: dict, a: InputMap, b: InputMap) -> dict:
    """The ``grid`` method on one pair (module docstring): its row."""
    r = merge_grids(a, b, GridMergeConfig())
    row = judged(pair, b, map_frames(a, b, r.transform))
    row.update(accepted=bool(r.accepted), confidence=float(r.confidence), seconds=r.time_s,
               features=r.features(), margin=float(min(r.margin, 1e9)),
               overlap_m2=float(r.overlap_m2), reason=r.reason)
    return row


def orb_method() -> Any:
    """``benchmarks/_orb.py``'s ``orb_rigid``, or ``None`` (with why) when it is missing."""
    try:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        import cv2  # noqa: F401 - the bench extra: missing, the method is skipped
        from _orb import orb_rigid
    except ImportError as exc:
        print(f"orb skipped: {exc}")
        return None
    return orb_rigid


def run_orb(orb_rigid: Any, pair: dict, a: InputMap, b: InputMap) -> dict:
    """The ``orb`` method on one pair: its row (no estimate when ORB found none)."""
    t0 = time.perf_counter()
    out = orb_rigid(a, b)
    seconds = time.perf_counter() - t0
    if isinstance(out, tuple):
        transform, confidence, accepted = out[:3]
    else:
        transform, confidence, accepted = out.transform, out.confidence, out.accepted
    estimate = None if transform is None else map_frames(a, b, transform)
    row = judged(pair, b, estimate)
    row.update(accepted=bool(accepted and estimate is not None),
               confidence=float(confidence or 0.0), seconds=seconds)
    return row


def evaluate(pairs: Sequence[dict], methods: Sequence[str], out: Path) -> dict[str, list[dict]]:
    """Run ``methods`` on ``pairs``, appending to ``OUT/<method>.jsonl`` (pairs already there
    are skipped); returns every method's rows for ``pairs``."""
    out.mkdir(parents=True, exist_ok=True)
    runners: dict[str, Any] = {}
    for m in methods:
        if m == "orb":
            orb = orb_method()
            if orb is not None:
                runners[m] = lambda p, a, b, orb=orb: run_orb(orb, p, a, b)
        else:
            runners[m] = run_grid
    rows = {m: read_json_lines(out / f"{m}.jsonl") for m in runners}
    done = {m: {r["id"] for r in rs} for m, rs in rows.items()}
    for k, pair in enumerate(pairs):
        todo = [m for m in runners if pair["id"] not in done[m]]
        if not todo:
            continue
        a, b = load_pair(pair)
        for m in todo:
            row = runners[m](pair, a, b)
            rows[m].append({"id": pair["id"], "building": pair["building"],
                            "split": pair["split"], "method": m, "overlap": pair["overlap"],
                            "true_overlap_m2": pair["overlap_m2"],
                            "no_truth": pair["truth"] is None,
                            # the calibration's row keys (fusion.calibration.rows)
                            "set": f"real_pairs_{pair['split']}", "pair": pair["id"],
                            "world": pair["building"], "way": "ab", **row})
            atomic_write_json_lines(out / f"{m}.jsonl", rows[m], allow_nan=False)
        print(f"{k + 1}/{len(pairs)} {pair['id']}: " + ", ".join(
            f"{m} {'accepted' if r['accepted'] else 'rejected'} "
            f"{'right' if r['right'] else 'wrong'}"
            for m in todo for r in rows[m][-1:]), flush=True)
    ids = {p["id"] for p in pairs}
    return {m: [r for r in rs if r["id"] in ids] for m, rs in rows.items()}


def rejudged(rows: Sequence[dict], model: str, threshold: float) -> list[dict]:
    """The grid rows with the confidence and accept of ``model`` at ``threshold`` (the
    estimate and evidence stay: they do not depend on the model)."""
    rule = MergeRule(accept_threshold=threshold)
    calibrator = load_model(model)
    out = []
    for r in rows:
        conf = rule.tie_capped(calibrator(r["features"]), r["margin"])
        ok = r["estimate"] is not None and rule.grid(conf, r["overlap_m2"], r["margin"],
                                                     0.0, 0.0) is None
        out.append({**r, "confidence": conf, "accepted": ok})
    return out


def summary(rows: Sequence[dict], gate_m2: float = 0.0) -> dict[str, float]:
    """The table's figures of one method's rows (module docstring); ``gate_m2``: the
    method's hard overlap gate, kept in the best-threshold sweep."""
    n = len(rows)
    right = np.array([r["right"] for r in rows], dtype=bool)
    acc = np.array([r["accepted"] for r in rows], dtype=bool)
    should = np.array([not r["no_truth"] and r["true_overlap_m2"] >= SHOULD_MERGE_M2
                       for r in rows])
    none = np.array([r["no_truth"] or r["overlap"] == 0 for r in rows], dtype=bool)
    conf = np.array([r["confidence"] for r in rows])
    gated = np.array([r.get("overlap_m2", math.inf) >= gate_m2 for r in rows])
    best = 0.0
    for th in np.unique(conf):
        a = (conf >= th) & gated
        if (a & ~right).sum() <= MAX_WRONG * n:
            best = max(best, (a & right & should).sum() / max(should.sum(), 1))
    return {"pairs": n, "should": int(should.sum()), "none": int(none.sum()),
            "accepted": acc.mean() if n else math.nan,
            "right": (acc & right & should).sum() / max(should.sum(), 1),
            "wrong": (acc & ~right).sum() / max(n, 1),
            "false": (acc & none).sum() / max(none.sum(), 1),
            "ceiling": (right & should).sum() / max(should.sum(), 1), "best": best,
            "ms": 1000 * statistics.median(r["seconds"] for r in rows) if n else math.nan}


def table(results: dict[str, list[dict]]) -> str:
    """The markdown table of every method (and of each stored grid model)."""
    lines = ["| method | pairs | should merge | accepted | right | wrong accepts (all) | "
             "false accepts (no overlap) | estimate right | best threshold ≤ 1 % wrong: right"
             " | median ms |", "|---|---|---|---|---|---|---|---|---|---|"]
    judged_rows: list[tuple[str, list[dict], float]] = []
    stored = read_table()
    for m, rows in results.items():
        if m == "grid":
            for label, name in MODELS.items():
                if name in stored:
                    th = model_threshold(name) if name != "grid" else (
                        GridMergeConfig().accept_threshold)
                    judged_rows.append((f"grid [{label}: {name} ≥ {th:g}]",
                                        rejudged(rows, name, th),
                                        GridMergeConfig().min_overlap_m2))
        else:
            judged_rows.append((m, rows, 0.0))
    for label, rows, gate in judged_rows:
        if not rows:
            continue
        s = summary(rows, gate)
        lines.append(f"| {label} | {s['pairs']} | {s['should']} | {100 * s['accepted']:.1f} % | "
                     f"{100 * s['right']:.1f} % | {100 * s['wrong']:.1f} % | "
                     f"{100 * s['false']:.1f} % ({s['none']}) | {100 * s['ceiling']:.1f} % | "
                     f"{100 * s['best']:.1f} % | {s['ms']:.0f} |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """The command line (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pairs", type=Path, required=True, metavar="MANIFEST",
                        help="a topomerge.real_pairs manifest.json")
    parser.add_argument("--methods", default="grid",
                        help=f"comma-separated, of {', '.join(METHODS)}")
    parser.add_argument("--split", choices=("dev", "test", "all"), default="dev")
    parser.add_argument("--out", type=Path, default=ROOT / "data" / "real_maps",
                        help="folder of the rows (<method>.jsonl) and table.md")
    args = parser.parse_args(argv)
    methods = [m for m in args.methods.split(",") if m]
    bad = sorted(set(methods) - set(METHODS))
    if bad:
        parser.error(f"--methods: unknown {bad}; choose from {list(METHODS)}")
    try:
        pairs = read_manifest(args.pairs, args.split)
    except ManifestError as exc:
        parser.error(str(exc))
    results = evaluate(pairs, methods, args.out)
    text = (f"{len(pairs)} pairs ({args.split}) of {args.pairs}; should merge: true overlap "
            f"≥ {SHOULD_MERGE_M2:g} m²; right: < 2° and < 0.3 m at B's known-cells centroid\n\n"
            + table(results))
    print(text)
    atomic_write_bytes(args.out / "table.md", (text + "\n").encode())
    return 0


if __name__ == "__main__":
    sys.exit(main())
