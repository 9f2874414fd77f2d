"""The grid alignment's layers: occupancy grids cropped to their known cells and pooled to one
resolution (:func:`pooled_layers`), how B's cells moved by a transform land on A's
(:func:`landing`, :class:`GridAgreement`), and the FFT correlation that scores every
translation of B at once (:class:`Correlator`). What :func:`fusion.grid_merge.merge_grids`
is built from; split from it to keep each module about one thing.

Grids are duck-typed: anything with cell-state codes (``cell_states()`` or ``states``),
``resolution`` and ``origin``. ``cfg`` arguments are :class:`fusion.grid_merge.GridMergeConfig`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
from scipy import fft as sfft

from fusion import _kernels as GK

UNKNOWN, FREE, OCCUPIED = 0, 1, 2  # topo.grid.CellState codes

if TYPE_CHECKING:
    from fusion.grid_merge import GridMergeConfig


def cell_states(grid: Any) -> np.ndarray:
    """``grid``'s ``(H, W)`` cell-state codes, whether it offers them as ``states()`` (a
    ``topo.OccupancyGrid``) or as an array attribute ``states`` (a snapshot)."""
    s = grid.states() if callable(getattr(grid, "states", None)) else grid.states
    return np.asarray(s)


def pooled_layers(grid: Any, res: float | tuple[float, ...]
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | list | None:
    """(wall mask, free mask, origin) of ``grid`` cropped to its known cells, pooled to
    cells of exactly ``res`` (a cell is a wall if any fine cell is occupied, free if most are
    free and none is occupied; a pooled cell may cover a fractional number of fine cells, e.g.
    6.7 of 0.03 m: rounding to whole cells would stretch the map); for a tuple of
    resolutions, a list of them (the grid is read once); ``None`` if nothing is known. Grids
    coarser than ``res`` give pooled layers with gaps. A :class:`LayerCache` pools each
    resolution once (its arrays are read-only)."""
    if isinstance(grid, LayerCache):
        out = [grid.pooled(r) for r in (res if isinstance(res, tuple) else (res,))]
        return None if out[0] is None else out if isinstance(res, tuple) else out[0]
    states = cell_states(grid)
    box = known_box(states)
    if box is None:
        return None
    out = [_pooled(states, box, float(grid.resolution), grid.origin, r)
           for r in (res if isinstance(res, tuple) else (res,))]
    return out if isinstance(res, tuple) else out[0]


def known_box(states: np.ndarray) -> tuple[int, int, int, int] | None:
    """First and last row, first and last column of ``states``' known cells (``None`` if
    none is known)."""
    known = states != UNKNOWN
    rows, cols = np.flatnonzero(known.any(axis=1)), np.flatnonzero(known.any(axis=0))
    if not len(rows):
        return None
    return int(rows[0]), int(rows[-1]), int(cols[0]), int(cols[-1])


def _pooled(states: np.ndarray, box: tuple[int, int, int, int], fine: float, origin: Any,
            res: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`pooled_layers` at one resolution, of the known ``box``."""
    r0, r1, c0, c1 = box
    corner = np.asarray(origin, dtype=np.float64) + np.array([c0, r0]) * fine
    ratio = fine / res
    h, w = int((r1 - r0 + 0.5) * ratio) + 1, int((c1 - c0 + 0.5) * ratio) + 1
    return (*GK.pool(states, r0, c0, h, w, ratio, FREE, OCCUPIED), corner)


