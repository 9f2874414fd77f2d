"""Evaluate map merging against ground truth and an oracle: ``python -m fusion.evaluation``.

    python -m fusion.evaluation --synthetic 200 --methods auto,paper_icp,exhaustive,multistart_icp
    python -m fusion.evaluation PAIRS_DIR [PAIRS_DIR ...] --methods hybrid,grid,auto --out out/eval

For every pair and method it records whether the merge was accepted, the rotation error and the
translation error (distance between the true and the estimated position of B's centroid in A's
frame: ``‖ΔT‖`` alone depends on B's arbitrary origin), and the wall time. A merge **succeeds**
when it is accepted with rotation error < 2° and translation error < 0.3 m. The **oracle** is the
SVD fit on the true node correspondences (always "accepted"): the ceiling any point-based
estimate can reach — noise, dropped nodes and the thresholds cap it below 100%. On pairs without
overlap, any accepted merge is a **false accept**.

Printed: per noise level, success per overlap bin (with the oracle), then per method the success
on pairs with ≥ 40% overlap, median errors, median time and false-accept rate, and success per
true-rotation bin (where the paper's ICP, which starts from ``R = I``, fails). For every method
whose results carry a confidence (``hybrid``, ``grid``, and the structural methods through their
evidence), the **threshold sweep**: success on ≥ 40 % overlap, wrong accepts (accepted and not
right, % of all pairs) and false accepts (% of no-overlap pairs) as the accept threshold
moves (``*`` marks the default, :data:`fusion.grid_merge.DEFAULT_ACCEPT_THRESHOLD`), and the
**calibration**: per confidence bin, the mean confidence against the observed fraction of
right transforms (accepted or not), with the Brier score. Written to ``--out``:
``results.json`` (every record, the summary, the sweep and the calibration),
``error_cdf.png``, ``success_vs_overlap.png``, ``success_vs_rotation.png``,
``threshold_curves.png`` (success against wrong accepts, one curve per method),
``calibration.png`` (the reliability diagram) and ``merged_*.png`` pictures.

Pairs come from :func:`fusion.evaluation.synthetic.generate_pairs` (``--synthetic N``, once per
``--noise``
level, with the true correspondences so the oracle can be computed) or from a map-pair dataset
folder or several evaluated as one set (:func:`load_pair_dir`; the :mod:`fusion.evaluation.pairs`
format that ``agents.dataset`` writes: it stores no node correspondences, so the oracle column
is empty; ``--truth current`` judges pairs made with drifting odometry at the robots' current
places). Pairs made with drifting odometry also hold both robots' trajectories: each merge's
record then has the ATE of the fused map it makes and the floor no rigid merge beats on those
bent maps (:class:`fusion.evaluation.bending.PairTrajectories`), and the summary a table of
both.

The pair and record types, the success criteria and the summaries are
:mod:`fusion.evaluation.results`.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from fusion.evaluation.bending import PairTrajectories
from fusion.evaluation.results import (
    ORACLE,
    OVERLAP_BINS,
    ROTATION_BINS_DEG,
    ROTATION_OK_DEG,
    TRANSLATION_OK_M,
    EvalPair,
    Record,
    calibration_summary,
    format_tables,
    format_threshold_tables,
    is_right,
    is_success,
    oracle_transform,
    success_rate,
    summarise,
    threshold_sweep,
    transform_errors,
    with_confidence,
    within_bin,
)
from fusion.evaluation.synthetic import SyntheticConfig, generate_pairs
from fusion.rigid import Rigid2D
from fusion.search import DEFAULT_MAX_EVALUATIONS, too_many_evaluations
from fusion.structural import METHODS, MergeConfig, merge_maps
from topo.fileio import atomic_write_json
from topo.graph import TopoMap
from topo.validation import config_from


# ----------------------------------------------------------------------------------- pairs
def synthetic_pairs(n: int, seed: int = 0, noise_levels: Sequence[float] = (0.05, 0.15, 0.3),
                    config: SyntheticConfig | dict | None = None) -> list[EvalPair]:
    """``n`` pairs of :func:`fusion.evaluation.synthetic.generate_pairs` per noise level (the same
    worlds
    and regions at every level: only the noise differs)."""
    base = config_from(SyntheticConfig, config, "config")
    out = []
    for noise in noise_levels:
        cfg = config_from(SyntheticConfig, {**asdict(base), "noise": float(noise)}, "config")
        for p in generate_pairs(n, seed, cfg):
            out.append(EvalPair(f"synthetic/s{noise:g}/{p.index}", p.map_a, p.map_b,
                                None if p.kind == "other_world" else p.transform,
                                p.correspondences, p.overlap, p.kind, float(noise)))
    return out


TRUTHS = ("start", "current")
"""What a dataset pair's merge is judged against: the start-frame truth, or (drifting
odometry) the truth at the robots' current places."""


