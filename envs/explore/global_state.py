"""The env's global state for centralised critics (manual, State; its index table is in
``docs/env_explore.md``): every robot's true pose, coverage and progress, and three coarse
world-frame maps — swept, shared and reachable.

The maps are ``STATE_MAP_SIZE²`` blocks over the world's extent; each block is the mean of
``STATE_SAMPLES²`` points sampled evenly inside it, read from the world grid (swept, reachable)
and from the shared map (robot 0's frame, moved into the world by robot 0's true start pose).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from gymnasium import spaces

from envs.explore.mapping import OracleCoverage, SharedMap, cell_indices
from fusion.rigid import Rigid2D

STATE_MAP_SIZE = 32
"""Side of the world-frame maps of the state (blocks per side)."""

STATE_SAMPLES = 4
"""Each state map block is the mean of ``STATE_SAMPLES²`` points sampled evenly inside it."""

STATE_SCALARS = 12
"""Entries of the two-robot state vector before its maps (manual, State):
``state_scalars(2)``."""


def state_scalars(robots: int) -> int:
    """Entries of the state vector before its maps: 4 per robot, then 4 (manual, State)."""
    return 4 * robots + 4


def state_space(robots: int = 2) -> spaces.Box:
    """The state vector's space: ``(state_scalars(robots) + 3 · STATE_MAP_SIZE²,)`` float32
    in ``[0, 1]``, the headings' cosines and sines in ``[-1, 1]``."""
    n = state_scalars(robots) + 3 * STATE_MAP_SIZE ** 2
    low = np.zeros(n, dtype=np.float32)
    for i in range(robots):
        low[4 * i + 2: 4 * i + 4] = -1.0  # cos, sin of the headings
    return spaces.Box(low, np.ones(n, dtype=np.float32), dtype=np.float32)


def _blocks(mask: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Mean of ``mask`` at the sampled ``cells`` (listed block by block; ``-1``: outside,
    False) per block, ``(STATE_MAP_SIZE**2,)`` float32, row-major, row 0 at the bottom."""
    hits = (cells >= 0) & mask.ravel()[np.maximum(cells, 0)]
    per_block = hits.reshape(STATE_MAP_SIZE ** 2, -1)
    return (per_block.sum(axis=1) / per_block.shape[1]).astype(np.float32)


class GlobalState:
    """One episode's state sampler: the sampled points' cells are found once, at ``reset``.

    Args:
        extent: the world's ``(x0, y0, x1, y1)``, metres.
        frame_0: robot 0's map frame → world (its true start pose).
        oracle: the episode's true coverage (its grid is the world grid).
        shared: the episode's shared map (robot 0's frame).
    """

    def __init__(self, extent: tuple[float, float, float, float], frame_0: Rigid2D,
                 oracle: OracleCoverage, shared: SharedMap) -> None:
        s, k = STATE_MAP_SIZE, STATE_SAMPLES
        x0, y0, x1, y1 = extent
        self.extent = extent
        # sample (a, b) of block (r, c) at row r·k + a, column c·k + b of an (s·k)² lattice
        # (row 0 at the bottom, like the grids), listed block by block so that a block's
        # samples are contiguous
        r, c, a, b = np.meshgrid(*(np.arange(n) for n in (s, s, k, k)), indexing="ij")
        points = np.stack([x0 + ((c * k + b).ravel() + 0.5) * ((x1 - x0) / (s * k)),
                           y0 + ((r * k + a).ravel() + 0.5) * ((y1 - y0) / (s * k))], axis=1)
        self._world_cells = cell_indices(points, oracle.geometry)
        self._shared_cells = cell_indices(frame_0.inverse().apply(points), shared.geometry)
        self._reachable = _blocks(oracle.reachable, self._world_cells)

    def vector(self, poses: Sequence[tuple[float, float, float]], oracle: OracleCoverage,
               shared: SharedMap, steps: int, max_cycles: int) -> np.ndarray:
        """The state now, from every robot's true ``poses`` ``(x, y, θ)``, the coverage, the
        shared map and the step count (manual, State)."""
        x0, y0, x1, y1 = self.extent
        n = len(poses)
        head = np.zeros(state_scalars(n), dtype=np.float64)
        for i, (x, y, th) in enumerate(poses):
            head[4 * i: 4 * i + 4] = ((x - x0) / (x1 - x0), (y - y0) / (y1 - y0),
                                      math.cos(th), math.sin(th))
        xy = [4 * i + k for i in range(n) for k in (0, 1)]
        head[xy] = np.clip(head[xy], 0.0, 1.0)
        head[4 * n:] = (oracle.fraction, oracle.overlap, len(shared.members) / (n - 1),
                        min(steps / max_cycles, 1.0))
        return np.concatenate([
            head.astype(np.float32),
            _blocks(oracle.union, self._world_cells),
            _blocks(shared.ever, self._shared_cells),
            self._reachable,
        ])
