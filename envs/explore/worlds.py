"""Worlds: a free-space grid plus the wall segments traced from it.

A :class:`World` is built from a boolean free-space grid (``[iy, ix]``, row 0 at the bottom,
CONTRIBUTING.md conventions). Its walls are the contours of the non-free region
(``skimage.measure.find_contours``), simplified with ``skimage.measure.approximate_polygon``
and with collinear runs merged into single segments. **The same segments are the pymunk
collision shapes and the sonar's ray targets**, so a sonar can never see a wall a robot could
drive through, nor miss one it bumps into.

Sources:

* :func:`procedural_world` — a seeded building of rooms, corridors, doors (a random spanning
  tree of the room graph, plus extra doors that close loops) and furniture boxes;
* :func:`load_world` — real maps: ROS ``map_server`` YAML+PGM and DungeonMaps PNG through
  ``topo.maps``, and HouseExpo-style JSON polygons (:func:`load_houseexpo_json`).

Unknown cells of a real map are treated as not free (the robot can neither enter nor see
through them).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage
from skimage.draw import polygon as draw_polygon
from skimage.measure import approximate_polygon, find_contours

from envs.explore.config import WorldConfig

MAX_WORLD_CELLS = 2 ** 24
"""Most cells of a world grid (a procedural ``world.size`` over ``world.resolution``, or a map
file's). Building one holds, per cell, the distance transform's float64 distances and int32
feature indices (16 bytes), two int32 label arrays (8), the float32 clearance (4), a float32
copy for the wall tracing (4) and a few bool masks: about 40 bytes, so 2**24 cells stay under
1 GiB while the world is built."""

MAX_FILE_RESOLUTION = 0.5
"""Coarsest map file accepted, metres per cell (as ``world.resolution``): a robot needs a
few cells across a doorway, and a coarse map of a large area asks for huge robot maps."""

_COLLINEAR_SIN = 0.02
"""Two consecutive segments whose directions differ by less than ~1.1° are merged."""


@dataclass(frozen=True, slots=True, eq=False)
class World:
    """A static 2-D world: free space, wall segments and where robots may stand.

    Attributes:
        free: ``(H, W)`` bool, ``True`` where space is free (row 0 at the bottom).
        resolution: metres per cell.
        origin: world position of the lower-left corner of cell ``(0, 0)``.
        segments: ``(M, 4)`` float64 wall segments ``x0, y0, x1, y1`` in metres.
        reachable: ``(H, W)`` bool, free cells connected to where the robots can drive (the
            coverage denominator).
        drivable: ``(H, W)`` bool, cells where a robot centre can be (free clearance
            ``>= robot radius``) in the largest connected region.
        clearance: ``(H, W)`` float32, distance in metres from each cell centre to the nearest
            non-free cell.
        name: where the world came from.
    """

    free: np.ndarray
    resolution: float
    origin: tuple[float, float]
    segments: np.ndarray
    reachable: np.ndarray
    drivable: np.ndarray
    clearance: np.ndarray
    name: str

    @classmethod
    def from_free_mask(cls, free: np.ndarray, resolution: float,
                       origin: tuple[float, float] = (0.0, 0.0), *, name: str = "grid",
                       robot_radius: float = 0.25, simplify: float | None = None) -> World:
        """Trace walls from a free-space mask and find the drivable region.

        Args:
            free: ``(H, W)`` bool free-space mask, row 0 at the bottom.
            resolution: metres per cell.
            origin: world position of the lower-left corner of cell ``(0, 0)``.
            name: label kept in :attr:`name`.
            robot_radius: robots need this clearance (metres) to drive.
            simplify: polygon simplification tolerance in metres (default half a cell).

        Raises:
            ValueError: ``free`` is not 2-D, is smaller than 8×8 cells, or no cell has room
                for a robot.
        """
        free = np.asarray(free)
        if free.ndim != 2 or min(free.shape) < 8:
            raise ValueError(f"free must be a 2-D mask of at least 8x8 cells, got {free.shape}")
        free = free.astype(bool)
        clearance = (ndimage.distance_transform_edt(np.pad(free, 1)) [1:-1, 1:-1]
                     * resolution).astype(np.float32)
        drivable_all = clearance >= robot_radius + 0.5 * resolution
        labels, n = ndimage.label(drivable_all)
        if n == 0:
            raise ValueError(
                f"world {name!r} has no free cell with {robot_radius} m clearance for a robot "
                f"({int(free.sum())} free cells at {resolution} m)"
            )
        sizes = np.bincount(labels.ravel())[1:]
        drivable = labels == 1 + int(np.argmax(sizes))
        free_labels, _ = ndimage.label(free)
        reach_ids = np.unique(free_labels[drivable])
        reachable = np.isin(free_labels, reach_ids[reach_ids > 0])
        tol = 0.5 * resolution if simplify is None else simplify
        segments = trace_segments(free, resolution, origin, tol)
        for a in (free, reachable, drivable, clearance, segments):
            a.setflags(write=False)
        return cls(free, float(resolution), (float(origin[0]), float(origin[1])), segments,
                   reachable, drivable, clearance, name)

    @property
    def shape(self) -> tuple[int, int]:
        return self.free.shape  # type: ignore[return-value]

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` in metres."""
        h, w = self.free.shape
        x0, y0 = self.origin
        return (x0, y0, x0 + w * self.resolution, y0 + h * self.resolution)

    @property
    def reachable_area(self) -> float:
        """Area of :attr:`reachable` in m² (what 100 % coverage means)."""
        return float(np.count_nonzero(self.reachable)) * self.resolution ** 2

    def cell_of(self, xy: np.ndarray) -> np.ndarray:
        """``(N, 2)`` integer ``(iy, ix)`` of world points ``(N, 2)`` (may be out of bounds)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        ix = np.floor((xy[:, 0] - self.origin[0]) / self.resolution).astype(np.int64)
        iy = np.floor((xy[:, 1] - self.origin[1]) / self.resolution).astype(np.int64)
        return np.stack([iy, ix], axis=1)

    def is_free(self, xy: np.ndarray) -> np.ndarray:
        """``(N,)`` bool: each point lies in a free cell (out of bounds is not free)."""
        ij = self.cell_of(xy)
        h, w = self.free.shape
        inside = (ij[:, 0] >= 0) & (ij[:, 0] < h) & (ij[:, 1] >= 0) & (ij[:, 1] < w)
        out = np.zeros(len(ij), dtype=bool)
        out[inside] = self.free[ij[inside, 0], ij[inside, 1]]
        return out

    def sample_starts(self, rng: np.random.Generator, clearance: float,
                      min_separation: float, n: int = 2) -> np.ndarray:
        """``n`` start poses ``(n, 3)`` ``(x, y, heading)``: drivable cells with at least
        ``clearance`` metres of free space, each ``min_separation`` from the others, random
        headings (the first two drawn as for a pair, then each from the cells far enough
        from those before).

        Raises:
            ValueError: the map has no such cells, or no ``n`` that far apart.
        """
        ok = self.drivable & (self.clearance >= clearance)
        cells = np.flatnonzero(ok)
        if len(cells) == 0:
            raise ValueError(
                f"world {self.name!r} has no drivable cell with start clearance {clearance} m"
            )
        first = int(cells[rng.integers(len(cells))])
        h, w = self.free.shape
        iy, ix = np.divmod(cells, w)
        fy, fx = divmod(first, w)
        d = np.hypot(iy - fy, ix - fx) * self.resolution
        far = cells[d >= min_separation]
        if len(far) == 0:
            raise ValueError(
                f"world {self.name!r} is too small for two robots: no start cells "
                f"{min_separation} m apart (world.min_start_separation)"
            )
        chosen = [first, int(far[rng.integers(len(far))])]
        while len(chosen) < n:
            ok_far = np.ones(len(cells), dtype=bool)
            for c in chosen:
                cy, cx = divmod(c, w)
                ok_far &= np.hypot(iy - cy, ix - cx) * self.resolution >= min_separation
            far = cells[ok_far]
            if len(far) == 0:
                raise ValueError(
                    f"world {self.name!r} is too small for {n} robots: no start cells "
                    f"{min_separation} m apart (world.min_start_separation)")
            chosen.append(int(far[rng.integers(len(far))]))
        poses = np.empty((n, 3))
        for k, c in enumerate(chosen):
            cy, cx = divmod(c, w)
            poses[k, 0] = self.origin[0] + (cx + 0.5) * self.resolution
            poses[k, 1] = self.origin[1] + (cy + 0.5) * self.resolution
        poses[:, 2] = rng.uniform(-math.pi, math.pi, size=n)
        return poses

    def spread_starts(self, clearance: float, min_separation: float,
                      n: int) -> np.ndarray | None:
        """``n`` start poses ``(n, 3)`` (headings 0) placed without randomness, or ``None`` if
        this placement finds none: :func:`spread_points` over the centres of the drivable cells
        with ``clearance`` metres of free space.

        Why: the fallback of the random draw, and what ``check_feasible`` runs on a map file's
        world, so a file world that passes the check has starts for every seed.
        """
        cells = np.flatnonzero(self.drivable & (self.clearance >= clearance))
        iy, ix = np.divmod(cells, self.free.shape[1])
        xy = np.stack([ix + 0.5, iy + 0.5], axis=1) * self.resolution + np.asarray(self.origin)
        chosen = spread_points(xy, min_separation, n)
        if chosen is None:
            return None
        poses = np.zeros((n, 3))
        poses[:, :2] = xy[chosen]
        return poses


def spread_points(xy: np.ndarray, min_separation: float, n: int) -> np.ndarray | None:
    """Indices of ``n`` of the points ``xy`` ``(M, 2)`` at least ``min_separation`` apart, found
    by farthest-point placement, or ``None``. The placement starts from each of the five points
    extreme along ``x + y``, ``x − y`` (the corners of a room) and nearest to the points' mean,
    in that order, and adds the point farthest from those chosen until ``n`` are chosen or the
    farthest is nearer than ``min_separation``; the first start that places ``n`` wins.

    Why: deterministic, and from a corner it finds the best placements of a few points in a
    rectangle (its corners, then their middles).
    """
    if len(xy) == 0:
        return None
    s, t = xy.sum(axis=1), xy[:, 0] - xy[:, 1]
    mean = np.hypot(*(xy - xy.mean(axis=0)).T)
    firsts = dict.fromkeys(int(i) for i in (np.argmin(s), np.argmax(s), np.argmin(t),
                                            np.argmax(t), np.argmin(mean)))
    for first in firsts:
        chosen = [first]
        nearest = np.hypot(*(xy - xy[first]).T)
        while len(chosen) < n:
            k = int(np.argmax(nearest))
            if nearest[k] < min_separation:
                break
            chosen.append(k)
            np.minimum(nearest, np.hypot(*(xy - xy[k]).T), out=nearest)
        if len(chosen) == n:
            return np.asarray(chosen)
    return None


def _drop_collinear(poly: np.ndarray, closed: bool) -> np.ndarray:
    """Remove vertices where the polyline goes straight on (collinear runs → one segment)."""
    changed = True
    while changed and len(poly) > (3 if closed else 2):
        changed = False
        pts = poly[:-1] if closed else poly
        n = len(pts)
        keep = np.ones(n, dtype=bool)
        idx = range(n) if closed else range(1, n - 1)
        for i in idx:
            if not keep[(i - 1) % n]:
                continue
            a, b, c = pts[(i - 1) % n], pts[i], pts[(i + 1) % n]
            u, v = b - a, c - b
            lu, lv = math.hypot(*u), math.hypot(*v)
            if lu == 0.0 or lv == 0.0:
                keep[i] = False
                changed = True
                continue
            cross = (u[0] * v[1] - u[1] * v[0]) / (lu * lv)
            dot = (u[0] * v[0] + u[1] * v[1])
            if abs(cross) < _COLLINEAR_SIN and dot > 0:
                keep[i] = False
                changed = True
        pts = pts[keep]
        poly = np.vstack([pts, pts[:1]]) if closed else pts
    return poly


def trace_segments(free: np.ndarray, resolution: float, origin: tuple[float, float],
                   tolerance: float) -> np.ndarray:
    """Wall segments ``(M, 4)`` around the non-free region of ``free``.

    The grid is padded with one ring of obstacle so every wall contour is closed. Contours run
    half-way between free and non-free cell centres (the cell boundary), are simplified with
    ``approximate_polygon(tolerance)`` and collinear runs are merged.
    """
    blocked = np.pad(~np.asarray(free, dtype=bool), 1, constant_values=True)
    out = []
    tol_cells = tolerance / resolution
    for contour in find_contours(blocked.astype(np.float32), 0.5):
        closed = bool(np.allclose(contour[0], contour[-1]))
        poly = approximate_polygon(contour, tol_cells) if tol_cells > 0 else contour
        poly = _drop_collinear(poly, closed)
        if len(poly) < 2:
            continue
        # (row, col) of the padded grid → metres
        xy = np.empty_like(poly)
        xy[:, 0] = origin[0] + (poly[:, 1] - 0.5) * resolution
        xy[:, 1] = origin[1] + (poly[:, 0] - 0.5) * resolution
        seg = np.hstack([xy[:-1], xy[1:]])
        out.append(seg[np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]) > 1e-9])
    if not out:
        return np.empty((0, 4))
    return np.ascontiguousarray(np.vstack(out))


# ------------------------------------------------------------------ procedural buildings
def _split(length: float, cfg: WorldConfig, rng: np.random.Generator) -> tuple[np.ndarray,
                                                                                 np.ndarray]:
    """Cut ``length`` metres into room widths; returns (boundaries, is_corridor)."""
    widths, corridor = [], []
    lo, hi = cfg.room_size
    while sum(widths) < length:
        if rng.random() < cfg.corridor_prob:
            widths.append(rng.uniform(1.4, 2.0))
            corridor.append(True)
        else:
            widths.append(rng.uniform(lo, hi))
            corridor.append(False)
    w = np.asarray(widths) * (length / sum(widths))
    return np.concatenate([[0.0], np.cumsum(w)]), np.asarray(corridor)


def _spanning_doors(ny: int, nx: int, rng: np.random.Generator) -> set[tuple]:
    """Adjacent room pairs joined by a random spanning tree (randomised DFS)."""
    seen = np.zeros((ny, nx), dtype=bool)
    stack = [(int(rng.integers(ny)), int(rng.integers(nx)))]
    seen[stack[0]] = True
    tree: set[tuple] = set()
    while stack:
        r, c = stack[-1]
        nbrs = [(r + dr, c + dc) for dr, dc in ((1, 0), (-1, 0), (0, 1), (0, -1))
                if 0 <= r + dr < ny and 0 <= c + dc < nx and not seen[r + dr, c + dc]]
        if not nbrs:
            stack.pop()
            continue
        nxt = nbrs[int(rng.integers(len(nbrs)))]
        seen[nxt] = True
        tree.add(tuple(sorted([(r, c), nxt])))
        stack.append(nxt)
    return tree


def procedural_world(cfg: WorldConfig, rng: np.random.Generator, *,
                     robot_radius: float = 0.25) -> World:
    """A seeded indoor building of ``cfg.size`` metres.

    Rooms come from cutting the floor into rows and columns of random widths
    (``cfg.room_size``); a row or column is a corridor (1.4–2 m) with probability
    ``cfg.corridor_prob`` and its walls along the corridor are removed. Doors follow a random
    spanning tree of the room graph (so every room is reachable) plus, with probability
    ``cfg.loop_prob``, each other shared wall (loops). Furniture boxes (0.4–1 m) are placed
    ``cfg.obstacle_density`` per 10 m², at least 0.8 m from the room's walls.
    """
    res = cfg.resolution
    width, height = cfg.size
    nx_cells, ny_cells = int(round(width / res)), int(round(height / res))
    occ = np.zeros((ny_cells, nx_cells), dtype=bool)
    t = cfg.wall_thickness
    half = max(1, int(round(t / res / 2)))

    def cells(v: float, n: int) -> int:
        return int(np.clip(round(v / res), 0, n))

    def fill(x0: float, y0: float, x1: float, y1: float, value: bool = True) -> None:
        rows = slice(cells(y0, ny_cells), cells(y1, ny_cells))
        occ[rows, cells(x0, nx_cells):cells(x1, nx_cells)] = value

    xs, col_corr = _split(width, cfg, rng)
    ys, row_corr = _split(height, cfg, rng)
    nx, ny = len(xs) - 1, len(ys) - 1
    tree = _spanning_doors(ny, nx, rng)
    ht = half * res
    # interior walls, each between two adjacent rooms: open, a door, or solid
    for r in range(ny):
        for c in range(nx):
            for dr, dc in ((0, 1), (1, 0)):
                r2, c2 = r + dr, c + dc
                if r2 >= ny or c2 >= nx:
                    continue
                if dc:  # vertical wall at xs[c + 1] spanning ys[r]..ys[r + 1]
                    along = (ys[r], ys[r + 1])
                    opened = bool(row_corr[r])  # along a corridor row
                else:
                    along = (xs[c], xs[c + 1])
                    opened = bool(col_corr[c])  # along a corridor column
                if opened:
                    continue
                pos = xs[c + 1] if dc else ys[r + 1]
                rect = ((pos - ht, along[0] - ht, pos + ht, along[1] + ht) if dc
                        else (along[0] - ht, pos - ht, along[1] + ht, pos + ht))
                fill(*rect)
                pair = ((r, c), (r2, c2))
                if pair in tree or rng.random() < cfg.loop_prob:
                    span = along[1] - along[0]
                    free_len = span - 2 * t - cfg.door_width
                    mid = (along[0] + t + cfg.door_width / 2 + rng.uniform(0, free_len)
                           if free_len > 0 else (along[0] + along[1]) / 2)
                    dw = min(cfg.door_width, span) / 2
                    if dc:
                        fill(pos - ht, mid - dw, pos + ht, mid + dw, False)
                    else:
                        fill(mid - dw, pos - ht, mid + dw, pos + ht, False)
    # furniture
    margin = 0.8
    for r in range(ny):
        for c in range(nx):
            if row_corr[r] or col_corr[c]:
                continue
            x0, x1, y0, y1 = xs[c] + margin, xs[c + 1] - margin, ys[r] + margin, ys[r + 1] - margin
            if x1 - x0 < 1.0 or y1 - y0 < 1.0:
                continue
            n_box = rng.poisson(cfg.obstacle_density * (x1 - x0) * (y1 - y0) / 10.0)
            for _ in range(int(n_box)):
                bw, bh = rng.uniform(0.4, 1.0, size=2)
                bx = rng.uniform(x0, max(x0, x1 - bw))
                by = rng.uniform(y0, max(y0, y1 - bh))
                fill(bx, by, min(bx + bw, x1), min(by + bh, y1))
    # outer walls
    b = max(1, int(round(t / res)))
    occ[:b, :] = occ[-b:, :] = True
    occ[:, :b] = occ[:, -b:] = True
    name = f"procedural {width:g}x{height:g} m ({ny}x{nx} rooms)"
    return World.from_free_mask(~occ, res, (0.0, 0.0), name=name, robot_radius=robot_radius)


# ------------------------------------------------------------------ real maps
def load_houseexpo_json(path: str | Path, resolution: float = 0.1) -> tuple[np.ndarray, float,
                                                                          tuple[float, float]]:
    """Rasterise a HouseExpo-style JSON floor plan ``{"verts": [[x, y], ...]}`` (metres).

    The polygon's inside is free, everything else is wall. Other keys of the file (``id``,
    ``bbox``, ``room_category``...) are ignored. Returns ``(free, resolution, origin)``.

    Raises:
        FileNotFoundError: no such file.
        ValueError: not JSON, no ``verts`` key, fewer than 3 vertices, non-finite values, a
            polygon over :data:`MAX_WORLD_CELLS` cells at ``resolution``.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"world file {str(path)!r} does not exist")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"world file {str(path)!r} is not valid JSON: {exc}") from exc
    if not isinstance(data, dict) or "verts" not in data:
        raise ValueError(f"world file {str(path)!r} must be a JSON object with a 'verts' key "
                         f"(HouseExpo polygon in metres)")
    try:
        verts = np.asarray(data["verts"], dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"world file {str(path)!r}: 'verts' must be a list of [x, y] "
                         f"pairs") from exc
    if verts.ndim != 2 or verts.shape[1] != 2 or len(verts) < 3:
        raise ValueError(f"world file {str(path)!r}: 'verts' must hold at least 3 [x, y] pairs, "
                         f"got shape {verts.shape}")
    if not np.all(np.isfinite(verts)):
        raise ValueError(f"world file {str(path)!r}: 'verts' must be finite")
    margin = 2 * resolution
    lo = verts.min(axis=0) - margin
    hi = verts.max(axis=0) + margin
    w, h = (np.ceil((hi - lo) / resolution)).astype(int)
    _check_cells(int(w) * int(h), f"world file {str(path)!r} ({hi[0] - lo[0]:g} x "
                                  f"{hi[1] - lo[1]:g} m at {resolution} m)")
    rows = (verts[:, 1] - lo[1]) / resolution - 0.5
    cols = (verts[:, 0] - lo[0]) / resolution - 0.5
    free = np.zeros((h, w), dtype=bool)
    rr, cc = draw_polygon(rows, cols, shape=free.shape)
    free[rr, cc] = True
    return free, float(resolution), (float(lo[0]), float(lo[1]))


