"""What the calibrated models are fitted on: one row per alignment of a tuning pair — its
evidence features and whether it is right (rotation error < 2°, translation error < 0.3 m at the
moved map's node centroid, or its wall centroid when it has no nodes: the rule of
:func:`fusion.evaluation.results.is_success`).

* ``"grid"`` (:func:`alignment_rows`): every tuning env pair's grids aligned both ways (B onto A
  and A onto B) by :func:`fusion.grid_merge.merge_grids`, with the pair's drift prior.
* ``"structural"`` (:func:`structural_rows`): :func:`fusion.merge_maps` (``"auto"``) on the
  tuning env pairs, their maps extracted again with the current :func:`topo.extract_topomap`,
  and on synthetic pairs (:func:`fusion.evaluation.evaluate.synthetic_pairs`,
  :data:`SYNTHETIC_SEED`).
* ``"ranking"`` (:func:`ranking_rows`): every candidate of the structural search
  (:func:`fusion.structural.candidate_features`) on the same pairs, labelled right, wrong or
  near miss.

The tuning env pairs are ``fusion.evaluation.pairs`` datasets made by
``benchmarks/env_pairs.py`` (fusion does not run the env): by default every folder of
``data/env_pairs/tune`` below the current directory, never those of ``data/env_pairs/test``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

import fusion.grid_merge as gm
import fusion.structural as fm
from fusion.decision import DEFAULT_RULE
from fusion.evaluation.evaluate import synthetic_pairs
from fusion.evaluation.pairs import load_pairs
from fusion.evaluation.results import is_success
from fusion.rigid import Rigid2D
from topo.extract import extract_topomap

DATA = Path("data") / "env_pairs"
"""Where ``benchmarks/env_pairs.py`` writes the env pairs (relative to the repository root, the
directory the refit runs in)."""

SYNTHETIC_SEED = 100
"""Seed of the synthetic tuning pairs (the evaluation uses 0 and 7)."""

NEAR_MISS = (5.0, 1.0)
"""Candidates within these (degrees, metres) of the truth but not right are left out of the
ranking fit: neither right nor clearly wrong."""


def default_dirs(data: str | Path = DATA) -> list[Path]:
    """The tuning dataset folders: those of ``data/tune`` (the drift-aware ones of
    ``benchmarks/env_pairs.py --odometry-noise``: ``default_dirs(data / "drift")``)."""
    return sorted(p for p in (Path(data) / "tune").glob("*") if (p / "dataset.json").exists())


def _centre(topo: Any, result: gm.GridMergeResult) -> np.ndarray | None:
    if topo.n_nodes:
        return topo.xy.mean(axis=0)
    return None if result.centre is None else np.asarray(result.centre)


def _errors(transform: Rigid2D, truth: Rigid2D, centre: np.ndarray) -> tuple[float, float]:
    return (math.degrees(transform.rotation_error(truth)),
            transform.translation_error(truth, at=centre))


def pair_config(pair: Any, config: gm.GridMergeConfig | None = None) -> gm.GridMergeConfig:
    """``config`` with the pair's :attr:`fusion.grid_merge.GridMergeConfig.drift_prior`: its
    odometry noise (``extra["odometry_noise"]`` of a drift-aware pair, else 0) over its
    snapshot's steps."""
    noise = float(pair.extra.get("odometry_noise", 0.0))
    return dataclasses.replace(config or gm.GridMergeConfig(),
                               drift_prior=gm.drift_prior(noise, int(pair.step)))


def alignment_rows(dirs: Iterable[Path], config: gm.GridMergeConfig | None = None,
                   both_ways: bool = True) -> list[dict]:
    """One row per grid alignment: set, pair, world, direction, overlap, features, right,
    errors."""
    rows = []
    for d in dirs:
        d = Path(d)
        for p in load_pairs(d):
            cfg = pair_config(p, config)
            ways = [(p.grid_a, p.grid_b, p.map_b, p.transform, "ab")]
            if both_ways:
                ways.append((p.grid_b, p.grid_a, p.map_a, p.transform.inverse(), "ba"))
            for ga, gb, topo_b, truth, way in ways:
                r = gm.merge_grids(ga, gb, cfg)
                centre = _centre(topo_b, r)
                rot = trans = math.inf
                if centre is not None:
                    rot, trans = _errors(r.transform, truth, centre)
                rows.append({"set": d.name,
                             "pair": p.pair_id, "world": f"{d.name}:{p.world_id}", "way": way,
                             "overlap": p.overlap, "features": r.features(),
                             "right": bool(p.overlap > 0 and is_success((rot, trans))),
                             "rotation_error_deg": rot if math.isfinite(rot) else None,
                             "translation_error_m": trans if math.isfinite(trans) else None,
                             "overlap_m2": r.overlap_m2, "time_s": r.time_s, "step": p.step})
    return rows


