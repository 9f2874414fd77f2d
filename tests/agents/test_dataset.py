"""Map-pair dataset generation: round trip with ground truth, resume, workers, Ray, CLI."""

import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

import agents.dataset as dataset
from agents.dataset import (
    TRAJECTORY_EVERY,
    GenerateArgs,
    SettingsError,
    coverage_levels,
    episode_seed,
    generate,
    info,
    main,
)
from fusion import Rigid2D
from fusion.evaluation.pairs import LOCK_FILE, load_pairs, pair_files
from topo.fileio import exclusive_lock
from topo.grid import CellState

KW = {"explorer": "frontier", "snapshots": 2, "max_cycles": 200, "world_size": (10.0, 10.0),
      "progress": False}


def fields(pair):
    return (pair.pair_id, pair.step, pair.seed, pair.world_id, round(pair.overlap, 12),
            pair.map_a.xy.round(9).tolist(), pair.map_b.edges.tolist(),
            pair.grid_b.states.tobytes(), round(pair.transform.theta, 12))


def wall_agreement(pair, transform) -> float:
    """Share of B's occupied cells, moved into A's frame by ``transform``, that land within two
    cells of an occupied cell of A (counting only cells A knows)."""
    a, b = pair.grid_a, pair.grid_b
    h, w = a.states.shape
    rows, cols = np.nonzero(b.states == CellState.OCCUPIED)
    xy = np.stack([b.origin[0] + (cols + 0.5) * b.resolution,
                   b.origin[1] + (rows + 0.5) * b.resolution], 1)
    ia = np.floor((transform.apply(xy) - a.origin) / a.resolution).astype(int)
    ia = ia[(ia[:, 0] >= 0) & (ia[:, 0] < w) & (ia[:, 1] >= 0) & (ia[:, 1] < h)]
    known = a.states[ia[:, 1], ia[:, 0]] != CellState.UNKNOWN
    walls = ndimage.binary_dilation(a.states == CellState.OCCUPIED, iterations=2)
    return float(walls[ia[known, 1], ia[known, 0]].mean()) if known.sum() > 30 else float("nan")


def made(tmp_path_factory, name: str, pairs: int, kw: dict):
    """A dataset of ``pairs`` pairs generated into a new folder, and its pairs."""
    out = tmp_path_factory.mktemp(name)
    generate(GenerateArgs(out=out, pairs=pairs, **kw))
    return out, load_pairs(out)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    return made(tmp_path_factory, "ref", 4, KW)


def test_round_trip_and_ground_truth(reference):
    out, pairs = reference
    assert [p.pair_id for p in pairs] == [0, 1, 2, 3]
    assert {p.episode for p in pairs} == {0, 1} and [p.snapshot for p in pairs] == [0, 1, 0, 1]
    assert pairs[0].seed == episode_seed(0, 0) and pairs[2].seed == episode_seed(0, 1)
    assert all(p.step >= 1 and p.explorer == "frontier" for p in pairs)
    assert pairs[0].step <= pairs[1].step
    # the stored transform takes B's frame onto A's: B's walls land on A's walls, and a
    # transform 10° / 0.3 m off does much worse
    # (of the pairs that overlap, the one with the most walls: small early maps discriminate
    # little)
    best = max((p for p in pairs if p.overlap > 0.3),
               key=lambda p: int((p.grid_b.states == CellState.OCCUPIED).sum()))
    off = Rigid2D.from_degrees(10.0, (0.3, 0.0)) @ best.transform
    assert wall_agreement(best, best.transform) > 0.7
    assert wall_agreement(best, best.transform) > wall_agreement(best, off) + 0.2
    assert "4 pairs" in info(out)


