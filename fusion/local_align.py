"""Aligning two occupancy grids near a known estimate: a local correlative search.

Once a pose graph knows roughly where two local maps lie (two windows of a robot's own map
that revisit a place, or a teammate's window after the pair is joined), a global search of
every rotation and translation (:func:`fusion.grid_merge.merge_grids`) is both wasteful and
drawn to look-alikes far away. :func:`align_near` searches only near the estimate — B's wall
cells scored on A's wall likelihood field (a Gaussian of the distance to A's nearest wall
cell, as in correlative scan matching, Olson 2009) over a small box of rotations and
translations — then refines the best pose on the walls and keeps it only if the grids agree
with it (:func:`fusion.grid_merge.check_with_grids`). :func:`near_features` is the evidence the
calibrated confidence of such an alignment reads (model ``"window_near"``,
:mod:`fusion.calibration`).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
from scipy import ndimage

from fusion.grid_layers import OCCUPIED, LayerCache, cached, cell_states
from fusion.grid_merge import (
    GridMergeConfig,
    check_with_grids,
    grid_agreement,
    refine_with_grids,
)
from fusion.grid_refine import native_evidence, native_walls
from fusion.inputs import check_grid_inputs
from fusion.rigid import Rigid2D
from topo.validation import check_real

MAX_TRANSLATIONS = 2000
"""Translations scored per rotation at most (the search box's area in grid A's cells): what
keeps a call's memory and time bounded."""
MAX_WALL_POINTS = 1500
"""B's wall cells scored at most (a regular subsample beyond): the search's cost is linear in
them and a few hundred already pin a pose."""


def align_near(grid_a: Any, grid_b: Any, estimate: Rigid2D,
               config: GridMergeConfig | None = None, *, max_deg: float = 3.0,
               step_deg: float = 1.0, reach_m: float = 0.5) -> Rigid2D | None:
    """Grid B's alignment onto grid A (B → A) within ``max_deg`` degrees and ``reach_m``
    metres of ``estimate`` (rotations about B's wall centroid in ``step_deg`` steps,
    translations on A's cells), refined on the walls; ``None`` when either grid has fewer
    than 10 wall cells or the grids do not agree with the best pose (too little overlap, B's
    walls off A's walls or in A's free space: ``config``'s gates).

    Args:
        grid_a, grid_b: occupancy grids (``topo.OccupancyGrid`` or anything
            :func:`fusion.grid_merge.merge_grids` takes).
        estimate: the transform to search near (B's frame → A's).
        config: the gates and refinement settings (:class:`fusion.grid_merge.GridMergeConfig`).
        max_deg, step_deg, reach_m: the search box (``max_deg`` and ``reach_m`` ≥ 0,
            ``step_deg`` > 0; at most :data:`MAX_TRANSLATIONS` translations).

    Raises:
        TypeError, ValueError: malformed grids or config (as ``merge_grids``), ``estimate``
            not a :class:`fusion.Rigid2D`, a search box out of those bounds.
    """
    check_grid_inputs(grid_a, grid_b, config)
    if not isinstance(estimate, Rigid2D):
        raise TypeError(f"estimate must be a fusion.Rigid2D, got {type(estimate).__name__}")
    max_deg = check_real(max_deg, "max_deg", low=0.0, low_inclusive=True, high=180.0)
    step_deg = check_real(step_deg, "step_deg", low=0.0, high=180.0)
    reach_m = check_real(reach_m, "reach_m", low=0.0, low_inclusive=True)
    cfg = config or GridMergeConfig()
    walls_a = cached(grid_a, "walls", lambda: cell_states(grid_a) == OCCUPIED)
    res = float(grid_a.resolution)
    side = 2 * int(reach_m / res + 1e-9) + 1
    if side * side > MAX_TRANSLATIONS:
        raise ValueError(f"reach_m={reach_m} gives {side * side} translations a rotation on "
                         f"grid_a's {res} m cells (at most {MAX_TRANSLATIONS}): search a "
                         f"smaller box")
    walls_b, _ = native_walls(grid_b)
    if np.count_nonzero(walls_a) < 10 or len(walls_b) < 10:
        return None
    if len(walls_b) > MAX_WALL_POINTS:
        walls_b = walls_b[:: math.ceil(len(walls_b) / MAX_WALL_POINTS)]
    field = cached(grid_a, "likelihood_field", lambda: _likelihood_field(walls_a))
    origin = np.asarray(grid_a.origin, dtype=np.float64)
    offsets = np.arange(-reach_m, reach_m + 1e-9, res)
    ox, oy = (v.ravel() for v in np.meshgrid(offsets, offsets))
    centre = walls_b.mean(axis=0)
    anchor = estimate.apply(centre[None])[0]  # where the estimate puts B's wall centroid
    turns = np.radians(np.arange(-max_deg, max_deg + 1e-9, step_deg))
    scores = np.empty((len(turns), len(ox)))
    for k, turn in enumerate(turns):
        moved = Rigid2D(estimate.theta + turn).apply(walls_b - centre) + anchor
        cols = (moved[:, 0] - origin[0]) / res - 0.5
        rows = (moved[:, 1] - origin[1]) / res - 0.5
        at = [(rows[None, :] + (oy / res)[:, None]).ravel(),
              (cols[None, :] + (ox / res)[:, None]).ravel()]
        scores[k] = ndimage.map_coordinates(field, at, order=0, mode="constant",
                                            cval=0.0).reshape(len(ox), -1).mean(axis=1)
    k, j = np.unravel_index(int(np.argmax(scores)), scores.shape)
    theta = estimate.theta + float(turns[k])
    t = anchor + np.array([ox[j], oy[j]]) - Rigid2D(theta).R @ centre
    best = refine_with_grids(grid_a, grid_b, Rigid2D(theta, (float(t[0]), float(t[1]))), cfg)
    return best if check_with_grids(grid_a, grid_b, best, cfg) is None else None


