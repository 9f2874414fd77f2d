"""The options that took over folded scripts: ``explorers.py --only speed|heldout`` and
``--compare`` (were ``explorer_speed.py``, ``explorers_heldout.py``) and ``env_speed.py
--copies`` (was ``copy_speed.py``) run their tables and refuse what does not fit. What they
measure is read from their tables, not tested."""

import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))  # the scripts and their helpers, as when run

import env_speed  # noqa: E402
import explorers  # noqa: E402


def test_explorers_refuses_what_does_not_fit(capsys):
    with pytest.raises(SystemExit):
        explorers.main(["--only", "heldout"])
    assert "--only heldout needs --out FILE" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        explorers.main(["--only", "metrics", "--explorers", "frontier@known"])
    assert "--explorers of the metrics table must be among" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        explorers.main(["--only", "speed", "--sizes", "20", "40", "--steps", "1", "2", "3"])
    assert "--steps must give one value or one per size (2), got 3" in capsys.readouterr().err


def test_explorers_compare_pairs_worlds_of_two_row_files(tmp_path, capsys):
    def rows(t85):
        return {f"frontier|w{i}": {"T85": t, "T95": t + 100, "seconds": 1.0}
                for i, t in enumerate(t85)}

    before, after = tmp_path / "before.json", tmp_path / "after.json"
    before.write_text(json.dumps(rows([100, 200, 300])))
    after.write_text(json.dumps({**rows([90, 200, 330]), "frontier|only_after": {
        "T85": 1, "T95": 1, "seconds": 1.0}}))
    explorers.main(["--compare", str(before), str(after)])
    text = capsys.readouterr().out
    assert "| frontier | 3 | T85 | 200 | 200 |" in text and "| 1 / 1 / 1 |" in text


def test_env_speed_copies_prints_the_copy_table_only(capsys):
    env_speed.main(["--copies", "20", "--repeats", "1"])
    text = capsys.readouterr().out
    assert "| defaults | 20 |" in text and "| no topo/merge | 20 |" in text
    assert "## Defaults" not in text
