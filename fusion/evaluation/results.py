"""What a merge evaluation produces and how it is read (:mod:`fusion.evaluation.evaluate` runs it):
the
pair and record types, the success criteria (rotation < 2°, translation < 0.3 m at B's
centroid), and the summaries of records — tables per noise level and overlap, the accept
threshold sweep and the calibration of confidences."""

from __future__ import annotations

import math
import statistics
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from fusion.evaluation.bending import PairTrajectories
from fusion.icp import rigid_fit
from fusion.rigid import Rigid2D
from topo.graph import TopoMap

ROTATION_OK_DEG = 2.0
"""Success threshold on the rotation error (degrees)."""


TRANSLATION_OK_M = 0.3
"""Success threshold on the translation error at B's centroid (metres)."""


OVERLAP_BINS = (0.0, 0.2, 0.4, 0.6, 0.8, 1.0)
"""Edges of the overlap bins of the tables (the last bin includes 1.0)."""


ROTATION_BINS_DEG = (0.0, 30.0, 90.0, 180.0)
"""Edges of the |true rotation| bins of the rotation table."""


NO_OVERLAP_KINDS = ("disjoint", "other_world", "no_overlap")
"""Pair kinds on which an accepted merge is a false accept."""


ORACLE = "oracle"


@dataclass(frozen=True, slots=True, eq=False)
class EvalPair:
    """A pair to evaluate, whatever its source.

    Attributes:
        name: identifies the pair in the results (``"synthetic/s0.15/17"``, ``"pair_000017"``).
        map_a, map_b: the two maps, each in its own frame.
        transform: the true B → A motion; ``None`` when there is none (two different worlds).
        correspondences: ``(K, 2)`` true node pairs ``(a, b)``, or ``None`` if unknown.
        overlap: shared fraction of the explored areas, in ``[0, 1]``.
        kind: ``"overlap"`` or one of :data:`NO_OVERLAP_KINDS`.
        noise: node noise std the pair was made with (``None`` if unknown).
        grids: the two occupancy grids (dataset pairs), for the grid methods; ``None`` for
            synthetic pairs.
        trajectories: both robots' trajectories as mapped and as driven (dataset pairs made
            with drifting odometry), which judge a merge by its fused map's ATE; else
            ``None``.
    """

    name: str
    map_a: TopoMap
    map_b: TopoMap
    transform: Rigid2D | None
    correspondences: np.ndarray | None
    overlap: float
    kind: str
    noise: float | None
    grids: tuple[Any, Any] | None = None
    trajectories: PairTrajectories | None = None


@dataclass(frozen=True, slots=True)
class Record:
    """One method on one pair (a row of ``results.json``). ``ate_m``: the ATE (m) of the fused
    map its transform makes, ``ate_floor_m`` the least any rigid merge makes
    (:class:`fusion.evaluation.bending.PairTrajectories`; ``None`` for pairs without
    trajectories or without a transform)."""

    pair: str
    method: str
    kind: str
    overlap: float
    noise: float | None
    true_rotation_deg: float | None
    accepted: bool
    rotation_error_deg: float | None
    translation_error_m: float | None
    success: bool
    time_s: float
    score: float | None
    reason: str | None
    nodes_a: int
    nodes_b: int
    confidence: float | None = None
    gated: bool = True
    ate_m: float | None = None
    ate_floor_m: float | None = None


def oracle_transform(pair: EvalPair) -> Rigid2D | None:
    """The SVD fit of B's truly corresponding nodes onto A's (``None`` with fewer than 2)."""
    c = pair.correspondences
    if c is None or len(c) < 2:
        return None
    return Rigid2D(*rigid_fit(pair.map_b.xy[c[:, 1]], pair.map_a.xy[c[:, 0]]))


