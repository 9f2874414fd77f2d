"""Calibrated merge confidence: a logistic model on a merge's evidence features, fitted on
tuning pairs, stored in the package, and the measures that check it (reliability table and
diagram, Brier score).

A merge method computes a few evidence features of its best alignment (for
:func:`fusion.merge_grids`: its correlation score, its margin over the best distinct rival, how
B's walls land on A's walls and free space, the overlap ...). :class:`Calibrator` turns them into
the probability that the alignment is right (rotation error < 2°, translation error < 0.3 m at
B's centroid: :func:`fusion.evaluation.evaluate.is_success`), and a merge is accepted when that
probability
reaches the caller's ``accept_threshold``. Why logistic regression rather than isotonic: a few
hundred tuning pairs fit a handful of coefficients well, the model is monotone and smooth in each
feature (isotonic regression would need one score to be sorted on first, and its steps over a few
pairs per step are noisy), and the coefficients say which evidence counts.

Features are standardised with the tuning set's mean and spread and clipped to the range seen
when fitting (a model never extrapolates beyond its data). The fit is a ridge-penalised
Newton/IRLS in numpy (scikit-learn is not a dependency). Models live in
``fusion/calibration.json`` (:data:`TABLE_PATH`), one per name, with the date, commit and data
they were fitted on; ``python -m fusion.calibration fit`` refits them (``make calibrate``:
all of them).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

TABLE_PATH = Path(__file__).resolve().parent.with_name("calibration.json")
"""Where the fitted models and weights are stored (package data, ``fusion/calibration.json``)."""
TABLE_FORMAT = "topomerge.calibration"
TABLE_VERSION = 1


@dataclass(frozen=True, slots=True)
class Calibrator:
    """A fitted logistic model ``P(right) = 1 / (1 + exp(−(b + Σ w_i z_i)))`` with
    ``z_i = (clip(x_i, lo_i, hi_i) − mean_i) / scale_i``.

    Attributes:
        names: feature names, in the order of the other tuples.
        mean, scale: standardisation of each feature (the fitting set's mean and spread).
        low, high: each feature is clipped to this range (what the fitting set spanned).
        coef: weight of each standardised feature.
        intercept: ``b``.
        meta: where the model comes from (date, commit, data, sizes, scores): JSON-safe.
    """

    names: tuple[str, ...]
    mean: tuple[float, ...]
    scale: tuple[float, ...]
    low: tuple[float, ...]
    high: tuple[float, ...]
    coef: tuple[float, ...]
    intercept: float
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = len(self.names)
        for name in ("mean", "scale", "low", "high", "coef"):
            if len(getattr(self, name)) != n:
                raise ValueError(f"Calibrator.{name} must have {n} values (one per name), got "
                                 f"{len(getattr(self, name))}")
        if any(not s > 0 for s in self.scale):
            raise ValueError(f"Calibrator.scale must be > 0, got {list(self.scale)}")

    def log_odds(self, features: Mapping[str, float]) -> float:
        """``b + Σ w_i z_i`` for one alignment's ``features`` (every name of :attr:`names`).

        Raises:
            KeyError: a feature of :attr:`names` is missing (names it).
        """
        total = self.intercept
        for i, name in enumerate(self.names):
            try:
                x = float(features[name])
            except KeyError:
                raise KeyError(f"feature {name!r} missing; the model needs "
                               f"{list(self.names)}") from None
            if math.isnan(x):
                x = self.mean[i]
            x = min(max(x, self.low[i]), self.high[i])
            total += self.coef[i] * (x - self.mean[i]) / self.scale[i]
        return total

    def __call__(self, features: Mapping[str, float]) -> float:
        """The probability that the alignment with these ``features`` is right."""
        return _sigmoid(self.log_odds(features))

    def predict(self, X: np.ndarray) -> np.ndarray:
        """Probabilities of the rows of ``X`` (``(N, len(names))``, columns in :attr:`names`
        order)."""
        X = np.asarray(X, dtype=np.float64)
        if X.ndim != 2 or X.shape[1] != len(self.names):
            raise ValueError(f"X must have shape (N, {len(self.names)}), got {X.shape}")
        z = (np.clip(X, self.low, self.high) - np.asarray(self.mean)) / np.asarray(self.scale)
        return 1.0 / (1.0 + np.exp(-np.clip(self.intercept + z @ np.asarray(self.coef),
                                            -700, 700)))

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe form (:meth:`from_dict` reads it back)."""
        return {"names": list(self.names), "mean": list(self.mean), "scale": list(self.scale),
                "low": list(self.low), "high": list(self.high), "coef": list(self.coef),
                "intercept": self.intercept, "meta": self.meta}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Calibrator:
        """The model :meth:`to_dict` wrote.

        Raises:
            ValueError: a missing key (named) or inconsistent lengths.
        """
        keys = ("names", "mean", "scale", "low", "high", "coef", "intercept")
        missing = [k for k in keys if k not in d]
        if missing:
            raise ValueError(f"calibration model is missing {missing}")
        return cls(tuple(str(n) for n in d["names"]),
                   *(tuple(float(v) for v in d[k]) for k in keys[1:6]),
                   float(d["intercept"]), dict(d.get("meta", {})))


def _sigmoid(z: float) -> float:
    return 1.0 / (1.0 + math.exp(-min(max(z, -700.0), 700.0)))


# ------------------------------------------------------------------------------- fitting
def fit_logistic(X: np.ndarray, y: np.ndarray, names: Sequence[str], *, l2: float = 1.0,
                 meta: Mapping[str, Any] | None = None, max_iter: int = 100) -> Calibrator:
    """Ridge-penalised logistic regression of the 0/1 labels ``y`` on the rows of ``X`` by
    Newton/IRLS (the intercept is not penalised; ``l2`` is the penalty on the standardised
    weights, in units of pairs: ``l2 = 1`` weighs like one pair).

    Raises:
        ValueError: shapes that do not match ``names``, fewer than 2 rows, labels other than 0
            and 1, only one class, NaN/inf, ``l2 < 0``.
    """
    X = np.asarray(X, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    names = tuple(names)
    if X.ndim != 2 or X.shape[1] != len(names):
        raise ValueError(f"X must have shape (N, {len(names)}) (one column per name), got "
                         f"{X.shape}")
    if y.shape != (X.shape[0],):
        raise ValueError(f"y must have shape ({X.shape[0]},), got {y.shape}")
    if X.shape[0] < 2 or not np.isfinite(X).all():
        raise ValueError("X must have at least 2 rows, all finite")
    if not np.isin(y, (0.0, 1.0)).all() or y.min() == y.max():
        raise ValueError("y must hold 0s and 1s, both present")
    if not l2 >= 0:
        raise ValueError(f"l2 must be >= 0, got {l2}")
    low, high = X.min(axis=0), X.max(axis=0)
    mean = X.mean(axis=0)
    scale = X.std(axis=0)
    scale[scale <= 1e-12] = 1.0
    Z = np.hstack([np.ones((len(X), 1)), (X - mean) / scale])
    w = np.zeros(Z.shape[1])
    penalty = np.full(Z.shape[1], float(l2))
    penalty[0] = 0.0
    for _ in range(max_iter):
        p = 1.0 / (1.0 + np.exp(-np.clip(Z @ w, -700, 700)))
        grad = Z.T @ (p - y) + penalty * w
        hess = (Z * (p * (1 - p))[:, None]).T @ Z + np.diag(penalty) + 1e-9 * np.eye(len(w))
        step = np.linalg.solve(hess, grad)
        w -= step
        if np.max(np.abs(step)) < 1e-10:
            break
    return Calibrator(names, tuple(mean.tolist()), tuple(scale.tolist()), tuple(low.tolist()),
                      tuple(high.tolist()), tuple(w[1:].tolist()), float(w[0]),
                      dict(meta or {}))


def extend_logistic(base: Calibrator, X: np.ndarray, y: np.ndarray, names: Sequence[str], *,
                    l2: float = 1.0, meta: Mapping[str, Any] | None = None,
                    max_iter: int = 100) -> Calibrator:
    """``base`` with more features ``names``, fitted on data where they matter: the columns of
    ``X`` are ``base.names`` then ``names``; the new weights are fitted by ridge-penalised
    Newton/IRLS with ``base``'s log-odds as a fixed offset. The new features are standardised
    with mean 0 (scale: their root mean square) and clipped from 0, so that wherever they
    are 0 — e.g. a drift prior on perfect odometry — the extended model's log-odds are
    ``base``'s exactly: what ``base`` was fitted and tested on keeps its answers. Newton's
    steps are damped (halved until the penalised loss falls): where ``base`` is confident and
    wrong its offset saturates the probabilities and a full step diverges.

    Raises:
        ValueError: shapes that do not match the names, a name already in ``base``, labels
            other than 0 and 1, NaN/inf, negative new features, ``l2 < 0``.
    """
    X = np.asarray(X, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    names = tuple(names)
    k = len(base.names)
    if X.ndim != 2 or X.shape[1] != k + len(names):
        raise ValueError(f"X must have shape (N, {k + len(names)}) (base.names then names), "
                         f"got {X.shape}")
    if set(names) & set(base.names):
        raise ValueError(f"names must be new features, got {sorted(set(names) & set(base.names))}"
                         f" already in the base model")
    if y.shape != (X.shape[0],) or not np.isin(y, (0.0, 1.0)).all():
        raise ValueError(f"y must be {X.shape[0]} labels of 0 or 1")
    if not np.isfinite(X).all() or (X[:, k:] < 0).any():
        raise ValueError("X must be finite, the new features >= 0")
    if not l2 >= 0:
        raise ValueError(f"l2 must be >= 0, got {l2}")
    offset = np.array([base.log_odds(dict(zip(base.names, row, strict=True)))
                       for row in X[:, :k].tolist()])
    extra = X[:, k:]
    scale = np.sqrt(np.mean(extra ** 2, axis=0))
    scale[scale <= 1e-12] = 1.0
    Z = extra / scale
    sign = 2.0 * y - 1.0

    def loss(w: np.ndarray) -> float:
        # the penalised negative log-likelihood, which each step must lower
        return float(np.logaddexp(0.0, -sign * (offset + Z @ w)).sum() + 0.5 * l2 * w @ w)

    w = np.zeros(Z.shape[1])
    for _ in range(max_iter):
        p = 1.0 / (1.0 + np.exp(-np.clip(offset + Z @ w, -700, 700)))
        grad = Z.T @ (p - y) + l2 * w
        hess = (Z * (p * (1 - p))[:, None]).T @ Z + (l2 + 1e-9) * np.eye(len(w))
        step = np.linalg.solve(hess, grad)
        # Newton's full step overshoots where the offset saturates p (p (1 − p) ≈ 0 leaves
        # the Hessian at the penalty alone): halve it until the loss falls (Armijo)
        now, t = loss(w), 1.0
        while t > 1e-12 and loss(w - t * step) > now - 1e-4 * t * (grad @ step):
            t *= 0.5
        w -= t * step
        if np.max(np.abs(t * step)) < 1e-10:
            break
    n = len(names)
    return Calibrator(base.names + names, base.mean + (0.0,) * n,
                      base.scale + tuple(scale.tolist()), base.low + (0.0,) * n,
                      base.high + tuple(extra.max(axis=0).tolist()),
                      base.coef + tuple(w.tolist()), base.intercept, dict(meta or {}))


# ------------------------------------------------------------------------------ measures
def brier_score(p: Any, y: Any) -> float:
    """Mean squared difference of the predicted probabilities ``p`` and the 0/1 outcomes ``y``
    (0 is perfect; always predicting the base rate ``r`` scores ``r (1 − r)``)."""
    p, y = np.asarray(p, dtype=np.float64), np.asarray(y, dtype=np.float64)
    if p.shape != y.shape or p.size == 0:
        raise ValueError(f"p and y must have the same non-empty shape, got {p.shape} and "
                         f"{y.shape}")
    return float(np.mean((p - y) ** 2))


def reliability_table(p: Any, y: Any, bins: int = 10) -> list[dict[str, float]]:
    """Per confidence bin (``bins`` equal bins of [0, 1], the last closed): how many
    alignments, their mean predicted probability and the observed fraction right. Empty bins
    are left out."""
    p, y = np.asarray(p, dtype=np.float64), np.asarray(y, dtype=np.float64)
    if p.shape != y.shape:
        raise ValueError(f"p and y must have the same shape, got {p.shape} and {y.shape}")
    if not (isinstance(bins, int) and bins >= 1):
        raise ValueError(f"bins must be an integer >= 1, got {bins!r}")
    idx = np.minimum((p * bins).astype(int), bins - 1)
    rows = []
    for b in range(bins):
        sel = idx == b
        if sel.any():
            rows.append({"low": b / bins, "high": (b + 1) / bins, "n": int(sel.sum()),
                         "predicted": float(p[sel].mean()), "observed": float(y[sel].mean())})
    return rows


def max_calibration_gap(table: Sequence[Mapping[str, float]], min_count: int = 20) -> float:
    """Largest ``|predicted − observed|`` over the bins of :func:`reliability_table` holding
    at least ``min_count`` alignments (``nan`` when none does)."""
    gaps = [abs(r["predicted"] - r["observed"]) for r in table if r["n"] >= min_count]
    return max(gaps) if gaps else math.nan


def plot_reliability(curves: Mapping[str, tuple[Any, Any]], path: str | Path,
                     bins: int = 10, title: str = "Calibration") -> Path:
    """Reliability diagram (observed fraction right against mean predicted probability per
    bin, the diagonal is perfect calibration; marker area ∝ pairs in the bin) of each
    ``name → (p, y)``, with each curve's Brier score, written to ``path`` as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from topo.plotting import save_figure

    fig, ax = plt.subplots(figsize=(5.5, 5))
    ax.plot([0, 1], [0, 1], color="0.6", lw=1, ls="--", label="perfect")
    for name, (p, y) in curves.items():
        rows = reliability_table(p, y, bins)
        if not rows:
            continue
        ax.plot([r["predicted"] for r in rows], [r["observed"] for r in rows], marker="o",
                label=f"{name} (Brier {brier_score(p, y):.3f}, n={len(np.asarray(p))})")
        ax.scatter([r["predicted"] for r in rows], [r["observed"] for r in rows],
                   s=[8 + 2 * r["n"] for r in rows], alpha=0.3)
    ax.set(xlim=(0, 1), ylim=(0, 1), xlabel="predicted probability right (confidence)",
           ylabel="observed fraction right", title=title)
    ax.legend(loc="upper left", fontsize=8)
    ax.grid(alpha=0.3)
    out = save_figure(fig, path)
    plt.close(fig)
    return out


# ------------------------------------------------------------------------------- storage
_LOADED: dict[str, Calibrator] = {}


def load_model(name: str, path: str | Path | None = None) -> Calibrator:
    """The stored model ``name`` (from :data:`TABLE_PATH` unless ``path``; cached per path).

    Raises:
        ValueError: the table has no such model (the message lists those it has), or is not a
            calibration table.
    """
    key = f"{path or TABLE_PATH}::{name}"
    if key not in _LOADED:
        models = read_table(path)
        if name not in models:
            raise ValueError(f"no calibration model {name!r} in {path or TABLE_PATH}; it has "
                             f"{sorted(models)}")
        _LOADED[key] = models[name]
    return _LOADED[key]


def read_table(path: str | Path | None = None) -> dict[str, Calibrator]:
    """Every model of a calibration table (default :data:`TABLE_PATH`)."""
    path = Path(path or TABLE_PATH)
    return {name: Calibrator.from_dict(d) for name, d in _read_raw(path)["models"].items()}


def load_weights(name: str, path: str | Path | None = None) -> dict[str, float]:
    """The stored weight vector ``name`` (``"ranking"``: the structural search's
    :data:`fusion.structural.CONFIDENCE_WEIGHTS`), in its stored order (a fresh dict).

    Raises:
        ValueError: the table holds no such weights (the message lists those it has), or
            its names and values differ in length.
    """
    path = Path(path or TABLE_PATH)
    stored = _read_raw(path).get("weights", {})
    if name not in stored:
        raise ValueError(f"no weights {name!r} in {path}; it has {sorted(stored)}")
    names, values = stored[name]["names"], stored[name]["values"]
    if len(names) != len(values):
        raise ValueError(f"{path}: weights {name!r} have {len(names)} names and "
                         f"{len(values)} values")
    return {str(n): float(v) for n, v in zip(names, values, strict=True)}


def _read_raw(path: Path) -> dict[str, Any]:
    data = json.loads(path.read_text())
    if data.get("format") != TABLE_FORMAT or data.get("version") != TABLE_VERSION:
        raise ValueError(f"{path}: not a {TABLE_FORMAT} version {TABLE_VERSION} table")
    return data


def _write_raw(path: Path, models: dict[str, Any], weights: dict[str, Any]) -> Path:
    from topo.fileio import atomic_write_json

    _LOADED.clear()
    data = {"format": TABLE_FORMAT, "version": TABLE_VERSION, "models": models}
    if weights:
        data["weights"] = weights
    return atomic_write_json(path, data, allow_nan=False)


def write_model(name: str, model: Calibrator, path: str | Path | None = None) -> Path:
    """Store ``model`` as ``name`` in the table at ``path`` (default :data:`TABLE_PATH`),
    keeping the other models and the weights; written atomically."""
    path = Path(path or TABLE_PATH)
    data = _read_raw(path) if path.exists() else {}
    models = {n: Calibrator.from_dict(m).to_dict() for n, m in data.get("models", {}).items()}
    models[name] = model.to_dict()
    return _write_raw(path, models, data.get("weights", {}))


def write_weights(name: str, weights: Mapping[str, float], path: str | Path | None = None,
                  meta: Mapping[str, Any] | None = None) -> Path:
    """Store the weight vector ``weights`` (its order kept) as ``name`` in the table at
    ``path`` (default :data:`TABLE_PATH`), keeping everything else; written atomically. The
    package reads its weights when imported: a new process sees them.

    Raises:
        ValueError: a weight that is not finite.
    """
    values = [float(v) for v in weights.values()]
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"weights must be finite, got {dict(weights)}")
    path = Path(path or TABLE_PATH)
    data = _read_raw(path) if path.exists() else {}
    stored = dict(data.get("weights", {}))
    stored[name] = {"names": [str(n) for n in weights], "values": values,
                    "meta": dict(meta or {})}
    return _write_raw(path, data.get("models", {}), stored)