def test_resume_after_an_interruption_gives_the_same_pairs(reference, tmp_path, monkeypatch):
    real = dataset.generate_episode

    def dies_on_episode_1(root, episode, n_pairs, settings):
        if episode == 1:
            raise KeyboardInterrupt
        return real(root, episode, n_pairs, settings)

    monkeypatch.setattr(dataset, "generate_episode", dies_on_episode_1)
    with pytest.raises(KeyboardInterrupt):
        generate(GenerateArgs(out=tmp_path, pairs=4, **KW))
    assert sorted(pair_files(tmp_path)) == [0, 1]
    assert not (tmp_path / LOCK_FILE).exists()  # released: the same command resumes
    monkeypatch.setattr(dataset, "generate_episode", real)
    summary = generate(GenerateArgs(out=tmp_path, pairs=4, **KW))
    assert summary["already_there"] == 2 and summary["written"] == 2
    assert [fields(p) for p in load_pairs(tmp_path)] == [fields(p) for p in reference[1]]
    again = generate(GenerateArgs(out=tmp_path, pairs=4, **KW))  # nothing left to do
    assert again["written"] == 0


def test_worker_processes_give_the_same_pairs(reference, tmp_path):
    generate(GenerateArgs(out=tmp_path, pairs=4, workers=2, **KW))
    assert [fields(p) for p in load_pairs(tmp_path)] == [fields(p) for p in reference[1]]


def test_ray_backend_gives_the_same_pairs(reference, tmp_path):
    pytest.importorskip("ray")
    generate(GenerateArgs(out=tmp_path, pairs=4, workers=2, backend="ray", **KW))
    assert [fields(p) for p in load_pairs(tmp_path)] == [fields(p) for p in reference[1]]
    assert not (tmp_path / LOCK_FILE).exists()


def test_changed_settings_refuse_to_resume(reference, tmp_path):
    generate(GenerateArgs(out=tmp_path, pairs=2, **KW))
    with pytest.raises(SettingsError, match=r"holds a dataset made with other settings: "
                                            r"--explorer frontier \(this run: random_walk\)"):
        generate(GenerateArgs(out=tmp_path, pairs=2, **{**KW, "explorer": "random_walk"}))


def test_cli_generate_and_info(tmp_path, capsys):
    main(["generate", "--out", str(tmp_path), "--pairs", "1", "--snapshots", "1",
          "--max-cycles", "30", "--explorer", "random_walk", "--no-progress"])
    assert "wrote 1 pairs" in capsys.readouterr().out
    main(["info", str(tmp_path)])
    assert "1 pairs" in capsys.readouterr().out


def test_snapshot_levels_spread():
    np.testing.assert_allclose(coverage_levels(2), [0.325, 0.675])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"pairs": 0}, "pairs must be >= 1, got 0"),
        ({"backend": "spark"}, r"backend must be one of \['process', 'ray'\], got 'spark'"),
        ({"address": "auto"}, "address is only used with backend='ray'"),
        ({"explorer": "spiral"}, r"explorer must be one of \["),
        ({"explorer": "sb3:/nowhere/model.zip"}, "no saved model at '/nowhere/model.zip'"),
        ({"world": "/nowhere/map.yaml"}, "world must be 'procedural' or an existing map file"),
        ({"world_size": (1.0, 1.0)}, r"world.size\[0\] must be >= 6.0, got 1.0"),
    ],
)
def test_bad_arguments(tmp_path, kwargs, match):
    with pytest.raises(SettingsError, match=match) as exc:
        GenerateArgs(out=tmp_path, **kwargs)
    assert exc.value.field == next(iter(kwargs))


# ------------------------------------------------------------------------ CLI errors
TINY = ["--pairs", "1", "--snapshots", "1", "--max-cycles", "20", "--explorer", "random_walk",
        "--no-progress"]


