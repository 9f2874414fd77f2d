"""Merging in the loop: when the env merges the two robots' maps, the one call into
``fusion``, and what an episode keeps of the results.

Every ``mapping.merge_every`` steps the two topological maps are merged (``run_merge``); with
``"hybrid"``, every ``mapping.grid_merge_every`` steps (once the maps have grown by
``grid_merge_growth``) the occupancy grids are aligned too, and the transform in use is
checked against them. A merge of the same two maps as the last one is skipped (it would give
the same answer). An accepted transform that differs from the one in use replaces it and the
shared map is rebuilt (with ``"hybrid"``, one clearly different is not accepted when the grids
support the one in use clearly better); one the grids refute is dropped (the shared map is
robot 0's alone). Every such decision is a step of ``fusion.decision.MergeRule``: the
first-merge check, what a merge call does to a pair's transform in use
(``fusion.decision.pair_verdict``) and the team's threshold for unconfirmed merges.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from envs.explore.comm import TeamViews
from envs.explore.config import MERGE_METHODS as CONFIG_MERGE_METHODS
from envs.explore.config import MappingConfig
from envs.explore.mapping import RobotMap
from fusion.decision import MergeRule, pair_verdict
from fusion.grid_merge import drift_prior
from fusion.rigid import Rigid2D
from fusion.team import CycleCheck, Edge, consistent_edges, frames_from
from topo.graph import TopoMap
from topo.grid import OccupancyGrid

MERGE_SOURCES = ("none", "structural", "grid", "known")
"""The ``merge_source`` info's codes: what supplied the transform in use — the structural merge
of the topological maps (checked by the grids in ``"hybrid"``), the grid alignment, or the
true start poses (``mapping.merge_method="known"``)."""

MERGE_METHODS = ("none", *(m for m in CONFIG_MERGE_METHODS if m != "none"))
"""The ``merge_method`` info's codes: ``MERGE_METHODS[info["merge_method"]]`` is the ``method`` of
the merge result that supplied the transform in use (``"none"``: no transform in use); the
``mapping.merge_method`` values, "none" first."""


@dataclass(frozen=True, slots=True)
class PairState:
    """One robot pair's merging at one env step (``MergeState.pairs``).

    Attributes:
        transform: ``T_ij`` in use, robot j's frame → robot i's (``i < j``), ``None`` if none.
        confidence: the last merge call's calibrated confidence (0 before the first).
        method, source: what supplied the transform in use (as :class:`MergeState`).
        calls, drops: merge calls of this pair; transforms dropped (the grids refuted them).
        kept: the transform in use passes the team's cycle check (with everything the team
            knows: not disputed by triangles, not contradicted by the forest; ``False``
            without a transform).
    """

    transform: Rigid2D | None
    confidence: float
    method: str
    source: str
    calls: int
    drops: int
    kept: bool


@dataclass(frozen=True, slots=True)
class MergeState:
    """The merge state at one env step (``merge_state()``).

    Attributes:
        transform: the robot-1 → robot-0 transform in use in robot 0's fused map
            (``fusion.Rigid2D``, ``p_0 = R p_1 + T``), ``None`` when robot 1 is not in it.
        method: ``method`` of the merge result that supplied robot pair (0, 1)'s transform
            (``"none"`` without one).
        source: what supplied it: ``"structural"`` (the topological maps' merge) or ``"grid"``
            (the grid alignment); ``"none"`` without one.
        last: the last merge call's ``fusion.MergeResult`` (``None`` before the first).
        merges: merge calls this episode; ``drops``: transforms dropped (the grids refuted them).
        time_s: wall time of the last merge call, seconds (NaN before the first).
        pairs: ``{(i, j): PairState}`` for every robot pair ``i < j`` (each pair's confidence).
        frames: ``frames[i][j]``: robot j's frame → robot i's, for every robot j in robot i's
            fused map (``frames[i][i]`` is the identity).
        fused: ``fused[i]``: the robots of robot i's fused map (its merged component), sorted.
        contacts: ``contacts[i]``: the teammates robot i is in contact with now.
        bending: with ``mapping.pose_graph``, robot 0's fused map against the truth
            (``GraphMerging.bending``: ATE, wall share, links); empty otherwise.
    """

    transform: Rigid2D | None
    method: str
    source: str
    last: Any
    merges: int
    drops: int
    time_s: float
    pairs: dict[tuple[int, int], PairState] = field(default_factory=dict)
    frames: tuple[dict[int, Rigid2D], ...] = ()
    fused: tuple[tuple[int, ...], ...] = ()
    contacts: tuple[tuple[int, ...], ...] = ()
    bending: dict[str, float] = field(default_factory=dict)


def run_merge(map_a: TopoMap, map_b: TopoMap, method: str, grid_a: OccupancyGrid | None = None,
              grid_b: OccupancyGrid | None = None, try_grids: bool = False,
              in_use: Rigid2D | None = None, accept_threshold: float | None = None,
              drift_prior: float = 0.0, first_merge_check: bool = True
              ) -> tuple[Any, str | None]:
    """The one place fusion is called: ``fusion.hybrid.hybrid_merge`` for ``"hybrid"`` (the
    grids are aligned only when ``try_grids``; ``in_use`` is the transform the env uses now,
    and with the grids ``fusion.hybrid.recheck`` re-examines it; without it, a pair's first
    merge, the grids must vouch for a structural merge when ``first_merge_check``
    (``mapping.first_merge_check``); accepted when the confidence
    reaches ``accept_threshold``, ``None``: the library's default; ``drift_prior``: how far
    the maps' odometry may have drifted, ``fusion.grid_merge.drift_prior``, 0 for perfect
    odometry), else
    ``fusion.merge_maps(map_a, map_b, method=method)``. Returns the result and why the grids
    refute ``in_use`` (``None``: they do not, or were not asked)."""
    if method == "hybrid":
        from fusion.grid_merge import GridMergeConfig
        from fusion.hybrid import hybrid_merge, recheck

        config = None
        if accept_threshold is not None or drift_prior:
            fields = {} if accept_threshold is None else {"accept_threshold": accept_threshold}
            config = GridMergeConfig(**fields, drift_prior=drift_prior)
        if try_grids and in_use is not None:
            return recheck(map_a, map_b, grid_a, grid_b, in_use, config)
        vouch = MergeRule.of(config, first_merge_check=first_merge_check).first_merge_vouch(
            in_use)
        return hybrid_merge(map_a, map_b, grid_a, grid_b, try_grids=try_grids,
                            config=config, in_use=in_use, vouch=vouch), None
    from fusion.structural import merge_maps

    return merge_maps(map_a, map_b, method=method), None


class PairLoop:
    """One robot pair's merging (``i < j``): its schedule, the transform in use and what
    supplied it. The pair is merged only while the two robots are in contact, on their live
    maps; ``history`` keeps every change of its transform in use, so that a teammate learns
    of it when it learns the maps (``TeamMerging``).

    Attributes:
        i, j: the robots.
        result: the last merge call's result (``None`` before the first).
        calls, drops: merge calls; transforms dropped because the grids refuted them.
        method, source: what supplied the transform in use (``"none"`` without one).
        transform: ``T_ij`` in use (robot j's frame → robot i's), ``None`` if none.
        history: ``(step, transform or None, confidence)`` of every change of it.
        last_run: the step of the last merge call (``-1`` before).
    """

    __slots__ = ("i", "j", "config", "result", "calls", "drops", "method", "source",
                 "transform", "history", "last_run", "noise", "_turns", "_grid_tried_at",
                 "_merged_maps")

    def __init__(self, i: int, j: int, config: MappingConfig, noise: float = 0.0) -> None:
        self.i, self.j = i, j
        self.config = config
        self.noise = noise
        self.result: Any = None
        self.calls = 0
        self.drops = 0
        self.method = "none"
        self.source = "none"
        self.transform: Rigid2D | None = None
        self.history: list[tuple[int, Rigid2D | None, float]] = []
        self.last_run = -1
        self._turns = 0  # merge steps this pair was considered at
        self._grid_tried_at = 0  # known cells (both maps) at the last grid alignment
        self._merged_maps: tuple = (None, None)  # the topological maps of the last merge

    def due(self, map_i: RobotMap, map_j: RobotMap) -> bool | None:
        """``None`` if this pair has nothing to merge at this merge step, else whether it
        also tries the grids (and then counts them as tried). The grid alignment is considered
        on every ``grid_merge_every / merge_every``-th turn of the pair (every
        ``grid_merge_every`` steps for a pair merged at every merge step, as two robots are),
        so that a team's grid alignments grow with its merge calls, not its pairs."""
        cfg = self.config
        # the structural merge needs 3 nodes a map; the grid alignment (hybrid) only grids
        small = min(map_i.topomap.n_nodes, map_j.topomap.n_nodes) < 3
        if small and cfg.merge_method != "hybrid":
            return None
        known = map_i.n_ever + map_j.n_ever
        self._turns += 1
        slot = bool(cfg.grid_merge_every
                    and self._turns % (cfg.grid_merge_every // cfg.merge_every) == 0)
        # with drifting odometry the transform in use is re-examined whether or not the maps
        # grew: drift can make it wrong while nothing is added
        grown = known >= self._grid_tried_at * (1.0 + cfg.grid_merge_growth)
        try_grids = slot and (grown or (self.noise > 0 and self.transform is not None))
        topomaps = (map_i.topomap, map_j.topomap)
        unchanged = topomaps[0] is self._merged_maps[0] and topomaps[1] is self._merged_maps[1]
        if (small or unchanged) and not try_grids:
            return None  # no structural merge to try, or the same maps: the same answer
        self._merged_maps = topomaps
        if try_grids:
            self._grid_tried_at = known
        return try_grids

    def adopt(self, steps: int, transform: Rigid2D) -> None:
        """Use ``transform`` from step ``steps`` on, known rather than merged
        (``mapping.merge_method="known"``): confidence 1, no merge call counted."""
        self.method = self.source = "known"
        self.transform = transform
        self.history.append((steps, transform, 1.0))

    def run(self, steps: int, map_i: RobotMap, map_j: RobotMap, try_grids: bool) -> bool:
        """Merge the two maps now and keep the result; returns whether the transform in use
        changed (a new one accepted, or the one in use dropped)."""
        cfg = self.config
        prior = drift_prior(self.noise, steps) if self.noise > 0 else 0.0
        result, refuted = run_merge(map_i.topomap, map_j.topomap, cfg.merge_method,
                                    map_i.grid, map_j.grid, try_grids=try_grids,
                                    in_use=self.transform,
                                    accept_threshold=cfg.accept_threshold, drift_prior=prior,
                                    first_merge_check=cfg.first_merge_check)
        self.result = result
        self.calls += 1
        self.last_run = steps
        confidence = float(getattr(result, "confidence", 0.0))
        verdict = pair_verdict(result.accepted, result.transform, confidence, self.transform,
                               self.confidence, refuted)
        if verdict == "replace":
            if result.method not in MERGE_METHODS:
                raise RuntimeError(f"merge result method {result.method!r} has no merge_method "
                                   f"code; known: {list(MERGE_METHODS)}")
            self.method = result.method
            # a hybrid result says what supplied it; any other method is the structural merge
            self.source = getattr(result, "supplied_by", None) or "structural"
            self.transform = result.transform
            self.history.append((steps, self.transform, confidence))
            return True
        if verdict == "confirm":
            # the transform in use, found again more confidently
            self.history.append((steps, self.transform, confidence))
            return True
        if verdict == "drop":
            self.drops += 1
            self.method = "none"
            self.source = "none"
            self.transform = None
            self.history.append((steps, None, confidence))
            return True
        return False

    @property
    def confidence(self) -> float:
        """The confidence the transform in use was last accepted with (0 without one)."""
        return self.history[-1][2] if self.transform is not None else 0.0

    def known(self, step: int) -> tuple[Rigid2D | None, float]:
        """The transform in use and its confidence as of ``step`` (``(None, 0)`` before)."""
        for s, transform, confidence in reversed(self.history):
            if s <= step:
                return transform, confidence
        return None, 0.0


class TeamMerging:
    """One episode's merging for the whole team: the pairs' merges, scheduled; each robot's
    fused map (its merged component and the frames into its own) from what it knows.

    Every ``merge_every`` steps, pairs in contact are considered, at most
    ``max(1, N // 2)`` merged per merge step (so a robot's share of the merge cost does not
    grow with the team): first pairs that would join two robots not yet in one fused map,
    then the least recently merged (with ``mapping.merge_method="known"`` nothing is merged:
    every pair's transform is its true one, ``truths``, from the first step). Robot ``i``
    knows a pair's transform as it was at the later of its last contacts with the pair's two
    robots, and fuses the maps it holds (``TeamViews``) along the pairs that pass the cycle
    check (``fusion.team``).

    Attributes:
        pairs: ``{(i, j): PairLoop}``.
        result, time_s: the last merge call's result and its wall time.
        calls, drops: merge calls and dropped transforms, all pairs together.
        frames: ``frames[i]``: ``{j: (to_i, from_i)}`` for each robot j in robot i's fused map.
        noise: the robots' odometry noise level (``drift.odometry_noise_level``): with drift,
            merges weigh ``fusion.grid_merge.drift_prior`` and rechecks need no growth.
        check: the team's cycle check with everything known (for ``merge_state``).
    """

    def __init__(self, n: int, config: MappingConfig, noise: float = 0.0,
                 truths: Sequence[Sequence[Rigid2D]] | None = None) -> None:
        if config.merge_method == "known" and truths is None:
            raise ValueError('mapping.merge_method "known" needs the true transforms '
                             '(truths), got None')
        self.n = n
        self._truths = truths
        self.config = config
        self.noise = noise
        self.pairs = {(i, j): PairLoop(i, j, config, noise) for i in range(n)
                      for j in range(i + 1, n)}
        self.result: Any = None
        self.time_s = math.nan
        ident = Rigid2D.identity()
        self.frames: list[dict[int, tuple[Rigid2D, Rigid2D]]] = [{i: (ident, ident)}
                                                                 for i in range(n)]
        self.check: CycleCheck | None = None
        self._keys: list[tuple | None] = [None] * n
        self._per_step = max(1, n // 2)
        # two robots have no cycle to confirm a merge: their pair is the accept rule alone
        self._min_unconfirmed = MergeRule(
            team_accept_threshold=config.team_accept_threshold).team_min_unconfirmed(n)
        self._errors: dict[int, tuple] = {}

    @property
    def calls(self) -> int:
        """Merge calls this episode, all pairs together."""
        return sum(p.calls for p in self.pairs.values())

    @property
    def drops(self) -> int:
        """Transforms dropped this episode (the grids refuted them), all pairs together."""
        return sum(p.drops for p in self.pairs.values())

    @property
    def pair01(self) -> PairLoop:
        """Robot pair (0, 1) (the two-robot env's only pair)."""
        return self.pairs[(0, 1)]

    def step(self, steps: int, views: TeamViews) -> bool:
        """Merge the pairs due at step ``steps``; returns whether a pair's transform changed."""
        cfg = self.config
        if cfg.merge_method == "known":
            # known from the start (history step 0): a robot learns a pair's transform with
            # its first contact with either robot, and fuses only the maps it holds
            fresh = [p for p in self.pairs.values() if p.transform is None]
            for pair in fresh:
                pair.adopt(0, self._truths[pair.i][pair.j])
            return bool(fresh)
        if not cfg.merge_every or cfg.merge_method == "none" or steps % cfg.merge_every:
            return False
        changed = False
        runs = 0
        for pair in self._order(views):
            if runs == self._per_step:
                break
            mi, mj = views.maps[pair.i], views.maps[pair.j]
            try_grids = pair.due(mi, mj)
            if try_grids is None:
                continue
            changed |= pair.run(steps, mi, mj, try_grids)
            runs += 1
            self.result = pair.result
            self.time_s = float(pair.result.time_s)
        return changed

    def _order(self, views: TeamViews) -> list[PairLoop]:
        """Pairs in contact, those joining two fused maps first, then least recently run."""
        comp = {}
        for i in range(self.n):
            for j in self.frames[i]:
                comp.setdefault(j, min(self.frames[i]))
        live = [p for p in self.pairs.values() if views.in_contact(p.i, p.j)]
        return sorted(live, key=lambda p: (comp.get(p.i) == comp.get(p.j), p.last_run, p.i,
                                           p.j))

    def refresh(self, views: TeamViews, centres: dict[int, np.ndarray]) -> list[int]:
        """Recompute each robot's fused map from what it knows now (``centres``: each map's
        centre, where the cycle check measures); returns the robots whose fused map changed
        (members or frames)."""
        changed = []
        for r in range(self.n):
            # the pairs' transforms it knows and the teammates' maps it holds: a map received
            # after its transform was known must join the fused map too
            held = {j for j in range(self.n) if views.view(r, j) is not None}
            knowledge = self._knowledge(r, views)
            key = (knowledge, tuple(sorted(held)))
            if key == self._keys[r]:
                continue
            self._keys[r] = key
            edges = [Edge(i, j, t, c) for (i, j), (t, c) in knowledge if t is not None]
            edges = [e for e in edges if e.i in held and e.j in held]
            check = consistent_edges(edges, centres, check=self.config.cycle_check,
                                     min_unconfirmed=self._min_unconfirmed)
            frames = frames_from(r, check.consistent, centres)
            old = self.frames[r]
            if frames.keys() != old.keys() or any(
                    frames[j][0] is not old[j][0] and not frames[j][0].allclose(old[j][0])
                    for j in frames):
                self.frames[r] = frames
                changed.append(r)
        edges = [Edge(p.i, p.j, p.transform, p.confidence) for p in self.pairs.values()
                 if p.transform is not None]
        self.check = consistent_edges(edges, centres, check=self.config.cycle_check,
                                      min_unconfirmed=self._min_unconfirmed)
        return changed

    def _knowledge(self, r: int, views: TeamViews) -> tuple:
        """What robot ``r`` knows of the pairs' transforms: ``((i, j), (transform,
        confidence))`` for each pair with one, as of its latest contact with i or j (now,
        while in contact: ``views.seen`` is the current step then)."""
        return tuple(((i, j), pair.known(int(max(views.seen[r, i], views.seen[r, j]))))
                     for (i, j), pair in self.pairs.items() if pair.history)

    def errors(self, j: int, transform: Rigid2D, map_j: TopoMap, truth: Rigid2D,
               fallback: Any) -> tuple[float, float]:
        """Rotation error (degrees) and translation error (metres, at the centroid of robot
        j's map ``map_j``; at ``fallback``, its position, when it has no node) of ``transform``
        (robot j → the reference robot) against ``truth``. The last answer per robot is kept
        while the transform, the map and the truth stay the same objects."""
        cached = self._errors.get(j)
        if (cached is not None and cached[0] is transform and cached[1] is map_j
                and cached[2] is truth):
            return cached[3]
        xy = map_j.xy
        at = xy.mean(axis=0) if len(xy) else fallback
        errors = (math.degrees(transform.rotation_error(truth)),
                  transform.translation_error(truth, at))
        # with no nodes the errors are measured at the moving robot: not kept
        if len(xy):
            self._errors[j] = (transform, map_j, truth, errors)
        else:
            self._errors.pop(j, None)
        return errors

    def state(self, views: TeamViews, transform: Rigid2D | None) -> MergeState:
        """A :class:`MergeState` (``transform``: robot 1 → robot 0 in robot 0's fused map)."""
        out = set() if self.check is None else {*self.check.disputed, *self.check.rejected,
                                                *self.check.unconfirmed}
        pairs = {k: PairState(p.transform, float(getattr(p.result, "confidence", 0.0))
                              if p.result is not None else p.confidence, p.method, p.source,
                              p.calls, p.drops, p.transform is not None and k not in out)
                 for k, p in self.pairs.items()}
        p01 = self.pair01
        return MergeState(transform, p01.method, p01.source, self.result, self.calls,
                          self.drops, self.time_s, pairs,
                          tuple({j: f[0] for j, f in fr.items()} for fr in self.frames),
                          tuple(tuple(sorted(fr)) for fr in self.frames),
                          tuple(views.contacts(i) for i in range(self.n)))
