"""Fitting the calibrated models on rows (:mod:`fusion.calibration.rows`): the features each
model weighs, leave-one-world-out cross-validation, the accept-threshold rule, and the fit
itself — :func:`fit_model` for ``"grid"`` and ``"structural"`` (a
:class:`fusion.calibration.Calibrator`), :func:`fit_ranking` for the structural search's
score weights (:data:`fusion.structural.CONFIDENCE_WEIGHTS`).

Cross-validation holds out one world at a time (:func:`world_group`), so every prediction is
of a world the fit did not see. The threshold rule (:func:`choose_threshold`): the smallest
threshold on a 0.05 grid at which at most :data:`MAX_FALSE_ACCEPTS` of the no-overlap
alignments, and of all alignments wrong ones, are accepted in cross-validation — what the
defaults of :mod:`fusion.decision` were chosen by.
"""

from __future__ import annotations

import datetime
import math
import re
import subprocess
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from fusion.calibration import Calibrator, brier_score, extend_logistic, fit_logistic
from fusion.local_align import NEAR_FEATURES
from fusion.structural import CALIBRATION_FEATURES

L2 = 2.0
"""Ridge penalty of the fit (in pairs)."""

BASE_FEATURES = ("log_margin", "log_overlap", "native_agreement", "log_wall_hits")
"""The noise-free evidence of the ``"grid"`` model (a subset of
:data:`fusion.grid_merge.FEATURES`)."""

DRIFT_FEATURES = ("log_drift_prior", "drift_native_agreement")
"""The drift terms of the ``"grid"`` model (0 on perfect odometry): no grid feature tells a bent
map's alignment a little off the robots' current frames from a right one, the drift prior
does. ``extend`` fits only these on top of the stored noise-free model
(:func:`fusion.calibration.extend_logistic`): on perfect odometry the confidence stays the
stored model's, bit for bit."""

MODEL_FEATURES = BASE_FEATURES + DRIFT_FEATURES
"""The evidence the ``"grid"`` model weighs. How the features were chosen (the cross-validated
scores of the candidates tried): ``docs/notes/fusion.md`` and ``docs/notes/drift.md``."""

MODELS = {"grid": MODEL_FEATURES, "structural": CALIBRATION_FEATURES,
          "grid_real": MODEL_FEATURES, "window_near": NEAR_FEATURES}
"""The features of each calibrated model. ``"grid_real"`` (:data:`fusion.decision.
REAL_MAP_MODEL`, the grid alignment's confidence on real sensor maps) is the ``"grid"`` model
recalibrated on real map pairs (:func:`recalibrated`, :func:`fit_model`): its features and
their weighting are the grid model's, at most the scale and shift of its log-odds are fitted
on the real rows, and its accept threshold is chosen on them. ``"window_near"`` is the
confidence of a pose graph's window alignment searched near its estimate
(``fusion.local_align.near_features``; ``envs.explore.graph_merging``), fitted on the rows
``benchmarks/bending_in_loop.py --rows`` writes."""

DEDUP_FEATURE = {"grid": "log_score", "grid_real": "log_score", "structural": "score",
                 "window_near": "corr_deg"}
"""The feature :func:`unique_rows` tells repeated alignments apart by, per model."""

THRESHOLDS = tuple(round(0.05 * k, 2) for k in range(1, 20))
"""The accept thresholds the rule chooses from."""

MAX_FALSE_ACCEPTS = 0.01
"""Most false accepts of no-overlap alignments, and wrong accepts of all alignments, the chosen
threshold allows in cross-validation."""


_NOISE_LEVEL = re.compile(r"/s[0-9.e+-]+(?=/)")
"""The noise level in a synthetic or generic pair's name (``…/s0.05/12``)."""


def world_group(row: Mapping[str, Any]) -> str:
    """Cross-validation group of a row: its world. The procedural sets of one seed share
    worlds, and the synthetic and generic pairs of one index share theirs at every noise level
    (only the noise differs), so those are one group: held out together, none is judged by a
    model that saw its world's other noise levels. A real map's pairs are their own."""
    if "real" in row["set"]:
        return row["world"]
    return _NOISE_LEVEL.sub("", row["world"].split(":", 1)[1])


def unique_rows(rows: Sequence[dict], key_feature: str = "log_score") -> list[dict]:
    """``rows`` without repeats: the procedural tuning sets of one seed share their first
    snapshots (the same world, step and maps, so the same alignment), which would count
    twice."""
    seen, out = set(), []
    for r in rows:
        key = (world_group(r), r["way"], round(r["overlap"], 9),
               round(r["features"][key_feature], 9))
        if key not in seen:
            seen.add(key)
            out.append(r)
    return out


