"""The real maps the explorer benchmarks run on, shared by ``explorers.py`` and
``training_eval.py`` so that both mean the same four worlds."""

from __future__ import annotations

from pathlib import Path
from typing import Any

MAPS = (Path(__file__).resolve().parents[2] / "shared" / "maps").resolve()
"""``shared/maps`` beside the repository (resolved, so that paths built from it are the same
from any checkout or symlink)."""

REAL_MAX_CYCLES = 2000
"""Episode length on a real map."""


def real_worlds() -> list[tuple[str, dict[str, Any]]]:
    """``(world id, env world config)`` of the ROS maps and DungeonMaps 1 (0.05 m/pixel), those
    present under :data:`MAPS`."""
    out = [(f"ros/{path.stem}", {"source": str(path)})
           for path in sorted((MAPS / "ros").glob("*.yaml"))]
    png = MAPS / "dungeon" / "1.png"
    if png.exists():
        out.append(("dungeon/1", {"source": str(png), "png_resolution": 0.05}))
    return out
