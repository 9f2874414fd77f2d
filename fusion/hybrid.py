"""``hybrid_merge``: the environment's merge — the structural merge of the topological maps
checked by the grids, and the occupancy-grid alignment with its calibrated confidence — and
``recheck``, which re-examines a transform in use as the maps grow.

The structural merge (:func:`fusion.merge_maps` on the robots' topological maps) runs first;
the grids check what it accepts, and the grid alignment (:func:`fusion.grid_merge.merge_grids`)
searches when it finds nothing. Every result carries ``confidence``, the probability that its
transform is right (< 2°, < 0.3 m). Every decision is a step of one rule,
:class:`fusion.decision.MergeRule` (read from :class:`fusion.grid_merge.GridMergeConfig`): one
threshold, ``accept_threshold``, decides for both, with the hard gates (the grid alignment's
``min_overlap_m2``; for a structural merge, its matches and the grids' check), so a rejected
result may still report a confidence above the threshold. Given the transform in use, a
result clearly different from it replaces it unless the grids support the one in use clearly
better (``in_use``, :attr:`fusion.decision.MergeRule.in_use_margin`).

The steps of :func:`hybrid_merge`:

1. the structural merge (:func:`fusion.merge_maps`) at ``accept_threshold``;
2. if accepted: the grids' check (:meth:`~fusion.decision.MergeRule.grid_check`), the
   refinement on the grids' walls, the transform in use kept if the grids support it clearly
   better (:meth:`~fusion.decision.MergeRule.keeps`), and when asked or on drifting odometry
   the grids' vouching (:meth:`~fusion.decision.MergeRule.vouches`): all passed, it is the
   result (``supplied_by="structural"``);
3. otherwise, with the grids tried, the grid alignment
   (:meth:`~fusion.decision.MergeRule.grid`) and the transform in use kept likewise: passed,
   it is the result (``supplied_by="grid"``), else the rejection with both reasons.

:func:`recheck` adds the drop rule (:meth:`~fusion.decision.MergeRule.drops`,
:meth:`~fusion.decision.MergeRule.refutes`).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from fusion import grid_merge as gm
from fusion.decision import DEFAULT_RULE, MergeRule
from fusion.inputs import check_grid_inputs
from fusion.rigid import Rigid2D
from fusion.structural import MergeResult, fuse_maps, merge_maps

HYBRID_EPS = 0.6
"""Node fusion radius (m) when a grid alignment builds the merged topological map: sonar
topological maps of the same place put their nodes apart by up to about this much
(``docs/notes/fusion.md``)."""

IN_USE_MARGIN = DEFAULT_RULE.in_use_margin
"""A confident result clearly different from the transform in use replaces it unless the grids
support the one in use more than this many times better
(:attr:`fusion.decision.MergeRule.in_use_margin`, where the reason is documented)."""


@dataclass(frozen=True, slots=True)
class HybridResult(MergeResult):
    """A :class:`fusion.MergeResult` (``method="hybrid"``) and the grid alignment behind it.

    ``confidence`` is the grid alignment's calibrated :attr:`GridMergeResult.confidence` when
    the grids were aligned, else the structural merge's own.

    Attributes:
        grid: the grid alignment behind the result (``None`` if the grids were not aligned).
        supplied_by: what supplied an accepted transform: ``"structural"`` (the structural
            merge, checked by the grids) or ``"grid"``; ``None`` when rejected.
    """

    grid: gm.GridMergeResult | None = None
    supplied_by: str | None = None


def hybrid_merge(map_a: Any, map_b: Any, grid_a: Any, grid_b: Any, *,
                 try_grids: bool = True, config: gm.GridMergeConfig | None = None,
                 in_use: Rigid2D | None = None, vouch: bool = False) -> HybridResult:
    """The structural merge first (:func:`fusion.merge_maps`, ``"auto"``, at
    ``config.accept_threshold``): kept if it is accepted and the grids agree with it
    (:func:`fusion.grid_merge.check_with_grids`, a hard sanity gate), then refined on the grids'
    wall cells (:func:`fusion.grid_merge.refine_with_grids`). Otherwise, when
    ``try_grids``, the grid alignment (:func:`fusion.grid_merge.merge_grids`): accepted when its
    calibrated confidence reaches ``accept_threshold``; an accepted grid alignment fuses the
    topological maps at nodes within :data:`HYBRID_EPS`. A rejection keeps the grids' best
    alignment (no matches, ``merged`` = ``map_a``; ``evidence`` stays the structural merge's),
    or without grids the structural one, with the reasons; ``score`` is the log-odds of
    ``confidence`` for a grid alignment, the structural score otherwise.

    With ``vouch``, or ``config.drift_prior > 0`` (odometry that drifts), an accepted
    structural merge also needs the grids to vouch for it: their best alignment the same one,
    with a calibrated confidence of at least ``accept_threshold`` (one grid alignment more per
    such merge). Under drift the structural confidence knows nothing of the drift and the
    grids' weighs it. The env asks ``vouch`` of a pair's first merge: early in an episode the
    two maps often share no place at all — far more often than in the map pairs the
    structural confidence was calibrated on — and a room row then fits its twin with a high
    structural confidence (``docs/notes/fusion.md``).

    With ``in_use``, the transform the caller uses now, an accepted result clearly different
    from it (``distinct_deg`` / ``distinct_m`` at B's node centroid) is rejected when the grids
    support ``in_use`` clearly better (:attr:`fusion.grid_merge.GridAgreement.support` more
    than :data:`IN_USE_MARGIN` times the new one's): a confident merge of a look-alike part of
    the building must not replace an alignment of the whole maps.

    Raises:
        TypeError: ``in_use`` is neither ``None`` nor a :class:`fusion.Rigid2D`; ``vouch``
            is not a bool.
        TypeError, ValueError: malformed maps or grids (both grids are needed, even without
            ``try_grids``: they check a structural merge), or work beyond
            :mod:`fusion.inputs`' bounds, naming the argument.
    """
    check_grid_inputs(grid_a, grid_b, config)
    _check_in_use(in_use, allow_none=True)
    if not isinstance(vouch, bool):
        raise TypeError(f"vouch must be a bool, got {type(vouch).__name__}")
    return _hybrid(map_a, map_b, grid_a, grid_b, try_grids, config, in_use, vouch)


def recheck(map_a: Any, map_b: Any, grid_a: Any, grid_b: Any, in_use: Rigid2D,
            config: gm.GridMergeConfig | None = None) -> tuple[HybridResult, str | None]:
    """:func:`hybrid_merge` (grids tried) for maps already merged by ``in_use``, and whether
    the grids now refute ``in_use``: ``(result, None)``, or with the result rejected and the
    grids' best alignment clearly different from ``in_use`` (``distinct_deg`` / ``distinct_m``
    at B's wall centroid) — the evidence no longer supports it though nothing is confident
    enough to replace it — ``(result, why)``, ``why`` also appended to the result's reason.
    Likewise, on maps that may have drifted (``config.drift_prior > 0``), when the grids' best
    alignment is ``in_use``'s own (not distinct), has no rival
    it ties with (``margin`` above :data:`fusion.grid_merge.TIE_MARGIN`: a symmetric room's
    look-alikes keep the one in use) and its calibrated confidence has fallen below
    ``accept_threshold − drop_margin`` (:class:`fusion.grid_merge.GridMergeConfig`):
    drifting odometry bends the maps until no rigid transform is right, and the merge must
    then be dropped, not kept on old evidence. Without drift the rule is off: there the grids'
    confidence in a right merge can dip for a while (``docs/notes/drift.md``).

    An accepted result (the same alignment refined, or a distinct one the grids do not support
    ``in_use`` clearly better than: :func:`hybrid_merge`'s ``in_use``) is for the caller to use
    instead; the grids' best alignment refutes ``in_use`` only if they do not support
    ``in_use`` clearly better.
    This is how a merge accepted early on small, self-similar maps (a building's 180°-turned
    or shifted copy of a room row) gets undone once the maps have grown.

    Raises:
        TypeError: ``in_use`` is not a :class:`fusion.Rigid2D`.
    """
    _check_in_use(in_use, allow_none=False)
    cfg = config or gm.GridMergeConfig()
    rule = MergeRule.of(cfg)
    result = _hybrid(map_a, map_b, grid_a, grid_b, True, cfg, in_use)
    grid = result.grid
    if result.accepted or grid is None or grid.centre is None:
        return result, None
    if not rule.distinct(grid.transform, in_use, grid.centre):
        why = rule.drops(grid)
    else:
        why = rule.refutes(grid, in_use, _keeps(grid_a, grid_b, grid.transform, in_use, cfg))
    if why is None:
        return result, None
    return dataclasses.replace(result, reason=f"{result.reason}; {why}"), why


def _check_in_use(in_use: Any, allow_none: bool) -> None:
    if in_use is None and allow_none:
        return
    if not isinstance(in_use, Rigid2D):
        raise TypeError(f"in_use must be a fusion.Rigid2D (the transform in use)"
                        f"{' or None' if allow_none else ''}, got {type(in_use).__name__}")


def _keeps(grid_a: Any, grid_b: Any, new: Rigid2D, in_use: Rigid2D,
           cfg: gm.GridMergeConfig) -> str | None:
    """Why ``in_use`` stays rather than ``new`` replacing it
    (:meth:`fusion.decision.MergeRule.keeps` of the grids' agreement with each), ``None`` if
    ``new`` may replace it."""
    now = gm.grid_agreement(grid_a, grid_b, in_use, cfg)
    then = gm.grid_agreement(grid_a, grid_b, new, cfg)
    return MergeRule.of(cfg).keeps(now, then)


def _log_odds(p: float) -> float:
    p = min(max(p, 1e-12), 1 - 1e-12)
    return math.log(p / (1 - p))


def _hybrid(map_a: Any, map_b: Any, grid_a: Any, grid_b: Any, try_grids: bool,
            config: gm.GridMergeConfig | None, in_use: Rigid2D | None = None,
            vouch: bool = False) -> HybridResult:
    """The steps of the module docstring."""
    t0 = time.perf_counter()
    cfg = config or gm.GridMergeConfig()
    rule = MergeRule.of(cfg)
    # 1. the structural merge, at the one threshold
    topo = merge_maps(map_a, map_b, method="auto",
                      config={"accept_threshold": rule.accept_threshold})
    fields = {f.name: getattr(topo, f.name) for f in dataclasses.fields(MergeResult)}
    grid: gm.GridMergeResult | None = None
    if topo.accepted:
        # 2. checked, refined and (if asked) vouched for by the grids
        why, refined, grid = _structural_step(map_b, grid_a, grid_b, topo.transform, cfg, rule,
                                              in_use, vouch)
        if why is None:
            merged = fuse_maps(map_a, map_b, refined, topo.matches, HYBRID_EPS)
            return HybridResult(**{**fields, "transform": refined, "merged": merged,
                                   "method": "hybrid", "time_s": time.perf_counter() - t0},
                                supplied_by="structural")
        fields.update(transform=refined, accepted=False, merged=map_a,
                      reason=f"structural merge refuted by the grids: {why}")
    if not try_grids:
        return HybridResult(**{**fields, "method": "hybrid", "time_s": time.perf_counter() - t0})
    # 3. the grid alignment (once: the vouching's, if it ran)
    grid = grid or gm.merge_grids(grid_a, grid_b, cfg)
    why = grid.reason if not grid.accepted else _kept(map_b, grid_a, grid_b, grid.transform,
                                                      cfg, rule, in_use)
    if why is not None:
        return HybridResult(**{**fields, "transform": grid.transform, "accepted": False,
                               "matches": np.empty((0, 2), dtype=np.int64), "merged": map_a,
                               "score": _log_odds(grid.confidence), "method": "hybrid",
                               "time_s": time.perf_counter() - t0,
                               "reason": f"topology: {fields['reason']}; grids: {why}",
                               "confidence": grid.confidence}, grid=grid)
    matches = _nearest_matches(map_a, map_b, grid.transform)
    merged = fuse_maps(map_a, map_b, grid.transform, matches, HYBRID_EPS)
    return HybridResult(transform=grid.transform, accepted=True,
                        score=_log_odds(grid.confidence), matches=matches, merged=merged,
                        method="hybrid", time_s=time.perf_counter() - t0, reason=None,
                        evidence=None, confidence=grid.confidence, grid=grid,
                        supplied_by="grid")


def _kept(map_b: Any, grid_a: Any, grid_b: Any, transform: Rigid2D, cfg: gm.GridMergeConfig,
          rule: MergeRule, in_use: Rigid2D | None) -> str | None:
    """Why the transform in use stays instead of ``transform`` (clearly different from it at
    B's node centroid, and the grids support it clearly better); ``None`` if nothing is in
    use or ``transform`` may replace it."""
    if in_use is None:
        return None
    centre = map_b.xy.mean(axis=0) if map_b.n_nodes else np.zeros(2)
    if not rule.distinct(transform, in_use, centre):
        return None
    return _keeps(grid_a, grid_b, transform, in_use, cfg)


def _structural_step(map_b: Any, grid_a: Any, grid_b: Any, transform: Rigid2D,
                     cfg: gm.GridMergeConfig, rule: MergeRule, in_use: Rigid2D | None,
                     vouch: bool) -> tuple[str | None, Rigid2D, gm.GridMergeResult | None]:
    """Step 2 for an accepted structural merge's ``transform``: ``(why it is refuted or None,
    the transform to report, the grid alignment if the vouching ran it)``. The grids' check is
    a hard gate; then the walls place it to the cells' precision, the transform in use may be
    kept instead, and the grids vouch when :meth:`fusion.decision.MergeRule.needs_vouch`."""
    why = gm.check_with_grids(grid_a, grid_b, transform, cfg)
    if why is not None:
        return why, transform, None
    refined = gm.refine_with_grids(grid_a, grid_b, transform, cfg)
    why = _kept(map_b, grid_a, grid_b, refined, cfg, rule, in_use)
    grid = None
    if why is None and rule.needs_vouch(vouch):
        grid = gm.merge_grids(grid_a, grid_b, cfg)
        why = rule.vouches(grid, refined)
    return why, refined, grid


def _nearest_matches(map_a: Any, map_b: Any, transform: Rigid2D) -> np.ndarray:
    """``(K, 2)`` node pairs ``(a, b)`` of B moved by ``transform`` within :data:`HYBRID_EPS`
    of an A node, one B node per A node (the closest)."""
    matches = np.empty((0, 2), dtype=np.int64)
    if not (map_a.n_nodes and map_b.n_nodes):
        return matches
    d, idx = cKDTree(map_a.xy).query(transform.apply(map_b.xy),
                                     distance_upper_bound=HYBRID_EPS)
    keep = np.isfinite(d)
    matches = np.stack([idx[keep], np.flatnonzero(keep)], axis=1).astype(np.int64)
    order = np.argsort(d[keep], kind="stable")
    _, first = np.unique(matches[order, 0], return_index=True)
    return matches[order[first]]