NEAR_FEATURES = ("corr_deg", "log_corr_m", "anchor_shift_deg", "loop", "conflict",
                 "native_deep", "wall_agreement", "log_wall_hits")
"""The evidence of a near alignment (:func:`near_features`) that its calibrated confidence
weighs (model ``"window_near"``). How they were chosen (leave-one-world-out scores of the
subsets tried): ``docs/notes/bending.md``."""


def near_features(grid_a: Any, grid_b: Any, estimate: Rigid2D, transform: Rigid2D,
                  config: GridMergeConfig | None = None, *, loop: bool = False,
                  anchor_shift_deg: float = 0.0) -> dict[str, float]:
    """The evidence of :func:`align_near`'s ``transform`` (B → A), found near ``estimate``
    (names of :data:`NEAR_FEATURES`): how far it moved from the estimate (rotation, degrees;
    ``log`` of the translation at B's wall centroid plus 0.05 m) — a near search that has to
    move far from a good estimate is more often off —, how B's walls land on A's
    (``fusion.grid_merge.grid_agreement``: wall agreement, conflict, ``log1p`` of the wall hits;
    at the grids' own cells, the share deep in A's free space), whether both grids are one
    robot's (``loop``) and how far a second alignment at one anchor turned it
    (``anchor_shift_deg``, 0 if none). Why: a pose graph ranks its measurements by their
    calibrated confidence, and a search near an estimate has no margin over rivals to
    judge it by.

    Raises:
        TypeError, ValueError: malformed grids or config (as :func:`align_near`).
        TypeError: ``estimate`` or ``transform`` is not a :class:`fusion.Rigid2D`.
        ValueError: ``anchor_shift_deg`` negative or not finite.
    """
    check_grid_inputs(grid_a, grid_b, config)
    for name, t in (("estimate", estimate), ("transform", transform)):
        if not isinstance(t, Rigid2D):
            raise TypeError(f"{name} must be a fusion.Rigid2D, got {type(t).__name__}")
    shift = check_real(anchor_shift_deg, "anchor_shift_deg", low=0.0, low_inclusive=True)
    cfg = config or GridMergeConfig()
    grid_a, grid_b = LayerCache.of(grid_a), LayerCache.of(grid_b)
    walls_b, _ = native_walls(grid_b)
    centre = walls_b.mean(axis=0) if len(walls_b) else np.zeros(2)
    agreement = grid_agreement(grid_a, grid_b, transform, cfg)
    _, _, deep = native_evidence(grid_a, grid_b, transform, centre,
                                 dataclasses.replace(cfg, native_refine=False))
    hits = 0 if agreement is None else agreement.wall_hits
    return {"corr_deg": math.degrees(transform.rotation_error(estimate)),
            "log_corr_m": math.log(transform.translation_error(estimate, at=centre) + 0.05),
            "anchor_shift_deg": shift, "loop": float(bool(loop)),
            "conflict": 1.0 if agreement is None else agreement.conflict,
            "native_deep": deep,
            "wall_agreement": 0.0 if agreement is None else agreement.wall_agreement,
            "log_wall_hits": math.log1p(hits)}


def _likelihood_field(walls: np.ndarray) -> np.ndarray:
    """``exp(−d² / 2σ²)`` of each cell's distance ``d`` (in cells) to the nearest true cell of
    ``walls`` (σ = 1.5 cells): how well a wall point landing there agrees."""
    return np.exp(-0.5 * (ndimage.distance_transform_edt(~walls) / 1.5) ** 2)


__all__ = ["MAX_TRANSLATIONS", "MAX_WALL_POINTS", "NEAR_FEATURES", "align_near", "near_features"]