def load_pair_dir(path: str | Path, truth: str = "start") -> list[EvalPair]:
    """The pairs of a map-pair dataset folder (:func:`fusion.evaluation.pairs.load_pairs`, the
    format ``agents.dataset`` writes). Pairs with zero overlap count as no-overlap pairs.
    ``truth``: ``"start"`` judges merges against the pair's transform (the robots' start
    frames); ``"current"`` against the transform right at the robots' current places where a
    pair has one (``extra["current_transform"]``, datasets made with drifting odometry; the
    two are the same without drift). Why: a bent map has no one rigid truth.

    Raises:
        FileNotFoundError: ``path`` is not a folder.
        ValueError: ``truth`` is not one of :data:`TRUTHS`.
        fusion.evaluation.pairs.DatasetError: a missing manifest, foreign or corrupt file (named).
    """
    if truth not in TRUTHS:
        raise ValueError(f"truth must be one of {list(TRUTHS)}, got {truth!r}")
    path = Path(path)
    if not path.is_dir():
        raise FileNotFoundError(f"PAIRS_DIR {str(path)!r} is not a folder")
    from fusion.evaluation.pairs import load_pairs

    out = []
    for p in load_pairs(path):
        kind = "overlap" if p.overlap > 0 else "no_overlap"
        transform = p.transform
        extra = p.extra or {}
        current = extra.get("current_transform")
        if truth == "current" and current is not None:
            transform = Rigid2D(float(current[0]), (float(current[1]), float(current[2])))
        out.append(EvalPair(f"pair_{p.pair_id:06d}", p.map_a, p.map_b, transform, None,
                            float(p.overlap), kind, None, (p.grid_a, p.grid_b),
                            _trajectories(p)))
    return out


def _trajectories(pair: Any) -> PairTrajectories | None:
    """A dataset pair's trajectories (``extra["trajectory_a"]`` / ``["trajectory_b"]``,
    written with drifting odometry), ``None`` without them.

    Raises:
        fusion.evaluation.pairs.DatasetError: malformed trajectories (names the pair)."""
    extra = pair.extra or {}
    if "trajectory_a" not in extra or "trajectory_b" not in extra:
        return None
    from fusion.evaluation.pairs import DatasetError

    try:
        return PairTrajectories.from_start_frames(extra["trajectory_a"], extra["trajectory_b"],
                                                  pair.transform)
    except (TypeError, ValueError) as exc:
        raise DatasetError(f"pair {pair.pair_id}: extra trajectory_a / trajectory_b: {exc}"
                           ) from None


# ------------------------------------------------------------------------------ evaluation
def _record(pair: EvalPair, method: str, transform: Rigid2D | None, accepted: bool,
            time_s: float, score: float | None, reason: str | None,
            confidence: float | None = None, gated: bool = True) -> Record:
    errors = transform_errors(transform, pair) if transform is not None else None
    good = pair.kind == "overlap" and is_success(errors)
    bent = pair.trajectories is not None and transform is not None
    return Record(
        pair.name, method, pair.kind, pair.overlap, pair.noise,
        None if pair.transform is None else pair.transform.degrees, bool(accepted),
        None if errors is None else errors[0], None if errors is None else errors[1],
        bool(accepted and good), float(time_s), score, reason, pair.map_a.n_nodes,
        pair.map_b.n_nodes, confidence, bool(gated),
        pair.trajectories.ate(transform) if bent else None,
        pair.trajectories.floor() if bent else None)


def _confidence(result: Any) -> tuple[float | None, bool]:
    """A merge result's confidence (``None`` if it has none) and whether it passed the
    method's hard gates (accepted at any threshold it would be: the grid alignment's
    ``min_overlap_m2``; structural merges have none here)."""
    conf = getattr(result, "confidence", None)
    if conf is None and getattr(result, "evidence", None) is not None:
        conf = result.evidence.confidence
    grid = result if hasattr(result, "overlap_m2") else getattr(result, "grid", None)
    gated = True
    if grid is not None:
        from fusion.grid_merge import GridMergeConfig

        gated = bool(grid.overlap_m2 >= GridMergeConfig().min_overlap_m2)
    elif getattr(result, "method", None) == "hybrid":
        gated = bool(result.accepted)
    return (None if conf is None or math.isnan(conf) else float(conf)), gated


