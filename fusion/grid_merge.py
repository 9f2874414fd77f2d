"""``merge_grids``: global alignment of two occupancy grids by rotation search and FFT
cross-correlation (the classic grid map-merging recipe, cf. Carpin 2008), with an explicit
accept rule.

Sonar topological maps of the same building disagree a lot (the 15° cones smear walls and
leak free space through them), so on the robots' own maps the structural merge
(:func:`fusion.merge_maps`) rarely finds a confident alignment. The grids themselves carry far
more evidence — every wall cell — so this method aligns them directly:

1. both grids are cropped to their known cells and pooled to ``resolution`` (a cell is a wall
   if any fine cell is occupied, free if most are free);
2. for every rotation ``θ`` in ``step_deg`` steps, B's wall and free cells are rotated and
   rasterised, and one FFT cross-correlation per layer scores **every** translation at once:
   ``+1`` per B wall on an A wall (within one cell), ``−conflict`` per B wall on A free space
   and per B free cell on an A wall, ``+free_weight`` per B free cell on A free space;
3. the best ``(θ, t)`` is refined on a finer angle grid, then by gated ICP-SVD on wall cells;
4. it is **accepted** only if enough area overlaps (``min_overlap_m2``), enough of B's walls
   that land on A's known cells meet A's walls (``min_wall_agreement``), few land in A's free
   space (``max_conflict``), and the score beats the best alignment that is clearly different
   (more than ``distinct_deg`` or ``distinct_m`` away) by a factor ``min_margin`` — symmetric
   buildings are rejected rather than merged wrongly.

All inputs are duck-typed grids: :class:`topo.OccupancyGrid` or :class:`fusion.pairs.GridSnapshot`
(anything with cell-state codes — ``states()`` or ``states`` — ``resolution`` and ``origin``).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import fft as sfft
from scipy import ndimage

from fusion.icp import icp_svd
from fusion.rigid import Rigid2D
from topo._checks import check_real

UNKNOWN, FREE, OCCUPIED = 0, 1, 2  # topo.grid.CellState codes


@dataclass(frozen=True, slots=True)
class GridMergeConfig:
    """Settings of :func:`merge_grids` (metres, degrees; validated)."""

    resolution: float = 0.2
    step_deg: float = 3.0
    conflict: float = 1.0
    free_weight: float = 0.05
    min_overlap_m2: float = 6.0
    min_wall_agreement: float = 0.6
    max_conflict: float = 0.3
    min_margin: float = 2.0
    distinct_deg: float = 15.0
    distinct_m: float = 1.5

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            check_real(getattr(self, f.name), f"GridMergeConfig.{f.name}", low=0.0)
        check_real(self.min_wall_agreement, "GridMergeConfig.min_wall_agreement", low=0.0,
                   high=1.0)


@dataclass(frozen=True, slots=True)
class GridMergeResult:
    """What :func:`merge_grids` found: ``transform`` (B → A), ``accepted``, ``score`` and the
    numbers behind the decision; ``reason`` when rejected."""

    transform: Rigid2D
    accepted: bool
    score: float
    overlap_m2: float
    wall_agreement: float
    conflict: float
    margin: float
    time_s: float
    reason: str | None = None


def _states(grid: Any) -> np.ndarray:
    s = grid.states() if callable(getattr(grid, "states", None)) else grid.states
    return np.asarray(s)


def _pooled(grid: Any, res: float) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(wall mask, free mask, origin) of ``grid`` cropped to its known cells, pooled to
    ``res``; ``None`` if nothing is known."""
    states = _states(grid)
    known = states != UNKNOWN
    rows, cols = np.nonzero(known)
    if len(rows) == 0:
        return None
    fine = float(grid.resolution)
    f = max(1, int(round(res / fine)))
    r0, c0 = rows.min(), cols.min()
    h = (rows.max() - r0) // f + 1
    w = (cols.max() - c0) // f + 1
    crop = np.zeros((h * f, w * f), dtype=states.dtype)
    part = states[r0: r0 + h * f, c0: c0 + w * f]
    crop[: part.shape[0], : part.shape[1]] = part
    blocks = crop.reshape(h, f, w, f)
    wall = (blocks == OCCUPIED).any(axis=(1, 3))
    free = ((blocks == FREE).sum(axis=(1, 3)) * 2 > f * f) & ~wall
    origin = np.asarray(grid.origin, dtype=np.float64) + np.array([c0, r0]) * fine
    return wall, free, origin


