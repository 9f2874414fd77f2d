"""The evaluation CLI: tables, JSON and plots, the oracle, dataset folders, bad arguments."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fusion.evaluation import evaluate as evaluate_module
from fusion.evaluation.evaluate import (
    check_exhaustive,
    evaluate,
    load_pair_dir,
    main,
    parse_methods,
    synthetic_pairs,
)
from fusion.evaluation.results import (
    ROTATION_OK_DEG,
    TRANSLATION_OK_M,
    EvalPair,
    is_success,
    oracle_transform,
    summarise,
)
from fusion.evaluation.synthetic import make_pair
from topo import TopoMap
from topo.fileio import atomic_write_json


def test_success_needs_both_errors_strictly_below_the_thresholds():
    assert is_success((ROTATION_OK_DEG - 1e-9, TRANSLATION_OK_M - 1e-9))
    assert not is_success((ROTATION_OK_DEG, 0.0))
    assert not is_success((0.0, TRANSLATION_OK_M))
    assert not is_success(None)  # no true transform (another world)


def test_cli_writes_results_and_plots(tmp_path, capsys):
    out = tmp_path / "eval"
    assert main(["--synthetic", "5", "--noise", "0.1", "--methods", "auto,paper_icp",
                 "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "node noise σ = 0.1 m" in printed and "oracle" in printed and "false acc" in printed
    data = json.loads((out / "results.json").read_text())
    assert data["methods"] == ["auto", "paper_icp"]
    assert {r["method"] for r in data["records"]} == {"oracle", "auto", "paper_icp"}
    assert len(data["records"]) == 5 * 3
    for name in ("error_cdf.png", "success_vs_overlap.png", "success_vs_rotation.png",
                 "threshold_curves.png", "calibration.png"):
        assert (out / name).stat().st_size > 0
    assert "success against wrong accepts as accept_threshold moves" in printed
    assert "calibration of confidence (Brier" in printed
    assert [r["threshold"] for r in data["threshold_sweep"]["auto"]][:3] == [0.0, 0.05, 0.1]
    assert set(data["calibration"]) == {"auto", "paper_icp"}
    assert list(out.glob("merged_*.png"))
    assert not list(out.glob(".*"))  # no temporary files left behind


def test_cli_config_per_noise_level(tmp_path):
    out = tmp_path / "eval"
    assert main(["--synthetic", "2", "--noise", "0.3", "--methods", "auto", "--for-noise",
                 "--config", "{\"candidates\": 8}", "--out", str(out), "--quiet",
                 "--no-plots"]) == 0
    data = json.loads((out / "results.json").read_text())
    assert data["config_for_noise"] is True
    assert not list(out.glob("*.png"))


def test_cli_argument_errors(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main([])
    assert exc.value.code == 2
    assert "give either PAIRS_DIR or --synthetic N" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["--synthetic", "2", "--methods", "auto,icp"])
    assert "got ['icp']" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main([str(tmp_path / "missing")])
    assert "is not a folder" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["--synthetic", "2", "--config", "{\"eps\": -1}"])
    assert "eps must be > 0.0, got -1" in capsys.readouterr().err


def chain_pair(name: str, n: int) -> EvalPair:
    """A pair of ``n``-node chains (every node ends a path: ``n`` endpoints each)."""
    m = TopoMap.from_arrays(np.column_stack([np.arange(n), np.arange(n) % 3]),
                            np.column_stack([np.arange(n - 1), np.arange(1, n)]))
    return EvalPair(name, m, m, None, None, 1.0, "overlap", None)


def test_exhaustive_on_large_pairs_is_refused_before_anything_runs(monkeypatch):
    def no_merge(*args, **kwargs):
        raise AssertionError("a merge ran")

    monkeypatch.setattr(evaluate_module, "merge_maps", no_merge)
    pairs = [chain_pair("small", 20), chain_pair("big", 200), chain_pair("bigger", 300)]
    with pytest.raises(ValueError, match=(
            r"^'exhaustive' \(the paper's search\) is too slow for 2 of 3 pairs; the largest, "
            r"bigger: 300 × 300 endpoints × 181 angles \(exhaustive_step_deg=2\) = 16,290,000 "
            r"placements, .* exhaustive_step_deg >= 6.6 fits\)\. Leave 'exhaustive' out of the "
            r"methods, or coarsen it with the config field exhaustive_step_deg$")):
        evaluate(pairs, ["auto", "exhaustive"], progress=False)
    check_exhaustive(pairs, {"exhaustive_step_deg": 6.6})  # coarse enough: no error
    check_exhaustive(pairs[:1])


def test_cli_exhaustive_on_large_maps_is_an_argument_error(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--synthetic", "1", "--noise", "0.05", "--synthetic-config",
              "{\"map_nodes\": [250, 300]}", "--methods", "auto,exhaustive", "--quiet",
              "--out", str(tmp_path)])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert ("error: --methods: 'exhaustive' (the paper's search) is too slow for 1 of 1 pairs"
            in err)
    assert "--config '{\"exhaustive_step_deg\": ...}'" in err and "Traceback" not in err
    assert not list(tmp_path.iterdir())


def test_parse_methods():
    assert parse_methods("auto, exhaustive,auto,ransac") == ["auto", "exhaustive", "ransac"]
    with pytest.raises(ValueError, match=r"methods must be a comma-separated list of \['auto'"):
        parse_methods("auto,icp")


def test_oracle_is_exact_without_noise():
    p = make_pair(np.random.default_rng(4), {"noise": 0.0}, overlap=0.7, nodes=(20, 20))
    pair = EvalPair("p", p.map_a, p.map_b, p.transform, p.correspondences, p.overlap,
                    p.kind, 0.0)
    assert oracle_transform(pair).allclose(p.transform, atol=1e-9)
    empty = EvalPair("q", p.map_a, p.map_b, None, np.empty((0, 2), int), 0.0, "disjoint", 0.0)
    assert oracle_transform(empty) is None


def test_summary_counts_false_accepts_and_bins():
    pairs = synthetic_pairs(10, seed=2, noise_levels=(0.05,))
    records = evaluate(pairs, ["auto"], progress=False)
    level = summarise(records)["0.05"]
    assert sum(row["pairs"] for row in level["overlap_bins"].values()) == 8
    assert level["methods"]["auto"]["no_overlap_pairs"] == 2
    assert level["methods"]["oracle"]["false_accept_rate"] == 0.0


def test_reads_a_map_pair_dataset(tmp_path):
    import fusion.evaluation.pairs as pairs_mod

    grid = pairs_mod.GridSnapshot(np.zeros((2, 2), np.int8), 0.1, (0.0, 0.0))
    atomic_write_json(tmp_path / "dataset.json",
                                {"format": pairs_mod.FORMAT, "version": pairs_mod.FORMAT_VERSION})
    for i, kind in enumerate(["overlap", "disjoint"]):
        p = make_pair(np.random.default_rng(i), overlap=0.8, kind=kind, nodes=(25, 25))
        pairs_mod.write_pair(tmp_path, pairs_mod.MapPair(
            i, p.map_a, p.map_b, grid, grid, p.transform, p.overlap, "w", i, "test", 0, 0, 0))
    loaded = load_pair_dir(tmp_path)
    assert [p.kind for p in loaded] == ["overlap", "no_overlap"]
    assert loaded[0].correspondences is None
    records = evaluate(loaded, ["auto"], progress=False)
    assert [r.method for r in records] == ["auto", "auto"]  # no oracle without correspondences


def test_malformed_trajectories_of_a_dataset_pair_are_named(tmp_path):
    import fusion.evaluation.pairs as pairs_mod

    grid = pairs_mod.GridSnapshot(np.zeros((2, 2), np.int8), 0.1, (0.0, 0.0))
    atomic_write_json(tmp_path / "dataset.json",
                      {"format": pairs_mod.FORMAT, "version": pairs_mod.FORMAT_VERSION})
    p = make_pair(np.random.default_rng(0), overlap=0.8, kind="overlap", nodes=(25, 25))
    bad = {"trajectory_a": [[0.0] * 6, [1.0] * 6], "trajectory_b": [[0.0] * 5]}
    pairs_mod.write_pair(tmp_path, pairs_mod.MapPair(
        3, p.map_a, p.map_b, grid, grid, p.transform, p.overlap, "w", 0, "test", 0, 0, 0,
        extra=bad))
    with pytest.raises(pairs_mod.DatasetError,
                       match=r"pair 3: extra trajectory_a / trajectory_b: rows_b must be "
                             r"\(K, 6\) rows .* got shape \(1, 5\)"):
        load_pair_dir(tmp_path)


def test_grid_methods_need_grids():
    from fusion.evaluation.evaluate import evaluate, parse_methods, synthetic_pairs

    assert parse_methods("hybrid,grid,auto") == ["hybrid", "grid", "auto"]
    pairs = synthetic_pairs(2, seed=3, noise_levels=(0.05,))
    records = evaluate(pairs, ["grid"], progress=False)
    grid_records = [r for r in records if r.method == "grid"]
    assert grid_records and all(not r.accepted for r in grid_records)


def _rec(name, conf, right, kind="overlap", overlap=0.5, gated=True):
    from fusion.evaluation.results import Record

    err = (0.5, 0.1) if right else (30.0, 3.0)
    return Record(name, "m", kind, overlap, None, 10.0, conf >= 0.5, *err,
                  bool(conf >= 0.5 and right), 0.01, None, None, 5, 5, conf, gated)


def test_threshold_sweep_counts_what_each_threshold_accepts():
    from fusion.evaluation.results import calibration_summary, is_right, threshold_sweep

    records = [_rec("p0", 0.95, True), _rec("p1", 0.7, True), _rec("p2", 0.6, False),
               _rec("p3", 0.8, False, kind="no_overlap", overlap=0.0),
               _rec("p4", 0.99, True, gated=False), _rec("p5", 0.3, True, overlap=0.2)]
    assert [is_right(r) for r in records] == [True, True, False, False, True, True]
    rows = {r["threshold"]: r for r in threshold_sweep(records, (0.0, 0.65, 0.9))["m"]}
    # >= 40 % overlap: p0, p1, p2, p4 (p4 fails its hard gate at any threshold)
    assert rows[0.0]["success_overlap_ge_40"] == pytest.approx(50.0)
    assert rows[0.65]["success_overlap_ge_40"] == pytest.approx(50.0)
    assert rows[0.9]["success_overlap_ge_40"] == pytest.approx(25.0)
    # wrong accepts of all 6 pairs: p2 and p3 at 0, p3 at 0.65, none at 0.9
    assert [rows[t]["wrong_accepts"] for t in (0.0, 0.65, 0.9)] == pytest.approx(
        [200 / 6, 100 / 6, 0.0])
    assert [rows[t]["false_accepts"] for t in (0.0, 0.65, 0.9)] == [100.0, 100.0, 0.0]
    cal = calibration_summary(records)["m"]
    assert cal["merges"] == 6 and cal["max_gap_bins_ge_20"] is None
    assert cal["brier"] == pytest.approx(np.mean(
        [(0.95 - 1) ** 2, 0.3 ** 2, 0.6 ** 2, 0.8 ** 2, 0.01 ** 2, 0.7 ** 2]))


def test_cli_evaluates_several_folders_as_one_set(tmp_path, capsys):
    import fusion.evaluation.pairs as pairs_mod

    grid = pairs_mod.GridSnapshot(np.zeros((2, 2), np.int8), 0.1, (0.0, 0.0))
    for folder in ("one", "two"):
        root = tmp_path / folder
        atomic_write_json(root / "dataset.json", {
            "format": pairs_mod.FORMAT, "version": pairs_mod.FORMAT_VERSION})
        p = make_pair(np.random.default_rng(len(folder)), overlap=0.8, nodes=(20, 20))
        pairs_mod.write_pair(root, pairs_mod.MapPair(
            0, p.map_a, p.map_b, grid, grid, p.transform, p.overlap, "w", 0, "test", 0, 0, 0))
    out = tmp_path / "eval"
    assert main([str(tmp_path / "one"), str(tmp_path / "two"), "--methods", "auto",
                 "--out", str(out), "--quiet", "--no-plots"]) == 0
    data = json.loads((out / "results.json").read_text())
    assert [r["pair"] for r in data["records"]] == ["one/pair_000000", "two/pair_000000"]
    assert str(tmp_path / "two") in data["source"]


def test_merges_of_bent_maps_are_summarised_by_their_fused_map_ate():
    """Records with a fused-map ATE (pairs with trajectories): the summary gives the median
    over accepted merges on overlapping pairs beside the floor on the same pairs, and the
    table prints both; without trajectories neither appears."""
    from dataclasses import replace

    from fusion.evaluation.results import format_tables

    records = [replace(_rec("p0", 0.9, True), ate_m=0.3, ate_floor_m=0.2),
               replace(_rec("p1", 0.9, False), ate_m=2.0, ate_floor_m=0.4),
               replace(_rec("p2", 0.9, True), ate_m=0.5, ate_floor_m=0.5),
               replace(_rec("p3", 0.2, True), ate_m=9.0, ate_floor_m=0.1),  # not accepted
               _rec("p4", 0.9, True)]  # no trajectories
    s = summarise(records)["unknown"]["methods"]["m"]
    assert (s["ate_pairs"], s["median_ate_m"], s["median_ate_floor_m"]) == (3, 0.5, 0.4)
    table = format_tables(summarise(records))
    assert "fused-map ATE of accepted merges" in table
    assert "m                     3       0.50         0.40" in table
    assert "fused-map ATE" not in format_tables(summarise([_rec("p4", 0.9, True)]))