def evaluate(pairs: Sequence[EvalPair], methods: Sequence[str],
             config: MergeConfig | dict | None = None, progress: bool = True,
             for_noise: bool = False) -> list[Record]:
    """Run every method (and the oracle, where correspondences are known) on every pair.

    With ``for_noise``, each pair with a known noise level is merged with
    :meth:`MergeConfig.for_noise` of that level (``config``, a dict, overriding its fields).

    Raises:
        ValueError: unknown methods; or ``"exhaustive"`` on pairs too large for the paper's
            search (:func:`check_exhaustive`), before anything runs.
    """
    methods = parse_methods(methods)
    config_of = _config_of(config, for_noise)
    if "exhaustive" in methods:
        check_exhaustive(pairs, config, for_noise)
    from tqdm import tqdm

    records = []
    bar = tqdm(total=len(pairs) * len(methods), unit="merge", disable=not progress,
               desc="merging", file=sys.stderr)
    for pair in pairs:
        oracle = oracle_transform(pair)
        if pair.correspondences is not None:
            records.append(_record(pair, ORACLE, oracle, oracle is not None, 0.0, None,
                                   None if oracle is not None else "fewer than 2 true pairs"))
        cfg = config_of(pair)
        for method in methods:
            if method in GRID_METHODS:
                r = _grid_method(pair, method)
            else:
                r = merge_maps(pair.map_a, pair.map_b, method=method, config=cfg)
            records.append(_record(pair, method, r.transform, r.accepted, r.time_s, r.score,
                                   r.reason, *_confidence(r)))
            bar.update()
    bar.close()
    return records


def _search_points(m: TopoMap) -> int:
    """How many points ``merge_maps(method="exhaustive")`` searches over for map ``m``: its
    path endpoints, or all its nodes when it has no paths."""
    return len(m.endpoints()) or m.n_nodes


def _config_of(config: MergeConfig | dict | None,
               for_noise: bool) -> Callable[[EvalPair], MergeConfig]:
    """The merge config of each pair, as :func:`evaluate` documents it."""
    base = config_from(MergeConfig, config, "config")
    overrides = config if isinstance(config, dict) else {}

    def config_of(pair: EvalPair) -> MergeConfig:
        if for_noise and pair.noise is not None:
            return MergeConfig.for_noise(pair.noise, **overrides)
        return base
    return config_of


def check_exhaustive(pairs: Sequence[EvalPair], config: MergeConfig | dict | None = None,
                     for_noise: bool = False) -> None:
    """Refuse, before any merge runs, pairs on which ``"exhaustive"`` would refuse (more than
    :data:`fusion.search.DEFAULT_MAX_EVALUATIONS` placements at the pair's
    ``exhaustive_step_deg``; ``config`` and ``for_noise`` as in :func:`evaluate`): otherwise the
    evaluation would stop there, possibly after minutes of the other methods.

    Raises:
        ValueError: naming how many pairs are too large, the largest, its count and estimated
            time, and the ``exhaustive_step_deg`` that fits it.
    """
    config_of = _config_of(config, for_noise)
    too_big = []
    for pair in pairs:
        if min(pair.map_a.n_nodes, pair.map_b.n_nodes) < 3:
            continue  # merge_maps does not search maps that small
        n_a, n_b = _search_points(pair.map_a), _search_points(pair.map_b)
        why = too_many_evaluations(n_a, n_b, config_of(pair).exhaustive_step_deg,
                                   DEFAULT_MAX_EVALUATIONS, step_name="exhaustive_step_deg")
        if why:
            too_big.append((n_a * n_b, pair.name, why))
    if too_big:
        _, name, why = max(too_big)
        raise ValueError(
            f"'exhaustive' (the paper's search) is too slow for {len(too_big)} of "
            f"{len(pairs)} pairs; the largest, {name}: {why}. Leave 'exhaustive' out of the "
            f"methods, or coarsen it with the config field exhaustive_step_deg")


GRID_METHODS = ("hybrid", "grid")
"""Methods that also use the pairs' occupancy grids (``fusion.grid_merge``): ``"hybrid"`` (the
env's default merge) and ``"grid"`` (grid alignment alone). Synthetic pairs have no grids."""