def _centres(mask: np.ndarray, origin: np.ndarray, res: float) -> np.ndarray:
    rows, cols = np.nonzero(mask)
    return np.stack([origin[0] + (cols + 0.5) * res, origin[1] + (rows + 0.5) * res], axis=1)


def _consistency(wall_a, free_a, near_wall_a, origin_a, res, transform, pts_wall, pts_free,
                 n_free_b) -> tuple[float, float, float]:
    """(overlap m², wall agreement, conflict) of B's wall and free cells moved by
    ``transform`` onto A's pooled layers."""
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
    step_free = max(1, int(math.ceil(n_free_b / max(len(pts_free), 1))))
    overlap = float(known_a[ifm[:, 1], ifm[:, 0]].sum()) * step_free * res * res
    return overlap, agree, conflict


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


def check_with_grids(grid_a: Any, grid_b: Any, transform: Rigid2D,
                     config: GridMergeConfig | None = None) -> str | None:
    """``None`` if the grids agree with ``transform`` (enough overlap, B's walls on A's walls,
    few on A's free space), else why not — the check :func:`hybrid_merge` puts on a structural
    merge before trusting it."""
    cfg = config or GridMergeConfig()
    pa, pb = _pooled(grid_a, cfg.resolution), _pooled(grid_b, cfg.resolution)
    if pa is None or pb is None:
        return "a grid has no known cells"
    wall_a, free_a, origin_a = pa
    wall_b, free_b, origin_b = pb
    near_wall_a = ndimage.binary_dilation(wall_a, iterations=1)
    numbers = _consistency(wall_a, free_a, near_wall_a, origin_a, cfg.resolution, transform,
                           _centres(wall_b, origin_b, cfg.resolution),
                           _centres(free_b, origin_b, cfg.resolution), int(free_b.sum()))
    return "; ".join(_consistency_reasons(*numbers, cfg)) or None


