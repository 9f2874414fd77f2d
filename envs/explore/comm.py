"""Communication: which robots are in contact, and what each robot knows of its teammates' maps.

Two robots are **in range** when their centres are at most ``comm.range`` apart (and, with
``comm.line_of_sight``, no wall crosses the segment between them: a pymunk segment query
against the world's walls, the same shapes the robots collide with). Robots are **in contact**
when a chain of in-range robots joins them (multi-hop: the connected groups of the in-range
graph, ``scipy.sparse.csgraph.connected_components``). With ``comm.range = None`` every robot
is always in contact with every other.

What robot ``i`` knows of robot ``j``'s map is a **view**: ``j``'s live map while they are in
contact; the copy of it as it was at the end of their last step in contact once contact ends
(taken when it ends: between contacts nothing streams); nothing if they never were in contact.
Robots that lose contact with ``j`` at the same step share one copy.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pymunk
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial.distance import pdist, squareform

from envs.explore.config import CommConfig
from envs.explore.mapping import RobotMap
from envs.explore.robot import WALL_COLLISION_TYPE

NEVER = -1
"""``TeamViews.seen`` of two robots that were never in contact."""


def contact_groups(positions: np.ndarray, config: CommConfig,
                   space: pymunk.Space | None = None) -> np.ndarray:
    """Each robot's contact group label (robots with equal labels are in contact), from their
    ``(N, 2)`` world ``positions`` (module docstring). ``space``: the world, needed for
    ``config.line_of_sight``."""
    n = len(positions)
    if config.unlimited:
        return np.zeros(n, dtype=np.int64)
    d = squareform(pdist(positions))
    near = d <= (math.inf if config.range is None else config.range)
    np.fill_diagonal(near, False)
    if config.line_of_sight:
        for i, j in zip(*np.nonzero(np.triu(near)), strict=True):
            if _wall_between(space, positions[i], positions[j]):
                near[i, j] = near[j, i] = False
    _, labels = connected_components(csr_matrix(near), directed=False)
    return labels.astype(np.int64)


def _wall_between(space: pymunk.Space, a: np.ndarray, b: np.ndarray) -> bool:
    """Whether a wall of ``space`` crosses the segment from ``a`` to ``b``."""
    hits = space.segment_query(tuple(a.tolist()), tuple(b.tolist()), 0.0, pymunk.ShapeFilter())
    return any(h.shape.collision_type == WALL_COLLISION_TYPE for h in hits)


class TeamViews:
    """What every robot knows of every teammate's map (module docstring).

    Args:
        maps: the robots' live maps (the env's ``maps``; read, never changed here).
        config: the communication settings.

    Attributes:
        groups: each robot's contact group label now.
        seen: ``(N, N)`` int, ``seen[i, j]``: the last step robots ``i`` and ``j`` were in
            contact (the current step while they are; :data:`NEVER`); ``seen[i, i]`` is now.
    """

    __slots__ = ("maps", "config", "groups", "seen", "_odometry", "_copies", "_unlimited")

    def __init__(self, maps: Sequence[RobotMap], config: CommConfig) -> None:
        n = len(maps)
        self.maps = list(maps)
        self.config = config
        self._unlimited = config.unlimited
        self.groups = np.zeros(n, dtype=np.int64)
        self.seen = np.full((n, n), NEVER, dtype=np.int64)
        self._odometry: list[list[np.ndarray | None]] = [[None] * n for _ in range(n)]
        self._copies: list[list[RobotMap | None]] = [[None] * n for _ in range(n)]

    def in_contact(self, i: int, j: int) -> bool:
        """Whether robots ``i`` and ``j`` are in contact now (``i == j``: True)."""
        return bool(self.groups[i] == self.groups[j])

    def contacts(self, i: int) -> tuple[int, ...]:
        """The teammates robot ``i`` is in contact with now."""
        return tuple(int(j) for j in np.flatnonzero(self.groups == self.groups[i]) if j != i)

    def view(self, i: int, j: int) -> RobotMap | None:
        """Robot ``j``'s map as robot ``i`` knows it: the live map while in contact (and
        ``j == i``), else the copy from their last contact, ``None`` if never."""
        if self.groups[i] == self.groups[j]:
            return self.maps[j]
        return self._copies[i][j]

    def odometry(self, i: int, j: int, live: Sequence[np.ndarray]) -> np.ndarray | None:
        """Robot ``j``'s odometry pose as robot ``i`` knows it: ``live[j]`` while in contact,
        else the pose at their last contact (``None`` if never)."""
        if self.groups[i] == self.groups[j]:
            return live[j]
        return self._odometry[i][j]

    def update(self, step: int, positions: np.ndarray, odometry: Sequence[np.ndarray],
               space: pymunk.Space | None) -> tuple[list[tuple[int, int]], bool]:
        """Contacts at ``step`` from the robots' world ``positions`` ``(N, 2)``, taken before
        this step's odometry and scans enter the maps (``odometry`` and the maps are still
        those of the last step): copies the maps and poses of contacts that end now.

        Returns:
            the ``(i, j)`` (``i != j``) that came into contact (at step 0: every pair in
            contact), and whether any contact began or ended (always at step 0).
        """
        old = self.groups
        new = old if self._unlimited else contact_groups(positions, self.config, space)
        same = new[:, None] == new[None, :]
        self.seen[same] = step
        if step == 0:
            self.groups = new
            n = len(self.maps)
            return [(i, j) for i in range(n) for j in range(n) if i != j and same[i, j]], True
        was = old[:, None] == old[None, :]
        if np.array_equal(same, was):
            return [], False
        made: dict[int, RobotMap] = {}
        for i, j in np.argwhere(was & ~same).tolist():
            if j not in made:
                made[j] = self.maps[j].copy()
            self._copies[i][j] = made[j]
            self._odometry[i][j] = np.array(odometry[j], dtype=np.float64)
        gained = [(i, j) for i, j in np.argwhere(same & ~was).tolist()]
        for i, j in gained:
            self._copies[i][j] = None
        self.groups = new
        return gained, True