def transform_errors(estimate: Rigid2D, pair: EvalPair) -> tuple[float, float] | None:
    """(rotation error in degrees, translation error in metres at B's centroid), or ``None``
    when the pair has no true transform."""
    if pair.transform is None or pair.map_b.n_nodes == 0:
        return None
    centre = pair.map_b.xy.mean(axis=0)
    return (math.degrees(estimate.rotation_error(pair.transform)),
            estimate.translation_error(pair.transform, at=centre))


def is_success(errors: tuple[float, float] | None) -> bool:
    """Whether :func:`transform_errors`' ``errors`` are within the success thresholds
    (:data:`ROTATION_OK_DEG`, :data:`TRANSLATION_OK_M`); ``False`` for ``None``."""
    return errors is not None and errors[0] < ROTATION_OK_DEG and errors[1] < TRANSLATION_OK_M


def _bin_label(lo: float, hi: float, unit: str = "") -> str:
    return f"{lo:g}-{hi:g}{unit}"


def within_bin(value: float, lo: float, hi: float, last: bool) -> bool:
    return lo <= value < hi or (last and value == hi)


def success_rate(rows: list[Record]) -> float | None:
    return 100.0 * sum(r.success for r in rows) / len(rows) if rows else None


def _median(values: Iterable[float | None]) -> float | None:
    vals = [v for v in values if v is not None]
    return statistics.median(vals) if vals else None


def summarise(records: Sequence[Record]) -> dict[str, Any]:
    """Per noise level: success rate per overlap bin and per |true rotation| bin, and per
    method the success on ≥ 40% overlap, median errors, median time and false-accept rate."""
    out: dict[str, Any] = {}
    methods = list(dict.fromkeys(r.method for r in records))
    noises = sorted({r.noise for r in records}, key=lambda v: (v is None, v or 0.0))
    for noise in noises:
        rows = [r for r in records if r.noise == noise]
        key = "unknown" if noise is None else f"{noise:g}"
        level: dict[str, Any] = {"overlap_bins": {}, "rotation_bins": {}, "methods": {}}
        edges = OVERLAP_BINS
        for i, (lo, hi) in enumerate(zip(edges[:-1], edges[1:], strict=True)):
            in_bin = [r for r in rows if r.kind == "overlap"
                      and within_bin(r.overlap, lo, hi, i == len(edges) - 2)]
            level["overlap_bins"][_bin_label(lo, hi)] = {
                "pairs": len({r.pair for r in in_bin}),
                **{m: success_rate([r for r in in_bin if r.method == m]) for m in methods}}
        redges = ROTATION_BINS_DEG
        for i, (lo, hi) in enumerate(zip(redges[:-1], redges[1:], strict=True)):
            in_bin = [r for r in rows if r.kind == "overlap" and r.overlap >= 0.4
                      and within_bin(abs(r.true_rotation_deg), lo, hi, i == len(redges) - 2)]
            level["rotation_bins"][_bin_label(lo, hi, "°")] = {
                "pairs": len({r.pair for r in in_bin}),
                **{m: success_rate([r for r in in_bin if r.method == m]) for m in methods}}
        for m in methods:
            mine = [r for r in rows if r.method == m]
            overlap = [r for r in mine if r.kind == "overlap"]
            none = [r for r in mine if r.kind in NO_OVERLAP_KINDS]
            level["methods"][m] = {
                "success_overlap_ge_40": success_rate([r for r in overlap if r.overlap >= 0.4]),
                "median_rotation_error_deg": _median(r.rotation_error_deg for r in overlap),
                "median_translation_error_m": _median(r.translation_error_m for r in overlap),
                "median_time_ms": (None if m == ORACLE else
                                   1000.0 * statistics.median(r.time_s for r in mine)),
                "accepted_overlap": (100.0 * sum(r.accepted for r in overlap) / len(overlap)
                                     if overlap else None),
                "false_accept_rate": (100.0 * sum(r.accepted for r in none) / len(none)
                                      if none else None),
                "no_overlap_pairs": len(none),
                **_ate_summary(overlap),
            }
        out[key] = level
    return out


