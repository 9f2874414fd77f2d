"""The grid alignment's refinement: gated ICP-SVD of wall cells (:func:`refined`), a local
correlation search on fine layers (:func:`local_search`) and the evidence and refinement at the
grids' own cells (:func:`native`). What :func:`fusion.grid_merge.merge_grids` and
:func:`fusion.grid_merge.refine_with_grids` finish an alignment with; split from
``fusion.grid_merge`` to keep each module about one thing. ``cfg`` arguments are
:class:`fusion.grid_merge.GridMergeConfig`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.spatial import cKDTree

from fusion.grid_layers import (
    FREE,
    OCCUPIED,
    UNKNOWN,
    Correlator,
    LayerCache,
    cell_states,
    centres_of,
    pooled_layers,
    score_layers_of,
    true_cells,
)
from fusion.icp import BRUTE_FORCE_MAX_PAIRS, icp_svd
from fusion.rigid import Rigid2D

if TYPE_CHECKING:
    from fusion.grid_merge import GridMergeConfig


def icp_refined(walls_a: np.ndarray, walls_b: np.ndarray, estimate: Rigid2D, res: float,
             gate: float, centre: np.ndarray, cfg: GridMergeConfig,
             max_iter: int = 30, bound: tuple[float, float] | None = None,
             tree: cKDTree | None = None) -> Rigid2D:
    """``estimate`` refined by gated, trimmed ICP-SVD of B's wall points onto A's, kept only if
    it stays within ``bound`` (degrees, metres at ``centre``; by default ``step_deg`` and two
    ``res``) of ``estimate`` (else ``estimate``). ``tree``: a ``cKDTree`` of ``walls_a``
    already built (:func:`wall_tree`), or ``None``."""
    if len(walls_a) < 3 or len(walls_b) < 3:
        return estimate
    max_deg, max_m = bound or (cfg.step_deg, 2 * res)
    icp = icp_svd(walls_a, walls_b, tau=None, rel_tol=1e-6, max_iter=max_iter, init=estimate,
                  max_distance=gate, trim=0.8, tree=tree)
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


def local_search(grid_a: Any, grid_b: Any, estimate: Rigid2D, centre: np.ndarray,
                  radius: float, cfg: GridMergeConfig) -> Rigid2D:
    """The best alignment within :data:`LOCAL_REACH` and ``step_deg / 3`` of ``estimate`` by
    the correlation score on layers pooled to :data:`LOCAL_CELL` (finer than ``resolution``;
    only the translations within reach are scored, :meth:`Correlator.window_best`):
    on maps of fine cells it fixes a rotation the ICP refinement alone can leave degrees off
    (``docs/notes/fusion.md``, fine maps). ``estimate`` itself if the grids' cells are not
    finer than :data:`LOCAL_CELL`."""
    fine = max(float(grid_a.resolution), float(grid_b.resolution))
    cell = LOCAL_CELL
    if fine > 0.75 * cell or cell > 0.75 * cfg.resolution:
        return estimate
    la, lb = pooled_layers(grid_a, cell), pooled_layers(grid_b, cell)
    pts_wall, pts_free = centres_of(grid_b, *lb, cell, cell)
    if len(pts_wall) < 3:
        return estimate
    if len(pts_free) > 8000:
        pts_free = pts_free[:: int(math.ceil(len(pts_free) / 8000))]
    corr = Correlator(la[0], la[1], la[2], cell, pts_wall, pts_free, centre, radius + cell, cfg,
                      score_layers_of(grid_a, la[0], la[1], cfg, cell))
    thetas = estimate.theta + np.radians(np.linspace(-cfg.step_deg, cfg.step_deg, 5) / 3)
    best, out = -np.inf, estimate
    for th in thetas:  # only the translations within reach are scored (not the whole map)
        score, k = corr.window_best(float(th), estimate.T, LOCAL_REACH / cell)
        if score > best:
            best = score
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


def native_walls(grid: Any) -> tuple[np.ndarray, float]:
    """Centres of ``grid``'s occupied cells (its own frame) and its cell size (computed once
    for a :class:`fusion.grid_layers.LayerCache`, then read-only)."""
    if not isinstance(grid, LayerCache):
        return _walls(cell_states(grid), float(grid.resolution), grid.origin), float(
            grid.resolution)
    if "native_walls" not in grid.memo:
        walls = _walls(grid.states, grid.resolution, grid.origin)
        walls.flags.writeable = False
        grid.memo["native_walls"] = walls, grid.resolution
    return grid.memo["native_walls"]


def wall_tree(grid: Any, walls: np.ndarray, key: Any, n_moved: int = 0) -> cKDTree | None:
    """A ``cKDTree`` of ``walls`` (wall points of ``grid``), for ICP onto them and distances to
    them: built once per ``key`` for a :class:`fusion.grid_layers.LayerCache` (a map aligned
    with several others reuses it), else built here. ``None`` when ICP moving ``n_moved``
    points onto ``walls`` would not use a tree (:data:`fusion.icp.BRUTE_FORCE_MAX_PAIRS`) and
    none is cached yet."""
    memo = grid.memo if isinstance(grid, LayerCache) else {}
    name = ("wall_tree", key)
    if name not in memo:
        if len(walls) * n_moved <= BRUTE_FORCE_MAX_PAIRS:
            return None
        memo[name] = cKDTree(walls)
    return memo[name]


def _walls(states: np.ndarray, fine: float, origin: Any) -> np.ndarray:
    rows, cols = true_cells(states == OCCUPIED)
    origin = np.asarray(origin, dtype=np.float64)
    return np.stack([origin[0] + (cols + 0.5) * fine, origin[1] + (rows + 0.5) * fine], axis=1)


def native_evidence(grid_a: Any, grid_b: Any, estimate: Rigid2D, centre: np.ndarray,
            cfg: GridMergeConfig, bound: tuple[float, float] | None = None
            ) -> tuple[Rigid2D, float, float]:
    """At the grids' own cells: ``estimate`` refined (when ``native_refine`` and the cells are
    finer than ``resolution``: real maps of 0.03–0.05 m cells carry walls far sharper than the
    search's pooled cells), and how B's wall cells that land on A's known cells lie: the
    fraction within :data:`NATIVE_NEAR_M` of an A wall cell, and the fraction in A's free
    space farther than :data:`NATIVE_DEEP_M` from any — sharper evidence than the pooled
    layers'. The distances are fixed in metres so that the calibrated confidence reads the same
    evidence on grids of any cell size."""
    walls_a, fine_a = native_walls(grid_a)
    walls_b, fine_b = native_walls(grid_b)
    if len(walls_a) < 3 or len(walls_b) < 3:
        return estimate, 0.0, 0.0
    if len(walls_b) > MAX_NATIVE_POINTS:
        walls_b = walls_b[:: int(math.ceil(len(walls_b) / MAX_NATIVE_POINTS))]
    fine = max(fine_a, fine_b)
    # A's walls' tree: built once for the ICP passes and the distances below
    tree = wall_tree(grid_a, walls_a, "native", math.inf)
    if cfg.native_refine and fine <= 0.75 * cfg.resolution:
        sub = walls_b[:: int(math.ceil(len(walls_b) / MAX_NATIVE_ICP_POINTS))]
        # the pooled estimate is within about one pooled cell; then a tighter gate
        estimate = icp_refined(walls_a, sub, estimate, cfg.resolution, cfg.resolution, centre,
                            cfg, max_iter=15, bound=bound, tree=tree)
        estimate = icp_refined(walls_a, sub, estimate, cfg.resolution, 2.5 * fine, centre, cfg,
                            max_iter=15, bound=bound, tree=tree)
    states_a = cell_states(grid_a)
    ij = np.floor((estimate.apply(walls_b) - np.asarray(grid_a.origin)) / fine_a).astype(int)
    h, w = states_a.shape
    ij = ij[(ij[:, 0] >= 0) & (ij[:, 0] < w) & (ij[:, 1] >= 0) & (ij[:, 1] < h)]
    on = states_a[ij[:, 1], ij[:, 0]]
    known = on != UNKNOWN
    if not known.any():
        return estimate, 0.0, 0.0
    pts = (ij[known] + 0.5) * fine_a + np.asarray(grid_a.origin)
    d = tree.query(pts, k=1, distance_upper_bound=NATIVE_DEEP_M + fine_a, workers=1)[0]
    near = float(np.mean(d <= NATIVE_NEAR_M))
    deep = float(np.mean((d > NATIVE_DEEP_M) & (on[known] == FREE)))
    return estimate, near, deep
