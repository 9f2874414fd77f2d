"""The refit command (``python -m fusion.calibration fit``): cross-validation groups (a world is
held out whole), the reports, and the fit of each model end to end on tiny tuning sets, with the
table it writes read back."""

import json

import numpy as np
import pytest

from fusion.calibration import (
    TABLE_FORMAT,
    TABLE_PATH,
    TABLE_VERSION,
    fit_logistic,
    load_model,
    load_weights,
    read_table,
    write_weights,
)
from fusion.calibration import fit as cf
from fusion.calibration.__main__ import main
from fusion.calibration.report import held_out_report


def _row(set_name, world, right=True, score=1.0):
    return {"set": set_name, "world": world, "way": "ab", "overlap": 0.5, "right": right,
            "features": {"score": score}}


def test_a_synthetic_or_generic_world_is_one_group_at_every_noise_level():
    """The synthetic and generic pairs of one index are one world at every noise level."""
    groups = {cf.world_group(_row("generic", f"generic:500/s{s}/64")) for s in ("0", "0.05", "0.15")}
    assert groups == {"500/64"}
    assert cf.world_group(_row("generic", "generic:500/s0/64")) != \
        cf.world_group(_row("generic", "generic:501/s0/64"))
    groups = {cf.world_group(_row("synthetic", f"synthetic:synthetic/s{s}/12"))
              for s in ("0.05", "0.15", "0.3")}
    assert groups == {"synthetic/12"}


def test_env_worlds_group_as_before():
    """Procedural sets of one seed share worlds; a real map's pairs are its own."""
    assert cf.world_group(_row("frontier", "frontier:procedural:1234")) == \
        cf.world_group(_row("coordinated_frontier", "coordinated_frontier:procedural:1234"))
    assert cf.world_group(_row("real_dungeon_1", "real_dungeon_1:dungeon/1.png")) == \
        "real_dungeon_1:dungeon/1.png"


def test_cross_validation_holds_out_every_noise_level_of_a_world():
    """A world's rows are predicted by a model fitted without any of its noise levels."""
    rng = np.random.default_rng(0)
    rows = [_row("generic", f"generic:500/s{s}/{i}", bool(i % 2), float(rng.normal(i % 2)))
            for i in range(30) for s in ("0", "0.05", "0.1")]
    p = cf.cross_validated(rows, names=("score",))
    held = np.array([r["world"].endswith("/7") for r in rows])
    X, y = cf.matrix(rows, ("score",))
    alone = fit_logistic(X[~held], y[~held], ("score",), l2=cf.L2).predict(X[held])
    np.testing.assert_allclose(p[held], alone)


def test_held_out_report_reads_cached_rows_and_scores_both_models(tmp_path, capsys):
    """``--held-out``: per folder, the stored and the fitted model on rows neither saw (read
    from ``<cache stem>.held-out.json``); an extension names its noise-free base's origin."""
    rng = np.random.default_rng(1)
    rows = [{"set": "sigma_0.02", "world": f"sigma_0.02:procedural:{i}", "way": "ab",
             "overlap": 0.5, "right": bool(i % 3 == 0),
             "features": {**{n: float(rng.uniform(0.1, 1.0)) for n in cf.MODEL_FEATURES},
                          "log_score": float(i)}} for i in range(40)]
    cache = tmp_path / "rows.json"
    (tmp_path / "rows.held-out.json").write_text(json.dumps(rows))
    stored = load_model("grid")
    held_out_report([tmp_path / "sigma_0.02"], stored, cache)
    out = capsys.readouterr().out
    assert "sigma_0.02: 40 alignments, 14 right" in out
    assert out.count("largest gap in bins of ≥ 20") == 2 and "fitted:" in out
    base = cf.noise_free_base(stored)
    assert base.names == cf.BASE_FEATURES
    assert base.meta == stored.meta.get("extends", stored.meta)


def test_the_structural_models_features_are_the_merges():
    from fusion.structural import CALIBRATION_FEATURES

    assert cf.MODELS["structural"] == CALIBRATION_FEATURES


def _copy_table(tmp_path):
    path = tmp_path / "calibration.json"
    path.write_text(TABLE_PATH.read_text())
    return path


def _schema(path):
    data = json.loads(path.read_text())
    assert data["format"] == TABLE_FORMAT and data["version"] == TABLE_VERSION
    assert set(data) == {"format", "version", "models", "weights"}
    for model in data["models"].values():
        assert set(model) == {"names", "mean", "scale", "low", "high", "coef", "intercept",
                              "meta"}
    return data


