"""Whether an env configuration can run, decided before the run, and the episode's draw.

A setting either works for every seed or is refused when the env is constructed, with an error
naming the setting, its value and the limit (:func:`check_feasible`):

* **cells**: a procedural world grid holds at most :data:`~envs.explore.worlds.MAX_WORLD_CELLS`
  cells, each robot's map grid at most :data:`MAX_MAP_CELLS` (map files: their own limits,
  :func:`envs.explore.worlds.load_world`);
* **robots that fit**: the ``n_robots`` starts lie in the world's start area, ``world.
  min_start_separation`` apart. For a procedural building that area is at most the rectangle
  inside its outer walls less ``world.start_clearance`` (:func:`start_area`), and no more
  points than :func:`max_points_apart` fit in it (Groemer's packing bound: a true bound, whatever
  the rooms and furniture), and the draw's spread placement must place them in an empty building
  (:func:`fits_empty_building`). Where a square grid of that pitch holds fewer than twice the
  robots (crowded), or a start's clear disc and a wall take more than half the smallest room
  side (``2 start_clearance + wall_thickness > room_size[0] / 2``: rooms are cut smaller than
  ``room_size`` to fill the building), at least half of :data:`PROBE_BUILDINGS` sample buildings
  must have starts: rooms and furniture can take what the empty building offers (and a reset
  then draws up to :data:`WORLD_TRIES` buildings). A map file's world is known at
  construction: the spread placement (:meth:`World.spread_starts
  <envs.explore.worlds.World.spread_starts>`) must fit them there.

Why: a setting that fails on some seeds fails deep inside a long run (a dataset generator, a
training job), at the same episode every time it is resumed.

The draw (:func:`draw_world_and_starts`) keeps the episodes of today's seeds: the building and
the starts are drawn as before, and only where that draw finds no starts does it retry, from the
same generator (so the same seed gives the same episode): :data:`START_TRIES` more random draws
in the building, then the spread placement, then a new building, up to :data:`WORLD_TRIES`.
"""

from __future__ import annotations

import math

import numpy as np

from envs.explore.config import EnvConfig
from envs.explore.worlds import MAX_WORLD_CELLS, World, procedural_world, spread_points

MAX_MAP_CELLS = 2 ** 26
"""Most cells of one robot's map grid (``mapping.grid_resolution`` over the square of half-side
:func:`frame_radius` around its start). A cell holds a float32 log-odds, an int8 state and a
bool (6 bytes), and a map snapshot copies them: 2**26 cells are 384 MiB a robot, 768 MiB with
a snapshot."""

START_TRIES = 16
"""Random start draws in one building after the first fails, before the spread placement."""

WORLD_TRIES = 32
"""Procedural buildings drawn for one episode before the reset gives up."""

PROBE_BUILDINGS = 16
"""Sample buildings a crowded procedural setting must place its starts in at construction."""

PROBE_SEED = 0
"""Seed of the sample buildings (construction draws nothing from the env's generator)."""


def frame_radius(config: EnvConfig, extent: tuple[float, float, float, float]) -> float:
    """Half-side (metres) of the square each robot's map covers around its start at most: the
    world's diagonal plus the sonar's reach and a metre, so every wall a robot can see fits."""
    x0, y0, x1, y1 = extent
    return float(math.hypot(x1 - x0, y1 - y0) + config.sonar.max_range + 1.0)


def start_area(config: EnvConfig) -> tuple[float, float]:
    """Width and height (metres, ``< 0`` if none) of the rectangle that holds every start cell
    centre of a procedural ``world.size`` building: inside its outer walls (``world.
    wall_thickness``, at least one cell) by a start's clearance, ``world.start_clearance`` or
    the drivable clearance ``robot.radius`` + half a cell, whichever is larger
    (:func:`envs.explore.worlds.procedural_world`, :meth:`World.from_free_mask`)."""
    w = config.world
    res = w.resolution
    wall = max(1, int(round(w.wall_thickness / res)))
    # less a rounding margin: the clearances compared are float32
    need = max(w.start_clearance, config.robot.radius + 0.5 * res) - 1e-6
    # cell i's clearance is (i - wall + 1) * res from the outer wall's last cell
    sides = (int(round(s / res)) - 2 * wall + 1 for s in w.size)
    return tuple(n * res - 2.0 * need for n in sides)  # type: ignore[return-value]