def structural_pairs(dirs: Iterable[Path], n_synthetic: int) -> Iterator[tuple]:
    """``(set, world, overlap, map_a, map_b, truth or None)`` of the tuning env pairs (maps
    extracted again) and ``n_synthetic`` synthetic tuning pairs per noise level."""
    for d in dirs:
        d = Path(d)
        for p in load_pairs(d):
            maps = [extract_topomap(np.asarray(g.states), g.resolution, g.origin)
                    for g in (p.grid_a, p.grid_b)]
            yield (d.name, f"{d.name}:{p.world_id}", p.overlap, *maps,
                   p.transform if p.overlap > 0 else None)
    if n_synthetic:
        for p in synthetic_pairs(n_synthetic, seed=SYNTHETIC_SEED):
            yield ("synthetic", f"synthetic:{p.name}", p.overlap if p.kind == "overlap" else 0.0,
                   p.map_a, p.map_b, p.transform if p.kind == "overlap" else None)


def structural_rows(dirs: Iterable[Path], n_synthetic: int) -> list[dict]:
    """One row per pair the structural merge tried: its result's calibration features, whether
    its transform is right, and whether it fails the rule's hard gates (``gated``)."""
    rows = []
    for name, world, overlap, map_a, map_b, truth in structural_pairs(dirs, n_synthetic):
        r = fm.merge_maps(map_a, map_b)
        if r.evidence is None or not map_b.n_nodes:
            continue
        rot, trans = (math.inf, math.inf) if truth is None else _errors(
            r.transform, truth, map_b.xy.mean(axis=0))
        rows.append({"set": name, "world": world, "pair": f"{world}:{overlap}", "way": "ab",
                     "overlap": overlap, "features": r.evidence.calibration_features(),
                     "right": is_success((rot, trans)),
                     "gated": bool(r.evidence.inliers < DEFAULT_RULE.min_inliers
                                   or r.evidence.collinear
                                   or r.evidence.margin < DEFAULT_RULE.min_margin)})
    return rows


def ranking_rows(dirs: Iterable[Path], n_synthetic: int) -> list[dict]:
    """One row per candidate of the structural search: its score features (``x``, in the order
    of :data:`fusion.structural.CONFIDENCE_WEIGHTS`) and label (1 right, 0 wrong, -1 near
    miss)."""
    rows = []
    for name, world, overlap, map_a, map_b, truth in structural_pairs(dirs, n_synthetic):
        transforms, X = fm.candidate_features(map_a, map_b)
        if not transforms or not map_b.n_nodes:
            continue
        centre = map_b.xy.mean(axis=0)
        for t, x in zip(transforms, X.tolist(), strict=True):
            label = 0
            if truth is not None:
                rot, trans = _errors(t, truth, centre)
                label = 1 if is_success((rot, trans)) else (
                    -1 if rot < NEAR_MISS[0] and trans < NEAR_MISS[1] else 0)
            rows.append({"set": name, "world": world, "pair": f"{world}:{overlap}",
                         "label": label, "x": x})
    return rows


def collect(model: str, dirs: Sequence[Path], n_synthetic: int) -> list[dict]:
    """The rows of ``model`` (``"grid"``, ``"structural"`` or ``"ranking"``).

    Raises:
        ValueError: an unknown ``model`` (the known ones are named).
    """
    if model == "grid":
        return alignment_rows(dirs)
    if model == "structural":
        return structural_rows(dirs, n_synthetic)
    if model == "ranking":
        return ranking_rows(dirs, n_synthetic)
    raise ValueError(f"model must be one of ['grid', 'structural', 'ranking'], got {model!r}")
