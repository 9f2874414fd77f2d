"""The ``topomerge`` command: help everywhere, dispatch to the existing command-line tools."""

import json
import subprocess
import sys

import pytest

from agents import commands
from agents.commands import COMMANDS, main

HELP_ARGS = {
    "demo": ["--help"],
    "dataset": ["--help"],
    "evaluate": ["--help"],
    "calibrate": ["--help"],
    "train": ["--help"],
    "bench": ["--help"],
}


def test_top_level_help_lists_every_command(capsys):
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    for name in ("demo", "dataset", "evaluate", "merge", "train", "bench"):
        assert f"  {name} " in out


def test_no_command_prints_help_and_fails(capsys):
    assert main([]) == 2
    assert "commands:" in capsys.readouterr().out


def test_unknown_command_names_the_valid_ones(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["explore"])
    assert exit_.value.code == 2
    assert "unknown command 'explore'; choose from demo, dataset" in capsys.readouterr().err


@pytest.mark.parametrize("name", sorted(HELP_ARGS))
def test_subcommand_help(name, capsys):
    try:
        status = main([name, *HELP_ARGS[name]])
    except SystemExit as exit_:  # argparse and tyro exit after printing help
        status = exit_.code
    assert status in (0, None)
    assert "usage" in capsys.readouterr().out.lower()


def test_dataset_subcommand_help():
    with pytest.raises(SystemExit) as exit_:
        main(["dataset", "generate", "--help"])
    assert exit_.value.code == 0


def test_merge_dispatches_to_the_map_merge_tool_under_its_own_name(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["merge", "--help"])
    assert exit_.value.code == 0
    assert "usage: topomerge merge" in capsys.readouterr().out
    (tmp_path / "notes.txt").write_text("not a map")
    assert main(["merge", str(tmp_path / "notes.txt"), str(tmp_path / "notes.txt"),
                 "--out", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err.startswith("topomerge merge: error: ")


def test_bench_refuses_an_unknown_script(capsys):
    assert main(["bench", "nope"]) == 2
    assert "unknown benchmark 'nope'; choose from" in capsys.readouterr().err
    assert "env_speed" in commands.bench_scripts()


def test_demo_refuses_an_unknown_stage():
    with pytest.raises(SystemExit) as exit_:
        main(["demo", "--only", "paper,nope"])
    assert exit_.value.code == 2


def test_dispatches_a_real_command(tmp_path):
    """``topomerge evaluate --synthetic`` runs the evaluation harness and writes its results."""
    out = tmp_path / "eval"
    assert main(["evaluate", "--synthetic", "3", "--methods", "paper_icp", "--out", str(out)]) == 0
    assert any(out.iterdir())


def test_demo_stage_runs_and_summarises(tmp_path, capsys):
    """The paper's example stage: its output goes to a log, the summary keeps the key rows."""
    assert main(["demo", "--out", str(tmp_path), "--only", "paper"]) == 0
    out = capsys.readouterr().out
    assert "ICP-SVD (paper's init)" in out and "rot err" in out
    assert len(out.splitlines()) <= 12
    assert (tmp_path / "logs" / "paper.log").stat().st_size > 0
    assert (tmp_path / "paper_fig8_merged.png").is_file()
    assert json.loads((tmp_path / "logs" / "summary.json").read_text())["stages"] == ["paper"]


def test_demo_can_run_again_over_its_own_output(tmp_path):
    """``make demo`` twice: the stages that would refuse an existing output replace the
    demo's own (the PPO run folder by ``--overwrite``; the pairs folder is cleared)."""
    from agents.commands import demo_stages

    train = next(s for s in demo_stages() if s.name == "train")
    argv = train.argv(tmp_path, 64)
    assert "--overwrite" in argv and argv[argv.index("--run-name") + 1] == "demo"


def test_python_m_form_works():
    done = subprocess.run([sys.executable, "-m", "agents.commands", "--help"],
                          capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 0 and "topomerge" in done.stdout
    assert all(f"  {name} " in done.stdout for name in COMMANDS)