def max_points_apart(width: float, height: float, separation: float) -> float:
    """Most points a ``width`` × ``height`` rectangle holds at least ``separation`` apart
    (``inf`` for ``separation = 0``; ``0`` for an empty rectangle): Groemer's bound for a convex
    region of area ``A`` and perimeter ``P``, ``2 A / (√3 d²) + P / (2 d) + 1`` (H. Groemer,
    "Über die Einlagerung von Kreisen in einen konvexen Bereich", Math. Z. 73, 1960)."""
    if width < 0.0 or height < 0.0:
        return 0.0
    if separation <= 0.0:
        return math.inf
    d = separation
    return math.floor(2.0 * width * height / (math.sqrt(3.0) * d * d)
                      + (width + height) / d + 1.0 + 1e-9)


def fits_empty_building(width: float, height: float, separation: float, n: int,
                        resolution: float) -> bool:
    """Whether the spread placement (:func:`envs.explore.worlds.spread_points`) puts ``n``
    starts ``separation`` apart in an empty building, whose start cells are the lattice of
    ``resolution`` cells filling the ``width`` × ``height`` start area (:func:`start_area`;
    at most 512 a side are tried, the area's edges always). Yes at once if a square grid of
    pitch ``separation`` holds ``n``.

    Why: the draw tries the spread placement when random draws fail; where it fails in the
    empty building, only luck would place the starts in a furnished one.
    """
    if width < 0.0 or height < 0.0:
        return False
    if separation <= 0.0 or (math.floor(width / separation) + 1) * (
            math.floor(height / separation) + 1) >= n:
        return True
    axes = []
    for side in (width, height):
        k = math.floor(side / resolution + 1e-9)
        axes.append(np.unique(np.linspace(0, k, min(k + 1, 512)).round()) * resolution)
    gx, gy = np.meshgrid(*axes)
    return spread_points(np.stack([gx.ravel(), gy.ravel()], axis=1), separation, n) is not None


