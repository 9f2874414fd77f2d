"""Refit the merges' calibrated models and score weights on tuning pairs::

    python -m fusion.calibration fit --model grid|structural|ranking [--pairs DIR ...]
        [--data data/env_pairs] [--drift] [--extend] [--synthetic N] [--cache FILE]
        [--write] [--table FILE] [--plot PNG] [--held-out DIR ...]
    python -m fusion.calibration fit --model grid_real --rows FILE [FILE ...] [--split dev]
        [--free] [--write]
    python -m fusion.calibration fit --model window_near --rows FILE [FILE ...] [--split dev]
        [--write]

Run it from the repository root after ``benchmarks/env_pairs.py`` has made the tuning pairs
(``make calibrate`` chains both), whenever what the models read changes: the topological map
extraction, the occupancy grids, the structural search or the grid alignment's evidence.

``--model ranking`` refits the structural search's score weights
(:data:`fusion.structural.CONFIDENCE_WEIGHTS`, stored as weights ``"ranking"``);
``--model structural`` the structural merge's confidence (it reads the score: refit it after
the ranking); ``--model grid`` the grid alignment's confidence (``--extend``: keep the stored
noise-free weights and fit only the drift terms, with ``--drift`` adding the drift-aware sets).
``--model grid_real`` the grid alignment's confidence on real sensor maps
(:data:`fusion.decision.REAL_MAP_MODEL`: the stored grid model recalibrated,
:func:`fusion.calibration.fit.recalibrated`) from the rows ``benchmarks/real_maps.py`` wrote
(``--rows``: JSON lines or a JSON list, any rows of the ``"grid"`` features; ``--split``
keeps those of one split; env rows from ``--cache`` may be added to fit both together),
cross-validated leaving one building out (``--free``: its weights fitted freely instead).
``--model window_near`` the confidence of the pose graph's near window searches from the rows
``benchmarks/bending_in_loop.py --rows`` wrote, cross-validated leaving one world out.
Each prints the cross-validated calibration, the threshold table and the threshold rule's
choice; ``--write`` stores the model (with the date, commit and data) in
``fusion/calibration.json`` (or ``--table``). ``--cache`` keeps the rows (a JSON file, read
back if it exists) so that a refit with other settings does not re-run the merges.
"""

from __future__ import annotations

import argparse
import datetime
import json
import sys
import time
from pathlib import Path

from fusion.calibration import load_model, plot_reliability, write_model, write_weights
from fusion.calibration.fit import (
    L2,
    MODELS,
    commit,
    fit_model,
    fit_ranking,
    matrix,
    noise_free_base,
)
from fusion.calibration.report import held_out_report, print_fit, print_ranking
from fusion.calibration.rows import DATA, collect, default_dirs
from fusion.decision import DEFAULT_RULE
from topo.fileio import atomic_write_json, read_json_lines

SCRIPT = "python -m fusion.calibration fit"


def parser() -> argparse.ArgumentParser:
    """The command line (``fit`` and its options)."""
    out = argparse.ArgumentParser(prog="python -m fusion.calibration",
                                  description=__doc__.split("\n\n")[0])
    sub = out.add_subparsers(dest="command", required=True)
    fit = sub.add_parser("fit", help="refit a model on tuning pairs and report it")
    fit.add_argument("--model", choices=[*MODELS, "ranking"], default="grid")
    fit.add_argument("--pairs", type=Path, nargs="*", default=None,
                     help="tuning dataset folders (default: those of DATA/tune)")
    fit.add_argument("--data", type=Path, default=DATA,
                     help="where benchmarks/env_pairs.py wrote the pairs")
    fit.add_argument("--drift", action="store_true",
                     help="add the drift-aware sets of DATA/drift/tune")
    fit.add_argument("--synthetic", type=int, default=150,
                     help="synthetic tuning pairs per noise level (structural, ranking)")
    fit.add_argument("--cache", type=Path, default=None,
                     help="JSON file of the rows (read if it exists, else written)")
    fit.add_argument("--rows", type=Path, nargs="*", default=(),
                     help="rows files (JSON lines or a JSON list) to fit on, besides --cache "
                          "(grid_real: benchmarks/real_maps.py's OUT/grid.jsonl; window_near: "
                          "benchmarks/bending_in_loop.py --rows)")
    fit.add_argument("--split", default=None,
                     help="keep only the --rows whose 'split' is this (e.g. dev)")
    fit.add_argument("--free", action="store_true",
                     help="grid_real: fit its weights freely on the rows (a comparison: by "
                          "default the grid model is recalibrated)")
    fit.add_argument("--l2", type=float, default=L2, help="ridge penalty")
    fit.add_argument("--extend", action="store_true",
                     help="grid: keep the stored model's noise-free weights and fit only the "
                          "drift terms on top")
    fit.add_argument("--write", action="store_true",
                     help="store the fitted model in the calibration table")
    fit.add_argument("--table", type=Path, default=None,
                     help="the calibration table --write stores into (default: the "
                          "package's fusion/calibration.json)")
    fit.add_argument("--plot", type=Path, default=None,
                     help="write the cross-validated reliability diagram to this PNG")
    fit.add_argument("--held-out", type=Path, nargs="*", default=(),
                     help="grid: report the stored and the fitted model on these folders "
                          "(their rows cached next to --cache)")
    return out