def cli_error(capsys, argv: list[str]) -> str:
    """Run the CLI expecting a user error: exit status 2 and one line on stderr."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    out = capsys.readouterr()
    assert out.err.count("\n") == 1 and "Traceback" not in out.err and out.out == ""
    return out.err


def test_cli_too_small_world_is_one_line_and_writes_nothing(tmp_path):
    out = tmp_path / "new" / "pairs"
    run = subprocess.run([sys.executable, "-m", "agents.dataset", "generate", "--world-size",
                          "1", "1", "--out", str(out), *TINY], capture_output=True, text=True,
                         cwd=Path(__file__).parents[2], timeout=120)
    assert run.returncode == 2
    assert run.stderr == ("python -m agents.dataset generate: error: --world-size: "
                          "world.size[0] must be >= 6.0, got 1.0\n")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("flags", "match"),
    [
        (["--pairs", "0"], "error: --pairs: pairs must be >= 1, got 0"),
        (["--max-cycles", "5"], "error: --max-cycles: max_cycles must be >= 10, got 5"),
        (["--address", "auto"], "error: --address: address is only used with backend='ray'"),
        (["--explorer", "spiral"], r"error: --explorer: explorer must be one of \["),
        (["--world", "/nowhere/map.yaml"], "error: --world: world must be 'procedural' or an"),
        (["--odometry", "wobbly"], "error: --odometry: odometry must be 'perfect', "
                                   "'pioneer3dx' or a noise level such as '0.02', got 'wobbly'"),
        (["--odometry", "-0.1"], r"error: --odometry: robot.odometry_noise\[0\] must be >= 0"),
    ],
)
def test_cli_bad_settings(tmp_path, capsys, flags, match):
    err = cli_error(capsys, ["generate", "--out", str(tmp_path / "d"), *flags])
    assert re.search(match, err)
    assert list(tmp_path.iterdir()) == []


def test_cli_unloadable_world_file_or_model_writes_nothing(tmp_path, capsys):
    bad_map = tmp_path / "room.json"
    bad_map.write_text('{"verts": [[0, 0], [1, 0]]}')
    bad_model = tmp_path / "model.zip"
    bad_model.write_text("not a model")
    out = tmp_path / "d"
    err = cli_error(capsys, ["generate", "--out", str(out), "--world", str(bad_map)])
    assert "error: --world: world file" in err and "at least 3 [x, y] pairs" in err
    err = cli_error(capsys, ["generate", "--out", str(out), "--explorer", f"sb3:{bad_model}"])
    assert "error: --explorer: explorer 'sb3:" in err and "cannot load the model" in err
    assert not out.exists()


def test_cli_out_is_a_file_or_a_foreign_folder(tmp_path, capsys):
    (tmp_path / "notes.txt").write_text("mine")
    err = cli_error(capsys, ["generate", "--out", str(tmp_path / "notes.txt"), *TINY])
    assert f"error: --out: {tmp_path / 'notes.txt'} is a file, not a folder" in err
    err = cli_error(capsys, ["generate", "--out", str(tmp_path), *TINY])
    assert (f"error: --out: {tmp_path} is a folder that is not a map-pair dataset (no "
            f"dataset.json; it holds ['notes.txt'])") in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]


def test_cli_settings_mismatch_names_the_flags(tmp_path, capsys):
    main(["generate", "--out", str(tmp_path), *TINY])
    capsys.readouterr()
    err = cli_error(capsys, ["generate", "--out", str(tmp_path), *TINY, "--max-cycles", "30",
                             "--world-size", "12", "12"])
    assert err == (f"python -m agents.dataset generate: error: --out: {tmp_path} holds a "
                   "dataset made with other settings: --max-cycles 20 (this run: 30); "
                   "--world-size 20.0 20.0 (this run: 12.0 12.0); run with its settings to "
                   "resume it, or give another --out for a new dataset\n")


def test_cli_info_of_a_folder_that_is_no_dataset(tmp_path, capsys):
    err = cli_error(capsys, ["info", str(tmp_path)])
    assert f"error: ROOT: {tmp_path / 'dataset.json'}: missing" in err


def test_a_second_writer_is_locked_out(tmp_path, capsys):
    with exclusive_lock(tmp_path / LOCK_FILE):
        err = cli_error(capsys, ["generate", "--out", str(tmp_path), *TINY])
    assert (f"error: --out: {tmp_path} is being written by another run (pid {os.getpid()} "
            f"on ") in err
    assert f"its lock {tmp_path / LOCK_FILE} goes with that process" in err
    assert list(tmp_path.iterdir()) == []  # neither the lock nor a manifest is left
    main(["generate", "--out", str(tmp_path), *TINY])  # the lock went with its holder
    assert "wrote 1 pairs" in capsys.readouterr().out
    assert not (tmp_path / LOCK_FILE).exists()


def test_a_killed_writer_leaves_no_stale_lock(tmp_path):
    lock = tmp_path / LOCK_FILE
    code = ("import os, signal, sys\nfrom topo.fileio import exclusive_lock\n"
            f"with exclusive_lock({str(lock)!r}):\n    os.kill(os.getpid(), signal.SIGKILL)\n")
    run = subprocess.run([sys.executable, "-c", code], cwd=Path(__file__).parents[2],
                         timeout=60)
    assert run.returncode == -signal.SIGKILL and lock.exists()  # its file is left behind...
    generate(GenerateArgs(out=tmp_path, pairs=1, **KW))  # ...but not its lock
    assert sorted(pair_files(tmp_path)) == [0] and not lock.exists()


def test_a_failed_new_dataset_leaves_the_folder_as_it_was(tmp_path, monkeypatch):
    def fails(root, episode, n_pairs, settings):
        raise RuntimeError("the first episode failed")

    real = dataset.generate_episode
    monkeypatch.setattr(dataset, "generate_episode", fails)
    out = tmp_path / "new" / "pairs"
    with pytest.raises(RuntimeError, match="the first episode failed"):
        generate(GenerateArgs(out=out, pairs=1, **KW))
    assert list(tmp_path.iterdir()) == []  # the folders it created are gone too
    (tmp_path / "empty").mkdir()
    with pytest.raises(RuntimeError, match="the first episode failed"):
        generate(GenerateArgs(out=tmp_path / "empty", pairs=1, **KW))
    assert list((tmp_path / "empty").iterdir()) == []  # a folder that existed stays
    monkeypatch.setattr(dataset, "generate_episode", real)
    generate(GenerateArgs(out=out, pairs=1, **{**KW, "explorer": "random_walk"}))
    assert sorted(pair_files(out)) == [0]


# ------------------------------------------------------------------------ teams of N robots
TEAM_KW = {**KW, "robots": 3, "world_size": (12.0, 12.0)}


@pytest.fixture(scope="module")
def team_reference(tmp_path_factory):
    return made(tmp_path_factory, "team", 6, TEAM_KW)


def test_a_team_of_three_gives_every_pair_of_a_snapshot(team_reference):
    out, pairs = team_reference
    assert [p.pair_id for p in pairs] == list(range(6))
    assert [p.extra["robots"] for p in pairs] == [[0, 1], [0, 2], [1, 2]] * 2
    assert [p.snapshot for p in pairs] == [0, 0, 0, 1, 1, 1]
    assert {p.episode for p in pairs} == {0} and {p.seed for p in pairs} == {episode_seed(0, 0)}
    # robot 0's map is the same one in the snapshot's (0, 1) and (0, 2) pairs, robot 2's in
    # (0, 2) and (1, 2)
    for s in (pairs[:3], pairs[3:]):
        assert len({p.step for p in s}) == 1
        np.testing.assert_array_equal(s[0].grid_a.states, s[1].grid_a.states)
        np.testing.assert_array_equal(s[1].grid_b.states, s[2].grid_b.states)
        np.testing.assert_array_equal(s[0].grid_b.states, s[2].grid_a.states)
        # the truths compose: 2 -> 0 is 2 -> 1 then 1 -> 0
        assert (s[0].transform @ s[2].transform).allclose(s[1].transform, atol=1e-9)
    manifest = json.loads((out / "dataset.json").read_text())
    assert manifest["settings"]["robots"] == 3
    assert "6 pairs" in info(out)
    assert "robot pairs (i, j): (0, 1) 2, (0, 2) 2, (1, 2) 2" in info(out)


def test_team_truths_take_robot_j_start_pose_into_robot_i_frame(team_reference):
    """Each stored transform maps robot j's frame onto robot i's: the world through robot j's
    true start pose, then back through robot i's."""
    from envs import parallel_env_for

    _, pairs = team_reference
    env = parallel_env_for(dataset.env_kwargs(GenerateArgs(out=Path("x"), **TEAM_KW).settings()))
    env.reset(seed=pairs[0].seed)
    starts = [env.unwrapped.frames[i] for i in range(3)]
    points = np.array([[0.0, 0.0], [1.0, 0.5], [-2.0, 3.0]])
    for p in pairs:
        i, j = p.extra["robots"]
        world = starts[j].apply(points)  # points of robot j's frame, in the world
        np.testing.assert_allclose(p.transform.apply(points), starts[i].inverse().apply(world),
                                   atol=1e-9)
    env.close()


