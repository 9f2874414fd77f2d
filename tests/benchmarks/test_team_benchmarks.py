"""The team benchmarks (``team_size.py``, ``merge_in_loop.py --robots N``, ``env_scaling.py``): a tiny
run of each writes its rows, resumes without re-running them, and prints its tables; the
ratio tables pair episodes by seed. What they measure is read from their tables, not tested."""

import importlib.util
import sys
from pathlib import Path

import pytest

from topo.fileio import read_json_lines

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))  # their shared helpers, as when run


def _load(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "benchmarks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


ts = _load("team_size")
mil = _load("merge_in_loop")
es = _load("env_scaling")


def _row(n, seed, t85, explorer="frontier", comm="unlimited", max_cycles=100):
    return {"explorer": explorer, "size": 10.0, "comm": comm, "n": n, "seed": seed,
            "max_cycles": max_cycles, "t50": t85, "t85": t85, "t95": None, "fused_all": None,
            "coverage": 0.9, "cpu_s": 1.0}


def test_team_size_runs_resumes_and_prints(tmp_path, capsys):
    out = tmp_path / "rows.jsonl"
    argv = ["--sizes", "10", "--cycles-per-metre", "2", "--ns", "2", "3", "--seeds", "1",
            "--explorers", "frontier", "--comms", "unlimited", "5", "--out", str(out)]
    ts.main(argv)
    rows = read_json_lines(out)
    # Frontier ignores the range: its limited-range episodes are not run
    assert sorted((r["n"], r["comm"]) for r in rows) == [(2, "unlimited"), (3, "unlimited")]
    assert all(r["steps"] == 20 and r["max_cycles"] == 20 for r in rows)
    text = capsys.readouterr().out
    assert "| frontier | 10 | unlimited | 3 | 1 |" in text and "T85(N) / T85(2)" in text
    ts.main(argv)  # resumed: nothing left to run
    assert "0 episodes to run" in capsys.readouterr().out
    assert len(read_json_lines(out)) == 2


def test_team_size_known_poses_team_fuses_from_the_start():
    row = ts.run_cell("coordinated_frontier@known", 10.0, "unlimited", 3, 0, 5)
    assert row["fused_all"] == 1 and row["explorer"] == "coordinated_frontier@known"
    plain = ts.run_cell("coordinated_frontier", 10.0, "unlimited", 3, 0, 5)
    assert plain["fused_all"] is None


def test_team_size_ratios_pair_seeds_and_mark_censored_medians():
    rows = [_row(2, 100, 40), _row(2, 101, 50), _row(4, 100, 20), _row(4, 101, 30),
            _row(4, 102, 10)]  # seed 102 has no N = 2 episode: not paired
    text = ts.ratio_tables(rows)
    assert "| frontier | 10 | unlimited | 0.55 (0.50, 0.60) |" in text
    never = [_row(2, s, None) for s in (1, 2)] + [_row(2, 3, 40)]
    assert "| >101 | >101 |" in ts.cell_table(never)
    assert ts._fmt_median([(None, 101), (10, 101), (20, 101)]) == "20"  # a reached median
    # T85(2) not reached: the ratio is at most T85(4) / (max_cycles + 1)
    bound = ts.ratio_tables([_row(2, 100, None), _row(4, 100, 50), _row(2, 101, 40),
                             _row(4, 101, 20)])
    assert "| frontier | 10 | unlimited | ~0.50 (<0.50, 0.50) |" in bound


def test_merge_in_loop_refuses_the_other_runs_options():
    with pytest.raises(SystemExit):
        mil.parse_args(["--robots", "3", "--odometry-noise", "0.01"])
    with pytest.raises(SystemExit):
        mil.parse_args(["--checks", "on"])
    with pytest.raises(SystemExit):
        mil.parse_args(["--robots", "9"])
    team, pair = mil.parse_args(["--robots", "4"]), mil.parse_args([])
    assert (team.worlds, team.first_seed, pair.worlds, pair.first_seed) == (10, 100, 20, 0)


def test_team_size_rejects_bad_arguments():
    with pytest.raises(SystemExit):
        ts.parse_args(["--ns", "1"])
    with pytest.raises(ValueError, match="--comms values must be 'unlimited' or a range > 0"):
        ts.comm_range("-3")


def test_team_merge_in_loop_runs_both_checks(tmp_path, capsys):
    out = tmp_path / "merge.jsonl"
    mil.main(["--robots", "3", "--worlds", "1", "--steps", "20", "--size", "10", "--out", str(out)])
    rows = read_json_lines(out)
    assert sorted(r["cycle_check"] for r in rows) == [False, True]
    assert all(0 <= r["gross"] <= r["wrong"] <= r["merged"] and r["steps"] == 20 for r in rows)
    assert "| cycle check | episodes | merged robot-steps |" in capsys.readouterr().out


@pytest.mark.parametrize("driver", ["random", "frontier"])
def test_env_scaling_runs_and_reports_per_robot_cost(capsys, tmp_path, driver):
    es.main(["--ns", "2", "3", "--steps", "15", "--rounds", "1", "--size", "10", "--profile",
             "--top", "3", "--driver", driver, "--out", str(tmp_path / "scaling.json")])
    text = capsys.readouterr().out
    assert "ms per robot-step, N = 3 / N = 2" in text and "cProfile, N = 3" in text
    assert (tmp_path / "scaling.json").exists()


def test_env_scaling_times_the_pose_graph_with_drifting_odometry(capsys):
    es.main(["--ns", "2", "--steps", "30", "--rounds", "1", "--size", "10", "--pose-graph",
             "--odometry", "pioneer3dx"])
    text = capsys.readouterr().out
    assert "pose graph True, odometry pioneer3dx" in text
    row = next(line for line in text.splitlines() if line.startswith("| 2 |"))
    assert row.split(" | ")[9].endswith("%")  # mapping + merging share of a step
    kwargs = es.env_kwargs(10.0, None, True, "pioneer3dx")
    assert kwargs["mapping"] == {"pose_graph": True}
    assert kwargs["robot"]["odometry_alphas"] == "pioneer3dx"
    assert es.mapping_share({"stages": {"_sense_and_map": 1.0, "_fuse": 1.0,
                                        "_simulate": 2.0}}) == 0.5


def test_env_scaling_commands_are_the_same_for_the_first_robots_at_any_n():
    two, four = es.commands(2, 30, seed=5), es.commands(4, 30, seed=5)
    for a, b in zip(two, four, strict=True):
        assert set(b) == {"robot_0", "robot_1", "robot_2", "robot_3"}
        for agent in ("robot_0", "robot_1"):
            assert (a[agent] == b[agent]).all()