def matrix(rows: Sequence[dict], names: Sequence[str] = MODEL_FEATURES
           ) -> tuple[np.ndarray, np.ndarray]:
    """Features (in ``names`` order) and 0/1 labels of alignment rows."""
    return (np.array([[r["features"][n] for n in names] for r in rows], dtype=np.float64),
            np.array([r["right"] for r in rows], dtype=np.float64))


def cross_validated(rows: Sequence[dict], l2: float = L2,
                    names: Sequence[str] = MODEL_FEATURES) -> np.ndarray:
    """Leave-one-world-out predictions of every row."""
    X, y = matrix(rows, names)
    groups = np.array([world_group(r) for r in rows])
    p = np.zeros(len(rows))
    for g in np.unique(groups):
        test = groups == g
        p[test] = fit_logistic(X[~test], y[~test], names, l2=l2).predict(X[test])
    return p


def noise_free_base(model: Calibrator) -> Calibrator:
    """The noise-free part of a stored ``"grid"`` model: its :data:`BASE_FEATURES` (those of a
    model fitted before the drift terms, or the first of an extended one).

    Raises:
        ValueError: the model's features do not start with :data:`BASE_FEATURES`.
    """
    k = len(BASE_FEATURES)
    if tuple(model.names[:k]) != BASE_FEATURES:
        raise ValueError(f"the stored grid model's features {list(model.names)} do not start "
                         f"with {list(BASE_FEATURES)}")
    # an extended model's meta says where its noise-free weights came from under "extends"
    meta = dict(model.meta.get("extends") or model.meta)
    return Calibrator(BASE_FEATURES, model.mean[:k], model.scale[:k], model.low[:k],
                      model.high[:k], model.coef[:k], model.intercept, meta)


def cross_validated_extension(rows: Sequence[dict], base: Calibrator,
                              l2: float = L2) -> np.ndarray:
    """Leave-one-world-out predictions of ``base`` extended by :data:`DRIFT_FEATURES`
    (``base`` itself is not refitted: on noise-free rows these are its own predictions)."""
    X, y = matrix(rows, MODEL_FEATURES)
    groups = np.array([world_group(r) for r in rows])
    p = np.zeros(len(rows))
    for g in np.unique(groups):
        test = groups == g
        p[test] = extend_logistic(base, X[~test], y[~test], DRIFT_FEATURES,
                                  l2=l2).predict(X[test])
    return p


def recalibrated(base: Calibrator, X: np.ndarray, y: np.ndarray, *, l2: float = L2,
                 meta: Mapping[str, Any] | None = None) -> Calibrator:
    """``base`` with its log-odds ``z`` replaced by ``a·z + c``, ``a`` and ``c`` fitted to the
    0/1 labels ``y`` of the rows of ``X`` (columns ``base.names``) by a logistic fit of ``z``
    (Platt scaling). Why: a small set of real map pairs from a few buildings does not pin down
    every evidence weight, while the grid model's weights, fitted on many env pairs, may carry
    over to real maps when the confidence's scale does not (``benchmarks/RESULTS.md`` compares
    the two). The result is a :class:`fusion.calibration.Calibrator` of ``base``'s features,
    standardisation and clipping, its weights scaled by ``a`` (a monotone map of ``base``'s
    confidence while ``a > 0``), ``meta`` with ``scale`` ``a`` and ``shift`` ``c``.

    Raises:
        ValueError: as :func:`fusion.calibration.fit_logistic` (one class only, bad shapes).
    """
    X = np.asarray(X, dtype=np.float64)
    if X.ndim != 2 or X.shape[1] != len(base.names):
        raise ValueError(f"X must have shape (N, {len(base.names)}) (base.names), got {X.shape}")
    z = np.array([[base.log_odds(dict(zip(base.names, row, strict=True)))]
                  for row in X.tolist()])
    platt = fit_logistic(z, y, ("log_odds",), l2=l2)
    a = platt.coef[0] / platt.scale[0]
    c = platt.intercept - a * platt.mean[0]
    return Calibrator(base.names, base.mean, base.scale, base.low, base.high,
                      tuple(a * w for w in base.coef), a * base.intercept + c,
                      {**(meta or {}), "scale": round(a, 6), "shift": round(c, 6)})