class LayerCache:
    """A grid whose cell states, known box, pooled layers (:func:`pooled_layers`), occupied
    cells (:func:`fusion.grid_refine.native_walls`) and KD-trees of its wall points
    (:func:`fusion.grid_refine.wall_tree`) are each computed once, on first use: what one map
    merged with several others (:func:`fusion.mapmerge.merge_maps_n`), or read at several
    resolutions in one :func:`fusion.grid_merge.merge_grids`, would otherwise recompute.
    A snapshot: ``grid`` must not change while the cache is in use.

    Attributes:
        states: ``grid``'s ``(H, W)`` cell-state codes (read once: ``states()`` called, or
            the ``states`` array itself, not copied).
        resolution: its cell size (m).
        origin: the lower-left corner of its cell ``(0, 0)``.
        memo: other modules' results of the grid, by name (e.g. ``"native_walls"``).
    """

    def __init__(self, grid: Any) -> None:
        self.states = cell_states(grid)
        self.resolution = float(grid.resolution)
        self.origin = np.asarray(grid.origin, dtype=np.float64)
        self._box: tuple | None = None
        self._pooled: dict[float, tuple | None] = {}
        self.memo: dict[str, Any] = {}

    @classmethod
    def of(cls, grid: Any) -> LayerCache:
        """``grid`` itself if it is a :class:`LayerCache`, else a new one of it."""
        return grid if isinstance(grid, LayerCache) else cls(grid)

    def pooled(self, res: float) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """:func:`pooled_layers` at ``res`` (one resolution), computed once."""
        if res not in self._pooled:
            if self._box is None:
                self._box = known_box(self.states) or ()
            layers = (_pooled(self.states, self._box, self.resolution, self.origin, res)
                      if self._box else None)
            for a in layers or ():
                a.flags.writeable = False
            self._pooled[res] = layers
        return self._pooled[res]


def cached(grid: Any, key: Any, make: Any) -> Any:
    """``make()``, computed once per ``key`` for a :class:`LayerCache` (kept in its
    :attr:`~LayerCache.memo`; its arrays made read-only), else computed here: what depends
    only on one grid (and the settings in ``key``) is then shared by all its pairs."""
    if not isinstance(grid, LayerCache):
        return make()
    if key not in grid.memo:
        value = make()
        for a in value if isinstance(value, tuple) else (value,):
            if isinstance(a, np.ndarray):
                a.flags.writeable = False
        grid.memo[key] = value
    return grid.memo[key]


def centres_of(grid: Any, wall: np.ndarray, free: np.ndarray, origin: np.ndarray, res: float,
               key: Any) -> tuple[np.ndarray, np.ndarray]:
    """:func:`cell_centres` of ``grid``'s pooled ``wall`` and ``free`` layers (cells ``res``
    wide), computed once per ``key`` (:func:`cached`)."""
    return cached(grid, ("centres", key), lambda: (cell_centres(wall, origin, res),
                                                   cell_centres(free, origin, res)))


