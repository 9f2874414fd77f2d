"""python -m fusion.evaluation: a bad argument is one line on stderr, exit status 2, nothing
written."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from fusion.evaluation.evaluate import main

ROOT = Path(__file__).parents[2]


def one_line_error(capsys, argv: list[str]) -> str:
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    out = capsys.readouterr()
    assert out.err.count("\n") == 1 and "Traceback" not in out.err and "usage:" not in out.err
    assert out.err.startswith("python -m fusion.evaluation: error: ")
    return out.err


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        ([], "give either PAIRS_DIR or --synthetic N (exactly one)"),
        (["--synthetic", "x"], "argument --synthetic: invalid int value: 'x'"),
        (["--synthetic", "0"], "--synthetic must be >= 1, got 0"),
        (["--synthetic", "2", "--noise", "a,b"],
         "--noise must be comma-separated numbers (metres), got 'a,b'"),
        (["--synthetic", "2", "--bogus"], "unrecognized arguments: --bogus"),
        (["--synthetic", "2", "--config", "[1]"], "--config must be a JSON object, got '[1]'"),
        (["--synthetic", "2", "--methods", "auto,icp"], "got ['icp']"),
    ],
)
def test_bad_arguments_are_one_line(tmp_path, capsys, flags, message):
    err = one_line_error(capsys, [*flags, "--out", str(tmp_path / "eval")])
    assert message in err
    assert list(tmp_path.iterdir()) == []  # the run could not start: no folder left


def test_out_that_is_a_file_is_refused_before_evaluating(tmp_path, capsys):
    (tmp_path / "results").write_text("mine")
    err = one_line_error(capsys, ["--synthetic", "2", "--out", str(tmp_path / "results")])
    assert f"--out: {tmp_path / 'results'} is a file, not a folder" in err


def test_a_stray_pair_file_is_one_line_naming_it(tmp_path, capsys):
    data = tmp_path / "d"
    (data / "pairs").mkdir(parents=True)
    (data / "dataset.json").write_text(json.dumps(
        {"format": "topomerge.map_pairs", "version": 1, "settings": {}, "pairs": 1}))
    (data / "pairs" / "pair_000003.npz").write_bytes(b"")
    err = one_line_error(capsys, [str(data), "--out", str(tmp_path / "eval")])
    assert "pair_000003.npz: a stray file: this dataset holds pairs 0–0" in err
    assert not (tmp_path / "eval").exists()


def test_the_command_line_prints_no_traceback():
    run = subprocess.run([sys.executable, "-m", "fusion.evaluation", "--synthetic", "2",
                          "--noise", "x"], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert run.returncode == 2
    assert run.stderr == ("python -m fusion.evaluation: error: --noise must be "
                          "comma-separated numbers (metres), got 'x'\n")