def merge_grids(grid_a: Any, grid_b: Any, config: GridMergeConfig | None = None
                ) -> GridMergeResult:
    """Align occupancy grid B onto grid A (module docstring); never raises on poor input:
    grids with too little known space come back rejected with a reason."""
    t0 = time.perf_counter()
    cfg = config or GridMergeConfig()
    res = cfg.resolution
    pa, pb = _pooled(grid_a, res), _pooled(grid_b, res)
    identity = Rigid2D.identity()
    if pa is None or pb is None:
        return GridMergeResult(identity, False, 0.0, 0.0, 0.0, 0.0, 0.0,
                               time.perf_counter() - t0, "a grid has no known cells")
    wall_a, free_a, origin_a = pa
    wall_b, free_b, origin_b = pb
    if wall_a.sum() < 10 or wall_b.sum() < 10:
        return GridMergeResult(identity, False, 0.0, 0.0, 0.0, 0.0, 0.0,
                               time.perf_counter() - t0, "too few wall cells to align")
    near_wall_a = ndimage.binary_dilation(wall_a, iterations=1)
    # A's layers scored against B's walls and B's free cells
    for_walls = near_wall_a.astype(np.float64) - cfg.conflict * (free_a & ~near_wall_a)
    for_free = cfg.free_weight * free_a - cfg.conflict * wall_a
    pts_wall = _centres(wall_b, origin_b, res)
    pts_free = _centres(free_b, origin_b, res)
    if len(pts_free) > 4000:  # free space is only a weak term: a regular subsample is enough
        pts_free = pts_free[:: int(math.ceil(len(pts_free) / 4000))]
    centre = pts_wall.mean(axis=0)

    # B rotated about its wall centroid fits in a square of side 2·radius; A's layers are
    # transformed once at the padded size, each rotation costs two forward FFTs and one inverse
    # (the two correlations are summed in the frequency domain)
    radius = float(np.max(np.linalg.norm(np.vstack([pts_wall, pts_free]) - centre, axis=1)))
    side = int(math.ceil(2 * radius / res)) + 2
    shape = (wall_a.shape[0] + side, wall_a.shape[1] + side)
    fshape = tuple(sfft.next_fast_len(n, real=True) for n in shape)
    fa_walls = sfft.rfft2(for_walls, fshape)
    fa_free = sfft.rfft2(for_free, fshape)
    half = side // 2

    def score_map(theta: float) -> tuple[np.ndarray, np.ndarray]:
        """Score of every translation for rotation ``theta`` (A-cell offsets) and R."""
        c, s = math.cos(theta), math.sin(theta)
        rot = np.array([[c, -s], [s, c]])
        kw = np.zeros((side, side))
        kf = np.zeros((side, side))
        iw = np.floor(((pts_wall - centre) @ rot.T) / res).astype(int) + half
        kw[iw[:, 1], iw[:, 0]] = 1.0
        if len(pts_free):
            ifr = np.floor(((pts_free - centre) @ rot.T) / res).astype(int) + half
            kf[ifr[:, 1], ifr[:, 0]] = 1.0
        # correlation = convolution with the flipped kernel
        spec = fa_walls * sfft.rfft2(kw[::-1, ::-1], fshape)
        spec += fa_free * sfft.rfft2(kf[::-1, ::-1], fshape)
        return sfft.irfft2(spec, fshape)[: shape[0], : shape[1]], rot

    def to_translation(r: int, col: int, rot: np.ndarray) -> np.ndarray:
        # flipped-kernel cell (side-1, side-1), i.e. kernel cell (0, 0), lands on A cell
        # (r - side + 1, col - side + 1); kernel cell (0, 0) is B's point centre - half·res
        corner = origin_a + np.array([col - side + 1, r - side + 1]) * res
        return corner + half * res - rot @ centre

    def score_at(theta: float) -> tuple[float, np.ndarray]:
        """Best translation for rotation ``theta``: (score, T)."""
        smap, rot = score_map(theta)
        k = int(np.argmax(smap))
        r, col = divmod(k, smap.shape[1])
        return float(smap[r, col]), to_translation(r, col, rot)

    thetas = np.radians(np.arange(0.0, 360.0, cfg.step_deg))
    results = [score_at(th) for th in thetas]
    scores = np.array([r[0] for r in results])
    best = int(np.argmax(scores))
    # refine the angle around the best coarse one
    fine = thetas[best] + np.radians(np.linspace(-cfg.step_deg, cfg.step_deg, 7))
    fine_results = [score_at(th) for th in fine]
    k = int(np.argmax([r[0] for r in fine_results]))
    theta, (score, t) = float(fine[k]), fine_results[k]
    estimate = Rigid2D(theta, t)

    # the best clearly different alignment: other angles, or far-away peaks at this angle
    # (buildings repeat rooms: a shifted copy can score almost as well)
    smap, rot = score_map(theta)
    r_best, c_best = divmod(int(np.argmax(smap)), smap.shape[1])
    rr, cc = np.ogrid[: smap.shape[0], : smap.shape[1]]
    far = (rr - r_best) ** 2 + (cc - c_best) ** 2 > (cfg.distinct_m / res) ** 2
    rival = float(smap[far].max()) if far.any() else 0.0
    for th, (s, tt) in zip(thetas, results, strict=True):
        other = Rigid2D(float(th), tt)
        if (math.degrees(other.rotation_error(estimate)) > cfg.distinct_deg
                or other.translation_error(estimate, at=centre) > cfg.distinct_m):
            rival = max(rival, s)

    # sub-cell refinement on wall points, gated to the wall band
    walls_a_pts = _centres(wall_a, origin_a, res)
    moved = estimate.apply(pts_wall)
    if len(walls_a_pts) >= 3 and len(moved) >= 3:
        icp = icp_svd(walls_a_pts, pts_wall, tau=None, rel_tol=1e-6, max_iter=30, init=estimate,
                      max_distance=1.5 * res, trim=0.8)
        if icp.degenerate is None and (
                icp.transform.rotation_error(estimate) < math.radians(cfg.step_deg)
                and icp.transform.translation_error(estimate, at=centre) < 2 * res):
            estimate = icp.transform
            moved = estimate.apply(pts_wall)

    overlap, agree, conflict = _consistency(wall_a, free_a, near_wall_a, origin_a, res,
                                            estimate, pts_wall, pts_free, int(free_b.sum()))
    margin = score / rival if rival > 0 else math.inf

    reasons = _consistency_reasons(overlap, agree, conflict, cfg)
    if margin < cfg.min_margin:
        reasons.append(f"ambiguous: a distinct alignment scores {rival:.1f} against "
                       f"{score:.1f} (margin {margin:.2f} < min_margin={cfg.min_margin})")
    return GridMergeResult(estimate, not reasons, score, overlap, agree, conflict, margin,
                           time.perf_counter() - t0, "; ".join(reasons) or None)


