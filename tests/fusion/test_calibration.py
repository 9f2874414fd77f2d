"""fusion.calibration: the logistic fit recovers a known model, stored models round-trip, the
measures (Brier, reliability) mean what they say, and the shipped grid model is usable."""

import json
import math

import numpy as np
import pytest

from fusion.calibration import (
    Calibrator,
    brier_score,
    extend_logistic,
    fit_logistic,
    load_model,
    max_calibration_gap,
    plot_reliability,
    read_table,
    reliability_table,
    write_model,
)

NAMES = ("a", "b")


def _sample(n: int, seed: int = 0):
    """Labels drawn from a known logistic model: P = σ(−0.5 + 2a − b)."""
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(n, 2)) * [1.0, 2.0] + [0.5, 0.0]
    p = 1 / (1 + np.exp(-(-0.5 + 2 * X[:, 0] - X[:, 1])))
    return X, (rng.random(n) < p).astype(float), p


def test_fit_recovers_a_known_model_and_is_calibrated_on_new_data():
    X, y, _ = _sample(20_000)
    model = fit_logistic(X, y, NAMES, l2=0.0)
    # back to raw units: w_raw = coef / scale, b_raw = b − Σ coef·mean/scale
    w = np.array(model.coef) / np.array(model.scale)
    b = model.intercept - float(np.sum(np.array(model.coef) * np.array(model.mean)
                                       / np.array(model.scale)))
    np.testing.assert_allclose(w, [2.0, -1.0], atol=0.1)
    assert b == pytest.approx(-0.5, abs=0.1)
    Xt, yt, pt = _sample(20_000, seed=1)
    table = reliability_table(model.predict(Xt), yt)
    assert max_calibration_gap(table, min_count=500) < 0.03
    assert brier_score(model.predict(Xt), yt) == pytest.approx(brier_score(pt, yt), abs=0.005)


def test_one_alignment_at_a_time_matches_the_batch_and_clips_to_the_fitted_range():
    X, y, _ = _sample(500)
    model = fit_logistic(X, y, NAMES)
    row = {"a": float(X[3, 0]), "b": float(X[3, 1])}
    assert model(row) == pytest.approx(float(model.predict(X[3:4])[0]))
    # beyond the range seen when fitting, the confidence stops moving
    far = model({"a": 1e6, "b": 0.0})
    assert far == model({"a": model.high[0], "b": 0.0}) == model({"a": 1e3, "b": 0.0})
    assert model({"a": math.nan, "b": 0.0}) == model({"a": model.mean[0], "b": 0.0})


def test_round_trip_and_storage(tmp_path):
    X, y, _ = _sample(300)
    model = fit_logistic(X, y, NAMES, meta={"fitted": "2026-12-02"})
    again = Calibrator.from_dict(json.loads(json.dumps(model.to_dict())))
    assert again == model
    path = tmp_path / "table.json"
    write_model("one", model, path)
    write_model("two", model, path)  # keeps the first
    assert set(read_table(path)) == {"one", "two"}
    assert load_model("two", path) == model
    with pytest.raises(ValueError, match=r"no calibration model 'three' in .*; it has "
                                         r"\['one', 'two'\]"):
        load_model("three", path)


def test_bad_input_names_the_problem():
    X, y, _ = _sample(50)
    with pytest.raises(ValueError, match=r"y must hold 0s and 1s, both present"):
        fit_logistic(X, np.ones(50), NAMES)
    with pytest.raises(ValueError, match=r"X must have shape \(N, 3\)"):
        fit_logistic(X, y, ("a", "b", "c"))
    with pytest.raises(ValueError, match="l2 must be >= 0, got -1"):
        fit_logistic(X, y, NAMES, l2=-1)
    model = fit_logistic(X, y, NAMES)
    with pytest.raises(KeyError, match=r"feature 'b' missing; the model needs \['a', 'b'\]"):
        model({"a": 1.0})
    with pytest.raises(ValueError, match=r"calibration model is missing \['coef'\]"):
        Calibrator.from_dict({k: v for k, v in model.to_dict().items() if k != "coef"})
    with pytest.raises(ValueError, match=r"Calibrator.scale must have 2 values"):
        Calibrator(NAMES, (0, 0), (1,), (0, 0), (1, 1), (1, 1), 0.0)