def check_feasible(config: EnvConfig, file_world: World | None = None) -> None:
    """Refuse a configuration some seeds could not run (module docstring).

    Args:
        config: the env's configuration.
        file_world: the world loaded from ``config.world.source`` (``None``: procedural).

    Raises:
        ValueError: a grid over its cell limit, or ``n_robots`` that cannot start
            ``world.min_start_separation`` apart (beyond the packing bound, not in an empty
            building, or not in a sample building); the message names the settings and the
            limit.
    """
    w = config.world
    if file_world is None:
        cells = int(round(w.size[0] / w.resolution)) * int(round(w.size[1] / w.resolution))
        if cells > MAX_WORLD_CELLS:
            raise ValueError(
                f"world.size {w.size} at world.resolution {w.resolution} m needs {cells} cells, "
                f"more than MAX_WORLD_CELLS = {MAX_WORLD_CELLS} (envs.explore.worlds); use a "
                f"smaller world.size or a coarser world.resolution")
        extent = (0.0, 0.0, *w.size)
        where = f"world.size {w.size}"
    else:
        extent = file_world.extent
        where = f"world.source {w.source!r} ({extent[2] - extent[0]:g} x " \
                f"{extent[3] - extent[1]:g} m)"
    side = math.ceil(2.0 * frame_radius(config, extent) / config.mapping.grid_resolution)
    if side * side > MAX_MAP_CELLS:
        raise ValueError(
            f"{where} with sonar.max_range {config.sonar.max_range} m gives each robot a map "
            f"of {side} x {side} cells at mapping.grid_resolution "
            f"{config.mapping.grid_resolution} m, more than MAX_MAP_CELLS = {MAX_MAP_CELLS} "
            f"(envs.explore.feasibility); use a smaller world or a coarser "
            f"mapping.grid_resolution")
    n, sep = config.n_robots, w.min_start_separation
    if file_world is None:
        width, height = start_area(config)
        most = max_points_apart(width, height, sep)
        if n > most:
            raise ValueError(
                f"n_robots = {n} do not fit a world.size {w.size} building: its starts lie in "
                f"{max(width, 0.0):.2f} x {max(height, 0.0):.2f} m (inside the outer walls by "
                f"world.start_clearance {w.start_clearance} m), which holds at most {most:g} "
                f"points world.min_start_separation {sep} m apart; lower n_robots or "
                f"world.min_start_separation, or enlarge world.size")
        if not fits_empty_building(width, height, sep, n, w.resolution):
            raise ValueError(
                f"n_robots = {n} do not fit world.min_start_separation {sep} m apart even in "
                f"an empty world.size {w.size} building (its outer walls only: starts in "
                f"{width:.2f} x {height:.2f} m); lower n_robots or world.min_start_separation, "
                f"or enlarge world.size")
        crowded = (math.floor(width / sep) + 1) * (math.floor(height / sep) + 1) < 2 * n
        if crowded or 2.0 * w.start_clearance + w.wall_thickness > 0.5 * w.room_size[0]:
            failed = sum(place_starts(procedural_world(w, rng, robot_radius=config.robot.radius),
                                      rng, w.start_clearance, sep, n) is None
                         for rng in [np.random.default_rng(PROBE_SEED)] * PROBE_BUILDINGS)
            if failed > PROBE_BUILDINGS // 2:
                raise ValueError(
                    f"n_robots = {n} found no starts world.min_start_separation {sep} m apart "
                    f"in {failed} of {PROBE_BUILDINGS} sample world.size {w.size} buildings; "
                    f"lower n_robots or world.min_start_separation, or enlarge world.size")
    elif file_world.spread_starts(w.start_clearance, sep, n) is None:
        raise ValueError(
            f"n_robots = {n} do not fit {where}: no {n} drivable cells with "
            f"world.start_clearance {w.start_clearance} m found world.min_start_separation "
            f"{sep} m apart; lower n_robots or world.min_start_separation")


def place_starts(world: World, rng: np.random.Generator, clearance: float,
                 separation: float, n: int) -> np.ndarray | None:
    """``n`` start poses ``(n, 3)`` in ``world`` drawn from ``rng``, or ``None``: the draw of
    :meth:`World.sample_starts`, then up to :data:`START_TRIES` more, then the spread placement
    (:meth:`World.spread_starts`) with random headings."""
    for _ in range(1 + START_TRIES):
        try:
            return world.sample_starts(rng, clearance, separation, n)
        except ValueError:
            continue
    poses = world.spread_starts(clearance, separation, n)
    if poses is not None:
        poses[:, 2] = rng.uniform(-math.pi, math.pi, size=n)
    return poses


def draw_world_and_starts(config: EnvConfig, rng: np.random.Generator,
                          file_world: World | None) -> tuple[World, np.ndarray]:
    """The episode's world and ``(n_robots, 3)`` start poses, drawn from ``rng`` (module
    docstring): the file's world, or procedural buildings until one has starts.

    Raises:
        ValueError: no starts in :data:`WORLD_TRIES` buildings (or in the file's world), naming
            the settings.
    """
    w, n = config.world, config.n_robots
    for _ in range(1 if file_world is not None else WORLD_TRIES):
        world = file_world if file_world is not None else procedural_world(
            w, rng, robot_radius=config.robot.radius)
        starts = place_starts(world, rng, w.start_clearance, w.min_start_separation, n)
        if starts is not None:
            return world, starts
    where = (f"world.source {w.source!r}" if file_world is not None
             else f"{WORLD_TRIES} world.size {w.size} buildings drawn from this seed")
    raise ValueError(
        f"no start poses for n_robots = {n} at least world.min_start_separation "
        f"{w.min_start_separation} m apart with world.start_clearance {w.start_clearance} m in "
        f"{where}; lower n_robots or world.min_start_separation, or enlarge world.size")