def test_team_overlap_is_per_pair():
    a = np.zeros((4, 4), bool)
    b = np.zeros((4, 4), bool)
    a[:2] = True  # 8 cells
    b[1:] = True  # 12 cells, 4 of them a's
    assert dataset.pair_overlap(a, b) == dataset.pair_overlap(b, a) == 0.5
    assert dataset.pair_overlap(a, np.zeros_like(a)) == 0.0


def test_team_resume_rewrites_the_same_pairs(team_reference, tmp_path):
    generate(GenerateArgs(out=tmp_path, pairs=4, **TEAM_KW))  # stops inside snapshot 1
    assert sorted(pair_files(tmp_path)) == [0, 1, 2, 3]
    summary = generate(GenerateArgs(out=tmp_path, pairs=6, **TEAM_KW))
    assert summary["already_there"] == 4 and summary["written"] == 6  # the episode re-ran
    assert [fields(p) for p in load_pairs(tmp_path)] == [fields(p) for p in team_reference[1]]
    with pytest.raises(SettingsError, match=r"--robots 3 \(this run: \(unset\)\)"):
        generate(GenerateArgs(out=tmp_path, pairs=6, **{**TEAM_KW, "robots": 2}))


@pytest.mark.parametrize("robots", [1, 9])
def test_bad_team_size_names_the_flag(tmp_path, capsys, robots):
    with pytest.raises(SettingsError, match=f"n_robots must be between 2 and 8, got {robots}"
                       ) as exc:
        GenerateArgs(out=tmp_path, robots=robots)
    assert exc.value.field == "robots"
    err = cli_error(capsys, ["generate", "--out", str(tmp_path / "d"), "--robots", str(robots)])
    assert f"error: --robots: n_robots must be between 2 and 8, got {robots}" in err


