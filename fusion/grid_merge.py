"""``merge_grids``: global alignment of two occupancy grids by rotation search and FFT
cross-correlation (the classic grid map-merging recipe, cf. Carpin 2008), with a calibrated
confidence.

Sonar topological maps of the same building disagree a lot (the 15° cones smear walls and
leak free space through them), so on the robots' own maps the structural merge
(:func:`fusion.merge_maps`) rarely finds a confident alignment. The grids themselves carry far
more evidence — every wall cell — so this method aligns them directly:

1. both grids are cropped to their known cells and pooled to cells of exactly ``resolution``
   (a cell is a wall if any fine cell is occupied, free if most are free);
2. for every rotation ``θ`` in ``step_deg`` steps, B's wall and free cells are rotated and
   rasterised, and one FFT cross-correlation per layer scores **every** translation at once:
   ``+1`` per B wall on an A wall (within one cell), ``−conflict`` per B wall on A free space
   and per B free cell on an A wall, ``+free_weight`` per B free cell on A free space. This
   sweep runs on layers pooled ``coarse_factor`` times coarser (a quarter of the cells at 2), in
   single precision, batched over rotations (on large maps after a sweep coarser still:
   :func:`merge_grids`);
3. the ``refine_top`` best clearly different coarse alignments are scored again at
   ``resolution`` — the best on a ``step_deg / 3`` angle grid around it, the others (its
   rivals) on a ``2·step_deg / 3`` one — and the best is refined by gated ICP-SVD on wall
   cells, then (``native_refine``) on the grids' own cells: two gated ICP passes on their
   occupied cells, after a local correlation at 0.1 m for grids finer than that (so that maps
   of fine cells are aligned as precisely as their cells allow: ``docs/notes/fusion.md``);
4. its evidence — the margin of its score over the best alignment that is clearly different
   (more than ``distinct_deg`` or ``distinct_m`` away: the refined rivals, and far-away peaks
   at the best rotation), the overlapping area, how many of B's walls land on A's known cells
   and how many of them meet an A wall at the grids' own resolution (:meth:`GridMergeResult.
   features`) — gives its **confidence**, the probability that it is right (< 2°, < 0.3 m),
   from a logistic model fitted on tuning map pairs (:mod:`fusion.calibration`, model
   ``"grid"``, refitted by ``python -m fusion.calibration fit``). It is **accepted** when the
   confidence reaches ``accept_threshold`` and enough area overlaps (``min_overlap_m2``, a
   hard gate): symmetric buildings, whose rivals score as well, get a low confidence (at most
   1/2 for a tie, :data:`TIE_MARGIN`) and are rejected rather than merged wrongly.

:func:`fusion.hybrid.hybrid_merge` puts the structural merge first and this alignment second
(what the environment runs); :func:`fusion.hybrid.recheck` re-runs both for maps already
merged, to replace or refute the transform in use as the maps grow.

All inputs are duck-typed grids: :class:`topo.OccupancyGrid` or
:class:`fusion.evaluation.pairs.GridSnapshot`
(anything with cell-state codes — ``states()`` or ``states`` — ``resolution`` and ``origin``).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from fusion.decision import DEFAULT_ACCEPT_THRESHOLD, DEFAULT_RULE, MergeRule, clearly_different
from fusion.grid_layers import (
    Correlator,
    GridAgreement,
    LayerCache,
    cached,
    cell_centres,
    centres_of,
    dilated,
    landing,
    pooled_layers,
    score_layers_of,
)
from fusion.grid_refine import (
    icp_refined,
    local_search,
    native_evidence,
    native_walls,
    wall_tree,
)
from fusion.inputs import check_grid_inputs
from fusion.rigid import Rigid2D
from topo.validation import check_int, check_real

_pooled, _native_walls = pooled_layers, native_walls
"""Their names before the split into :mod:`fusion.grid_layers` and :mod:`fusion.grid_refine`
(old import paths keep working)."""

DEFAULT_DROP_MARGIN = DEFAULT_RULE.drop_margin
"""Default :attr:`GridMergeConfig.drop_margin` (:attr:`fusion.decision.MergeRule.drop_margin`).
The default accept threshold is :data:`fusion.decision.DEFAULT_ACCEPT_THRESHOLD`, where every
accept threshold is documented."""

TIE_MARGIN = DEFAULT_RULE.tie_margin
"""A clearly different alignment scoring within this factor of the best ties with it: the
confidence is then at most 1/2 (:attr:`fusion.decision.MergeRule.tie_margin`)."""


def drift_prior(odometry_noise: float, steps: int) -> float:
    """:attr:`GridMergeConfig.drift_prior` of maps made over ``steps`` env steps by robots whose
    odometry has relative noise ``odometry_noise`` (``RobotConfig.odometry_noise``, the larger
    of its two; ``0`` for perfect odometry): ``odometry_noise · steps / 1000``. The drift of a
    frontier robot grows about linearly with the steps (``docs/notes/drift.md``); the confidence
    model weighs it (fitted on ``benchmarks/env_pairs.py --odometry-noise`` pairs).

    Raises:
        ValueError: a negative ``odometry_noise`` or ``steps``.
    """
    check_real(odometry_noise, "odometry_noise", low=0.0, low_inclusive=True)
    check_int(steps, "steps", low=0)
    return float(odometry_noise) * int(steps) / 1000.0


@dataclass(frozen=True, slots=True)
class GridMergeConfig:
    """Settings of :func:`merge_grids` (metres, degrees; validated).

    ``accept_threshold``: an alignment is accepted when its calibrated :attr:`GridMergeResult.
    confidence` reaches this (:data:`DEFAULT_ACCEPT_THRESHOLD`); ``min_overlap_m2``: and only if
    this much of B's free space lands on A's known cells (a physical sanity gate: too little
    shared space to check anything). ``min_wall_agreement`` and ``max_conflict`` are the rule of
    :func:`check_with_grids` (the grids' check of a structural merge), not of
    :func:`merge_grids`. ``coarse_factor``: the rotation sweep runs on cells this many times
    wider than ``resolution`` (1: at full resolution); ``refine_top``: how many clearly
    different coarse alignments are scored again at full resolution (the best and its rivals);
    ``native_refine``: refine the alignment on the grids' own cells (finer than
    ``resolution``: 0.03–0.1 m). The confidence model was fitted with the default search
    settings (``resolution`` … ``refine_top``): other values change the evidence it reads, so
    refit it (``make calibrate``) before trusting its probabilities.
    ``drop_margin``: :func:`fusion.hybrid.recheck` drops the transform in use when the grids'
    alignment of it has a confidence below ``accept_threshold − drop_margin`` (a margin, so
    that a merge is not dropped and re-accepted as the confidence wavers at the threshold).
    ``drift_prior``: how far the maps' odometry may have drifted, :func:`drift_prior` (``0``:
    perfect odometry) — evidence of the confidence model, which the grids alone cannot give:
    drift bends both maps, and how far an alignment of bent maps is from the robots' current
    frames depends on the drift, not on how well the walls fit (``docs/notes/drift.md``);
    above 0, :func:`fusion.hybrid.hybrid_merge` also asks the grids about a structural merge.
    ``confidence_model``: the calibrated model of :mod:`fusion.calibration` the confidence is
    computed by (``"grid"``: fitted on the env's maps, with the default ``accept_threshold``;
    :data:`fusion.decision.REAL_MAP_MODEL` for real sensor maps, with its own threshold,
    :func:`fusion.decision.model_threshold`); a name the table lacks is a ``ValueError``
    naming those it has."""

    resolution: float = 0.2
    step_deg: float = 3.0
    conflict: float = 1.0
    free_weight: float = 0.05
    min_overlap_m2: float = DEFAULT_RULE.min_overlap_m2
    min_wall_agreement: float = DEFAULT_RULE.min_wall_agreement
    max_conflict: float = DEFAULT_RULE.max_conflict
    distinct_deg: float = DEFAULT_RULE.distinct_deg
    distinct_m: float = DEFAULT_RULE.distinct_m
    coarse_factor: int = 2
    refine_top: int = 3
    accept_threshold: float = DEFAULT_ACCEPT_THRESHOLD
    native_refine: bool = True
    drop_margin: float = DEFAULT_DROP_MARGIN
    drift_prior: float = 0.0
    confidence_model: str = "grid"

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            if f.name == "confidence_model":
                if not isinstance(self.confidence_model, str) or not self.confidence_model:
                    raise TypeError(f"GridMergeConfig.confidence_model must be a model name "
                                    f"(str), got {self.confidence_model!r}")
            elif f.name == "native_refine":
                if not isinstance(self.native_refine, bool):
                    raise TypeError(f"GridMergeConfig.native_refine must be a bool, got "
                                    f"{type(self.native_refine).__name__}")
            elif f.name in ("accept_threshold", "drop_margin"):
                check_real(getattr(self, f.name), f"GridMergeConfig.{f.name}", low=0.0,
                           low_inclusive=True, high=1.0)
            elif f.name == "drift_prior":
                check_real(self.drift_prior, "GridMergeConfig.drift_prior", low=0.0,
                           low_inclusive=True)
            elif f.name in ("coarse_factor", "refine_top"):
                check_int(getattr(self, f.name), f"GridMergeConfig.{f.name}", low=1)
            else:
                check_real(getattr(self, f.name), f"GridMergeConfig.{f.name}", low=0.0)
        check_real(self.min_wall_agreement, "GridMergeConfig.min_wall_agreement", low=0.0,
                   high=1.0)


@dataclass(frozen=True, slots=True)
class GridMergeResult:
    """What :func:`merge_grids` found.

    Attributes:
        transform: B → A; the best alignment even when rejected.
        accepted: ``confidence >= accept_threshold`` and enough overlap
            (:class:`GridMergeConfig`).
        score: the alignment's correlation score at ``resolution`` (module docstring, step 2).
        overlap_m2: area of B's free space landing on A's known cells.
        wall_agreement: fraction of B's wall cells landing on A's known cells that meet an A
            wall (within one cell).
        conflict: fraction of them landing in A's free space, away from A's walls.
        margin: ``score`` over the best clearly different alignment's score.
        time_s: wall time of the call.
        reason: why it was rejected (``None`` when accepted).
        centre: B's wall centroid (B's frame), where alignments are compared (``None`` when
            nothing could be aligned).
        confidence: calibrated probability that ``transform`` is right (< 2°, < 0.3 m at B's
            centroid), from :meth:`features` (:mod:`fusion.calibration`, model ``"grid"``).
        free_conflict: fraction of B's free cells landing on A's known cells that land on an
            A wall (B saw through where A saw a wall).
        wall_hits: how many of B's wall cells (at ``resolution``) land on A's known cells.
        rival_agreement: :attr:`wall_agreement` of that best clearly different alignment.
        native_agreement: fraction of B's wall cells (the grids' own cells) landing on A's
            known cells that lie within :data:`NATIVE_NEAR_M` of an A wall cell.
        native_conflict: fraction of them landing on A's free cells farther than
            :data:`NATIVE_DEEP_M` from any A wall cell.
        drift_prior: :attr:`GridMergeConfig.drift_prior` of the call.
    """

    transform: Rigid2D
    accepted: bool
    score: float
    overlap_m2: float
    wall_agreement: float
    conflict: float
    margin: float
    time_s: float
    reason: str | None = None
    centre: tuple[float, float] | None = None
    confidence: float = 0.0
    free_conflict: float = 0.0
    wall_hits: int = 0
    rival_agreement: float = 0.0
    native_agreement: float = 0.0
    native_conflict: float = 0.0
    drift_prior: float = 0.0

    def features(self) -> dict[str, float]:
        """The evidence the calibrated :attr:`confidence` is computed from (names of
        :data:`FEATURES`)."""
        return grid_features(self.score, self.margin, self.overlap_m2, self.wall_agreement,
                             self.conflict, self.free_conflict, self.wall_hits,
                             self.rival_agreement, self.native_agreement,
                             self.native_conflict, self.drift_prior)


FEATURES = ("log_score", "log_margin", "log_overlap", "wall_agreement", "conflict",
            "free_conflict", "log_wall_hits", "score_per_hit", "agreement_gain",
            "native_agreement", "native_conflict", "drift_prior", "log_drift_prior",
            "drift_native_agreement")
"""Names of :meth:`GridMergeResult.features`, the inputs of the ``"grid"`` calibration."""
MAX_MARGIN = 20.0
"""Margins are capped here before their log is taken (no rival at all is ``inf``)."""

def grid_features(score: float, margin: float, overlap_m2: float, agreement: float,
                  conflict: float, free_conflict: float, wall_hits: int,
                  rival_agreement: float, native_agreement: float,
                  native_conflict: float, drift_prior: float = 0.0) -> dict[str, float]:
    """:meth:`GridMergeResult.features` from its fields."""
    m = min(margin, MAX_MARGIN) if margin == margin else 1.0
    return {"log_score": math.log1p(max(score, 0.0)), "log_margin": math.log(max(m, 1e-3)),
            "log_overlap": math.log1p(max(overlap_m2, 0.0)), "wall_agreement": agreement,
            "conflict": conflict, "free_conflict": free_conflict,
            "log_wall_hits": math.log1p(wall_hits),
            "score_per_hit": max(score, 0.0) / max(wall_hits, 1),
            "agreement_gain": agreement - rival_agreement,
            "native_agreement": native_agreement, "native_conflict": native_conflict,
            "drift_prior": drift_prior, "log_drift_prior": math.log1p(100.0 * drift_prior),
            "drift_native_agreement": drift_prior * native_agreement}


def _rejected(reason: str, t0: float) -> GridMergeResult:
    return GridMergeResult(Rigid2D.identity(), False, 0.0, 0.0, 0.0, 0.0, 0.0,
                           time.perf_counter() - t0, reason)


def grid_agreement(grid_a: Any, grid_b: Any, transform: Rigid2D,
                   config: GridMergeConfig | None = None) -> GridAgreement | None:
    """How grid B's wall and free cells moved by ``transform`` (B → A) land on grid A's, both
    pooled to ``config.resolution`` (:class:`GridAgreement`); ``None`` if a grid has no known
    cells. The evidence :func:`check_with_grids` judges, and what
    :func:`fusion.hybrid.hybrid_merge` compares between a new transform and the one in use.

    Raises:
        TypeError: ``transform`` is not a :class:`fusion.Rigid2D`.
    """
    if not isinstance(transform, Rigid2D):
        raise TypeError(f"transform must be a fusion.Rigid2D, got {type(transform).__name__}")
    cfg = config or GridMergeConfig()
    pa, pb = pooled_layers(grid_a, cfg.resolution), pooled_layers(grid_b, cfg.resolution)
    if pa is None or pb is None:
        return None
    wall_a, free_a, origin_a = pa
    wall_b, free_b, origin_b = pb
    near_wall_a = dilated(wall_a)
    return landing(wall_a, free_a, near_wall_a, origin_a, cfg.resolution, transform,
                        cell_centres(wall_b, origin_b, cfg.resolution),
                        cell_centres(free_b, origin_b, cfg.resolution), int(free_b.sum()))


def check_with_grids(grid_a: Any, grid_b: Any, transform: Rigid2D,
                     config: GridMergeConfig | None = None) -> str | None:
    """``None`` if the grids agree with ``transform`` (enough overlap, B's walls on A's walls,
    few on A's free space: :func:`grid_agreement` against ``min_overlap_m2``,
    ``min_wall_agreement``, ``max_conflict``), else why not — the check :func:`hybrid_merge`
    puts on a structural merge before trusting it."""
    cfg = config or GridMergeConfig()
    return MergeRule.of(cfg).grid_check(grid_agreement(grid_a, grid_b, transform, cfg))


def refine_with_grids(grid_a: Any, grid_b: Any, transform: Rigid2D,
                      config: GridMergeConfig | None = None) -> Rigid2D:
    """``transform`` (B → A) refined on the grids' own wall cells: gated ICP-SVD of B's occupied
    cells onto A's, as :func:`merge_grids` finishes its own alignments (when
    ``native_refine``; else ``transform`` unchanged). A structural merge places B by a few
    nodes 0.1–0.3 m off each, sometimes a few degrees: the walls fix it to the cells'
    precision. A correction larger than :func:`merge_grids` allows its own estimates
    (``step_deg``, two ``resolution`` cells) is kept only if it stays the same alignment
    (within ``distinct_deg`` / ``distinct_m``) and B's wall cells meet A's walls at least as
    well at the grids' own cells (:attr:`GridMergeResult.native_agreement` minus
    ``native_conflict``)."""
    if not isinstance(transform, Rigid2D):
        raise TypeError(f"transform must be a fusion.Rigid2D, got {type(transform).__name__}")
    cfg = config or GridMergeConfig()
    grid_a, grid_b = LayerCache.of(grid_a), LayerCache.of(grid_b)  # their walls found once
    walls_b, _ = native_walls(grid_b)
    if not cfg.native_refine or len(walls_b) < 3:
        return transform
    centre = walls_b.mean(axis=0)
    refined, near, deep = native_evidence(grid_a, grid_b, transform, centre, cfg,
                                  bound=(cfg.distinct_deg, cfg.distinct_m))
    if (math.degrees(refined.rotation_error(transform)) <= cfg.step_deg
            and refined.translation_error(transform, at=centre) <= 2 * cfg.resolution):
        return refined
    _, near_0, deep_0 = native_evidence(grid_a, grid_b, transform, centre,
                                dataclasses.replace(cfg, native_refine=False))
    return refined if near - deep >= near_0 - deep_0 else transform


def distinct(a: Rigid2D, b: Rigid2D, centre: np.ndarray, cfg: GridMergeConfig) -> bool:
    """Whether two alignments are clearly different (``distinct_deg`` / ``distinct_m`` at B's
    wall centroid)."""
    return clearly_different(a, b, centre, cfg.distinct_deg, cfg.distinct_m)


LARGE_POOLED_CELLS = 80_000
"""Grids with more cells than this at :attr:`GridMergeConfig.resolution` (either grid, cropped
to its known cells) take :func:`merge_grids`' large-map path; smaller ones — the environment's
grids, of worlds a few tens of metres wide (56 m × 56 m at 0.2 m cells is 80 000) — the full
sweep, unchanged."""
PYRAMID_TOP = 12
"""On the large-map path, how many rotations (those of the sweep at twice the coarse cell that
score best) are swept again at the coarse cell."""
PYRAMID_REACH = 2.0
"""On the large-map path, the translations scored at ``resolution`` lie within this many
coarse cells of a coarse alignment."""
MAX_LARGE_ICP_POINTS = 1500
"""On the large-map path, the refinement at ``resolution`` moves at most this many of B's wall
cells (a regular subsample), as the refinement on the grids' own cells does."""


