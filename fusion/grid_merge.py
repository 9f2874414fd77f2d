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
   sweep runs on layers pooled ``coarse_factor`` times coarser (4× fewer cells at 2), in
   single precision, batched over rotations;
3. the ``refine_top`` best clearly different coarse alignments are scored again at
   ``resolution`` — the best on a ``step_deg / 3`` angle grid around it, the others (its
   rivals) on a ``2·step_deg / 3`` one — and the best is refined by gated ICP-SVD on wall
   cells, then (``native_refine``) on the grids' own cells: two gated ICP passes on their
   occupied cells, after a local correlation at 0.1 m for grids finer than that (so that maps
   of fine cells are aligned as precisely as their cells allow: ``benchmarks/fusion.md``);
4. its evidence — the margin of its score over the best alignment that is clearly different
   (more than ``distinct_deg`` or ``distinct_m`` away: the refined rivals, and far-away peaks
   at the best rotation), the overlapping area, how many of B's walls land on A's known cells
   and how many of them meet an A wall at the grids' own resolution (:meth:`GridMergeResult.
   features`) — gives its **confidence**, the probability that it is right (< 2°, < 0.3 m),
   from a logistic model fitted on tuning map pairs (:mod:`fusion.calibration`, model
   ``"grid"``, refitted by ``benchmarks/calibrate_merge.py``). It is **accepted** when the
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
from typing import Any, NamedTuple

import numpy as np
from scipy import fft as sfft
from scipy import ndimage
from scipy.spatial import cKDTree

from fusion import _kernels as GK
from fusion.icp import icp_svd
from fusion.rigid import Rigid2D
from topo.validation import check_int, check_real

UNKNOWN, FREE, OCCUPIED = 0, 1, 2  # topo.grid.CellState codes

DEFAULT_ACCEPT_THRESHOLD = 0.9
"""Default :attr:`GridMergeConfig.accept_threshold`: the smallest (on a 0.05 grid) at which the
cross-validated tuning alignments of ``benchmarks/calibrate_merge.py`` had at most 1 % false
accepts on no-overlap pairs and 1 % wrong accepts of all pairs."""

DEFAULT_DROP_MARGIN = 0.3
"""Default :attr:`GridMergeConfig.drop_margin` (``benchmarks/drift.md``)."""


def drift_prior(odometry_noise: float, steps: int) -> float:
    """:attr:`GridMergeConfig.drift_prior` of maps made over ``steps`` env steps by robots whose
    odometry has relative noise ``odometry_noise`` (``RobotConfig.odometry_noise``, the larger
    of its two; ``0`` for perfect odometry): ``odometry_noise · steps / 1000``. The drift of a
    frontier robot grows about linearly with the steps (``benchmarks/drift.md``); the confidence
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
    refit it (``benchmarks/calibrate_merge.py``) before trusting its probabilities.
    ``drop_margin``: :func:`fusion.hybrid.recheck` drops the transform in use when the grids'
    alignment of it has a confidence below ``accept_threshold − drop_margin`` (a margin, so
    that a merge is not dropped and re-accepted as the confidence wavers at the threshold).
    ``drift_prior``: how far the maps' odometry may have drifted, :func:`drift_prior` (``0``:
    perfect odometry) — evidence of the confidence model, which the grids alone cannot give:
    drift bends both maps, and how far an alignment of bent maps is from the robots' current
    frames depends on the drift, not on how well the walls fit (``benchmarks/drift.md``);
    above 0, :func:`fusion.hybrid.hybrid_merge` also asks the grids about a structural merge."""

    resolution: float = 0.2
    step_deg: float = 3.0
    conflict: float = 1.0
    free_weight: float = 0.05
    min_overlap_m2: float = 6.0
    min_wall_agreement: float = 0.6
    max_conflict: float = 0.3
    distinct_deg: float = 15.0
    distinct_m: float = 1.5
    coarse_factor: int = 2
    refine_top: int = 3
    accept_threshold: float = DEFAULT_ACCEPT_THRESHOLD
    native_refine: bool = True
    drop_margin: float = DEFAULT_DROP_MARGIN
    drift_prior: float = 0.0

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            if f.name == "native_refine":
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
TIE_MARGIN = 1.05
"""A clearly different alignment scoring within this factor of the best ties with it: at
most one of the two is right, so the confidence is at most 1/2 whatever the model says
(the fitted model can read more into a perfect tie, e.g. a symmetric room, than its tuning
data held; ``benchmarks/fusion.md``)."""


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


def _states(grid: Any) -> np.ndarray:
    s = grid.states() if callable(getattr(grid, "states", None)) else grid.states
    return np.asarray(s)


def _pooled(grid: Any, res: float | tuple[float, ...]
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | list | None:
    """(wall mask, free mask, origin) of ``grid`` cropped to its known cells, pooled to
    cells of exactly ``res`` (a cell is a wall if any fine cell is occupied, free if most are
    free and none is occupied; a pooled cell may cover a fractional number of fine cells, e.g.
    6.7 of 0.03 m: rounding to whole cells would stretch the map by up to 5 %); for a tuple of
    resolutions, a list of them (the grid is read once); ``None`` if nothing is known. Grids
    coarser than ``res`` give pooled layers with gaps."""
    states = _states(grid)
    known = states != UNKNOWN
    rows, cols = np.flatnonzero(known.any(axis=1)), np.flatnonzero(known.any(axis=0))
    if not len(rows):
        return None
    r0, r1, c0, c1 = int(rows[0]), int(rows[-1]), int(cols[0]), int(cols[-1])
    fine = float(grid.resolution)
    origin = np.asarray(grid.origin, dtype=np.float64) + np.array([c0, r0]) * fine
    out = []
    for r in (res if isinstance(res, tuple) else (res,)):
        ratio = fine / r
        h, w = int((r1 - r0 + 0.5) * ratio) + 1, int((c1 - c0 + 0.5) * ratio) + 1
        out.append((*GK.pool(states, r0, c0, h, w, ratio, FREE, OCCUPIED), origin))
    return out if isinstance(res, tuple) else out[0]


def _centres(mask: np.ndarray, origin: np.ndarray, res: float) -> np.ndarray:
    rows, cols = np.nonzero(mask)
    return np.stack([origin[0] + (cols + 0.5) * res, origin[1] + (rows + 0.5) * res], axis=1)


class GridAgreement(NamedTuple):
    """How B's cells moved by a transform land on A's (:func:`grid_agreement`), at
    :attr:`GridMergeConfig.resolution`.

    Attributes:
        overlap_m2: area of B's free space landing on A's known cells.
        wall_agreement: fraction of B's wall cells landing on A's known cells that meet an A
            wall (within one cell).
        conflict: fraction of them landing in A's free space, away from A's walls.
        free_conflict: fraction of B's free cells landing on A's known cells that land on an
            A wall.
        wall_hits: how many of B's wall cells land on A's known cells.
    """

    overlap_m2: float
    wall_agreement: float
    conflict: float
    free_conflict: float
    wall_hits: int

    @property
    def support(self) -> float:
        """B's wall cells on A's walls minus those in A's free space: the net count of walls
        that support the transform, comparable between two transforms of the same grids."""
        return self.wall_hits * (self.wall_agreement - self.conflict)


def _consistency(wall_a, free_a, near_wall_a, origin_a, res, transform, pts_wall, pts_free,
                 n_free_b) -> GridAgreement:
    """How B's wall and free cells moved by ``transform`` land on A's pooled layers."""
    h, w = wall_a.shape

    def cells(pts: np.ndarray) -> np.ndarray:
        ij = np.floor((transform.apply(pts) - origin_a) / res).astype(int)
        return ij[(ij[:, 0] >= 0) & (ij[:, 0] < w) & (ij[:, 1] >= 0) & (ij[:, 1] < h)]

    known_a = wall_a | free_a
    ia = cells(pts_wall)
    on_known = known_a[ia[:, 1], ia[:, 0]]
    hits = ia[on_known]
    agree = float(near_wall_a[hits[:, 1], hits[:, 0]].mean()) if len(hits) else 0.0
    conflict = float((free_a & ~near_wall_a)[hits[:, 1], hits[:, 0]].mean()) if len(hits) else 1.0
    ifm = cells(pts_free)
    ifm = ifm[known_a[ifm[:, 1], ifm[:, 0]]]
    free_conflict = float(wall_a[ifm[:, 1], ifm[:, 0]].mean()) if len(ifm) else 0.0
    step_free = max(1, int(math.ceil(n_free_b / max(len(pts_free), 1))))
    overlap = float(len(ifm)) * step_free * res * res
    return GridAgreement(overlap, agree, conflict, free_conflict, len(hits))


def _consistency_reasons(overlap: float, agree: float, conflict: float,
                         cfg: GridMergeConfig) -> list[str]:
    reasons = []
    if overlap < cfg.min_overlap_m2:
        reasons.append(f"overlap {overlap:.1f} m² < min_overlap_m2={cfg.min_overlap_m2}")
    if agree < cfg.min_wall_agreement:
        reasons.append(f"wall agreement {agree:.2f} < min_wall_agreement="
                       f"{cfg.min_wall_agreement}")
    if conflict > cfg.max_conflict:
        reasons.append(f"conflict {conflict:.2f} > max_conflict={cfg.max_conflict}")
    return reasons


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
    pa, pb = _pooled(grid_a, cfg.resolution), _pooled(grid_b, cfg.resolution)
    if pa is None or pb is None:
        return None
    wall_a, free_a, origin_a = pa
    wall_b, free_b, origin_b = pb
    near_wall_a = ndimage.binary_dilation(wall_a, iterations=1)
    return _consistency(wall_a, free_a, near_wall_a, origin_a, cfg.resolution, transform,
                        _centres(wall_b, origin_b, cfg.resolution),
                        _centres(free_b, origin_b, cfg.resolution), int(free_b.sum()))


def check_with_grids(grid_a: Any, grid_b: Any, transform: Rigid2D,
                     config: GridMergeConfig | None = None) -> str | None:
    """``None`` if the grids agree with ``transform`` (enough overlap, B's walls on A's walls,
    few on A's free space: :func:`grid_agreement` against ``min_overlap_m2``,
    ``min_wall_agreement``, ``max_conflict``), else why not — the check :func:`hybrid_merge`
    puts on a structural merge before trusting it."""
    cfg = config or GridMergeConfig()
    agreement = grid_agreement(grid_a, grid_b, transform, cfg)
    if agreement is None:
        return "a grid has no known cells"
    return "; ".join(_consistency_reasons(*agreement[:3], cfg)) or None


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
    walls_b, _ = _native_walls(grid_b)
    if not cfg.native_refine or len(walls_b) < 3:
        return transform
    centre = walls_b.mean(axis=0)
    refined, near, deep = _native(grid_a, grid_b, transform, centre, cfg,
                                  bound=(cfg.distinct_deg, cfg.distinct_m))
    if (math.degrees(refined.rotation_error(transform)) <= cfg.step_deg
            and refined.translation_error(transform, at=centre) <= 2 * cfg.resolution):
        return refined
    _, near_0, deep_0 = _native(grid_a, grid_b, transform, centre,
                                dataclasses.replace(cfg, native_refine=False))
    return refined if near - deep >= near_0 - deep_0 else transform


class _Correlator:
    """Score of every translation of B's wall and free points, rotated about ``centre``,
    against A's layers at one resolution: ``+1`` per B wall on an A wall (within one cell),
    ``−conflict`` per B wall on A free space and per B free cell on an A wall, ``+free_weight``
    per B free cell on A free space (module doc, step 2). A's layers are transformed once;
    each rotation costs two forward FFTs and one inverse, batched over rotations; only the best
    translation of each rotation is kept (and the score maps when asked for)."""

    def __init__(self, wall_a: np.ndarray, free_a: np.ndarray, origin_a: np.ndarray,
                 res: float, pts_wall: np.ndarray, pts_free: np.ndarray, centre: np.ndarray,
                 radius: float, cfg: GridMergeConfig) -> None:
        self.res, self.origin_a, self.centre = res, origin_a, centre
        self.pts_wall, self.pts_free = pts_wall, pts_free
        near_wall_a = ndimage.binary_dilation(wall_a, iterations=1)
        for_walls = near_wall_a.astype(np.float64) - cfg.conflict * (free_a & ~near_wall_a)
        for_free = cfg.free_weight * free_a - cfg.conflict * wall_a
        # B rotated about ``centre`` fits in a square of side 2·radius
        self.side = int(math.ceil(2 * radius / res)) + 2
        self.half = self.side // 2
        self.shape = (wall_a.shape[0] + self.side, wall_a.shape[1] + self.side)
        self.fshape = tuple(sfft.next_fast_len(n, real=True) for n in self.shape)
        # single precision: scores are sums of a few thousand small terms
        self.fa_walls = sfft.rfft2(for_walls.astype(np.float32), self.fshape, workers=1)
        self.fa_free = sfft.rfft2(for_free.astype(np.float32), self.fshape, workers=1)

    def _kernels(self, pts: np.ndarray, thetas: np.ndarray) -> np.ndarray:
        """``(len(thetas), side, side)`` rasters of ``pts`` rotated about the centre, flipped
        (correlation is convolution with the flipped kernel)."""
        k = np.zeros((len(thetas), self.side, self.side), dtype=np.float32)
        if len(pts):
            GK.raster_rotated(k, pts, float(self.centre[0]), float(self.centre[1]),
                              np.cos(thetas), np.sin(thetas), self.res, self.half)
        return k

    def best(self, thetas: np.ndarray, keep_maps: bool = False
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Per rotation: the best score, the flat index of its translation in the score map
        (:meth:`translation`), and with ``keep_maps`` the ``(len(thetas), H, W)`` score maps
        of every translation (A-cell offsets)."""
        n = len(thetas)
        scores = np.empty(n)
        at = np.empty(n, dtype=np.int64)
        out = np.empty((n,) + self.shape, dtype=np.float32) if keep_maps else None
        rows = np.arange(16)
        for i in range(0, n, 16):  # bounded memory
            th = thetas[i: i + 16]
            spec = self.fa_walls * sfft.rfft2(self._kernels(self.pts_wall, th), self.fshape,
                                              workers=1)
            if len(self.pts_free):
                spec += self.fa_free * sfft.rfft2(self._kernels(self.pts_free, th),
                                                  self.fshape, workers=1)
            smaps = sfft.irfft2(spec, self.fshape, workers=1)[:, : self.shape[0],
                                                               : self.shape[1]]
            flat = smaps.reshape(len(th), -1)
            k = np.argmax(flat, axis=1)
            scores[i: i + 16] = flat[rows[: len(th)], k]
            at[i: i + 16] = k
            if out is not None:
                out[i: i + 16] = smaps
        return scores, at, out

    def index(self, T: np.ndarray, theta: float) -> tuple[float, float]:
        """(row, column) of the score map where translation ``T`` at rotation ``theta`` lies
        (:meth:`translation`'s inverse, not rounded)."""
        c, s = math.cos(theta), math.sin(theta)
        corner = (np.asarray(T) + np.array([[c, -s], [s, c]]) @ self.centre
                  - self.half * self.res - self.origin_a) / self.res
        return corner[1] + self.side - 1, corner[0] + self.side - 1

    def translation(self, k: int, theta: float, width: int) -> np.ndarray:
        """T of the flat score-map index ``k`` at rotation ``theta``: the flipped kernel's
        cell (side-1, side-1), i.e. kernel cell (0, 0) — B's point ``centre - half·res`` —
        lands on A cell (r - side + 1, col - side + 1)."""
        r, col = divmod(int(k), width)
        c, s = math.cos(theta), math.sin(theta)
        corner = self.origin_a + np.array([col - self.side + 1, r - self.side + 1]) * self.res
        return corner + self.half * self.res - np.array([[c, -s], [s, c]]) @ self.centre


def distinct(a: Rigid2D, b: Rigid2D, centre: np.ndarray, cfg: GridMergeConfig) -> bool:
    """Whether two alignments are clearly different (``distinct_deg`` / ``distinct_m`` at B's
    wall centroid)."""
    return (math.degrees(a.rotation_error(b)) > cfg.distinct_deg
            or a.translation_error(b, at=centre) > cfg.distinct_m)


def merge_grids(grid_a: Any, grid_b: Any, config: GridMergeConfig | None = None
                ) -> GridMergeResult:
    """Align occupancy grid B onto grid A (module docstring): the best alignment, its
    evidence and calibrated confidence, accepted or rejected with a reason. Never raises on
    poor input: grids with too little known space come back rejected with a reason.

    The rotation search runs coarse to fine: every ``step_deg`` rotation is scored at
    ``coarse_factor × resolution``; the ``refine_top`` best clearly different rotations are
    scored again at ``resolution`` on a ``step_deg / 3`` grid around each (the best is the
    estimate, the others its rivals, with far-away peaks at the estimate's rotation)."""
    t0 = time.perf_counter()
    cfg = config or GridMergeConfig()
    res = cfg.resolution
    # each grid read once: its layers at full and (if the sweep is coarser) coarse resolution
    both = (res, res * cfg.coarse_factor) if cfg.coarse_factor > 1 else (res,)
    layers_a, layers_b = _pooled(grid_a, both), _pooled(grid_b, both)
    if layers_a is None or layers_b is None:
        return _rejected("a grid has no known cells", t0)
    (wall_a, free_a, origin_a), coarse_a = layers_a[0], layers_a[-1]
    (wall_b, free_b, origin_b), coarse_b = layers_b[0], layers_b[-1]
    if wall_a.sum() < 10 or wall_b.sum() < 10:
        return _rejected("too few wall cells to align", t0)
    near_wall_a = ndimage.binary_dilation(wall_a, iterations=1)
    pts_wall = _centres(wall_b, origin_b, res)
    pts_free = _centres(free_b, origin_b, res)
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
        coarse = _Correlator(ca[0], ca[1], ca[2], cres, _centres(cb[0], cb[2], cres),
                             _centres(cb[1], cb[2], cres), centre, radius + cres, cfg)
    else:
        coarse = None
    fine = _Correlator(wall_a, free_a, origin_a, fine_res, pts_wall, pts_free, centre, radius,
                       cfg)
    sweep = coarse or fine
    c_scores, c_at, _ = sweep.best(thetas)
    c_alignments: dict[int, Rigid2D] = {}  # of the rotations looked at

    def c_alignment(i: int) -> Rigid2D:
        if i not in c_alignments:
            c_alignments[i] = Rigid2D(float(thetas[i]),
                                      sweep.translation(c_at[i], thetas[i], sweep.shape[1]))
        return c_alignments[i]

    picked: list[int] = []  # the best clearly different coarse alignments
    for i in np.argsort(-c_scores, kind="stable"):
        if all(distinct(c_alignment(i), c_alignment(j), centre, cfg) for j in picked):
            picked.append(int(i))
            if len(picked) == cfg.refine_top:
                break
    # the best coarse rotation on a step/3 grid, its rivals on a 3-point one
    offsets = np.radians(np.linspace(-cfg.step_deg, cfg.step_deg, 7))
    cand = np.concatenate([thetas[picked[0]] + offsets]
                          + [thetas[i] + offsets[1:6:2] for i in picked[1:]])
    f_scores, f_at, f_maps = fine.best(cand, keep_maps=True)
    f_ts = [fine.translation(kk, th, fine.shape[1]) for kk, th in zip(f_at, cand, strict=True)]
    k = int(np.argmax(f_scores))
    theta, score, t = float(cand[k]), float(f_scores[k]), f_ts[k]
    estimate = Rigid2D(theta, t)

    # the best clearly different alignment: the other refined rotations, or far-away peaks at
    # this rotation (buildings repeat rooms: a shifted copy can score almost as well)
    smap = f_maps[k]
    r_best, c_best = divmod(int(np.argmax(smap)), smap.shape[1])
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
    estimate = _refined(_centres(wall_a, origin_a, res), pts_wall, estimate, res, 1.5 * res,
                        centre, cfg)
    if cfg.native_refine:
        estimate = _local_search(grid_a, grid_b, estimate, centre, radius, cfg)
    estimate, native_agreement, native_conflict = _native(grid_a, grid_b, estimate, centre, cfg)

    ev = _consistency(wall_a, free_a, near_wall_a, origin_a, res, estimate, pts_wall, pts_free,
                      int(free_b.sum()))
    rv = GridAgreement(0.0, 0.0, 1.0, 1.0, 0)
    if rival_t is not None:
        rv = _consistency(wall_a, free_a, near_wall_a, origin_a, res, rival_t, pts_wall,
                          pts_free, int(free_b.sum()))
    rival_agreement = rv.wall_agreement
    margin = score / rival if rival > 0 else math.inf
    features = grid_features(score, margin, ev.overlap_m2, ev.wall_agreement, ev.conflict,
                             ev.free_conflict, ev.wall_hits, rival_agreement,
                             native_agreement, native_conflict, cfg.drift_prior)
    confidence = grid_calibrator()(features)
    if margin < TIE_MARGIN:
        confidence = min(confidence, 0.5)
    reasons = []
    if ev.overlap_m2 < cfg.min_overlap_m2:
        reasons.append(f"overlap {ev.overlap_m2:.1f} m² < min_overlap_m2={cfg.min_overlap_m2}")
    if confidence < cfg.accept_threshold:
        reasons.append(f"confidence {confidence:.2f} < accept_threshold="
                       f"{cfg.accept_threshold} (margin {margin:.2f} over a distinct "
                       f"alignment, wall agreement {ev.wall_agreement:.2f}, conflict "
                       f"{ev.conflict:.2f})")
    return GridMergeResult(estimate, not reasons, score, ev.overlap_m2, ev.wall_agreement,
                           ev.conflict, margin, time.perf_counter() - t0,
                           "; ".join(reasons) or None, (float(centre[0]), float(centre[1])),
                           confidence, ev.free_conflict, ev.wall_hits, rival_agreement,
                           native_agreement, native_conflict, cfg.drift_prior)


def grid_calibrator() -> Any:
    """The stored ``"grid"`` model of :mod:`fusion.calibration` (features :data:`FEATURES`)."""
    from fusion.calibration import load_model

    return load_model("grid")


def _refined(walls_a: np.ndarray, walls_b: np.ndarray, estimate: Rigid2D, res: float,
             gate: float, centre: np.ndarray, cfg: GridMergeConfig,
             max_iter: int = 30, bound: tuple[float, float] | None = None) -> Rigid2D:
    """``estimate`` refined by gated, trimmed ICP-SVD of B's wall points onto A's, kept only if
    it stays within ``bound`` (degrees, metres at ``centre``; by default ``step_deg`` and two
    ``res``) of ``estimate`` (else ``estimate``)."""
    if len(walls_a) < 3 or len(walls_b) < 3:
        return estimate
    max_deg, max_m = bound or (cfg.step_deg, 2 * res)
    icp = icp_svd(walls_a, walls_b, tau=None, rel_tol=1e-6, max_iter=max_iter, init=estimate,
                  max_distance=gate, trim=0.8)
    if icp.degenerate is None and (
            icp.transform.rotation_error(estimate) < math.radians(max_deg)
            and icp.transform.translation_error(estimate, at=centre) < max_m):
        return icp.transform
    return estimate


LOCAL_CELL = 0.1
"""Cell (m) of the local search that re-places the pooled estimate before the refinement on
the grids' own cells (no finer than the grids' cells)."""
LOCAL_REACH = 1.0
"""The local search keeps the best translation within this (m) of the pooled estimate's."""


def _local_search(grid_a: Any, grid_b: Any, estimate: Rigid2D, centre: np.ndarray,
                  radius: float, cfg: GridMergeConfig) -> Rigid2D:
    """The best alignment within :data:`LOCAL_REACH` and ``step_deg / 3`` of ``estimate`` by
    the correlation score on layers pooled to :data:`LOCAL_CELL` (finer than ``resolution``):
    on maps of fine cells it fixes a rotation the ICP refinement alone can leave degrees off
    (``benchmarks/fusion.md``, fine maps). ``estimate`` itself if the grids' cells are not
    finer than :data:`LOCAL_CELL`."""
    fine = max(float(grid_a.resolution), float(grid_b.resolution))
    cell = LOCAL_CELL
    if fine > 0.75 * cell or cell > 0.75 * cfg.resolution:
        return estimate
    la, lb = _pooled(grid_a, cell), _pooled(grid_b, cell)
    pts_wall, pts_free = _centres(lb[0], lb[2], cell), _centres(lb[1], lb[2], cell)
    if len(pts_wall) < 3:
        return estimate
    if len(pts_free) > 8000:
        pts_free = pts_free[:: int(math.ceil(len(pts_free) / 8000))]
    corr = _Correlator(la[0], la[1], la[2], cell, pts_wall, pts_free, centre, radius + cell, cfg)
    thetas = estimate.theta + np.radians(np.linspace(-cfg.step_deg, cfg.step_deg, 5) / 3)
    _, _, maps = corr.best(thetas, keep_maps=True)
    reach = LOCAL_REACH / cell
    rr, cc = np.ogrid[: corr.shape[0], : corr.shape[1]]
    best, out = -np.inf, estimate
    for th, smap in zip(thetas, maps, strict=True):
        r0, c0 = corr.index(estimate.T, float(th))
        window = (rr - r0) ** 2 + (cc - c0) ** 2 <= reach ** 2
        if not window.any():
            continue
        k = int(np.argmax(np.where(window, smap, -np.inf)))
        if smap.flat[k] > best:
            best = float(smap.flat[k])
            out = Rigid2D(float(th), corr.translation(k, float(th), corr.shape[1]))
    return out


NATIVE_NEAR_M = 0.15
"""A wall cell of B within this of an A wall cell agrees (:attr:`GridMergeResult.
native_agreement`: one cell and its diagonal on the env's 0.1 m grids)."""
NATIVE_DEEP_M = 0.3
"""A wall cell of B on A's free space farther than this from any A wall conflicts
(:attr:`GridMergeResult.native_conflict`)."""
MAX_NATIVE_POINTS = 6000
"""Most wall cells of B the evidence at the grids' own resolution looks at (a regular subsample
beyond: a 0.03 m map of a building has tens of thousands); the refinement moves at most
:data:`MAX_NATIVE_ICP_POINTS` of them."""
MAX_NATIVE_ICP_POINTS = 1200


def _native_walls(grid: Any) -> tuple[np.ndarray, float]:
    """Centres of ``grid``'s occupied cells (its own frame) and its cell size."""
    states = _states(grid)
    rows, cols = np.nonzero(states == OCCUPIED)
    fine = float(grid.resolution)
    origin = np.asarray(grid.origin, dtype=np.float64)
    return np.stack([origin[0] + (cols + 0.5) * fine, origin[1] + (rows + 0.5) * fine],
                    axis=1), fine


def _native(grid_a: Any, grid_b: Any, estimate: Rigid2D, centre: np.ndarray,
            cfg: GridMergeConfig, bound: tuple[float, float] | None = None
            ) -> tuple[Rigid2D, float, float]:
    """At the grids' own cells: ``estimate`` refined (when ``native_refine`` and the cells are
    finer than ``resolution``: real maps of 0.03–0.05 m cells carry walls far sharper than the
    search's pooled cells), and how B's wall cells that land on A's known cells lie: the
    fraction within :data:`NATIVE_NEAR_M` of an A wall cell, and the fraction in A's free
    space farther than :data:`NATIVE_DEEP_M` from any — sharper evidence than the pooled
    layers'. The distances are fixed in metres so that the calibrated confidence reads the same
    evidence on grids of any cell size."""
    walls_a, fine_a = _native_walls(grid_a)
    walls_b, fine_b = _native_walls(grid_b)
    if len(walls_a) < 3 or len(walls_b) < 3:
        return estimate, 0.0, 0.0
    if len(walls_b) > MAX_NATIVE_POINTS:
        walls_b = walls_b[:: int(math.ceil(len(walls_b) / MAX_NATIVE_POINTS))]
    fine = max(fine_a, fine_b)
    if cfg.native_refine and fine <= 0.75 * cfg.resolution:
        sub = walls_b[:: int(math.ceil(len(walls_b) / MAX_NATIVE_ICP_POINTS))]
        # the pooled estimate is within about one pooled cell; then a tighter gate
        estimate = _refined(walls_a, sub, estimate, cfg.resolution, cfg.resolution, centre,
                            cfg, max_iter=15, bound=bound)
        estimate = _refined(walls_a, sub, estimate, cfg.resolution, 2.5 * fine, centre, cfg,
                            max_iter=15, bound=bound)
    states_a = _states(grid_a)
    ij = np.floor((estimate.apply(walls_b) - np.asarray(grid_a.origin)) / fine_a).astype(int)
    h, w = states_a.shape
    ij = ij[(ij[:, 0] >= 0) & (ij[:, 0] < w) & (ij[:, 1] >= 0) & (ij[:, 1] < h)]
    on = states_a[ij[:, 1], ij[:, 0]]
    known = on != UNKNOWN
    if not known.any():
        return estimate, 0.0, 0.0
    pts = (ij[known] + 0.5) * fine_a + np.asarray(grid_a.origin)
    d = cKDTree(walls_a).query(pts, k=1, distance_upper_bound=NATIVE_DEEP_M + fine_a,
                               workers=1)[0]
    near = float(np.mean(d <= NATIVE_NEAR_M))
    deep = float(np.mean((d > NATIVE_DEEP_M) & (on[known] == FREE)))
    return estimate, near, deep


__all__ = ["FEATURES", "GridAgreement", "GridMergeConfig", "GridMergeResult", "check_with_grids",
           "distinct", "drift_prior", "grid_agreement", "grid_features", "merge_grids",
           "refine_with_grids"]