# ------------------------------------------------------------------------ dataset hygiene
def copy_of(reference, tmp_path) -> Path:
    import shutil

    out = tmp_path / "copy"
    shutil.copytree(reference[0], out)
    return out


def test_the_manifest_counts_the_pairs_and_a_stray_file_is_refused(reference, tmp_path,
                                                                     capsys):
    out = copy_of(reference, tmp_path)
    assert json.loads((out / "dataset.json").read_text())["pairs"] == 4
    stray = out / "pairs" / "pair_000025.npz"
    stray.write_bytes((out / "pairs" / "pair_000000.npz").read_bytes())
    err = cli_error(capsys, ["info", str(out)])
    assert (f"error: ROOT: {stray}: a stray file: this dataset holds pairs 0–3 (dataset.json: "
            f"pairs=4); move it out of {out / 'pairs'} or delete it") in err
    # a run that would grow the dataset over it refuses it too, before counting it as written
    err = cli_error(capsys, ["generate", "--out", str(out), "--pairs", "30", *_kw_flags()])
    assert f"error: --out: {stray}: a stray file" in err
    assert json.loads((out / "dataset.json").read_text())["pairs"] == 4
    stray.unlink()
    assert "4 pairs" in info(out)


def _kw_flags() -> list[str]:
    """:data:`KW` as command-line flags."""
    return ["--explorer", KW["explorer"], "--snapshots", str(KW["snapshots"]), "--max-cycles",
            str(KW["max_cycles"]), "--world-size", *map(str, KW["world_size"]), "--no-progress"]