def _check_cells(cells: int, what: str) -> None:
    if cells > MAX_WORLD_CELLS:
        raise ValueError(f"{what} needs {cells} cells, more than MAX_WORLD_CELLS = "
                         f"{MAX_WORLD_CELLS} (envs.explore.worlds)")


def load_world(cfg: WorldConfig, *, robot_radius: float = 0.25) -> World:
    """A :class:`World` from the map file ``cfg.source`` (see the module docstring).

    Raises:
        FileNotFoundError: the file does not exist.
        ValueError: a malformed file, a map coarser than :data:`MAX_FILE_RESOLUTION` or over
            :data:`MAX_WORLD_CELLS`, or a map with no room for a robot.
    """
    path = Path(cfg.source)
    if not path.is_file():
        raise FileNotFoundError(f"world.source {cfg.source!r} does not exist")
    suffix = path.suffix.lower()
    if suffix == ".json":
        free, res, origin = load_houseexpo_json(path, cfg.resolution)
        name = path.name
    else:
        from topo.maps import load_floor_plan

        plan = load_floor_plan(path, resolution=cfg.png_resolution if suffix == ".png" else None)
        free, res, origin, name = plan.free, plan.resolution, tuple(plan.origin), plan.name
        if res > MAX_FILE_RESOLUTION:
            raise ValueError(f"world.source {cfg.source!r} has a resolution of {res} m per "
                             f"cell (its YAML's resolution); at most {MAX_FILE_RESOLUTION} is "
                             f"allowed")
        _check_cells(free.size, f"world.source {cfg.source!r} ({free.shape[1]} x "
                                f"{free.shape[0]} cells)")
    return World.from_free_mask(free, res, origin, name=name, robot_radius=robot_radius)
