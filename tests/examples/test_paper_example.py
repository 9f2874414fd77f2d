"""The paper's example (``make demo``'s first step) runs end to end and writes both figures."""

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def load(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "examples" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_paper_example_writes_figures(tmp_path, capsys):
    load("paper_example").main(tmp_path)
    out = capsys.readouterr().out
    assert "5068 fusions" in out and "2 distinct optima" in out
    for name in ("paper_fig8_merged.png", "paper_fig9_convergence.png"):
        data = (tmp_path / name).read_bytes()
        assert data.startswith(b"\x89PNG") and len(data) > 10_000
    assert not list(tmp_path.glob(".*"))  # no temp files left behind