def cross_validated_recalibration(rows: Sequence[dict], base: Calibrator,
                                  l2: float = L2) -> np.ndarray:
    """Leave-one-world-out predictions of ``base`` :func:`recalibrated` (real map rows: one
    building held out at a time)."""
    X, y = matrix(rows, base.names)
    groups = np.array([world_group(r) for r in rows])
    p = np.zeros(len(rows))
    for g in np.unique(groups):
        test = groups == g
        p[test] = recalibrated(base, X[~test], y[~test], l2=l2).predict(X[test])
    return p


def accepted_mask(rows: Sequence[dict], p: np.ndarray, threshold: float,
                  min_overlap_m2: float) -> np.ndarray:
    """Which alignments the merge accepts at ``threshold`` given confidences ``p``: past its
    hard gate too (``merge_grids``: ``min_overlap_m2``; the structural merge: enough
    non-collinear matches and a margin, ``gated`` rows fail it)."""
    passed = [not r.get("gated", False) and r.get("overlap_m2", math.inf) >= min_overlap_m2
              for r in rows]
    return (p >= threshold) & np.array(passed, dtype=bool)


def threshold_table(rows: Sequence[dict], p: np.ndarray, min_overlap_m2: float) -> list[dict]:
    """Per threshold of :data:`THRESHOLDS`: success on ≥ 40 % overlap (B onto A), wrong
    accepts of all alignments, false accepts of no-overlap alignments."""
    y = np.array([r["right"] for r in rows], dtype=bool)
    hi = np.array([r["overlap"] >= 0.4 and r["way"] == "ab" for r in rows], dtype=bool)
    none = np.array([r["overlap"] == 0 for r in rows], dtype=bool)
    out = []
    for th in THRESHOLDS:
        acc = accepted_mask(rows, p, th, min_overlap_m2)
        out.append({"threshold": th, "success": float((acc & y & hi).sum() / max(hi.sum(), 1)),
                    "wrong": float((acc & ~y).sum() / max(len(rows), 1)),
                    "false": float((acc & none).sum() / max(none.sum(), 1))})
    return out


def choose_threshold(table: Sequence[Mapping[str, float]]) -> float:
    """The smallest threshold whose false accepts on no-overlap alignments and wrong accepts of
    all alignments are both within :data:`MAX_FALSE_ACCEPTS` (the largest if none is)."""
    ok = [r["threshold"] for r in table
          if r["false"] <= MAX_FALSE_ACCEPTS and r["wrong"] <= MAX_FALSE_ACCEPTS]
    return min(ok) if ok else max(THRESHOLDS)


def commit() -> str:
    """The current git commit (short), ``"unknown"`` outside a checkout."""
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], check=True,
                              capture_output=True, text=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


@dataclass(frozen=True, slots=True)
class Fit:
    """What :func:`fit_model` made.

    Attributes:
        model: the model fitted on all (unique) rows, its ``meta`` filled in.
        rows: the unique rows it was fitted on.
        cross_validated: the leave-one-world-out prediction of each row.
        thresholds: :func:`threshold_table` of those predictions.
        threshold: the threshold rule's choice (:func:`choose_threshold`).
        repeats: rows left out as repeats.
    """

    model: Calibrator
    rows: list[dict]
    cross_validated: np.ndarray
    thresholds: list[dict]
    threshold: float
    repeats: int