def read_rows(path: Path) -> list[dict]:
    """The rows of ``--rows`` file ``path`` (JSON lines or a JSON list).

    Raises:
        ValueError: a missing file (named).
    """
    if not path.is_file():
        raise ValueError(f"--rows: {path} not found")
    return read_json_lines(path)


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    cli = parser()
    args = cli.parse_args(argv)
    if args.extend and args.model != "grid":
        cli.error("--extend extends the grid model only")
    if args.held_out and args.model != "grid":
        cli.error("--held-out reports the grid model only")
    if args.free and args.model != "grid_real":
        cli.error("--free refits grid_real only")
    if args.model == "grid_real" and not args.rows:
        cli.error("--model grid_real fits on --rows (benchmarks/real_maps.py's grid.jsonl)")
    if args.model == "window_near" and not args.rows:
        cli.error("--model window_near fits on --rows (benchmarks/bending_in_loop.py --rows)")
    dirs = list(args.pairs or default_dirs(args.data))
    if args.drift:
        dirs += default_dirs(args.data / "drift")
    try:
        extra = [r for path in args.rows for r in read_rows(path)
                 if args.split is None or r.get("split") == args.split]
    except ValueError as exc:
        cli.error(str(exc))
    if args.model == "window_near":
        rows = []
    elif args.model == "grid_real":
        rows = json.loads(args.cache.read_text()) if args.cache is not None else []
    elif args.cache is not None and args.cache.exists():
        rows = json.loads(args.cache.read_text())
    else:
        if not dirs and (args.model == "grid" or not args.synthetic):
            cli.error(f"no tuning pairs: none in {args.data / 'tune'} (make them with "
                      f"benchmarks/env_pairs.py) and none given with --pairs")
        t0 = time.perf_counter()
        rows = collect(args.model, dirs, args.synthetic)
        print(f"{len(rows)} rows in {time.perf_counter() - t0:.0f} s")
        if args.cache is not None:
            atomic_write_json(args.cache, rows)
    rows = rows + extra
    if args.model == "ranking":
        from fusion.structural import CONFIDENCE_WEIGHTS

        weights = fit_ranking(rows, list(CONFIDENCE_WEIGHTS), args.l2)
        print_ranking(rows, CONFIDENCE_WEIGHTS, weights)
        if args.write:
            meta = {"fitted": datetime.date.today().isoformat(), "commit": commit(),
                    "data": sorted({r["set"] for r in rows}), "candidates": len(rows),
                    "l2": args.l2, "script": f"{SCRIPT} --model ranking"}
            print(f"wrote {write_weights('ranking', weights, args.table, meta)}")
        return 0
    base = noise_free_base(load_model("grid")) if args.extend else None
    # grid_real rescales the grid model the table holds now (fit.recalibrated)
    scaled = load_model("grid") if args.model == "grid_real" and not args.free else None
    min_overlap = DEFAULT_RULE.min_overlap_m2 if args.model.startswith("grid") else 0.0
    script = f"{SCRIPT} --model {args.model}" + "".join(f" --rows {p}" for p in args.rows) + (
        f" --split {args.split}" if args.split else "") + (" --free" if args.free else "")
    fit = fit_model(args.model, rows, l2=args.l2, extend=base, min_overlap_m2=min_overlap,
                    script=script, recalibrate=scaled)
    print_fit(args.model, fit)
    if args.plot is not None:
        _, y = matrix(fit.rows, fit.model.names)
        out = plot_reliability({f"{args.model} (cross-validated)": (fit.cross_validated, y)},
                               args.plot, title=f"{args.model} model, leave-one-world-out on "
                                                f"the tuning pairs")
        print(f"wrote {out}")
    if args.held_out:
        held_out_report(args.held_out, fit.model, args.cache)
    if args.write:
        print(f"wrote {write_model(args.model, fit.model, args.table)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
