"""``benchmarks/training_eval.py``'s statistics and worlds: the IQM, its two-level bootstrap
interval and the held-out world list (fixed, sized 10–20 m, disjoint from training seeds)."""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))  # its shared helpers (_maps), as when run
spec = importlib.util.spec_from_file_location("training_eval", ROOT / "benchmarks/training_eval.py")
te = importlib.util.module_from_spec(spec)
sys.modules["training_eval"] = te  # dataclasses look their module up there
spec.loader.exec_module(te)


def test_iqm_is_the_mean_of_the_middle_half():
    assert te.iqm(np.arange(1, 9)) == pytest.approx(np.mean([3, 4, 5, 6]))
    # an outlier moves the mean, not the IQM
    assert te.iqm([1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 50.0]) == 1.0


def test_bootstrap_interval_brackets_the_iqm_and_narrows_with_data():
    rng = np.random.default_rng(0)
    small = rng.lognormal(0.0, 0.3, size=(6, 3))
    large = rng.lognormal(0.0, 0.3, size=(60, 5))
    mid, lo, hi = te.bootstrap_iqm(small, np.random.default_rng(1), reps=400)
    assert lo <= mid <= hi
    mid2, lo2, hi2 = te.bootstrap_iqm(large, np.random.default_rng(1), reps=400)
    assert lo2 <= mid2 <= hi2 and hi2 - lo2 < hi - lo
    assert te.bootstrap_iqm(np.ones((5, 2)), np.random.default_rng(0), reps=50) == (1.0, 1.0, 1.0)
    # same generator state, same interval
    assert te.bootstrap_iqm(small, np.random.default_rng(1), reps=400) == (mid, lo, hi)


def test_heldout_worlds_are_fixed_and_in_range():
    a, b = te.heldout_worlds(12, real=False), te.heldout_worlds(12, real=False)
    assert a == b and len(a) == 12 and len({w.seed for w in a}) == 12
    for w in a:
        sx, sy = w.config["world"]["size"]
        assert 10 <= sx <= 20 and 10 <= sy <= 20
        assert w.max_cycles == int(150 * max(sx, sy))
    assert te.heldout_worlds(3, real=False) == a[:3]


def test_policy_path_picks_the_final_or_the_best_policy(tmp_path):
    (tmp_path / "model.zip").write_bytes(b"final")
    assert te._policy_path(tmp_path, best=False) == tmp_path / "model.zip"
    with pytest.raises(SystemExit, match="no best_model.zip or rllib_best"):
        te._policy_path(tmp_path, best=True)
    (tmp_path / "rllib_best").mkdir()
    assert te._policy_path(tmp_path, best=True) == tmp_path / "rllib_best"
    # the best policy is another explorer, cached apart from the final one
    world = te.heldout_worlds(1, real=False)[0]
    assert te._key(f"run:{tmp_path}", world) != te._key(f"best-run:{tmp_path}", world)
    # and so is the same policy run with the poses found by merging (benchmarks/_poses.py)
    assert te._key(f"run:{tmp_path}", world) != te._key(f"run:{tmp_path}@merged", world)


@pytest.mark.parametrize(("trained", "n", "ok"), [(2, 4, False), (4, 2, False), (3, 6, True),
                                                  (4, 4, True)])
def test_only_team_policies_are_evaluated_with_another_team_size(tmp_path, monkeypatch,
                                                                 capsys, trained, n, ok):
    import json

    run = tmp_path / "run"
    run.mkdir()
    (run / "args.json").write_text(json.dumps({"n_robots": trained}))
    (run / "model.zip").write_bytes(b"not read before the episodes")

    class Checked(Exception):
        """The checks passed: the episodes would run now."""

    def run_all(*_args):
        raise Checked

    monkeypatch.setattr(te, "run_all", run_all)
    monkeypatch.setattr(sys, "argv", ["training_eval.py", str(run), "--n-robots", str(n),
                                      "--worlds", "1", "--skip-real", "--baselines",
                                      "--rules", "--out", str(tmp_path / "out")])
    if ok:
        with pytest.raises(Checked):
            te.main()
    else:
        with pytest.raises(SystemExit):
            te.main()
        assert (f"was trained with {trained} robots, --n-robots is {n}: only an SB3 team "
                "policy") in capsys.readouterr().err


def test_known_poses_suffix_runs_the_same_explorer_with_the_poses_known():
    team, config = te._team("coordinated_frontier@known", 3)
    plain, plain_config = te._team("coordinated_frontier", 3)
    assert config == {**plain_config, "mapping": {"merge_method": "known"}}
    assert sorted(team) == sorted(plain) == ["robot_0", "robot_1", "robot_2"]
    assert type(team["robot_0"]) is type(plain["robot_0"])


def test_pose_suffixes_set_the_merge_method_and_keep_the_rest_of_mapping():
    from _poses import split_poses, with_merge_method

    assert split_poses("coordinated_frontier@known") == ("coordinated_frontier", "known")
    assert split_poses("run:runs/a@merged") == ("run:runs/a", "hybrid")
    assert split_poses("frontier") == ("frontier", None)
    trained = {"max_cycles": 9, "mapping": {"merge_method": "known", "grid_merge_every": 25}}
    assert with_merge_method(trained, "hybrid") == {
        "max_cycles": 9, "mapping": {"merge_method": "hybrid", "grid_merge_every": 25}}
    assert with_merge_method(trained, None) is trained


def test_poses_flag_runs_the_trained_policies_with_the_poses_found_by_merging(
        tmp_path, monkeypatch):
    import json

    run = tmp_path / "run"
    run.mkdir()
    (run / "args.json").write_text(json.dumps({"n_robots": 4, "known_poses": True}))
    (run / "model.zip").write_bytes(b"not read before the episodes")
    seen = {}

    class Checked(Exception):
        """The checks passed: the episodes would run now."""

    def run_all(explorers, *_args):
        seen["explorers"] = explorers
        raise Checked

    monkeypatch.setattr(te, "run_all", run_all)
    monkeypatch.setattr(sys, "argv", ["training_eval.py", str(run), "--n-robots", "4",
                                      "--poses", "merged", "--worlds", "1", "--skip-real",
                                      "--baselines", "--rules", "--out", str(tmp_path / "out")])
    with pytest.raises(Checked):
        te.main()
    assert f"run:{run}@merged" in seen["explorers"] and "frontier" in seen["explorers"]