def _pyramid_sweep(grid_a: Any, grid_b: Any, coarse_a: tuple, coarse_b: tuple,
                   coarse: Correlator, thetas: np.ndarray, centre: np.ndarray, radius: float,
                   cfg: GridMergeConfig) -> tuple[np.ndarray, np.ndarray]:
    """The coarse sweep of large grids (:func:`merge_grids`): every rotation on the coarse
    layers ``coarse_a``, ``coarse_b`` (wall, free, origin) merged by blocks of 2 × 2 cells
    (:func:`blocks`), then the :data:`PYRAMID_TOP` best of them by ``coarse``. Returns, per
    rotation, ``coarse``'s best score and the flat index of its translation (``-inf`` and
    ``-1`` for the rotations not swept by ``coarse``). The blocks' FFTs cost a quarter of
    ``coarse``'s, whose sweep of every rotation is what dominates on large maps. What depends
    on one grid only is computed once per :class:`~fusion.grid_layers.LayerCache`."""
    r = 2 * coarse.res
    wa, fa, oa = cached(grid_a, ("blocks", coarse.res), lambda: blocks(*coarse_a, 2))
    wb, fb, ob = cached(grid_b, ("blocks", coarse.res), lambda: blocks(*coarse_b, 2))
    level = Correlator(wa, fa, oa, r, *centres_of(grid_b, wb, fb, ob, r, ("blocks", r)), centre,
                       radius + r, cfg, score_layers_of(grid_a, wa, fa, cfg, ("blocks", r)))
    keep = np.sort(np.argsort(-level.best(thetas)[0], kind="stable")[:PYRAMID_TOP])
    scores, at = np.full(len(thetas), -np.inf), np.full(len(thetas), -1, dtype=np.int64)
    scores[keep], at[keep], _ = coarse.best(thetas[keep])
    return scores, at


