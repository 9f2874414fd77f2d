"""Every benchmark and example script starts: ``--help`` parses and exits 0 (so a rename or a
moved import breaks a test, not the next person to run the script). What they measure is not
tested here: speed is read from their tables (CONTRIBUTING)."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPTS = sorted(str(p.relative_to(ROOT)) for folder in ("benchmarks", "examples")
                 for p in (ROOT / folder).glob("[a-z]*.py"))


def test_the_scripts_are_found():
    assert "benchmarks/env_speed.py" in SCRIPTS and "examples/paper_example.py" in SCRIPTS


@pytest.mark.parametrize("script", SCRIPTS)
def test_script_help(script):
    env = {**os.environ, "PYTHONPATH": str(ROOT), "SDL_VIDEODRIVER": "dummy"}
    done = subprocess.run([sys.executable, script, "--help"], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.startswith("usage:"), done.stdout[:500]