def fit_model(name: str, rows: Sequence[dict], *, l2: float = L2,
              extend: Calibrator | None = None, min_overlap_m2: float = 0.0,
              script: str = "python -m fusion.calibration fit",
              recalibrate: Calibrator | None = None) -> Fit:
    """Fit the calibrated model ``name`` (a key of :data:`MODELS`) on ``rows``: repeats
    left out, cross-validated, the threshold chosen, then fitted on all rows — or, with
    ``extend`` (``"grid"`` only: the stored model's :func:`noise_free_base`), only the drift
    terms fitted on top of it; with ``recalibrate`` (``"grid_real"``: the stored ``"grid"``
    model), that model :func:`recalibrated` — or kept as it is (scale 1, shift 0; the
    threshold still chosen on ``rows``) when its own predictions score a Brier score no worse
    than the rescaled model's held-out ones (both in ``meta``): a rescale that does not
    predict held-out buildings better is fitting their differences.

    Raises:
        ValueError: an unknown ``name``; ``extend`` for a model other than ``"grid"``,
            ``recalibrate`` for one other than ``"grid_real"`` or of other features; rows of
            one class only (as :func:`fusion.calibration.fit_logistic`).
    """
    if name not in MODELS:
        raise ValueError(f"name must be one of {list(MODELS)}, got {name!r}")
    if extend is not None and name != "grid":
        raise ValueError(f"extend extends the grid model only, got name={name!r}")
    if recalibrate is not None and (name != "grid_real"
                                    or tuple(recalibrate.names) != MODELS[name]):
        raise ValueError(f"recalibrate rescales the grid model for grid_real only, got "
                         f"name={name!r}, features {list(recalibrate.names)}")
    names = MODELS[name]
    unique = unique_rows(rows, DEDUP_FEATURE[name])
    kept = False
    if recalibrate is not None:
        p = cross_validated_recalibration(unique, recalibrate, l2)
        Xb, yb = matrix(unique, names)
        unscaled = recalibrate.predict(Xb)
        scores = {"held_out_brier_rescaled": round(brier_score(p, yb), 4),
                  "brier_unchanged": round(brier_score(unscaled, yb), 4)}
        # rescale only where it predicts held-out buildings better than the model as it is
        kept = scores["brier_unchanged"] <= scores["held_out_brier_rescaled"]
        if kept:
            p = unscaled
    elif extend is not None:
        p = cross_validated_extension(unique, extend, l2)
    else:
        p = cross_validated(unique, l2, names)
    X, y = matrix(unique, names)
    table = threshold_table(unique, p, min_overlap_m2)
    chosen = choose_threshold(table)
    meta = {"fitted": datetime.date.today().isoformat(), "commit": commit(),
            "data": sorted({r["set"] for r in unique}), "alignments": len(unique),
            "right": int(y.sum()), "l2": l2, "cv_brier": round(brier_score(p, y), 4),
            "accept_threshold": chosen, "script": script}
    if recalibrate is not None:
        meta.update(scores, recalibrates={k: recalibrate.meta.get(k)
                                          for k in ("fitted", "commit", "data")},
                    note=("the grid model as it is (scale 1, shift 0): rescaling its log-odds "
                          "did not predict held-out buildings better" if kept else
                          "the grid model's log-odds z rescaled to scale * z + shift on real "
                          "map pairs (Platt scaling); its evidence weights kept"))
        model = (Calibrator(recalibrate.names, recalibrate.mean, recalibrate.scale,
                            recalibrate.low, recalibrate.high, recalibrate.coef,
                            recalibrate.intercept, {**meta, "scale": 1.0, "shift": 0.0})
                 if kept else recalibrated(recalibrate, X, y, l2=l2, meta=meta))
    elif extend is not None:
        meta.update(extends={k: extend.meta.get(k) for k in ("fitted", "commit", "data")},
                    note="noise-free weights kept; the drift terms fitted on top")
        model = extend_logistic(extend, X, y, DRIFT_FEATURES, l2=l2, meta=meta)
    else:
        model = fit_logistic(X, y, names, l2=l2, meta=meta)
    return Fit(model, unique, p, table, chosen, len(rows) - len(unique))


def top_right(rows: Sequence[dict], weights: np.ndarray, synthetic: bool) -> tuple[int, int]:
    """Pairs whose top-ranked candidate under ``weights`` is right, and pairs (the synthetic
    pairs' or the others')."""
    by_pair: dict[str, list[dict]] = {}
    for r in rows:
        if (r["set"] == "synthetic") == synthetic:
            by_pair.setdefault(r["pair"], []).append(r)
    right = sum(rs[int(np.argmax(np.array([r["x"] for r in rs]) @ weights))]["label"] == 1
                for rs in by_pair.values())
    return right, len(by_pair)


def fit_ranking(rows: Sequence[dict], names: Sequence[str], l2: float = L2) -> dict[str, float]:
    """Score weights in raw feature units (``names``: :data:`fusion.structural.
    CONFIDENCE_WEIGHTS`' order, ``"bias"`` first) from a logistic fit of right against wrong
    candidates (near misses left out; the bias is the intercept).

    Raises:
        ValueError: ``names`` not starting with ``"bias"``; rows of one class only.
    """
    if not names or names[0] != "bias":
        raise ValueError(f"names must start with 'bias', got {list(names)}")
    kept = [r for r in rows if r["label"] != -1]
    X = np.array([r["x"][1:] for r in kept])
    y = np.array([r["label"] for r in kept], dtype=np.float64)
    model = fit_logistic(X, y, names[1:], l2=l2)
    coef, mean, scale = (np.array(v) for v in (model.coef, model.mean, model.scale))
    raw = coef / scale
    return {"bias": float(model.intercept - np.sum(coef * mean / scale)),
            **{n: float(w) for n, w in zip(names[1:], raw, strict=True)}}
