"""``benchmarks/calibrate_merge.py``'s cross-validation groups: a world is held out whole."""

import sys
from pathlib import Path

import numpy as np

from fusion.calibration import fit_logistic

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))  # the scripts and their helpers, as when run

import calibrate_merge as cm  # noqa: E402


def _row(set_name, world, right=True, score=1.0):
    return {"set": set_name, "world": world, "way": "ab", "overlap": 0.5, "right": right,
            "features": {"score": score}}


def test_a_synthetic_or_generic_world_is_one_group_at_every_noise_level():
    """The synthetic and generic pairs of one index are one world at every noise level."""
    groups = {cm._group(_row("generic", f"generic:500/s{s}/64")) for s in ("0", "0.05", "0.15")}
    assert groups == {"500/64"}
    assert cm._group(_row("generic", "generic:500/s0/64")) != \
        cm._group(_row("generic", "generic:501/s0/64"))
    groups = {cm._group(_row("synthetic", f"synthetic:synthetic/s{s}/12"))
              for s in ("0.05", "0.15", "0.3")}
    assert groups == {"synthetic/12"}


def test_env_worlds_group_as_before():
    """Procedural sets of one seed share worlds; a real map's pairs are its own."""
    assert cm._group(_row("frontier", "frontier:procedural:1234")) == \
        cm._group(_row("coordinated_frontier", "coordinated_frontier:procedural:1234"))
    assert cm._group(_row("real_dungeon_1", "real_dungeon_1:dungeon/1.png")) == \
        "real_dungeon_1:dungeon/1.png"


def test_cross_validation_holds_out_every_noise_level_of_a_world():
    """A world's rows are predicted by a model fitted without any of its noise levels."""
    rng = np.random.default_rng(0)
    rows = [_row("generic", f"generic:500/s{s}/{i}", bool(i % 2), float(rng.normal(i % 2)))
            for i in range(30) for s in ("0", "0.05", "0.1")]
    p = cm.cross_validated(rows, names=("score",))
    held = np.array([r["world"].endswith("/7") for r in rows])
    X, y = cm.matrix(rows, ("score",))
    alone = fit_logistic(X[~held], y[~held], ("score",), l2=cm.L2).predict(X[held])
    np.testing.assert_allclose(p[held], alone)


def test_held_out_report_reads_cached_rows_and_scores_both_models(tmp_path, capsys):
    """``--held-out``: per folder, the stored and the fitted model on rows neither saw (read
    from ``<cache stem>.held-out.json``); an extension names its noise-free base's origin."""
    import json

    from fusion.calibration import load_model

    rng = np.random.default_rng(1)
    rows = [{"set": "sigma_0.02", "world": f"sigma_0.02:procedural:{i}", "way": "ab",
             "overlap": 0.5, "right": bool(i % 3 == 0),
             "features": {**{n: float(rng.uniform(0.1, 1.0)) for n in cm.MODEL_FEATURES},
                          "log_score": float(i)}} for i in range(40)]
    cache = tmp_path / "rows.json"
    (tmp_path / "rows.held-out.json").write_text(json.dumps(rows))
    stored = load_model("grid")
    cm.held_out_report([tmp_path / "sigma_0.02"], stored, cache)
    out = capsys.readouterr().out
    assert "sigma_0.02: 40 alignments, 14 right" in out
    assert out.count("largest gap in bins of ≥ 20") == 2 and "fitted:" in out
    base = cm.noise_free_base(stored)
    assert base.names == cm.BASE_FEATURES
    assert base.meta == stored.meta.get("extends", stored.meta)
