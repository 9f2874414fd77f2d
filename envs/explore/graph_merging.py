"""Merging as a pose graph (``mapping.pose_graph``, experimental): links between local
windows, loop closures, and fused maps rendered from submaps.

Each robot's map is a chain of anchors with their patches (:mod:`envs.explore.submaps`) in a
team :class:`fusion.PoseGraph`. On every merge step (``mapping.merge_every``) each robot
tries at most ``mapping.window_searches`` window alignments (:meth:`GraphMerging._candidates`):
a **window** is ``mapping.window_anchors`` consecutive closed anchors rebuilt as one grid from
their own scans, near-rigid even when the whole map is bent. A robot's newest window is
aligned against

* the windows of a teammate it is in contact with — an accepted alignment ``T`` (window
  ``j``'s odometry frame → window ``i``'s) is made right at robot ``i``'s newest anchor
  ``a``: that anchor's own scans aligned on ``j``'s window near ``T`` (a window bends a few
  degrees inside, one anchor's stretch hardly; :data:`ANCHOR_DEG`), paired with the anchor
  ``b`` of ``j``'s window nearest to it, gives the link ``X_a⁻¹ · T_a · X_b`` (if the anchor's
  scans do not align: ``T`` between the windows' middle anchors). Links at the newest
  anchors are what keeps the robots' current places right. Before the pair is joined every
  window is a candidate (newest first), searched globally by
  ``fusion.grid_merge.merge_grids`` (no drift prior: a window has not drifted); after it,
  only windows whose estimate lies near, searched only near that estimate
  (``fusion.local_align.align_near``, :data:`NEAR_DEG`, :data:`NEAR_REACH_M`): a global
  search is drawn to look-alikes the estimate already rules out;
* its own older windows that do not overlap it and lie near in the current estimate — a loop
  closure, searched near the estimate too (``PoseGraph.add_loop``: kept only if the odometry
  can explain it).

The pose graph keeps each pair's pairwise-consistent links (at least two), optimises each
component of robots, and a robot's **fused map** is the patches of its component it has
received (:meth:`GraphMerging.received`: a teammate's as of their last contact) composed at
``corrections(robot, frame=i)``; its own grid, the **working map** it explores on, is its own
patches at their corrections pinned at its newest anchor (:meth:`GraphMerging.straighten`).
Its teammates' places in that working map (``frames``) are the rigid transforms right at the
robots' newest anchors: ``C_i⁻¹ · C_j`` of the two newest anchors' corrections. This
slice's simplification: the graph's estimates are the team's, whatever the robots' contacts
(a link found while a robot was out of contact still moves its map).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from envs.explore.comm import TeamViews
from envs.explore.config import MappingConfig, RobotConfig
from envs.explore.mapping import RobotMap
from envs.explore.submaps import (
    PatchCache,
    RobotSubmaps,
    ScanSettings,
    compose,
    shift_cells,
)
from fusion.grid_layers import LayerCache, known_box
from fusion.grid_merge import GridMergeConfig, merge_grids
from fusion.local_align import align_near, near_features
from fusion.posegraph import PoseGraph
from fusion.rigid import Rigid2D
from topo.grid import CellState

LINK_SIGMAS = (0.15, 0.15, math.radians(3.0))
"""Standard deviations ``(x, y, θ)`` (m, m, rad) of a window alignment at the windows' middle
anchors: the grid alignment's "right" is within 2° and 0.3 m, and a window still bends by a
few degrees inside."""

NEAR_DEG, NEAR_REACH_M = 3.0, 0.5
"""A known pair's window alignment (a joined pair, a loop closure) is searched only this close
(degrees, metres) to the graph's estimate (``fusion.local_align.align_near``)."""

ANCHOR_DEG = 4.0
"""A link's anchor alignment (robot ``i``'s newest anchor's scans on ``j``'s window) is searched
this close (degrees; and :data:`NEAR_REACH_M`) to the windows' alignment: about the heading
a window bends inside."""

STRAIGHTEN_CELLS = 1.0
"""A robot's working map is recomposed (:meth:`GraphMerging.straighten`) once the graph has
moved some patch of it by more than this many cells since it was drawn: each recomposition
costs a whole grid and a new topological map, and a cell's move changes little for either."""

NEAR_M = 8.0
"""A window is searched against another (after a pair is joined, or for a loop closure) only
if their centres lie this close (metres) in the current estimate."""