def _grid_method(pair: EvalPair, method: str) -> Any:
    from fusion.grid_merge import GridMergeResult, merge_grids
    from fusion.hybrid import hybrid_merge

    if pair.grids is None:
        return GridMergeResult(Rigid2D.identity(), False, math.nan, 0.0, 0.0, 0.0, 0.0, 0.0,
                               "no occupancy grids with this pair")
    if method == "grid":
        return merge_grids(*pair.grids)
    return hybrid_merge(pair.map_a, pair.map_b, *pair.grids)


def parse_methods(methods: str | Iterable[str]) -> list[str]:
    """``"auto,paper_icp"`` or a list of names → the list; unknown names are a ``ValueError``."""
    names = [m.strip() for m in methods.split(",")] if isinstance(methods, str) else list(methods)
    names = [m for m in names if m]
    allowed = list(METHODS) + list(GRID_METHODS)
    unknown = [m for m in names if m not in allowed]
    if unknown or not names:
        raise ValueError(f"methods must be a comma-separated list of {allowed}, "
                         f"got {unknown or names}")
    return list(dict.fromkeys(names))


# ---------------------------------------------------------------------------------- output
def plot_thresholds(sweep: dict[str, list[dict]], records: Sequence[Record], out: str | Path,
                    default: float | None = None) -> list[Path]:
    """``threshold_curves.png`` (success on ≥ 40 % overlap against wrong accepts of all
    pairs, one curve per method, thresholds labelled, the default ringed) and
    ``calibration.png`` (the reliability diagram of every method with confidences)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fusion.calibration import plot_reliability
    from topo.plotting import save_figure

    out = Path(out)
    files = []
    if sweep:
        fig, ax = plt.subplots(figsize=(6.5, 4.5))
        for m, table in sweep.items():
            x = [r["wrong_accepts"] for r in table]
            y = [np.nan if r["success_overlap_ge_40"] is None else r["success_overlap_ge_40"]
                 for r in table]
            ax.plot(x, y, marker=".", label=m)
            for r, xi, yi in zip(table, x, y, strict=True):
                if round(r["threshold"] * 20) % 4 == 2 or r["threshold"] == 0.99:
                    ax.annotate(f"{r['threshold']:g}", (xi, yi), fontsize=7,
                                textcoords="offset points", xytext=(3, 3))
                if default is not None and abs(r["threshold"] - default) < 1e-9:
                    ax.scatter([xi], [yi], s=90, facecolors="none", edgecolors="k", zorder=5)
        ax.axvline(1.0, color="k", ls=":", lw=1)
        ax.set_xlabel("wrong accepts (% of all pairs)")
        ax.set_ylabel("success on pairs with ≥ 40 % overlap (%)")
        ax.set_title("success against wrong accepts as accept_threshold moves"
                     + ("" if default is None else f" (ringed: default {default:g})"),
                     fontsize=9)
        ax.set_ylim(-2, 102)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        files.append(save_figure(fig, out / "threshold_curves.png"))
        plt.close(fig)
        curves = {m: ([r.confidence for r in rows], [float(is_right(r)) for r in rows])
                  for m, rows in with_confidence(records).items()}
        files.append(plot_reliability(curves, out / "calibration.png",
                                      title="calibration of the merge confidence"))
    return files


def plot_results(records: Sequence[Record], pairs: Sequence[EvalPair], out: str | Path,
                 config: MergeConfig | dict | None = None, pictures: int = 4) -> list[Path]:
    """Error CDFs, success vs overlap, success vs true rotation, and ``pictures`` merged maps
    (``auto`` on the first overlapping pairs of the lowest noise level). Returns the files."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from topo.plotting import equal_axes, plot_topomap, save_figure

    out = Path(out)
    methods = list(dict.fromkeys(r.method for r in records))
    overlap = [r for r in records if r.kind == "overlap"]
    files = []

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for ax, attr, label, limit in ((axes[0], "rotation_error_deg", "rotation error (°)",
                                    ROTATION_OK_DEG),
                                   (axes[1], "translation_error_m",
                                    "translation error at B's centroid (m)", TRANSLATION_OK_M)):
        for m in methods:
            v = np.sort([getattr(r, attr) for r in overlap
                         if r.method == m and getattr(r, attr) is not None])
            if len(v):
                ax.step(v, np.arange(1, len(v) + 1) / len(v), where="post", label=m)
        ax.axvline(limit, color="k", ls=":", lw=1)
        ax.set_xscale("log")
        ax.set_xlabel(f"{label}, overlapping pairs, all noise levels")
        ax.set_ylabel("fraction of pairs")
    axes[0].legend()
    files.append(save_figure(fig, out / "error_cdf.png"))
    plt.close(fig)

    for attr, edges, fname, xlabel in (
            ("overlap", OVERLAP_BINS, "success_vs_overlap.png", "overlap (all noise levels)"),
            ("rotation", ROTATION_BINS_DEG, "success_vs_rotation.png",
             "|true rotation| (°), overlap ≥ 40%, all noise levels")):
        fig, ax = plt.subplots(figsize=(6, 4))
        centres = 0.5 * (np.array(edges[:-1]) + np.array(edges[1:]))
        for m in methods:
            rates = []
            for i, (lo, hi) in enumerate(zip(edges[:-1], edges[1:], strict=True)):
                last = i == len(edges) - 2
                if attr == "overlap":
                    rows = [r for r in overlap if r.method == m
                            and within_bin(r.overlap, lo, hi, last)]
                else:
                    rows = [r for r in overlap if r.method == m and r.overlap >= 0.4
                            and within_bin(abs(r.true_rotation_deg), lo, hi, last)]
                rates.append(np.nan if not rows else success_rate(rows))
            ax.plot(centres, rates, marker="o", label=m, ls="--" if m == ORACLE else "-")
        ax.set_xlabel(xlabel)
        ax.set_ylabel("success rate (%)")
        ax.set_ylim(-2, 102)
        ax.legend()
        files.append(save_figure(fig, out / fname))
        plt.close(fig)

    cfg = config_from(MergeConfig, config, "config")
    lowest = min((p.noise for p in pairs if p.noise is not None), default=None)
    shown = [p for p in pairs if p.kind == "overlap" and p.noise == lowest
             and p.overlap >= 0.3][:pictures]
    for p in shown:
        r = merge_maps(p.map_a, p.map_b, config=cfg)
        fig, ax = plt.subplots(figsize=(6, 6))
        plot_topomap(ax, p.map_a, edge_colour="tab:blue", label="A")
        plot_topomap(ax, p.map_b.transformed(r.transform), edge_colour="tab:orange",
                     marker="s", label="B moved by auto")
        if p.transform is not None:
            truth = p.transform.apply(p.map_b.xy)
            ax.scatter(truth[:, 0], truth[:, 1], marker="x", c="k", s=20, label="B (truth)")
        err = transform_errors(r.transform, p)
        ax.set_title(f"{p.name}: overlap {p.overlap:.2f}, "
                     f"{'accepted' if r.accepted else 'rejected'}"
                     + (f", errors {err[0]:.2f}° {err[1]:.2f} m" if err else ""), fontsize=9)
        equal_axes(ax, np.vstack([p.map_a.xy, r.transform.apply(p.map_b.xy)]))
        ax.legend(fontsize=8)
        files.append(save_figure(fig, out / f"merged_{p.name.replace('/', '_')}.png"))
        plt.close(fig)
    return files