def blocks(wall: np.ndarray, free: np.ndarray, origin: np.ndarray, k: int
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pooled layers (wall, free, origin) merged by blocks of ``k × k`` cells: a wall where
    any cell is, free where more than half are and none is a wall (the layers' own rule, on
    cells rather than the grid's: a cheap ranking level, not evidence)."""
    h, w = -(-wall.shape[0] // k) * k, -(-wall.shape[1] // k) * k
    out = []
    for layer in (wall, free):
        padded = np.zeros((h, w), dtype=np.int32)
        padded[: layer.shape[0], : layer.shape[1]] = layer
        out.append(padded.reshape(h // k, k, w // k, k).sum(axis=(1, 3)))
    return out[0] > 0, (2 * out[1] > k * k) & (out[0] == 0), origin


def merge_grids(grid_a: Any, grid_b: Any, config: GridMergeConfig | None = None
                ) -> GridMergeResult:
    """Align occupancy grid B onto grid A (module docstring): the best alignment, its
    evidence and calibrated confidence, accepted or rejected with a reason. Grids with too
    little known space come back rejected with a reason; malformed grids, a ``config`` that is
    not a :class:`GridMergeConfig` and work beyond :mod:`fusion.inputs`' bounds raise a
    ``TypeError``/``ValueError`` naming the argument (:func:`fusion.inputs.check_grid_inputs`).

    The rotation search runs coarse to fine: every ``step_deg`` rotation is scored at
    ``coarse_factor × resolution``; the ``refine_top`` best clearly different rotations are
    scored again at ``resolution`` on a ``step_deg / 3`` grid around each (the best is the
    estimate, the others its rivals, with far-away peaks at the estimate's rotation).

    Large grids (either with more than :data:`LARGE_POOLED_CELLS` known-box cells at
    ``resolution``, when ``coarse_factor > 1``) take a coarse-to-fine path, since the FFTs of
    every rotation over the whole map dominate their cost: every rotation is first scored on
    the coarse layers merged by 2 × 2 blocks, and only the :data:`PYRAMID_TOP` best are swept
    at the coarse cell; at ``resolution``, the picked
    rotations are scored on the whole map as above, the others of the angle grids only within
    :data:`PYRAMID_REACH` coarse cells of a picked alignment (turned about B's centre), and the
    refinement moves at most :data:`MAX_LARGE_ICP_POINTS` wall cells. Contract: smaller grids
    (every grid of the environment) give exactly the full sweep's result; on large grids, a
    rotation's best alignment can be missed where the coarser sweeps rank it below the rest."""
    check_grid_inputs(grid_a, grid_b, config)
    t0 = time.perf_counter()
    # each grid read once however many resolutions the search looks at
    grid_a, grid_b = LayerCache.of(grid_a), LayerCache.of(grid_b)
    cfg = config or GridMergeConfig()
    res = cfg.resolution
    # each grid read once: its layers at full and (if the sweep is coarser) coarse resolution
    both = (res, res * cfg.coarse_factor) if cfg.coarse_factor > 1 else (res,)
    layers_a, layers_b = pooled_layers(grid_a, both), pooled_layers(grid_b, both)
    if layers_a is None or layers_b is None:
        return _rejected("a grid has no known cells", t0)
    (wall_a, free_a, origin_a), coarse_a = layers_a[0], layers_a[-1]
    (wall_b, free_b, origin_b), coarse_b = layers_b[0], layers_b[-1]
    if wall_a.sum() < 10 or wall_b.sum() < 10:
        return _rejected("too few wall cells to align", t0)
    # what depends on one grid only: computed once for all its pairs with a LayerCache
    prepared_a = score_layers_of(grid_a, wall_a, free_a, cfg, res)
    near_wall_a = prepared_a[0]
    pts_wall, pts_free = centres_of(grid_b, wall_b, free_b, origin_b, res, res)
    if len(pts_free) > 4000:  # free space is only a weak term: a regular subsample is enough
        pts_free = pts_free[:: int(math.ceil(len(pts_free) / 4000))]
    centre = pts_wall.mean(axis=0)
    radius = float(np.max(np.linalg.norm(np.vstack([pts_wall, pts_free]) - centre, axis=1)))

    # coarse: every rotation on pooled layers (B's points pooled to coarse cells)
    thetas = np.radians(np.arange(0.0, 360.0, cfg.step_deg))
    fine_res = res
    if cfg.coarse_factor > 1:
        cres = res * cfg.coarse_factor
        ca, cb = coarse_a, coarse_b
        coarse = Correlator(ca[0], ca[1], ca[2], cres, *centres_of(grid_b, *cb, cres, cres),
                            centre, radius + cres, cfg,
                            score_layers_of(grid_a, ca[0], ca[1], cfg, cres))
    else:
        coarse = None
    fine = Correlator(wall_a, free_a, origin_a, fine_res, pts_wall, pts_free, centre, radius,
                      cfg, prepared_a)
    sweep = coarse or fine
    large = coarse is not None and max(wall_a.size, wall_b.size) > LARGE_POOLED_CELLS
    if large:
        c_scores, c_at = _pyramid_sweep(grid_a, grid_b, coarse_a, coarse_b, coarse, thetas,
                                        centre, radius, cfg)
    else:
        c_scores, c_at, _ = sweep.best(thetas)
    c_alignments: dict[int, Rigid2D] = {}  # of the rotations looked at

    def c_alignment(i: int) -> Rigid2D:
        if i not in c_alignments:
            c_alignments[i] = Rigid2D(float(thetas[i]),
                                      sweep.translation(c_at[i], thetas[i], sweep.shape[1]))
        return c_alignments[i]

    picked: list[int] = []  # the best clearly different coarse alignments
    for i in np.argsort(-c_scores, kind="stable"):
        if c_scores[i] == -np.inf:  # not scored (the large-map path)
            break
        if all(distinct(c_alignment(i), c_alignment(j), centre, cfg) for j in picked):
            picked.append(int(i))
            if len(picked) == cfg.refine_top:
                break
    # the best coarse rotation on a step/3 grid, its rivals on a 3-point one
    offsets = np.radians(np.linspace(-cfg.step_deg, cfg.step_deg, 7))
    cand = np.concatenate([thetas[picked[0]] + offsets]
                          + [thetas[i] + offsets[1:6:2] for i in picked[1:]])
    if large:  # near each coarse alignment only; the score map of the best rotation whole
        reach = PYRAMID_REACH * cfg.coarse_factor
        # every coarse alignment turned to each rotation about B's centre (the full sweep's
        # best at a rotation may be another alignment's peak)
        lands = [c_alignment(i).apply(centre) for i in picked]
        # the picked rotations themselves on the whole score map, as the full sweep
        whole = [3] + [7 + 3 * m + 1 for m in range(len(picked) - 1)]
        f_scores, f_at = np.full(len(cand), -np.inf), np.full(len(cand), -1, dtype=np.int64)
        for n in sorted(set(range(len(cand))) - set(whole)):
            th = float(cand[n])
            f_scores[n], f_at[n] = max(fine.window_best(th, at - Rigid2D(th).apply(centre),
                                                        reach) for at in lands)
        f_scores[whole], f_at[whole], smap = fine.best(cand[whole], keep_best=True)
        k = int(np.argmax(f_scores))
        if k != whole[int(np.argmax(f_scores[whole]))]:  # smap is that rotation's
            smap = fine.best(cand[k: k + 1], keep_best=True)[2]
    else:
        f_scores, f_at, smap = fine.best(cand, keep_best=True)
        k = int(np.argmax(f_scores))
    f_ts = [fine.translation(kk, th, fine.shape[1]) for kk, th in zip(f_at, cand, strict=True)]
    theta, score, t = float(cand[k]), float(f_scores[k]), f_ts[k]
    estimate = Rigid2D(theta, t)

    # the best clearly different alignment: the other refined rotations, or far-away peaks at
    # this rotation (buildings repeat rooms: a shifted copy can score almost as well)
    r_best, c_best = divmod(int(f_at[k]), smap.shape[1])
    rr, cc = np.ogrid[: smap.shape[0], : smap.shape[1]]
    far = (rr - r_best) ** 2 + (cc - c_best) ** 2 > (cfg.distinct_m / fine_res) ** 2
    rival, rival_t = 0.0, None
    if far.any():
        kf = int(np.argmax(np.where(far, smap, -np.inf)))
        rival, rival_t = float(smap.flat[kf]), Rigid2D(theta, fine.translation(kf, theta,
                                                                                fine.shape[1]))
    for th, sc, tt in zip(cand, f_scores, f_ts, strict=True):
        other = Rigid2D(float(th), tt)
        if sc > rival and distinct(other, estimate, centre, cfg):
            rival, rival_t = float(sc), other

    # sub-cell refinement on wall points, gated to the wall band; then on the grids' own cells
    moved = pts_wall  # on large maps, a regular subsample
    if large and len(pts_wall) > MAX_LARGE_ICP_POINTS:
        moved = pts_wall[:: int(math.ceil(len(pts_wall) / MAX_LARGE_ICP_POINTS))]
    walls_at = cell_centres(wall_a, origin_a, res)
    estimate = icp_refined(walls_at, moved, estimate, res, 1.5 * res, centre, cfg,
                           tree=wall_tree(grid_a, walls_at, ("pooled", res), len(moved)))
    if cfg.native_refine:
        estimate = local_search(grid_a, grid_b, estimate, centre, radius, cfg)
    estimate, native_agreement, native_conflict = native_evidence(grid_a, grid_b, estimate,
                                                                  centre, cfg)

    ev = landing(wall_a, free_a, near_wall_a, origin_a, res, estimate, pts_wall, pts_free,
                      int(free_b.sum()))
    rv = GridAgreement(0.0, 0.0, 1.0, 1.0, 0)
    if rival_t is not None:
        rv = landing(wall_a, free_a, near_wall_a, origin_a, res, rival_t, pts_wall,
                          pts_free, int(free_b.sum()))
    rival_agreement = rv.wall_agreement
    margin = score / rival if rival > 0 else math.inf
    features = grid_features(score, margin, ev.overlap_m2, ev.wall_agreement, ev.conflict,
                             ev.free_conflict, ev.wall_hits, rival_agreement,
                             native_agreement, native_conflict, cfg.drift_prior)
    rule = MergeRule.of(cfg)
    confidence = rule.tie_capped(grid_calibrator(cfg.confidence_model)(features), margin)
    why = rule.grid(confidence, ev.overlap_m2, margin, ev.wall_agreement, ev.conflict)
    return GridMergeResult(estimate, why is None, score, ev.overlap_m2, ev.wall_agreement,
                           ev.conflict, margin, time.perf_counter() - t0, why,
                           (float(centre[0]), float(centre[1])),
                           confidence, ev.free_conflict, ev.wall_hits, rival_agreement,
                           native_agreement, native_conflict, cfg.drift_prior)


def grid_calibrator(name: str = "grid") -> Any:
    """The stored model ``name`` of :mod:`fusion.calibration` (``"grid"`` unless
    :attr:`GridMergeConfig.confidence_model` names another; features of :data:`FEATURES`)."""
    from fusion.calibration import load_model

    return load_model(name)


__all__ = ["FEATURES", "GridAgreement", "GridMergeConfig", "GridMergeResult", "check_with_grids",
           "distinct", "drift_prior", "grid_agreement", "grid_features", "merge_grids",
           "refine_with_grids"]