NEAR_MODEL = "window_near"
"""The calibrated model (``fusion/calibration.json``) of a near search's confidence: fitted
on development worlds' near searches, labelled right within 5° and 1 m at their anchors
(``python -m fusion.calibration fit --model window_near``)."""


def _near_model():
    from fusion.calibration import load_model

    return load_model(NEAR_MODEL)


@dataclass(frozen=True, slots=True)
class LinkRecord:
    """An accepted window alignment added to the graph: robots and anchors (``i == j``: a
    loop closure), the relative pose, its calibrated confidence (of being within 5° and 1 m at
    its anchors: the grid alignment's for a global search, model ``"window_near"`` on
    ``features``, ``fusion.local_align.near_features``, for a search near the estimate),
    whether the graph took it (loops only; a link's fate is decided with its pair's others)
    and the near search's features (``None`` for a global search)."""

    i: int
    a: int
    j: int
    b: int
    relative: Rigid2D
    confidence: float
    taken: bool
    features: dict[str, float] | None = None


class GraphMerging:
    """The team's pose-graph merging for one episode (module docstring).

    Args:
        maps: each robot's :class:`RobotMap` (their geometries).
        config: the env's mapping settings (``anchor_every``, ``window_anchors``,
            ``window_searches``, ``merge_every``).
        robot: the robots' settings (the odometry model and noise weigh odometry edges).
        scan: how the robots' scans are folded into a grid.

    Attributes:
        graph: the :class:`fusion.PoseGraph`.
        submaps: each robot's :class:`RobotSubmaps`.
        records: every accepted window alignment (:class:`LinkRecord`).
        searches: window alignments tried.
    """

    def __init__(self, maps: Sequence[RobotMap], config: MappingConfig, robot: RobotConfig,
                 scan: ScanSettings) -> None:
        self.config = config
        self.scan = scan
        self.n = len(maps)
        self.graph = PoseGraph(self.n)
        self.submaps = [RobotSubmaps(m.geometry) for m in maps]
        self.records: list[LinkRecord] = []
        self.searches = 0
        self._noise = tuple(float(v) for v in robot.odometry_noise)
        self._alphas = (tuple(robot.odometry_alphas) if robot.odometry_model == "rot_trans_rot"
                        else None)
        self._tried: set[tuple[int, int, int, int]] = set()
        self._turns = [0] * self.n  # merge steps each robot searched on
        self._joins = [0] * self.n  # joining searches each robot made
        self._windows: dict[tuple[int, int, int], object] = {}
        self._poses: dict[tuple[int, int], list[Rigid2D]] = {}
        self._grid_cfg = GridMergeConfig()
        self._drawn = PatchCache()  # closed patches drawn into fused maps, by (r, m, anchor),
        # and into working maps, by ("own", r, anchor)
        self._straightened = [False] * self.n  # working maps recomposed while non-trivial
        self._pinned: list[list[Rigid2D]] = [[] for _ in range(self.n)]  # as last drawn

    # ----------------------------------------------------------------- per step
    def before_scans(self, steps: int, odometry: Sequence[np.ndarray],
                     truths: Sequence[np.ndarray], maps: Sequence[RobotMap]) -> None:
        """This step's odometry into each robot's edge; a new anchor every ``anchor_every``
        steps (before the step's scans, which then belong to it)."""
        for i, sub in enumerate(self.submaps):
            sub.accumulate(odometry[i], self._noise, self._alphas)
            if steps % self.config.anchor_every == 0:
                sub.start_anchor(odometry[i], truths[i], maps[i].grid.log_odds)
                self.graph.add_anchor(i, sub.poses[-1], sub.sigmas[-1])

    def add_scan(self, i: int, odometry: np.ndarray, ranges: np.ndarray) -> None:
        """Keep robot ``i``'s scan under its newest anchor."""
        self.submaps[i].add_scan(odometry, ranges)

    def trivial(self, r: int) -> bool:
        """Robot ``r``'s fused map is its own grid unchanged: no teammate, no loop closure."""
        return len(self.graph.component(r)) == 1 and not any(
            rec.taken and rec.i == r == rec.j for rec in self.records)

    # ----------------------------------------------------------------- searching
    def step(self, views: TeamViews) -> bool:
        """Try this merge step's window alignments; returns whether the graph gained a link
        or a loop closure."""
        changed = False
        for i, ei, j, ej in self._candidates(views):
            self._tried.add((i, ei, j, ej))
            changed |= self._align(i, ei, j, ej)
        return changed

    def _closed(self, r: int) -> int:
        return len(self.submaps[r].patches)

    def _centre(self, r: int, end: int, frame: int) -> np.ndarray:
        if (r, frame) not in self._poses:
            self._poses[(r, frame)] = self.graph.corrected_poses(r, frame)
        poses = self._poses[(r, frame)]
        first = end - self.config.window_anchors + 1
        return np.mean([p.T for p in poses[first:end + 1]], axis=0)

    def _candidates(self, views: TeamViews) -> list[tuple[int, int, int, int]]:
        """``(i, newest window end of i, j, window end of j)`` to try this merge step: each
        robot's own ``window_searches`` (its budget: a team's cost grows with its size, and
        the pairs still to join cannot starve a joined robot's loop closures). A robot alone
        in its map searches its teammates first (**joining**: one candidate per teammate in
        contact, taken in turn), then its own loop closures; a robot already joined to some
        alternates, merge step by merge step, between joining the rest and the searches
        **near** its estimate: its loop closures and its joined teammates' windows, which of
        the two first changing every other turn (neither starves the other)."""
        w = self.config.window_anchors
        stride = max(1, w // 2)
        self._poses = {}  # corrected poses by (robot, frame), as the graph is now
        out = []
        for i in range(self.n):
            ei = self._closed(i) - 1
            if ei < w - 1:
                continue
            joining, loops, joined = [], [], []
            component = self.graph.component(i)
            for j in range(self.n):
                ej_max = self._closed(j) - 1 if j != i else ei - w
                ends = [e for e in range(ej_max, w - 2, -stride)
                        if (i, ei, j, e) not in self._tried]
                if not ends:
                    continue
                if j == i:
                    loops += [(i, ei, i, e) for e in self._near(i, ei, i, ends)[:1]]
                elif views.in_contact(i, j):
                    if j in component:
                        joined += [(i, ei, j, e) for e in self._near(i, ei, j, ends)[:1]]
                    else:
                        joining.append((i, ei, j, ends[0]))
            if joining:  # teammates in turn
                k = self._joins[i] % len(joining)
                joining = joining[k:] + joining[:k]
            near = loops + joined if self._turns[i] % 4 < 2 else joined + loops
            if len(component) > 1 and joining and near and self._turns[i] % 2:
                order = near + joining
            else:
                order = joining + near
            if joining or near:
                self._turns[i] += 1
            chosen = order[: self.config.window_searches]
            self._joins[i] += sum(c[2] != i and c[2] not in component for c in chosen)
            out += chosen
        return out

    def _near(self, i: int, ei: int, j: int, ends: list[int]) -> list[int]:
        """``ends`` of ``j``'s windows whose centre lies within :data:`NEAR_M` of ``i``'s
        window ``ei`` in ``i``'s frame, nearest first."""
        c = self._centre(i, ei, i)
        dist = [(float(np.linalg.norm(self._centre(j, e, i) - c)), e) for e in ends]
        return [e for d, e in sorted(dist) if d <= NEAR_M]

    def _window(self, r: int, end: int, first: int | None = None):
        """Robot ``r``'s grid of anchors ``first … end`` (default: the window ending at
        ``end``) rebuilt from their scans, cached."""
        if first is None:
            first = end - self.config.window_anchors + 1
        key = (r, first, end)
        if key not in self._windows:  # a window never changes: its layers are found once
            grid = self.submaps[r].window_grid(first, end, self.submaps[r].geometry.resolution,
                                               self.scan)
            self._windows[key] = None if grid is None else LayerCache.of(grid)
        return self._windows[key]

    def _predicted(self, i: int, a: int, j: int, b: int) -> Rigid2D:
        """The current estimate of robot ``j``'s odometry frame at anchor ``b`` → robot
        ``i``'s at anchor ``a`` (the transform between their windows' grids)."""
        return self.graph.correction(i, a).inverse() @ self.graph.correction(j, b, frame=i)

    def _align(self, i: int, ei: int, j: int, ej: int) -> bool:
        grid_a, grid_b = self._window(i, ei), self._window(j, ej)
        if grid_a is None or grid_b is None:
            return False
        self.searches += 1
        half = self.config.window_anchors // 2
        a, b = ei - half, ej - half
        features = None
        if i == j or j in self.graph.component(i):  # known: search near the estimate
            estimate = self._predicted(i, a, j, b)
            transform = align_near(grid_a, grid_b, estimate, self._grid_cfg,
                                   max_deg=NEAR_DEG, reach_m=NEAR_REACH_M)
            if transform is None:
                return False
            features = near_features(grid_a, grid_b, estimate, transform, self._grid_cfg,
                                     loop=i == j)
        else:
            result = merge_grids(grid_a, grid_b, self._grid_cfg)
            if not result.accepted:
                return False
            transform = result.transform
        if i != j:
            at = self._at_anchor(i, ei, j, ej, transform)
            if at is not None:
                a, b, moved = at
                if features is not None:
                    features["anchor_shift_deg"] = math.degrees(moved.rotation_error(transform))
                transform = moved
        confidence = (float(result.confidence) if features is None
                      else _near_model()(features))
        xa, xb = self.submaps[i].poses[a], self.submaps[j].poses[b]
        return self.add_alignment(i, a, j, b, xa.inverse() @ transform @ xb, confidence,
                                  features)

    def _at_anchor(self, i: int, ei: int, j: int, ej: int, transform: Rigid2D):
        """The window alignment ``transform`` (``j``'s odometry frame → ``i``'s) made right
        at robot ``i``'s newest anchor ``ei``: that anchor's own scans aligned on ``j``'s
        window near ``transform`` — a window bends a few degrees inside, an anchor hardly —
        and paired with ``j``'s window anchor nearest to it. ``(a, b, transform)``, or
        ``None`` if the anchor's scans do not align."""
        one, window = self._window(i, ei, ei), self._window(j, ej)
        if one is None:
            return None
        local = align_near(window, one, transform.inverse(), self._grid_cfg,
                           max_deg=ANCHOR_DEG, reach_m=NEAR_REACH_M)
        if local is None:
            return None
        here = local.apply(self.submaps[i].poses[ei].T[None])[0]
        first = ej - self.config.window_anchors + 1
        b = min(range(first, ej + 1),
                key=lambda k: float(np.linalg.norm(self.submaps[j].poses[k].T - here)))
        return ei, b, local.inverse()

    def add_alignment(self, i: int, a: int, j: int, b: int, relative: Rigid2D,
                      confidence: float, features: dict[str, float] | None = None) -> bool:
        """Anchor ``b`` of robot ``j`` placed in anchor ``a``'s frame of robot ``i``
        (``relative``) into the graph: a loop closure if ``i == j`` (``True`` if the graph
        took it), else a link (``True``; its fate is decided with its pair's others), and
        recorded (:attr:`records`, with the near search's ``features`` if it was one). What
        every accepted window alignment becomes — and what a benchmark's oracle aligner calls
        with the truth."""
        if i == j:
            taken = self.graph.add_loop(i, a, b, relative, LINK_SIGMAS, confidence)
        else:
            self.graph.add_link((i, a), (j, b), relative, LINK_SIGMAS, confidence)
            taken = True
        self.records.append(LinkRecord(i, a, j, b, relative, confidence, taken, features))
        return taken

    # ----------------------------------------------------------------- working maps
    def straighten(self, r: int, maps: Sequence[RobotMap]) -> bool:
        """Robot ``r``'s own grid (its **working map**: what it explores, observes and
        extracts its topological map from) recomposed from its own patches at the graph's
        corrections, **pinned at its newest anchor** — the anchor the robot is driving from
        keeps its odometry pose, so the robot's odometry stays right where it is and the
        older parts of its map move to where the graph puts them; the newest anchor's patch so
        far stays as scanned. Returns whether the grid was recomposed: while ``r`` has no
        teammate and no loop closure (every correction the identity) and was not recomposed
        before, it is left as scanned. Patches stay what each anchor's scans added in the
        odometry frame, so fused maps are unchanged by it. Why: under drift the robot's own
        map bends as its fused map did, and the explorers and the topological map read the
        own map."""
        sub = self.submaps[r]
        if not sub.patches or (self.trivial(r) and not self._straightened[r]):
            return False
        corrections = self.graph.corrections(r)
        pin = corrections[-1].inverse()
        closed = len(sub.patches)
        pinned = [pin @ c for c in corrections[:closed]]
        drawn = self._pinned[r] + [Rigid2D()] * (closed - len(self._pinned[r]))
        geom = maps[r].geometry
        if all(shift_cells(d, p, patch, geom) <= STRAIGHTEN_CELLS
               for d, p, patch in zip(drawn, pinned, sub.patches, strict=True)):
            return False  # nothing moved by more than a cell since it was drawn
        grid = maps[r].grid
        live = grid.log_odds.astype(np.float64) - sub.base
        base = compose(sub.patches, pinned, geom, geom, cache=self._drawn,
                       keys=[("own", r, k) for k in range(closed)])
        self._pinned[r] = pinned
        # clamped and rounded as the grid is (float32): the newest anchor's patch is then the
        # scans' change alone, not the clamp's or the rounding's over the whole map
        base = np.clip(base, -grid.model.clamp, grid.model.clamp).astype(grid.log_odds.dtype)
        base = base.astype(np.float64)
        grid.assign(base + live)
        sub.rebase(base)
        box = known_box(grid.states())
        if box is not None:  # moved cells stay inside the box its topological map is read from
            r0, r1, c0, c1 = box
            maps[r].widen(r0, r1 + 1, c0, c1 + 1)
        self._straightened[r] = not self.trivial(r)
        return True

    def scanned_log_odds(self, r: int, maps: Sequence[RobotMap]) -> np.ndarray:
        """Robot ``r``'s map as its scans made it, at its odometry: its patches added up
        without corrections (float64 log-odds of its grid) — the bent map the graph
        straightens, for comparison (``env.scanned_map``)."""
        patches = self.submaps[r].all_patches(maps[r].grid.log_odds)
        return compose(patches, [Rigid2D()] * len(patches), maps[r].geometry,
                       maps[r].geometry)

    # ----------------------------------------------------------------- fused maps
    def fused_log_odds(self, r: int, maps: Sequence[RobotMap], views: TeamViews) -> np.ndarray:
        """Robot ``r``'s fused map: its component's patches that ``r`` has received
        (:meth:`received`) composed at their corrections into ``r``'s frame (closed patches
        drawn again only once their correction moves them, :class:`PatchCache`), float64
        log-odds of ``r``'s grid geometry."""
        dst = maps[r].geometry
        acc = np.zeros(dst.shape, dtype=np.float64)
        for m in sorted(self.graph.component(r)):
            patches = self.received(r, m, maps, views)
            corrections = self.graph.corrections(m, frame=r)[:len(patches)]
            closed = len(self.submaps[m].patches)  # the newest (live) patch still changes
            keys = [(r, m, k) if k < closed else None for k in range(len(patches))]
            compose(patches, corrections, maps[m].geometry, dst, acc, cache=self._drawn,
                    keys=keys)
        return acc

    def received(self, r: int, m: int, maps: Sequence[RobotMap], views: TeamViews) -> list:
        """Robot ``m``'s patches as robot ``r`` has them (index = anchor): all, the newest one
        so far included, for ``r`` itself and while the two are in contact (``views``); else
        those closed by their last contact (none if they never were in contact) — what a
        teammate's map is between contacts (``envs.explore.comm``). Why: communication limits
        hold for the maps a fused map is made of (the graph's estimates are the team's)."""
        sub = self.submaps[m]
        if m == r or views.in_contact(r, m):
            return sub.all_patches(maps[m].grid.log_odds)
        seen = int(views.seen[r, m])
        return [] if seen < 0 else sub.patches[:seen // self.config.anchor_every]

    def frames(self, r: int) -> dict[int, tuple[Rigid2D, Rigid2D]]:
        """``{j: (to_r, from_r)}`` for each robot ``j`` of ``r``'s component: robot ``j``'s
        odometry frame → robot ``r``'s, right at the two robots' newest anchors."""
        own = self.graph.correction(r, -1).inverse()
        out = {}
        for j in sorted(self.graph.component(r)):
            to_r = own @ self.graph.correction(j, -1, frame=r)
            out[j] = (to_r, to_r.inverse())
        return out

    def link_errors(self) -> list[tuple[float, float]]:
        """Each accepted window alignment's error at its own anchors against the truth:
        rotation (degrees) and translation (metres)."""
        return [self._error((rec.i, rec.a), (rec.j, rec.b), rec.relative)
                for rec in self.records]

    def _error(self, a: tuple[int, int], b: tuple[int, int], relative: Rigid2D
               ) -> tuple[float, float]:
        """Rotation (degrees) and translation (metres) error of ``relative`` (anchor ``b``
        in anchor ``a``'s frame) against the anchors' true poses."""
        ta = Rigid2D.from_pose(self.submaps[a[0]].truths[a[1]])
        tb = Rigid2D.from_pose(self.submaps[b[0]].truths[b[1]])
        err = (ta.inverse() @ tb).inverse() @ relative
        return abs(math.degrees(err.theta)), float(np.hypot(*err.T))

    # ----------------------------------------------------------------- truth
    def fused_truth(self, maps: Sequence[RobotMap], views: TeamViews, walls,
                    states: np.ndarray | None = None) -> tuple[float, float]:
        """Robot 0's fused map against the truth now: the ATE (m) of its component's anchors
        in its frame (:func:`fusion.evaluation.bending.ate_rms`) and the share of its occupied
        cells within ``walls.tolerance`` of a true wall (``walls``: a
        :class:`fusion.evaluation.bending.WallIndex`; NaN without occupied cells) once put in
        the world by the anchors' best rigid fit. ``states``: its fused map's cell states if
        the caller has them (else composed here). For metrics only."""
        from fusion.evaluation.bending import ate_rms, world_alignment

        comp = sorted(self.graph.component(0))
        est = np.vstack([self.graph.trajectory(m, frame=0) for m in comp])
        truth = np.vstack([np.array(self.submaps[m].truths) for m in comp])
        if states is None:
            states = maps[0].grid.model.classify(self.fused_log_odds(0, maps, views))
        occupied = states == CellState.OCCUPIED
        return (ate_rms(est, truth),
                walls.share(_centres(occupied, maps[0]), world_alignment(est, truth)))

    def bending(self, maps: Sequence[RobotMap], walls, views: TeamViews) -> dict[str, float]:
        """Robot 0's fused map against the truth (:mod:`fusion.evaluation.bending`), beside
        its own map uncorrected (``own_*``: its patches as scanned, at its odometry) and as its
        working map (``working_*``: :meth:`straighten`'s): ATE of the anchors (m), the share
        of occupied cells within 0.2 m of a true wall; and the links and loop closures the
        graph keeps in that map, with how many of them are more than 5° or 1 m off at their
        own anchors (``walls``: the world's :class:`fusion.evaluation.bending.WallIndex`).
        For metrics only."""
        from fusion.evaluation.bending import ate_rms, world_alignment

        fused_ate, fused_wall = self.fused_truth(maps, views, walls)
        sub, model = self.submaps[0], maps[0].grid.model
        odo = np.array([[p.T[0], p.T[1]] for p in sub.poses])
        own_truth = np.array(sub.truths)
        pin = self.graph.correction(0, -1).inverse()
        working = np.array([(pin @ p).T for p in self.graph.corrected_poses(0)])
        raw = model.classify(self.scanned_log_odds(0, maps)) == CellState.OCCUPIED
        kept = [m for i in range(self.n) for j in range(i + 1, self.n)
                for m in self.graph.links(i, j)[0]]
        comp = sorted(self.graph.component(0))
        loops = [m for r in comp for m in self.graph.loops(r)]

        def wrong(measurements: list) -> float:  # more than 5° or 1 m off at their anchors
            return float(sum(rot > 5.0 or trans > 1.0 for rot, trans in
                             (self._error(m.a, m.b, m.relative) for m in measurements)))
        return {
            "fused_robots": float(len(comp)),
            "fused_ate_m": fused_ate,
            "own_ate_m": ate_rms(odo, own_truth),
            "working_ate_m": ate_rms(working, own_truth),
            "fused_wall_share": fused_wall,
            "own_wall_share": walls.share(_centres(raw, maps[0]),
                                          world_alignment(odo, own_truth)),
            "working_wall_share": walls.share(_centres(maps[0].grid.occupied_mask(), maps[0]),
                                              world_alignment(working, own_truth)),
            "links_kept": float(len(kept)),
            "links_kept_wrong": wrong(kept),
            "links_accepted": float(sum(r.i != r.j for r in self.records)),
            "loops_kept": float(len(loops)),
            "loops_kept_wrong": wrong(loops),
            "window_searches": float(self.searches),
        }


def _centres(mask: np.ndarray, robot_map: RobotMap) -> np.ndarray:
    """Map-frame centres of the true cells of ``mask`` (``robot_map``'s geometry)."""
    g = robot_map.geometry
    rows, cols = np.nonzero(mask)
    return np.stack([g.origin[0] + (cols + 0.5) * g.resolution,
                     g.origin[1] + (rows + 0.5) * g.resolution], axis=1)
