"""Which calibrated confidence model the grid alignment uses: the env's ``"grid"`` unless a
config names another; the map-merge tool the real-map model and the threshold stored with it
(``--confidence-model real``, the default) or the env's (``sim``)."""

import numpy as np
import pytest

from fusion.calibration import load_model
from fusion.decision import DEFAULT_ACCEPT_THRESHOLD, REAL_MAP_MODEL, model_threshold
from fusion.grid_merge import GridMergeConfig, merge_grids
from fusion.mapmerge import CONFIDENCE_MODELS, InputMap, parser, tool_config


def room(shift: int = 0) -> InputMap:
    """A walled room with an inner wall and a box: enough walls to align."""
    states = np.ones((60, 80), dtype=np.int8)
    states[[0, -1], :] = 2
    states[:, [0, -1]] = 2
    states[:40, 30] = 2
    states[45:50, 55 + shift:62 + shift] = 2
    return InputMap("room", "", states, 0.1, (0.0, 0.0))


def test_the_env_keeps_its_model_and_threshold():
    cfg = GridMergeConfig()
    assert cfg.confidence_model == "grid" and cfg.accept_threshold == DEFAULT_ACCEPT_THRESHOLD
    assert tool_config("sim") == cfg


def test_the_tool_uses_the_real_model_and_its_stored_threshold():
    cfg = tool_config()
    assert cfg.confidence_model == REAL_MAP_MODEL == CONFIDENCE_MODELS["real"]
    assert cfg.accept_threshold == model_threshold(REAL_MAP_MODEL)
    assert cfg.accept_threshold == load_model(REAL_MAP_MODEL).meta["accept_threshold"]
    assert parser().parse_args(["a", "b", "--out", "o"]).confidence_model == "real"


def test_the_confidence_follows_the_named_model():
    a, b = room(), room(shift=1)
    sim = merge_grids(a, b, GridMergeConfig())
    real = merge_grids(a, b, tool_config("real"))
    assert real.transform.allclose(sim.transform)  # the estimate does not depend on it
    assert real.features() == sim.features()
    expected = load_model(REAL_MAP_MODEL)(sim.features())
    assert real.confidence == pytest.approx(min(expected, 0.5) if sim.margin < 1.05
                                            else expected)


def test_bad_model_names_are_named():
    with pytest.raises(TypeError, match=r"GridMergeConfig\.confidence_model must be a model "
                                        r"name \(str\), got 3"):
        GridMergeConfig(confidence_model=3)
    with pytest.raises(ValueError, match=r"no calibration model 'nope' in .*; it has \["):
        merge_grids(room(), room(), GridMergeConfig(confidence_model="nope"))
    with pytest.raises(ValueError, match=r"no calibration model 'nope'"):
        model_threshold("nope")
    with pytest.raises(ValueError, match=r"confidence_model must be one of \['real', 'sim'\], "
                                         r"got 'x'"):
        tool_config("x")


def test_recalibration_rescales_the_grid_models_log_odds():
    from fusion.calibration.fit import MODELS, fit_model, recalibrated

    base = load_model("grid")
    rng = np.random.default_rng(0)
    X = rng.uniform(base.low, base.high, size=(4000, len(base.names)))
    z = np.array([base.log_odds(dict(zip(base.names, row, strict=True))) for row in X])
    y = (rng.random(len(z)) < 1 / (1 + np.exp(-(0.5 * z + 0.3)))).astype(float)
    model = recalibrated(base, X, y, l2=0.0)
    assert model.meta["scale"] == pytest.approx(0.5, abs=0.05)
    assert model.meta["shift"] == pytest.approx(0.3, abs=0.15)
    # a monotone map of the grid model's confidence: the same ranking, other probabilities
    p, q = model.predict(X[:50]), base.predict(X[:50])
    assert (np.argsort(p, kind="stable") == np.argsort(q, kind="stable")).all()
    assert MODELS["grid_real"] == tuple(base.names)
    with pytest.raises(ValueError, match=r"recalibrate rescales the grid model for grid_real "
                                         r"only, got name='grid'"):
        fit_model("grid", [], recalibrate=base)


def _fit_from_rows(tmp_path, model: str, rows: list[dict]):
    """``python -m fusion.calibration fit --model MODEL --rows F --split dev --write`` on
    ``rows``, after checking it refuses to run without rows; the stored model."""
    import json

    from fusion.calibration import read_table
    from fusion.calibration.__main__ import main

    path = tmp_path / f"{model}.jsonl"
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))
    with pytest.raises(SystemExit):
        main(["fit", "--model", model])  # no rows given
    table = tmp_path / "t.json"
    assert main(["fit", "--model", model, "--rows", str(path), "--split", "dev",
                 "--table", str(table), "--write"]) == 0
    fitted = read_table(table)[model]
    assert fitted.meta["alignments"] == sum(r["split"] == "dev" for r in rows)
    assert fitted.meta["script"].endswith(f"--rows {path} --split dev")
    return fitted


def test_the_fit_command_refits_grid_real_from_rows(tmp_path):
    base = load_model("grid")
    rng = np.random.default_rng(1)
    X = rng.uniform(base.low, base.high, size=(300, len(base.names)))
    z = np.array([base.log_odds(dict(zip(base.names, row, strict=True))) for row in X])
    right = rng.random(len(z)) < 1 / (1 + np.exp(-z))
    rows = [{"set": "real_pairs_dev", "split": "dev" if k % 5 else "test", "pair": str(k),
             "world": f"b{k % 6}", "way": "ab", "overlap": 0.5, "overlap_m2": 50.0,
             "right": bool(r),
             "features": {"log_score": k / 7, **dict(zip(base.names, x, strict=True))}}
            for k, (x, r) in enumerate(zip(X.tolist(), right, strict=True))]
    model = _fit_from_rows(tmp_path, "grid_real", rows)
    assert 0 < model.meta["accept_threshold"] <= 1 and model.meta["scale"] > 0


def test_the_fit_command_fits_the_near_model_from_bending_rows(tmp_path):
    """``--model window_near`` fits on the rows ``benchmarks/bending_in_loop.py --rows``
    writes, leaving one world out, and refuses to run without them."""
    from fusion.local_align import NEAR_FEATURES

    rng = np.random.default_rng(2)
    rows = []
    for k in range(240):
        corr = float(rng.uniform(0.0, 4.0))
        feats = dict.fromkeys(NEAR_FEATURES, 0.0) | {
            "corr_deg": corr, "wall_agreement": float(rng.uniform(0.7, 1.0)),
            "loop": float(k % 2)}
        rows.append({"set": "bending/pioneer3dx/2", "world": f"bending:{k % 8}",
                     "split": "dev" if k % 8 < 6 else "test", "way": "ab", "overlap": 1.0,
                     "features": feats, "right": bool(rng.random() < 1 - corr / 5)})
    model = _fit_from_rows(tmp_path, "window_near", rows)
    assert tuple(model.names) == NEAR_FEATURES
    zero = dict.fromkeys(NEAR_FEATURES, 0.0)
    low = model(zero | {"corr_deg": 3.5, "wall_agreement": 0.85})
    high = model(zero | {"corr_deg": 0.2, "wall_agreement": 0.85})
    assert low < high
