"""Checks of what the fusion entry points are given, run before they allocate anything.

Every entry point (:func:`fusion.merge_maps`, :func:`fusion.icp_svd`,
:func:`fusion.exhaustive_search`, :func:`fusion.similarity`,
:func:`fusion.grid_merge.merge_grids`, :func:`fusion.hybrid.hybrid_merge`) refuses a malformed
input with a ``TypeError``/``ValueError`` naming the parameter, the value and what is allowed,
and refuses work beyond the bounds below at once, rather than hanging or exhausting memory
minutes later. Poor but well-formed input (a grid with nothing known, maps too small to
align) is not an error: the merges return it rejected, with a reason.

Bounds (each far above the maps of any building the environment makes):

* :data:`MAX_NODES` nodes per topological map (the structural merge);
* :data:`MAX_POINTS` points per point set (ICP-SVD, ω);
* :data:`MAX_POOLED_CELLS` cells per grid pooled to ``GridMergeConfig.resolution`` and
  :data:`MAX_ROTATIONS` rotations per sweep (the grid alignment); the paper's exhaustive search
  has its own, ``max_evaluations``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from topo.graph import TopoMap
from topo.grid import CellState
from topo.validation import check_real

MAX_NODES = 5_000
"""Most nodes of a map :func:`fusion.merge_maps` aligns (its cost grows faster than the node
count: maps this large are better cut into parts)."""

MAX_POINTS = 1_000_000
"""Most points of a set :func:`fusion.icp_svd` and :func:`fusion.similarity` take."""

MAX_POOLED_CELLS = 4_000_000
"""Most cells of a grid pooled to ``GridMergeConfig.resolution`` (400 m × 400 m at 0.2 m):
the grid alignment correlates layers of that size once per rotation."""

MAX_ROTATIONS = 3_600
"""Most rotations of the grid alignment's sweep (``GridMergeConfig.step_deg >= 0.1``)."""

_CODES = (int(min(CellState)), int(max(CellState)))
_GRID = ("an occupancy grid (topo.OccupancyGrid, fusion.evaluation.pairs.GridSnapshot or "
         "anything with cell-state codes `states`, a `resolution` and an `origin`)")


def grid_states(grid: Any, name: str) -> np.ndarray:
    """The ``(H, W)`` cell-state codes of ``grid`` (``states()`` or ``states``) after checking
    the whole grid: ``resolution`` a finite number ``> 0``, ``origin`` two finite numbers,
    ``states`` a 2-D integer array of :class:`topo.CellState` codes.

    Raises:
        TypeError: ``grid`` lacks one of the three, or its states are not integers.
        ValueError: a bad resolution or origin, states that are not 2-D or hold other codes.
    """
    if not all(hasattr(grid, attr) for attr in ("states", "resolution", "origin")):
        raise TypeError(f"{name} must be {_GRID}, got {type(grid).__name__}")
    check_real(grid.resolution, f"{name}.resolution", low=0.0)
    try:
        origin = np.asarray(grid.origin, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name}.origin must be two numbers (x, y), got {grid.origin!r}") from exc
    if origin.shape != (2,) or not np.isfinite(origin).all():
        raise ValueError(f"{name}.origin must be two finite numbers (x, y), got "
                         f"{origin.tolist()}")
    states = np.asarray(grid.states() if callable(grid.states) else grid.states)
    if not np.issubdtype(states.dtype, np.integer):
        raise TypeError(f"{name}.states must be integer cell-state codes, got dtype "
                        f"{states.dtype}")
    if states.ndim != 2:
        raise ValueError(f"{name}.states must be a 2-D array [iy, ix], got shape {states.shape}")
    if states.size and not (_CODES[0] <= states.min() and states.max() <= _CODES[1]):
        bad = states[(states < _CODES[0]) | (states > _CODES[1])][0]
        raise ValueError(f"{name}.states must hold topo.CellState codes "
                         f"{[int(c) for c in CellState]}, got {int(bad)}")
    return states


def check_grid_inputs(grid_a: Any, grid_b: Any, config: Any) -> None:
    """Check the arguments of :func:`fusion.grid_merge.merge_grids` (and the grids of
    :func:`fusion.hybrid.hybrid_merge`): both grids (:func:`grid_states`), ``config`` a
    ``GridMergeConfig`` or ``None``, each grid pooled to ``config.resolution`` within
    :data:`MAX_POOLED_CELLS` and the sweep within :data:`MAX_ROTATIONS`.

    Raises:
        TypeError, ValueError: naming the argument at fault and what is allowed.
    """
    from fusion.grid_merge import GridMergeConfig

    if config is None:
        config = GridMergeConfig()
    elif not isinstance(config, GridMergeConfig):
        raise TypeError(f"config must be a fusion.grid_merge.GridMergeConfig or None, got "
                        f"{type(config).__name__}")
    rotations = math.ceil(360.0 / config.step_deg)
    if rotations > MAX_ROTATIONS:
        raise ValueError(f"config.step_deg={config.step_deg:g} asks for {rotations:,} rotations, "
                         f"above MAX_ROTATIONS={MAX_ROTATIONS:,}: give step_deg >= "
                         f"{360.0 / MAX_ROTATIONS:g}")
    for name, grid in (("grid_a", grid_a), ("grid_b", grid_b)):
        h, w = grid_states(grid, name).shape
        side = float(grid.resolution) / config.resolution
        pooled = (h * side + 1.0) * (w * side + 1.0)
        if pooled > MAX_POOLED_CELLS:
            raise ValueError(
                f"{name}: {h} × {w} cells of {float(grid.resolution):g} m pool to about "
                f"{pooled:,.0f} cells of config.resolution={config.resolution:g} m, above "
                f"MAX_POOLED_CELLS={MAX_POOLED_CELLS:,}: give a coarser config.resolution or "
                f"crop the grid")


def check_map_sizes(map_a: TopoMap, map_b: TopoMap) -> None:
    """Refuse maps of more than :data:`MAX_NODES` nodes (:func:`fusion.merge_maps`; the maps
    are already checked to be :class:`topo.TopoMap`)."""
    for name, m in (("map_a", map_a), ("map_b", map_b)):
        if m.n_nodes > MAX_NODES:
            raise ValueError(f"{name} has {m.n_nodes:,} nodes, above MAX_NODES={MAX_NODES:,}: "
                             f"merge parts of the maps")


def check_point_count(points: np.ndarray, name: str) -> np.ndarray:
    """``points`` (an ``(N, 2)`` array) if ``N <= MAX_POINTS``, else a ``ValueError``
    naming ``name``."""
    if len(points) > MAX_POINTS:
        raise ValueError(f"{name} has {len(points):,} points, above MAX_POINTS="
                         f"{MAX_POINTS:,}: subsample it")
    return points