def test_a_copied_or_corrupt_pair_file_says_what_to_do(reference, tmp_path, capsys):
    out = copy_of(reference, tmp_path)
    (out / "pairs" / "pair_000001.npz").write_bytes((out / "pairs" / "pair_000000.npz")
                                                     .read_bytes())
    err = cli_error(capsys, ["info", str(out)])
    assert ("pair_000001.npz: holds pair 0, not 1 (a copied or renamed file): delete it and "
            "rerun the command that generated the dataset") in err
    (out / "pairs" / "pair_000001.npz").write_bytes(b"PK\x03\x04 truncated")
    err = cli_error(capsys, ["info", str(out)])
    assert "pair_000001.npz: corrupt or not a map-pair file" in err
    assert "delete it and rerun the command that generated the dataset" in err
    (out / "pairs" / "pair_000001.npz").unlink()  # as told: the same command writes it again
    summary = generate(GenerateArgs(out=out, pairs=4, **KW))
    assert summary["written"] == 2 and summary["already_there"] == 3
    assert [fields(p) for p in load_pairs(out)] == [fields(p) for p in reference[1]]


def test_a_manifest_without_a_pair_count_gets_one(reference, tmp_path):
    out = copy_of(reference, tmp_path)
    manifest = json.loads((out / "dataset.json").read_text())
    del manifest["pairs"]  # as written before the count existed
    (out / "dataset.json").write_text(json.dumps(manifest))
    assert "4 pairs" in info(out)
    assert generate(GenerateArgs(out=out, pairs=2, **KW))["written"] == 0
    assert json.loads((out / "dataset.json").read_text())["pairs"] == 4


def test_a_full_disk_is_one_line_and_the_same_command_resumes(tmp_path, capsys, monkeypatch):
    import errno

    real = dataset.write_pair
    calls = []

    def disk_full(root, pair):
        calls.append(pair.pair_id)
        if len(calls) > 1:
            raise OSError(errno.ENOSPC, "No space left on device", str(root))
        return real(root, pair)

    monkeypatch.setattr(dataset, "write_pair", disk_full)
    argv = ["generate", "--out", str(tmp_path), *TINY[:1], "2", *TINY[2:]]
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert err == (f"python -m agents.dataset generate: error: {tmp_path}: no space left (No "
                   f"space left on device) writing {tmp_path}: the pairs written are whole; "
                   f"free space and rerun the same command to resume\n")
    assert sorted(pair_files(tmp_path)) == [0]
    monkeypatch.setattr(dataset, "write_pair", real)
    main(argv)
    assert "wrote 1 pairs (1 already there)" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "line"),
    [
        (["generate", "--out", "d", "--pairs", "abc"],
         "python -m agents.dataset generate: error: value error: Error parsing --pairs: invalid "
         "literal for int() with base 10: 'abc'"),
        (["generate", "--out", "d", "--bogus", "1"],
         "python -m agents.dataset generate: error: Unrecognized options: --bogus, 1"),
        (["generate"], "python -m agents.dataset generate: error: required options: Missing "
                       "from python -m agents.dataset generate: --out PATH"),
        ([], "python -m agents.dataset: error: missing subcommand: Expected one of {generate, "
             "info}."),
        (["generate", "--out", "d", "--backend", "spark"],
         "python -m agents.dataset generate: error: invalid choice 'spark' for argument "
         "'--backend'. Expected one of ('process', 'ray')."),
    ],
)
def test_cli_parse_errors_are_one_line_too(tmp_path, capsys, monkeypatch, argv, line):
    monkeypatch.chdir(tmp_path)
    assert cli_error(capsys, argv) == line + "\n"
    assert list(tmp_path.iterdir()) == []


def test_cli_help_is_untouched(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["generate", "--help"])
    assert exc.value.code == 0
    assert "--max-cycles" in capsys.readouterr().out


