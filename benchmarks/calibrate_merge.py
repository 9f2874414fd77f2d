"""Moved into the package: ``python -m fusion.calibration fit`` (:mod:`fusion.calibration`'s
``__main__``; ``make calibrate`` runs the whole refit). This wrapper keeps the old command::

    python benchmarks/calibrate_merge.py [--model grid|structural|ranking] [options of fit]

(the same options, the pairs read from this checkout's ``data/env_pairs`` wherever it is run)
and the names other benchmarks import (``default_dirs``, ``structural_rows``).
"""

from __future__ import annotations

import sys
from pathlib import Path

from fusion.calibration.__main__ import main as _fit_main
from fusion.calibration.rows import alignment_rows, ranking_rows, structural_rows
from fusion.calibration.rows import default_dirs as _default_dirs

DATA = Path(__file__).resolve().parents[1] / "data" / "env_pairs"
"""This checkout's env pairs (``benchmarks/env_pairs.py --out data/env_pairs``)."""

__all__ = ["DATA", "alignment_rows", "default_dirs", "main", "ranking_rows", "structural_rows"]


def default_dirs() -> list[Path]:
    """The tuning dataset folders of :data:`DATA` (``data/env_pairs/tune``)."""
    return _default_dirs(DATA)


def main(argv: list[str] | None = None) -> int:
    """``python -m fusion.calibration fit`` with ``argv`` (``--data`` :data:`DATA` unless
    given)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if not any(a == "--data" or a.startswith("--data=") for a in argv):
        argv = ["--data", str(DATA), *argv]
    return _fit_main(["fit", *argv])


if __name__ == "__main__":
    sys.exit(main())