# -------------------------------------------------------------------------------------- CLI
class _OneLineParser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line, ``PROG: error: MESSAGE`` (exit
    status 2), without the usage block: what a script's log needs."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())}\n")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``python -m fusion.evaluation`` (one-line usage errors)."""
    p = _OneLineParser(
        prog="python -m fusion.evaluation",
        description="Evaluate topological map merging against ground truth and an oracle.")
    p.add_argument("pairs_dir", nargs="*", type=Path,
                   help="map-pair dataset folders (the agents' format; several are evaluated "
                        "as one set); or use --synthetic")
    p.add_argument("--synthetic", type=int, metavar="N",
                   help="evaluate N synthetic pairs per noise level instead of a folder")
    p.add_argument("--methods", default="auto,paper_icp,multistart_icp,exhaustive",
                   help="comma-separated methods among "
                        f"{', '.join(METHODS + GRID_METHODS)} (grid methods need a dataset)")
    p.add_argument("--noise", default="0.05,0.15,0.3",
                   help="node noise levels (m) of the synthetic pairs, comma-separated")
    p.add_argument("--seed", type=int, default=0, help="seed of the synthetic pairs")
    p.add_argument("--synthetic-config", default=None, metavar="JSON",
                   help="fusion.evaluation.synthetic.SyntheticConfig fields as a JSON object")
    p.add_argument("--config", default=None, metavar="JSON",
                   help="fusion.MergeConfig fields as a JSON object, e.g. '{\"eps\": 0.6}'")
    p.add_argument("--for-noise", action="store_true",
                   help="merge each synthetic noise level with MergeConfig.for_noise(level)")
    p.add_argument("--truth", choices=TRUTHS, default="start",
                   help="judge dataset merges against the start-frame truth or, for datasets "
                        "made with drifting odometry, the truth at the robots' current places")
    p.add_argument("--out", type=Path, default=Path("out/fusion_eval"),
                   help="output folder for results.json and the plots")
    p.add_argument("--no-plots", action="store_true", help="write results.json only")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def _json_arg(parser: argparse.ArgumentParser, text: str | None, name: str) -> dict | None:
    if text is None:
        return None
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        parser.error(f"{name} must be a JSON object, got {text!r} ({exc})")
    if not isinstance(value, dict):
        parser.error(f"{name} must be a JSON object, got {text!r}")
    return value