def test_measures():
    assert brier_score([1.0, 0.0], [1, 0]) == 0.0
    assert brier_score([0.25] * 4, [1, 0, 0, 0]) == pytest.approx(0.25 * 0.75)
    table = reliability_table([0.05, 0.05, 0.95, 0.95, 1.0], [0, 1, 1, 1, 1], bins=10)
    assert [(r["low"], r["n"], r["observed"]) for r in table] == [(0.0, 2, 0.5), (0.9, 3, 1.0)]
    assert max_calibration_gap(table, min_count=3) == pytest.approx(abs(2.9 / 3 - 1.0))
    assert math.isnan(max_calibration_gap(table, min_count=4))
    with pytest.raises(ValueError, match="bins must be an integer >= 1"):
        reliability_table([0.5], [1], bins=0)


def test_reliability_diagram_is_written(tmp_path):
    X, y, _ = _sample(400)
    p = fit_logistic(X, y, NAMES).predict(X)
    out = plot_reliability({"model": (p, y)}, tmp_path / "cal.png")
    assert out.exists() and out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_shipped_grid_model():
    from fusion.grid_merge import FEATURES

    model = load_model("grid")
    assert set(model.names) <= set(FEATURES)
    assert {"fitted", "commit", "data", "accept_threshold"} <= set(model.meta)
    # more margin, overlap and agreeing walls never lower the confidence
    base = dict.fromkeys(FEATURES, 0.0) | {"log_margin": 0.3, "log_overlap": 3.5,
                                           "native_agreement": 0.7, "log_wall_hits": 5.5}
    for name in ("log_margin", "log_overlap", "native_agreement", "log_wall_hits"):
        assert model(base | {name: base[name] * 1.5}) >= model(base)


def test_an_extended_model_keeps_the_base_where_the_new_features_are_zero():
    """extend_logistic fits new weights with the base model's log-odds as an offset: where the
    new feature is 0 (perfect odometry) the answer is the base's, bit for bit; where it is not,
    the known extra effect is recovered."""
    X, y, _ = _sample(3000)
    base = fit_logistic(X, y, NAMES)
    rng = np.random.default_rng(5)
    d = rng.uniform(0.0, 2.0, 20_000)
    Xb = rng.normal(size=(20_000, 2)) * [1.0, 2.0] + [0.5, 0.0]
    z = np.array([base.log_odds({"a": a, "b": b}) for a, b in Xb.tolist()]) - 1.5 * d
    yd = (rng.random(len(d)) < 1 / (1 + np.exp(-z))).astype(float)
    ext = extend_logistic(base, np.column_stack([Xb, d]), yd, ("d",), l2=0.0,
                          meta={"note": "test"})
    assert ext.names == ("a", "b", "d") and ext.meta == {"note": "test"}
    assert ext.coef[2] / ext.scale[2] == pytest.approx(-1.5, abs=0.1)
    for a, b in Xb[:50].tolist():
        assert ext.log_odds({"a": a, "b": b, "d": 0.0}) == base.log_odds({"a": a, "b": b})
    with pytest.raises(ValueError, match=r"names must be new features, got \['a'\]"):
        extend_logistic(base, np.column_stack([Xb, d]), yd, ("a",))
    with pytest.raises(ValueError, match="the new features >= 0"):
        extend_logistic(base, np.column_stack([Xb, -d]), yd, ("d",))
    with pytest.raises(ValueError, match=r"X must have shape \(N, 3\)"):
        extend_logistic(base, Xb, yd, ("d",))


def test_extending_a_confident_base_converges():
    """Where the base model is sure (log-odds 8) and the new feature's rows are mostly wrong,
    Newton's full step overshoots back and forth (it stopped at weight +5, confidence 1.0);
    the damped steps reach the penalised optimum: 100 (p − 0.1) + 2 w = 0."""
    base = Calibrator(("a",), (0.0,), (1.0,), (-1.0,), (1.0,), (1.0,), 8.0)
    X = np.column_stack([np.zeros(100), np.ones(100)])
    y = (np.arange(100) < 10).astype(float)
    ext = extend_logistic(base, X, y, ("d",), l2=2.0)
    w = ext.coef[1]
    p = float(ext.predict(X[:1])[0])
    assert 100 * (p - 0.1) + 2 * w == pytest.approx(0.0, abs=1e-6)
    assert p == pytest.approx(0.279, abs=0.001)