def test_structural_fit_on_synthetic_pairs_writes_a_model_that_reads_back(tmp_path, capsys):
    """``fit --model structural --write`` on a few synthetic pairs: the table keeps its other
    models and the weights, and the stored model is the one fitted (a round trip)."""
    table = _copy_table(tmp_path)
    before = json.loads(table.read_text())
    assert main(["fit", "--model", "structural", "--synthetic", "6", "--data",
                 str(tmp_path / "none"), "--write", "--table", str(table)]) == 0
    out = capsys.readouterr().out
    assert "chosen accept_threshold:" in out and f"wrote {table}" in out
    data = _schema(table)
    assert data["models"]["grid"] == before["models"]["grid"]
    assert data["weights"] == before["weights"]
    model = read_table(table)["structural"]
    assert model.meta["data"] == ["synthetic"] and model.meta["alignments"] > 0
    assert model.meta["script"] == "python -m fusion.calibration fit --model structural"
    assert load_model("structural", table).to_dict() == model.to_dict()
    assert load_model("structural").to_dict() == read_table()["structural"].to_dict()


def test_ranking_fit_writes_weights_in_the_scores_order(tmp_path, capsys):
    """``fit --model ranking --write`` stores the score weights (the names of
    ``CONFIDENCE_WEIGHTS``, in their order) where ``load_weights`` reads them."""
    from fusion.structural import CONFIDENCE_WEIGHTS

    table = _copy_table(tmp_path)
    assert main(["fit", "--model", "ranking", "--synthetic", "3", "--data",
                 str(tmp_path / "none"), "--write", "--table", str(table)]) == 0
    assert "top-ranked candidate right" in capsys.readouterr().out
    _schema(table)
    weights = load_weights("ranking", table)
    assert list(weights) == list(CONFIDENCE_WEIGHTS)
    assert all(np.isfinite(list(weights.values())))
    assert read_table(table).keys() == read_table().keys()  # the models kept


def test_grid_fit_on_tiny_env_pairs(tmp_path, capsys):
    """``fit --model grid`` on a tiny dataset of grid pairs (three worlds, each with an
    overlapping and a non-overlapping pair): rows both ways, a model over its features."""
    from test_grid_merge import TINY, overlapping_views, plan, view

    from fusion import Rigid2D
    from fusion.evaluation.pairs import FORMAT, FORMAT_VERSION, MapPair, write_pair
    from topo.fileio import atomic_write_json

    root = tmp_path / "tiny"
    atomic_write_json(root / "dataset.json", {"format": FORMAT, "version": FORMAT_VERSION})
    k = 0
    for w, deg in enumerate((0.0, 90.0, 200.0)):
        a, b, truth = overlapping_views(deg)
        other = view(plan(w + 5), Rigid2D.identity(), (1, 1), (20, 22))
        for grid_b, t, overlap in ((b, truth, 0.5), (other, Rigid2D.identity(), 0.0)):
            write_pair(root, MapPair(k, TINY, TINY, a, grid_b, t, overlap, f"w{w}", 0, "test",
                                     100, w, k % 2))
            k += 1
    table = _copy_table(tmp_path)
    cache = tmp_path / "rows.json"
    assert main(["fit", "--model", "grid", "--pairs", str(root), "--cache", str(cache),
                 "--write", "--table", str(table)]) == 0
    rows = json.loads(cache.read_text())
    assert len(rows) == 12 and {r["way"] for r in rows} == {"ab", "ba"}
    assert sum(r["right"] for r in rows) == 6  # the overlapping pairs, both ways
    model = read_table(table)["grid"]
    assert model.names == cf.MODEL_FEATURES and model.meta["data"] == ["tiny"]
    capsys.readouterr()
    # the cached rows are read back: the same fit without running the merges again
    assert main(["fit", "--model", "grid", "--pairs", str(root / "missing"), "--cache",
                 str(cache)]) == 0
    assert "12 rows in" not in capsys.readouterr().out


def test_fit_refuses_what_it_cannot_do(tmp_path):
    with pytest.raises(SystemExit):
        main(["fit", "--model", "structural", "--extend"])
    with pytest.raises(SystemExit):
        main(["fit", "--model", "grid", "--data", str(tmp_path)])  # no pairs there
    with pytest.raises(ValueError, match=r"name must be one of \['grid', 'structural', "
                                         r"'grid_real', 'window_near'\], got "
                                         r"'ranking'"):
        cf.fit_model("ranking", [])
    with pytest.raises(ValueError, match=r"weights must be finite"):
        write_weights("ranking", {"bias": float("nan")}, tmp_path / "t.json")
    with pytest.raises(ValueError, match=r"no weights 'nope' in .*; it has \['ranking'\]"):
        load_weights("nope")
