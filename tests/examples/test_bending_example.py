"""Maps that bend (``make demo``'s sixth stage, ``examples/bending.py``) runs, prints what the
demo's summary keeps and writes its figure."""

import importlib.util
from pathlib import Path

import pytest

from agents.commands import _bending_summary

ROOT = Path(__file__).resolve().parents[2]


def test_bending_example_writes_the_figure_and_summarises(tmp_path, capsys):
    pytest.importorskip("gtsam")
    spec = importlib.util.spec_from_file_location("bending", ROOT / "examples" / "bending.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.main(["--out", str(tmp_path), "--steps", "150"])  # too short to merge: robot 0 alone
    out = capsys.readouterr().out
    assert "150 steps" in out and "robots [0] never merged" in out
    data = (tmp_path / "bending.png").read_bytes()
    assert data.startswith(b"\x89PNG") and len(data) > 10_000
    lines = _bending_summary(tmp_path, out)
    assert len(lines) == 5 and lines[0].startswith("maps that bend, seed 102")
    assert "map as scanned  ATE" in lines[1] and "working map           ATE" in lines[2]
    assert "fused map             ATE" in lines[3]
    assert lines[4] == f"figure: {tmp_path / 'bending.png'}"