def _ate_summary(overlap: list[Record]) -> dict[str, Any]:
    """Fused-map ATE of a method's accepted merges on overlapping pairs with trajectories:
    median ATE and median floor on the same pairs; empty if there are none."""
    judged = [r for r in overlap if r.accepted and r.ate_m is not None]
    if not judged:
        return {}
    return {"ate_pairs": len(judged), "median_ate_m": _median(r.ate_m for r in judged),
            "median_ate_floor_m": _median(r.ate_floor_m for r in judged)}


def _fmt(v: float | None, spec: str = ".1f") -> str:
    return "-" if v is None else format(v, spec)


def format_tables(summary: dict[str, Any]) -> str:
    """The summary as plain-text tables (what the CLI prints)."""
    lines = []
    for noise, level in summary.items():
        methods = list(level["methods"])
        lines.append(f"\n== node noise σ = {noise} m ==")
        head = f"{'overlap':<10}{'pairs':>6}" + "".join(f"{m:>16}" for m in methods)
        lines += ["success rate (%) per overlap bin: accepted, rotation < 2°, translation "
                  "< 0.3 m", head]
        for label, row in level["overlap_bins"].items():
            lines.append(f"{label:<10}{row['pairs']:>6}"
                         + "".join(f"{_fmt(row[m]):>16}" for m in methods))
        lines.append("success rate (%) per |true rotation| (overlap ≥ 40%)")
        lines.append(f"{'rotation':<10}{'pairs':>6}" + "".join(f"{m:>16}" for m in methods))
        for label, row in level["rotation_bins"].items():
            lines.append(f"{label:<10}{row['pairs']:>6}"
                         + "".join(f"{_fmt(row[m]):>16}" for m in methods))
        lines.append(f"{'method':<16}{'succ≥40%':>10}{'med rot°':>10}{'med m':>9}"
                     f"{'med ms':>10}{'acc %':>8}{'false acc %':>13}")
        for m, s in level["methods"].items():
            fa = s["false_accept_rate"]
            fa_text = "-" if fa is None else f"{_fmt(fa)} of {s['no_overlap_pairs']}"
            lines.append(
                f"{m:<16}{_fmt(s['success_overlap_ge_40']):>10}"
                f"{_fmt(s['median_rotation_error_deg'], '.2f'):>10}"
                f"{_fmt(s['median_translation_error_m'], '.2f'):>9}"
                f"{_fmt(s['median_time_ms'], '.2f'):>10}{_fmt(s['accepted_overlap']):>8}"
                f"{fa_text:>13}")
        judged = {m: s for m, s in level["methods"].items() if "ate_pairs" in s}
        if judged:
            lines += ["fused-map ATE of accepted merges (pairs with trajectories: drifting "
                      "odometry); floor: the least any rigid merge reaches on the same pairs",
                      f"{'method':<16}{'pairs':>7}{'med ATE m':>11}{'med floor m':>13}"]
            for m, s in judged.items():
                lines.append(f"{m:<16}{s['ate_pairs']:>7}{_fmt(s['median_ate_m'], '.2f'):>11}"
                             f"{_fmt(s['median_ate_floor_m'], '.2f'):>13}")
    return "\n".join(lines)


SWEEP_THRESHOLDS = tuple(round(0.05 * k, 2) for k in range(20)) + (0.99,)
"""Accept thresholds of :func:`threshold_sweep`."""


def is_right(record: Record) -> bool:
    """Whether the record's transform is right (overlapping pair, both errors within the
    success thresholds), accepted or not: what a calibrated confidence predicts."""
    if record.kind != "overlap" or record.rotation_error_deg is None:
        return False
    return is_success((record.rotation_error_deg, record.translation_error_m))


def with_confidence(records: Sequence[Record]) -> dict[str, list[Record]]:
    """Records per method, for the methods whose every record has a confidence."""
    out: dict[str, list[Record]] = {}
    for m in dict.fromkeys(r.method for r in records):
        rows = [r for r in records if r.method == m]
        if m != ORACLE and all(r.confidence is not None for r in rows):
            out[m] = rows
    return out


