"""Merging in the loop: when the env merges the two robots' maps, the one call into
``fusion``, and what an episode keeps of the results.

Every ``mapping.merge_every`` steps the two topological maps are merged (``run_merge``); with
``"hybrid"``, every ``mapping.grid_merge_every`` steps (once the maps have grown by
``grid_merge_growth``) the occupancy grids are aligned too, and the transform in use is
checked against them. A merge of the same two maps as the last one is skipped (it would give
the same answer). An accepted transform that differs from the one in use replaces it and the
shared map is rebuilt (with ``"hybrid"``, one clearly different is not accepted when the grids
support the one in use clearly better, ``fusion.hybrid.IN_USE_MARGIN``); one the grids refute
is dropped (the shared map is robot 0's alone).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from envs.two_robot_explore.config import MERGE_METHODS as CONFIG_MERGE_METHODS
from envs.two_robot_explore.config import MappingConfig
from envs.two_robot_explore.mapping import RobotMap, SharedMap
from fusion.rigid import Rigid2D
from topo.graph import TopoMap
from topo.grid import OccupancyGrid

MERGE_SOURCES = ("none", "structural", "grid")
"""The ``merge_source`` info's codes: what supplied the transform in use — the structural merge
of the topological maps (checked by the grids in ``"hybrid"``) or the grid alignment."""

MERGE_METHODS = ("none", *(m for m in CONFIG_MERGE_METHODS if m != "none"))
"""The ``merge_method`` info's codes: ``MERGE_METHODS[info["merge_method"]]`` is the ``method`` of
the merge result that supplied the transform in use (``"none"``: no transform in use); the
``mapping.merge_method`` values, "none" first."""


@dataclass(frozen=True, slots=True)
class MergeState:
    """The merge state at one env step (``TwoRobotExploreEnv.merge_state``).

    Attributes:
        transform: the robot-1 → robot-0 transform in use (``fusion.Rigid2D``, ``p_0 = R p_1 +
            T``), ``None`` when none is (never merged, or dropped).
        method: ``method`` of the merge result that supplied it (``"none"`` without one).
        source: what supplied it: ``"structural"`` (the topological maps' merge) or ``"grid"``
            (the grid alignment); ``"none"`` without one.
        last: the last merge call's ``fusion.MergeResult`` (``None`` before the first).
        merges: merge calls this episode; ``drops``: transforms dropped (the grids refuted them).
        time_s: wall time of the last merge call, seconds (NaN before the first).
    """

    transform: Rigid2D | None
    method: str
    source: str
    last: Any
    merges: int
    drops: int
    time_s: float


def run_merge(map_a: TopoMap, map_b: TopoMap, method: str, grid_a: OccupancyGrid | None = None,
              grid_b: OccupancyGrid | None = None, try_grids: bool = False,
              in_use: Rigid2D | None = None, accept_threshold: float | None = None
              ) -> tuple[Any, str | None]:
    """The one place fusion is called: ``fusion.hybrid.hybrid_merge`` for ``"hybrid"`` (the
    grids are aligned only when ``try_grids``; ``in_use`` is the transform the env uses now,
    and with the grids ``fusion.hybrid.recheck`` re-examines it; accepted when the confidence
    reaches ``accept_threshold``, ``None``: the library's default), else
    ``fusion.merge_maps(map_a, map_b, method=method)``. Returns the result and why the grids
    refute ``in_use`` (``None``: they do not, or were not asked)."""
    if method == "hybrid":
        from fusion.grid_merge import GridMergeConfig
        from fusion.hybrid import hybrid_merge, recheck

        config = (None if accept_threshold is None
                  else GridMergeConfig(accept_threshold=accept_threshold))
        if try_grids and in_use is not None:
            return recheck(map_a, map_b, grid_a, grid_b, in_use, config)
        return hybrid_merge(map_a, map_b, grid_a, grid_b, try_grids=try_grids,
                            config=config, in_use=in_use), None
    from fusion.merge import merge_maps

    return merge_maps(map_a, map_b, method=method), None


class MergeLoop:
    """One episode's merging (module docstring): the schedule, and what supplied the transform
    in use.

    Attributes:
        result: the last merge call's result (``None`` before the first).
        calls: merge calls; ``drops``: transforms dropped because the grids refuted them.
        method, source: the result ``method`` and the :data:`MERGE_SOURCES` name of what
            supplied the transform in use (``"none"`` without one).
        time_s: wall time of the last merge call, seconds (NaN before the first).
    """

    def __init__(self, config: MappingConfig) -> None:
        self.config = config
        self.result: Any = None
        self.calls = 0
        self.drops = 0
        self.method = "none"
        self.source = "none"
        self.time_s = math.nan
        self._grid_tried_at = 0  # known cells (both maps) at the last grid alignment
        self._merged_maps: tuple = (None, None)  # the topological maps of the last merge
        self._errors: tuple | None = None  # (transform, robot 1's map, truth, errors) last

    def step(self, steps: int, maps: list[RobotMap], shared: SharedMap) -> int:
        """Merge if one is due at step ``steps`` and keep the result; returns the change of
        the shared map's known cells (a new transform rebuilds it)."""
        try_grids = self._due(steps, maps)
        if try_grids is None:
            return 0
        cfg = self.config
        result, refuted = run_merge(maps[0].topomap, maps[1].topomap, cfg.merge_method,
                                    maps[0].grid, maps[1].grid, try_grids=try_grids,
                                    in_use=shared.transform,
                                    accept_threshold=cfg.accept_threshold)
        return self._install(result, refuted, maps, shared)

    def _due(self, steps: int, maps: list[RobotMap]) -> bool | None:
        """``None`` if no merge is due at step ``steps``, else whether it also tries the grids
        (and then counts it as tried)."""
        cfg = self.config
        if not cfg.merge_every or cfg.merge_method == "none" or steps % cfg.merge_every:
            return None
        # the structural merge needs 3 nodes a map; the grid alignment (hybrid) only grids
        small = min(m.topomap.n_nodes for m in maps) < 3
        if small and cfg.merge_method != "hybrid":
            return None
        known = maps[0].n_ever + maps[1].n_ever
        try_grids = bool(cfg.grid_merge_every and steps % cfg.grid_merge_every == 0
                         and known >= self._grid_tried_at * (1.0 + cfg.grid_merge_growth))
        topomaps = (maps[0].topomap, maps[1].topomap)
        unchanged = topomaps[0] is self._merged_maps[0] and topomaps[1] is self._merged_maps[1]
        if (small or unchanged) and not try_grids:
            return None  # no structural merge to try, or the same maps: the same answer
        self._merged_maps = topomaps
        if try_grids:
            self._grid_tried_at = known
        return try_grids

    def _install(self, result: Any, refuted: str | None, maps: list[RobotMap],
                 shared: SharedMap) -> int:
        """Keep a merge's result; an accepted new transform re-warps the shared map, and one
        the grids ``refuted`` (why, from :func:`run_merge`) is dropped: robot 0's map alone.
        Returns the change of the shared map's known cells."""
        self.result = result
        self.calls += 1
        self.time_s = float(result.time_s)
        if result.accepted and (shared.transform is None
                                or not result.transform.allclose(shared.transform)):
            if result.method not in MERGE_METHODS:
                raise RuntimeError(f"merge result method {result.method!r} has no merge_method "
                                   f"code; known: {list(MERGE_METHODS)}")
            self.method = result.method
            # a hybrid result says what supplied it; any other method is the structural merge
            self.source = getattr(result, "supplied_by", None) or "structural"
            return shared.rebuild(maps[0], maps[1], result.transform)
        if refuted is not None and shared.transform is not None:
            self.drops += 1
            self.method = "none"
            self.source = "none"
            return shared.rebuild(maps[0], maps[1], None)
        return 0

    def errors(self, transform: Rigid2D | None, map_b: TopoMap, truth: Rigid2D,
               fallback: Any) -> tuple[float, float]:
        """Rotation error (degrees) and translation error (metres, at the centroid of robot 1's
        map ``map_b``; at ``fallback``, robot 1's position, when it has no node) of
        ``transform`` against ``truth``; NaN without a transform. The last answer is kept
        while the transform, the map and the truth stay the same objects."""
        if transform is None:
            return math.nan, math.nan
        cached = self._errors
        if (cached is not None and cached[0] is transform and cached[1] is map_b
                and cached[2] is truth):
            return cached[3]
        xy = map_b.xy
        at = xy.mean(axis=0) if len(xy) else fallback
        errors = (math.degrees(transform.rotation_error(truth)),
                  transform.translation_error(truth, at))
        # with no nodes the errors are measured at the moving robot: not kept
        self._errors = (transform, map_b, truth, errors) if len(xy) else None
        return errors

    def state(self, transform: Rigid2D | None) -> MergeState:
        """A :class:`MergeState` with ``transform``, the one in use."""
        return MergeState(transform, self.method, self.source, self.result, self.calls,
                          self.drops, self.time_s)