def test_cli_parse_error_on_the_command_line_is_one_line(tmp_path):
    run = subprocess.run([sys.executable, "-m", "agents.dataset", "generate", "--out",
                          str(tmp_path / "d"), "--pairs", "abc"], capture_output=True, text=True,
                         cwd=Path(__file__).parents[2], timeout=120)
    assert run.returncode == 2
    assert run.stderr == ("python -m agents.dataset generate: error: value error: Error parsing "
                          "--pairs: invalid literal for int() with base 10: 'abc'\n")
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------------ drifting odometry
def test_drifting_pairs_hold_the_truth_at_the_robots_current_places(tmp_path_factory,
                                                                   reference):
    """With drifting odometry a pair keeps its start-frame truth and adds the one right where
    the robots are now and both robots' trajectories; without drift the two truths are the
    same and the trajectories exact; evaluation reads either truth and judges a merge by the
    fused map's ATE."""
    from fusion.evaluation.evaluate import evaluate, load_pair_dir

    out, pairs = made(tmp_path_factory, "drift", 2, {**KW, "odometry": "pioneer3dx"})
    assert json.loads((out / "dataset.json").read_text())["settings"]["odometry"] == "pioneer3dx"
    still_out, still = made(tmp_path_factory, "still", 2, {**KW, "odometry": "0"})
    for p, q in zip(pairs, still, strict=True):
        theta, tx, ty = p.extra["current_transform"]
        current = Rigid2D(theta, (tx, ty))
        assert not current.allclose(p.transform, atol=1e-3)  # the maps drifted apart
        assert len(p.extra["current_places"]) == 2
        theta, tx, ty = q.extra["current_transform"]
        assert Rigid2D(theta, (tx, ty)).allclose(q.transform, atol=1e-9)
    start, now = load_pair_dir(out), load_pair_dir(out, truth="current")
    for p, a, b in zip(pairs, start, now, strict=True):
        assert a.transform.allclose(p.transform, atol=0.0)
        assert b.transform.allclose(Rigid2D(p.extra["current_transform"][0],
                                            p.extra["current_transform"][1:]), atol=1e-12)
    with pytest.raises(ValueError, match=r"truth must be one of \['start', 'current'\], got 'x'"):
        load_pair_dir(out, truth="x")
    # both robots' trajectories, as mapped and as driven, from the start to the snapshot
    for p, q, e in zip(pairs, still, start, strict=True):
        rows = np.array(p.extra["trajectory_a"])
        # the start, every TRAJECTORY_EVERY steps, and each snapshot so far
        assert rows.shape[1] == 6
        assert 1 + p.step // TRAJECTORY_EVERY <= len(rows) <= 1 + p.step // TRAJECTORY_EVERY + 2
        assert rows[0].tolist() == [0.0] * 6
        assert len(p.extra["trajectory_b"]) == len(rows)
        assert not np.allclose(rows[:, :3], rows[:, 3:], atol=1e-3)  # odometry drifted
        still_rows = np.array(q.extra["trajectory_b"])
        assert np.allclose(still_rows[:, :3], still_rows[:, 3:], atol=1e-9)
        # the truth's merge of bent maps is no better than the best rigid one
        traj = e.trajectories
        assert traj.floor() <= traj.ate(p.transform) + 1e-12
        assert traj.ate(traj.best_merge()) == pytest.approx(traj.floor(), abs=1e-9)
    # the evaluation judges each merge found by the fused map it makes
    records = evaluate(start, ["grid"], progress=False)
    assert records and all(r.ate_m is not None and r.ate_floor_m <= r.ate_m + 1e-9
                           for r in records if r.rotation_error_deg is not None)
    for q, e in zip(still, load_pair_dir(still_out), strict=True):  # no drift: exact
        assert e.trajectories.ate(q.transform) < 1e-6
        assert e.trajectories.floor() < 1e-6
    # a perfect-odometry dataset stores no second truth: "current" reads the start frames'
    ref_out, ref_pairs = reference
    assert "current_transform" not in ref_pairs[0].extra
    assert "trajectory_a" not in ref_pairs[0].extra
    assert load_pair_dir(ref_out)[0].trajectories is None
    for p, e in zip(ref_pairs, load_pair_dir(ref_out, truth="current"), strict=True):
        assert e.transform.allclose(p.transform, atol=0.0)