def threshold_sweep(records: Sequence[Record],
                    thresholds: Sequence[float] = SWEEP_THRESHOLDS) -> dict[str, list[dict]]:
    """Per method with confidences, per threshold ``t``: the merges accepted by the rule
    ``confidence >= t`` (and the method's hard gates, :attr:`Record.gated`), and of them the
    success rate on pairs with ≥ 40 % overlap, the wrong accepts (accepted and not right) as a
    share of all pairs, and the false accepts as a share of no-overlap pairs (percent). For
    the structural methods this is what a pure confidence rule would do (their own rule
    ignored)."""
    out = {}
    for m, rows in with_confidence(records).items():
        hi = [r for r in rows if r.kind == "overlap" and r.overlap >= 0.4]
        none = [r for r in rows if r.kind in NO_OVERLAP_KINDS]
        table = []
        for t in thresholds:
            acc = [r for r in rows if r.gated and r.confidence >= t]
            table.append({
                "threshold": float(t),
                "success_overlap_ge_40": (100.0 * sum(r.gated and r.confidence >= t
                                                      and is_right(r) for r in hi) / len(hi)
                                          if hi else None),
                "wrong_accepts": 100.0 * sum(not is_right(r) for r in acc) / len(rows),
                "false_accepts": (100.0 * sum(r.gated and r.confidence >= t for r in none)
                                  / len(none) if none else None)})
        out[m] = table
    return out


def calibration_summary(records: Sequence[Record], bins: int = 10) -> dict[str, dict]:
    """Per method with confidences: the reliability table of its confidence against whether
    the transform is right (:func:`is_right`), the Brier score, and the largest
    ``|predicted − observed|`` over bins of ≥ 20 merges (``None`` if no bin has 20)."""
    from fusion.calibration import brier_score, max_calibration_gap, reliability_table

    out = {}
    for m, rows in with_confidence(records).items():
        p = [r.confidence for r in rows]
        y = [float(is_right(r)) for r in rows]
        table = reliability_table(p, y, bins)
        gap = max_calibration_gap(table)
        out[m] = {"brier": brier_score(p, y), "bins": table,
                  "max_gap_bins_ge_20": None if math.isnan(gap) else gap, "merges": len(rows)}
    return out


def format_threshold_tables(sweep: dict[str, list[dict]], calibration: dict[str, dict],
                            default: float | None = None) -> str:
    """The threshold sweep and the calibration as plain-text tables (``*`` marks the
    default threshold)."""
    lines = []
    for m, table in sweep.items():
        lines += [f"\n== {m}: success against wrong accepts as accept_threshold moves ==",
                  f"{'threshold':>10}{'succ≥40% %':>12}{'wrong acc % (all)':>19}"
                  f"{'false acc % (no ovl)':>22}"]
        for row in table:
            mark = "*" if default is not None and abs(row["threshold"] - default) < 1e-9 else ""
            lines.append(f"{row['threshold']:>9.2f}{mark:1}"
                         f"{_fmt(row['success_overlap_ge_40']):>12}"
                         f"{_fmt(row['wrong_accepts'], '.2f'):>19}"
                         f"{_fmt(row['false_accepts'], '.2f'):>22}")
    for m, cal in calibration.items():
        gap = cal["max_gap_bins_ge_20"]
        lines += [f"\n== {m}: calibration of confidence (Brier {cal['brier']:.4f}, "
                  f"largest gap in bins of ≥ 20: {_fmt(gap, '.3f')}) ==",
                  f"{'bin':>10}{'merges':>8}{'predicted':>11}{'observed':>10}"]
        for b in cal["bins"]:
            lines.append(f"{b['low']:>4.1f}–{b['high']:<4.1f}{b['n']:>9}"
                         f"{b['predicted']:>11.3f}{b['observed']:>10.3f}")
    return "\n".join(lines)