def _noise_levels(text: str) -> list[float]:
    """``--noise`` as numbers (comma-separated), or a ``ValueError`` naming the flag."""
    try:
        return [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ValueError(f"--noise must be comma-separated numbers (metres), got {text!r}"
                         ) from None


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI (see the module docstring); returns the exit status.

    A bad argument — a flag's value, an ``--out`` that is a file, an unreadable dataset — prints
    one line, ``python -m fusion.evaluation: error: ...``, before anything is evaluated or
    written, and exits with status 2; results that cannot be written, one line and status 1."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if (not args.pairs_dir) == (args.synthetic is None):
        parser.error("give either PAIRS_DIR or --synthetic N (exactly one)")
    if args.out.exists() and not args.out.is_dir():
        parser.error(f"--out: {args.out} is a file, not a folder: give a folder for "
                     f"results.json and the plots")
    try:
        methods = parse_methods(args.methods)
        config = config_from(MergeConfig, _json_arg(parser, args.config, "--config"), "--config")
        if args.synthetic is not None:
            if args.synthetic < 1:
                raise ValueError(f"--synthetic must be >= 1, got {args.synthetic}")
            noise = _noise_levels(args.noise)
            syn = _json_arg(parser, args.synthetic_config, "--synthetic-config")
            pairs = synthetic_pairs(args.synthetic, args.seed, noise, syn)
        else:
            pairs = []
            for folder in args.pairs_dir:
                loaded = load_pair_dir(folder, args.truth)
                if len(args.pairs_dir) > 1:
                    loaded = [dataclasses.replace(p, name=f"{folder.name}/{p.name}")
                              for p in loaded]
                pairs += loaded
    except (ValueError, TypeError, OSError, ImportError) as exc:
        parser.error(str(exc))
    overrides = _json_arg(parser, args.config, "--config")
    merge_config = overrides if args.for_noise else config
    if "exhaustive" in methods:
        try:
            check_exhaustive(pairs, merge_config, args.for_noise)
        except ValueError as exc:
            parser.error(f"--methods: {exc} (--config '{{\"exhaustive_step_deg\": ...}}')")
    records = evaluate(pairs, methods, merge_config, progress=not args.quiet,
                       for_noise=args.for_noise)
    summary = summarise(records)
    print(format_tables(summary))
    from fusion.grid_merge import GridMergeConfig

    default = GridMergeConfig().accept_threshold
    sweep, calibration = threshold_sweep(records), calibration_summary(records)
    print(format_threshold_tables(sweep, calibration, default))
    source = (f"synthetic N={args.synthetic} seed={args.seed} noise={args.noise}"
              if args.synthetic is not None else ", ".join(map(str, args.pairs_dir)))
    try:
        atomic_write_json(args.out / "results.json", {
            "source": source, "methods": methods, "config": asdict(config),
            "config_for_noise": args.for_noise,
            "thresholds": {"rotation_deg": ROTATION_OK_DEG, "translation_m": TRANSLATION_OK_M},
            "summary": summary, "threshold_sweep": sweep, "calibration": calibration,
            "accept_threshold": default, "records": [asdict(r) for r in records]},
            allow_nan=False)
        if not args.no_plots:
            plot_results(records, pairs, args.out, config)
            plot_thresholds(sweep, records, args.out, default)
    except OSError as exc:
        parser.exit(1, f"{parser.prog}: error: --out: cannot write {exc.filename or args.out} "
                       f"({exc.strerror}): free space or give another --out, and rerun\n")
    print(f"\nwrote {args.out / 'results.json'}" + ("" if args.no_plots else " and plots"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
