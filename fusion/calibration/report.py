"""The refit's printed report: how well a fitted model is calibrated (cross-validated reliability
table and Brier score, per dataset), the threshold table, and a model's reliability on
held-out folders. Printing only: the numbers are computed by :mod:`fusion.calibration.fit`.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from fusion.calibration import (
    Calibrator,
    brier_score,
    load_model,
    max_calibration_gap,
    reliability_table,
)
from fusion.calibration.fit import MODEL_FEATURES, Fit, matrix, top_right, unique_rows
from fusion.calibration.rows import alignment_rows
from topo.fileio import atomic_write_json


def _bins(table: Sequence[dict]) -> str:
    return " ".join(f"{r['low']:.1f}–{r['high']:.1f}: {r['n']} {r['predicted']:.2f}/"
                    f"{r['observed']:.2f}" for r in table)


def print_fit(name: str, fit: Fit) -> None:
    """The cross-validated calibration of ``fit`` (Brier score, reliability table, largest
    gap, per dataset), its threshold table and choice, and its coefficients."""
    names = fit.model.names
    p = fit.cross_validated
    _, y = matrix(fit.rows, names)
    print(f"{fit.repeats} repeated alignments left out")
    print(f"\n{len(fit.rows)} alignments of {len({(r['set'], r.get('pair')) for r in fit.rows})} "
          f"pairs, {int(y.sum())} right; leave-one-world-out Brier {brier_score(p, y):.4f} "
          f"(base rate's {y.mean() * (1 - y.mean()):.4f})")
    table = reliability_table(p, y)
    print("\n| confidence | alignments | predicted | observed |\n|---|---|---|---|")
    for r in table:
        print(f"| {r['low']:.1f}–{r['high']:.1f} | {r['n']} | {r['predicted']:.3f} | "
              f"{r['observed']:.3f} |")
    print(f"largest gap in bins of ≥ 20: {max_calibration_gap(table):.3f}")
    per_set_report(fit.rows, p, names, name)
    print("\n| threshold | success ≥ 40 % | wrong accepts (all) | false accepts (no overlap) |"
          "\n|---|---|---|---|")
    for r in fit.thresholds:
        print(f"| {r['threshold']:.2f} | {100 * r['success']:.1f} % | {100 * r['wrong']:.2f} % "
              f"| {100 * r['false']:.2f} % |")
    print(f"\nchosen accept_threshold: {fit.threshold}")
    print("coefficients (standardised):",
          {n: round(c, 3) for n, c in zip(fit.model.names, fit.model.coef, strict=True)},
          f"intercept {fit.model.intercept:.3f}")


def per_set_report(rows: Sequence[dict], p: np.ndarray, names: Sequence[str],
                   model_name: str) -> None:
    """Per dataset of ``rows``: the cross-validated reliability table (predictions ``p``) and
    its largest gap in bins of ≥ 20, and the largest gap of the model stored now."""
    sets = sorted({r["set"] for r in rows})
    if len(sets) < 2:
        return
    try:
        stored = load_model(model_name)
    except ValueError:
        stored = None
    X, y = matrix(rows, names)
    for name in sets:
        sel = np.array([r["set"] == name for r in rows])
        table = reliability_table(p[sel], y[sel])
        gap_now = math.nan
        if stored is not None and list(stored.names) == list(names):
            gap_now = max_calibration_gap(reliability_table(stored.predict(X[sel]), y[sel]))
        print(f"{name}: {int(sel.sum())} alignments, {int(y[sel].sum())} right; cross-validated "
              f"gap {max_calibration_gap(table):.3f}, stored model's gap {gap_now:.3f}; "
              f"bins (n predicted/observed): {_bins(table)}")


def held_out_report(dirs: Sequence[Path], model: Calibrator, cache: Path | None = None) -> None:
    """Per folder of ``dirs``: the reliability table (n, mean predicted, observed), largest gap
    in bins of ≥ 20 and Brier score of the ``"grid"`` model stored now and of ``model`` on its
    alignments (repeats left out). The rows are cached in ``<cache stem>.held-out.json`` when
    ``cache``."""
    path = None if cache is None else cache.with_name(f"{cache.stem}.held-out.json")
    if path is not None and path.exists():
        rows = json.loads(path.read_text())
    else:
        rows = alignment_rows(dirs)
        if path is not None:
            atomic_write_json(path, rows)
    stored = load_model("grid")
    for d in dirs:
        sel = unique_rows([r for r in rows if r["set"] == Path(d).name])
        X, y = matrix(sel, MODEL_FEATURES)
        print(f"\nheld out {d}: {len(sel)} alignments, {int(y.sum())} right")
        for label, m in (("stored", stored), ("fitted", model)):
            p = m.predict(X)
            table = reliability_table(p, y)
            print(f"{label}: largest gap in bins of ≥ 20 {max_calibration_gap(table):.3f}, "
                  f"Brier {brier_score(p, y):.4f}; bins (n predicted/observed): "
                  + _bins(table))


def print_ranking(rows: Sequence[dict], old: dict[str, float], new: dict[str, float]) -> None:
    """How often the top-ranked candidate is right under the ``old`` and the ``new`` score
    weights, on the env pairs and on the synthetic ones, and the new weights."""
    o, n = np.array(list(old.values())), np.array(list(new.values()))
    for label, synthetic in (("env pairs", False), ("synthetic pairs", True)):
        (right_old, pairs), (right_new, _) = (top_right(rows, o, synthetic),
                                              top_right(rows, n, synthetic))
        print(f"{label}: top-ranked candidate right in {right_old} of {pairs} pairs with the "
              f"current weights, {right_new} with the refit")
    print("ranking weights:", {k: round(v, 4) for k, v in new.items()})