def score_layers(wall_a: np.ndarray, free_a: np.ndarray, cfg: GridMergeConfig
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What :class:`Correlator` scores B's cells against, from A's pooled layers: A's walls
    dilated by one cell, and the terms met by a B wall and by a B free cell per A cell
    (single precision: scores are sums of a few thousand small terms)."""
    near_wall_a = dilated(wall_a)
    for_walls = near_wall_a.astype(np.float64) - cfg.conflict * (free_a & ~near_wall_a)
    for_free = cfg.free_weight * free_a - cfg.conflict * wall_a
    return near_wall_a, for_walls.astype(np.float32), for_free.astype(np.float32)


def dilated(mask: np.ndarray) -> np.ndarray:
    """``mask`` dilated by one cell along rows and columns: ``scipy.ndimage.binary_dilation``
    with its default (cross) structure and one iteration, by shifted ORs (many times faster
    on large grids)."""
    out = mask.copy()
    out[1:] |= mask[:-1]
    out[:-1] |= mask[1:]
    out[:, 1:] |= mask[:, :-1]
    out[:, :-1] |= mask[:, 1:]
    return out


def score_layers_of(grid: Any, wall_a: np.ndarray, free_a: np.ndarray, cfg: GridMergeConfig,
                    key: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`score_layers` of ``grid``'s pooled ``wall_a``, ``free_a``, computed once per
    ``key`` (:func:`cached`, with the settings it depends on)."""
    return cached(grid, ("score_layers", key, cfg.conflict, cfg.free_weight),
                  lambda: score_layers(wall_a, free_a, cfg))


def cell_centres(mask: np.ndarray, origin: np.ndarray, res: float) -> np.ndarray:
    """``(N, 2)`` centres (metres) of ``mask``'s true cells, for a grid whose cell ``(0, 0)``
    has its lower-left corner at ``origin`` and cells ``res`` metres wide."""
    rows, cols = true_cells(mask)
    return np.stack([origin[0] + (cols + 0.5) * res, origin[1] + (rows + 0.5) * res], axis=1)


def true_cells(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns of ``mask``'s true cells in row-major order: ``np.nonzero(mask)`` of a
    2-D array, found on the flattened array (many times faster on large grids)."""
    rows, cols = np.divmod(np.flatnonzero(mask), mask.shape[1])
    return rows, cols


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


def landing(wall_a, free_a, near_wall_a, origin_a, res, transform, pts_wall, pts_free,
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


FFT_BATCH_CELLS = 2 ** 18
""":meth:`Correlator.best` transforms as many rotations at once as fit in this many cells of
the padded score map (at least one, at most 16): larger batches leave the CPU's caches and
cost more per rotation."""


class Correlator:
    """Score of every translation of B's wall and free points, rotated about ``centre``,
    against A's layers at one resolution: ``+1`` per B wall on an A wall (within one cell),
    ``−conflict`` per B wall on A free space and per B free cell on an A wall, ``+free_weight``
    per B free cell on A free space (module doc, step 2). :meth:`best` scores every
    translation by FFT: A's layers are transformed once (on first use), each rotation costs
    two forward FFTs and one inverse, batched over rotations, and only the best translation of
    each rotation is kept (and the best rotation's score map when asked for).
    :meth:`window_best` scores only the translations near a given one, directly: what a local
    search needs, without the FFTs' cost, which grows with the whole map."""

    def __init__(self, wall_a: np.ndarray, free_a: np.ndarray, origin_a: np.ndarray,
                 res: float, pts_wall: np.ndarray, pts_free: np.ndarray, centre: np.ndarray,
                 radius: float, cfg: GridMergeConfig,
                 prepared: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> None:
        self.res, self.origin_a, self.centre = res, origin_a, centre
        self.pts_wall, self.pts_free = pts_wall, pts_free
        # ``prepared``: A's score_layers(wall_a, free_a, cfg), if already computed
        _, for_walls, for_free = prepared or score_layers(wall_a, free_a, cfg)
        # B rotated about ``centre`` fits in a square of side 2·radius
        self.side = int(math.ceil(2 * radius / res)) + 2
        self.half = self.side // 2
        self.shape = (wall_a.shape[0] + self.side, wall_a.shape[1] + self.side)
        self.fshape = tuple(sfft.next_fast_len(n, real=True) for n in self.shape)
        self.layers = (for_walls, for_free)
        self._spectra: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def spectra(self) -> tuple[np.ndarray, np.ndarray]:
        """The FFTs of A's two layers (wall term, free term), computed on first use."""
        if self._spectra is None:
            self._spectra = tuple(sfft.rfft2(layer, self.fshape, workers=1)
                                  for layer in self.layers)
        return self._spectra

    def _kernels(self, pts: np.ndarray, thetas: np.ndarray) -> np.ndarray:
        """``(len(thetas), side, side)`` rasters of ``pts`` rotated about the centre, flipped
        (correlation is convolution with the flipped kernel), in the corner of zeros the size
        of the FFT (``fshape``: padded here rather than copied into padding by the FFT)."""
        k = np.zeros((len(thetas), *self.fshape), dtype=np.float32)
        if len(pts):
            GK.raster_rotated(k[:, : self.side, : self.side], pts, float(self.centre[0]),
                              float(self.centre[1]), np.cos(thetas), np.sin(thetas), self.res,
                              self.half)
        return k

    def best(self, thetas: np.ndarray, keep_best: bool = False
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Per rotation: the best score and the flat index of its translation in the score
        map (:meth:`translation`); with ``keep_best``, the ``(H, W)`` score map of every
        translation (A-cell offsets) at the rotation of the highest score (the first of
        equals), else ``None``."""
        n = len(thetas)
        scores = np.empty(n)
        at = np.empty(n, dtype=np.int64)
        kept, kept_score = None, -np.inf
        fa_walls, fa_free = self.spectra
        # a few rotations at a time: bounded memory, and the arrays stay in the CPU's caches
        batch = max(1, min(16, FFT_BATCH_CELLS // (self.fshape[0] * self.fshape[1])))
        rows = np.arange(batch)
        h, w = self.shape
        for i in range(0, n, batch):
            th = thetas[i: i + batch]
            spec = sfft.rfft2(self._kernels(self.pts_wall, th), workers=1)
            np.multiply(fa_walls, spec, out=spec)  # in place, A's spectrum first as ever
            if len(self.pts_free):
                free = sfft.rfft2(self._kernels(self.pts_free, th), workers=1)
                spec += np.multiply(fa_free, free, out=free)
            full = sfft.irfft2(spec, self.fshape, workers=1)
            # the FFT's padding never wins, and the score map is searched without a copy
            full[:, h:, :] = -np.inf
            full[:, :h, w:] = -np.inf
            k = np.argmax(full.reshape(len(th), -1), axis=1)
            r, c = np.divmod(k, full.shape[2])
            scores[i: i + batch] = full[rows[: len(th)], r, c]
            at[i: i + batch] = r * w + c
            if keep_best:
                j = int(np.argmax(scores[i: i + batch]))
                if scores[i + j] > kept_score:
                    kept, kept_score = np.array(full[j, :h, :w]), scores[i + j]
        return scores, at, kept

    def box_scores(self, theta: float, r0: int, c0: int, h: int, w: int) -> np.ndarray:
        """The ``(h, w)`` block of the score map at rotation ``theta`` (:meth:`best`'s, but
        for the ``h × w`` translations from row ``r0``, column ``c0`` only), summed directly
        over B's cells (double precision: equal to the FFT's up to its rounding)."""
        out = np.zeros((h, w))
        for pts, layer in zip((self.pts_wall, self.pts_free), self.layers, strict=True):
            if len(pts):
                # score[r, c] = Σ layer[r - side + 1 + iy, c - side + 1 + ix] over the
                # kernel's cells (iy, ix) (:meth:`_kernels`' raster, unflipped)
                GK.box_correlation(layer, pts, float(self.centre[0]), float(self.centre[1]),
                                   math.cos(theta), math.sin(theta), self.res, self.side,
                                   r0 - self.side + 1, c0 - self.side + 1, out)
        return out

    def window_best(self, theta: float, T: np.ndarray, reach: float) -> tuple[float, int]:
        """The best score at rotation ``theta`` among the translations within ``reach`` cells
        of ``T`` (:meth:`index`), and its flat index in the score map (:meth:`translation`);
        ``(-inf, -1)`` if none is in the score map."""
        r_at, c_at = self.index(T, theta)
        r0, c0 = max(0, math.ceil(r_at - reach)), max(0, math.ceil(c_at - reach))
        r1 = min(self.shape[0] - 1, math.floor(r_at + reach))
        c1 = min(self.shape[1] - 1, math.floor(c_at + reach))
        if r1 < r0 or c1 < c0:
            return -math.inf, -1
        rr, cc = np.ogrid[r0: r1 + 1, c0: c1 + 1]
        inside = (rr - r_at) ** 2 + (cc - c_at) ** 2 <= reach ** 2
        if not inside.any():
            return -math.inf, -1
        box = np.where(inside, self.box_scores(theta, r0, c0, r1 - r0 + 1, c1 - c0 + 1),
                       -np.inf)
        dr, dc = divmod(int(np.argmax(box)), box.shape[1])
        return float(box[dr, dc]), (r0 + dr) * self.shape[1] + c0 + dc

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