HYBRID_EPS = 0.6
"""Node fusion radius (m) when a grid alignment builds the merged topological map: sonar
topological maps of the same place put their nodes ~0.5 m apart."""


def hybrid_merge(map_a: Any, map_b: Any, grid_a: Any, grid_b: Any, *,
                 try_grids: bool = True, config: GridMergeConfig | None = None) -> Any:
    """The structural merge first (:func:`fusion.merge_maps`, ``"auto"``) — kept only if the
    grids agree with it (:func:`check_with_grids`) — and if it fails, the grid alignment
    (:func:`merge_grids`) when ``try_grids``; returns a
    :class:`fusion.MergeResult` (``method="hybrid"``). An accepted grid alignment fuses the
    topological maps at nodes within :data:`HYBRID_EPS`; a double rejection keeps the
    structural result with both reasons."""
    from scipy.spatial import cKDTree

    from fusion.merge import MergeResult, fuse_maps, merge_maps

    t0 = time.perf_counter()
    topo = merge_maps(map_a, map_b, method="auto")
    if topo.accepted:
        # sonar topological maps fool the structural merge now and then: the grids must agree
        why = check_with_grids(grid_a, grid_b, topo.transform, config)
        if why is None:
            return dataclasses.replace(topo, method="hybrid", time_s=time.perf_counter() - t0)
        topo = dataclasses.replace(topo, accepted=False, merged=map_a,
                                   reason=f"structural merge refuted by the grids: {why}")
    if not try_grids:
        return dataclasses.replace(topo, method="hybrid", time_s=time.perf_counter() - t0)
    grid = merge_grids(grid_a, grid_b, config)
    if not grid.accepted:
        return dataclasses.replace(
            topo, method="hybrid", time_s=time.perf_counter() - t0,
            reason=f"topology: {topo.reason}; grids: {grid.reason}")
    moved = grid.transform.apply(map_b.xy)
    matches = np.empty((0, 2), dtype=np.int64)
    if map_a.n_nodes and map_b.n_nodes:
        d, idx = cKDTree(map_a.xy).query(moved, distance_upper_bound=HYBRID_EPS)
        keep = np.isfinite(d)
        matches = np.stack([idx[keep], np.flatnonzero(keep)], axis=1).astype(np.int64)
        # one B node per A node: the closest
        order = np.argsort(d[keep], kind="stable")
        _, first = np.unique(matches[order, 0], return_index=True)
        matches = matches[order[first]]
    merged = fuse_maps(map_a, map_b, grid.transform, matches, HYBRID_EPS)
    return MergeResult(transform=grid.transform, accepted=True, score=grid.margin,
                       matches=matches, merged=merged, method="hybrid",
                       time_s=time.perf_counter() - t0, reason=None, evidence=None)
