"""``merge_maps``: align two robots' topological maps from any relative pose, and know when not to.

The paper's ICP-SVD is local (it starts from ``R = I``), plain ICP is biased when maps overlap only
in part, and the paper's exhaustive search is slow and ambiguous. ``method="auto"`` is a global
merge built from the maps' structure:

1. **Node pairs** of each map: ends of a path, nodes two paths apart, and each node's ``knn``
   nearest nodes, at least ``min_pair_distance`` apart.
2. **2-point consensus**: every A pair and B pair whose lengths agree within ``pair_tolerance``
   and whose end kinds are compatible (:data:`KIND_COMPATIBLE`) gives one rigid hypothesis.
3. **Coarse score** of every hypothesis from a raster of A (each cell holds the nearest A node
   of each compatible kind within ``coarse_tolerance``, and whether it lies on an A path): one
   closed-form fit of the hypothesis to the B nodes that land on such a node, then a soft
   count ``Σ (1 − d²/eps²)`` of the B nodes landing within ``eps`` of their cell's node, −1 per
   B junction/corner landing on an A path far from any A node. Refitting before counting is
   what finds pairs sharing few nodes: the right hypothesis lands its 3–5 shared nodes tightly,
   while a hard count within the loose coarse tolerance preferred chance alignments of the
   corridor lattice landing 6–8 nodes loosely (thousands of hypotheses cost 1–2 ms).
4. **Candidates**: the ``path_pool`` best *distinct* hypotheses (non-maximum suppression on angle
   and on where B's centroid lands), and the ``sparse_pool`` best of those landing only 3 B nodes
   tightly (pairs sharing 3 nodes, kept apart so that the many chance 3-node landings do not
   crowd the coarse ranking), are re-ranked with their **path evidence** (how many metres of
   each map's paths lie on the other's, and how many run beside them: rasters of the distance to
   each map's paths), the ``candidates`` best refined by gated nearest-compatible-node SVD fits,
   and the ``scored`` most matched fully scored (:class:`MergeEvidence`): soft one-to-one matches
   within ``eps`` (the paper's ω with a tolerance), matched paths, **conflicts** (a junction or
   corner of one map on a path of the other with no node there: the other robot passed and saw
   no such place), **crossings** (paths crossing without a junction), the agreement of the
   paths leaving matched nodes, and the path evidence.
   The score is the calibrated log-odds that the alignment is right (:data:`CONFIDENCE_WEIGHTS`).
5. **Refinement** of the best candidate with the paper's ICP-SVD (:func:`fusion.icp_svd`), gated
   at ``eps`` and trimmed (TrICP) to the estimated overlap, then least-squares SVD fits on mutually
   nearest nodes within ``fit_eps`` — what the oracle does with the true correspondences — and on
   B's path points lying on A's paths (long corridors fix the rotation better than the few nodes
   of a small overlap: on 5 of the 900 evaluation pairs of seed 0 it succeeds where the oracle
   fails).
6. **Accept/reject** (:func:`decide`): enough matches, not collinear, log-odds at least
   ``min_score``, and a margin of ``min_margin`` over the best *distinct* runner-up (a symmetric
   map has several equally good alignments: rejected as ambiguous).

The baselines share steps 4–6 so that their difference is the search alone: ``"paper_icp"`` is the
paper's ICP-SVD from its own initialisation (no refinement), ``"exhaustive"`` the paper's search
(:func:`fusion.exhaustive_search`, ``exhaustive_step_deg``; its tied optima all refined, the best
by score kept, the others its runner-up), and ``"multistart_icp"`` the paper's ICP from
``multistart_starts`` rotations about the centroids, the 4 best refined.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from fusion import _merge_kernels as K
from fusion.icp import degeneracy, icp_checked, icp_svd, moments_degeneracy, rigid_fit
from fusion.rigid import Rigid2D, wrap_angle
from fusion.search import exhaustive_search
from topo.graph import NodeKind, TopoMap
from topo.validation import check_int, check_real, config_from

DEFAULT_ACCEPT_THRESHOLD = 0.8
"""Default :attr:`MergeConfig.accept_threshold`: the smallest (on a 0.05 grid) at which the
cross-validated tuning pairs of ``benchmarks/calibrate_merge.py --model structural`` (env pairs
and synthetic pairs) had at most 1 % false accepts on no-overlap pairs and 1 % wrong accepts of
all pairs."""

METHODS = ("auto", "paper_icp", "exhaustive", "multistart_icp")
"""Names accepted by :func:`merge_maps` ``method``."""

KIND_COMPATIBLE = np.zeros((len(NodeKind), len(NodeKind)), dtype=np.bool_)
"""``[kind_a, kind_b]``: may a node of A of ``kind_a`` be the same place as one of B of ``kind_b``?
Same kinds; junction ↔ corner (a side branch one robot did not see); dead end ↔ corner (a corner
at the edge of one robot's explored space, its second corridor unseen). Not dead end ↔ junction
(a frontier dead end sits part-way along a corridor; allowing it adds chance matches: measured)."""
for _a, _b in [(NodeKind.JUNCTION, NodeKind.JUNCTION), (NodeKind.CORNER, NodeKind.CORNER),
               (NodeKind.DEAD_END, NodeKind.DEAD_END), (NodeKind.JUNCTION, NodeKind.CORNER),
               (NodeKind.CORNER, NodeKind.JUNCTION), (NodeKind.DEAD_END, NodeKind.CORNER),
               (NodeKind.CORNER, NodeKind.DEAD_END), (NodeKind.GATEWAY, NodeKind.GATEWAY)]:
    KIND_COMPATIBLE[_a, _b] = True
KIND_COMPATIBLE.setflags(write=False)

CLEARANCE_STEP = 0.2
"""Width in metres of the clearance classes (:attr:`topo.TopoMap.clearance`) of matched nodes."""
CLEARANCE_CLASSES = 16
"""Clearance classes (the last one holds every clearance beyond)."""
CLEARANCE_TOLERANCE = 2
"""Two nodes may be the same place only if their clearance classes differ by at most this."""

_N_KINDS = len(NodeKind)
_PLACE_KINDS = (NodeKind.JUNCTION, NodeKind.CORNER, NodeKind.DEAD_END)


def _match_table() -> np.ndarray:
    """``[code_a, code_b]`` over descriptor codes ``kind + len(NodeKind) · clearance class``:
    may a node of A and one of B be the same place? Kinds as :data:`KIND_COMPATIBLE`, except
    that any two places with a clearance (class ≥ 1: made by ``topo.extract_topomap``) may
    match whatever their number of paths, which depends on how many exits each robot saw; and
    clearances within :data:`CLEARANCE_TOLERANCE` classes. Maps without clearances (all
    class 0) match by kind alone."""
    n = _N_KINDS * CLEARANCE_CLASSES
    code = np.arange(n)
    kind, cls = code % _N_KINDS, code // _N_KINDS
    place = np.isin(kind, [int(k) for k in _PLACE_KINDS]) & (cls > 0)
    kinds_ok = KIND_COMPATIBLE[kind[:, None], kind[None, :]] | (place[:, None] & place[None, :])
    table = kinds_ok & (np.abs(cls[:, None] - cls[None, :]) <= CLEARANCE_TOLERANCE)
    table.setflags(write=False)
    return table


MATCH_COMPATIBLE = _match_table()
"""The node compatibility the merge uses, over descriptor codes (:func:`_match_table`)."""


def descriptor_codes(m: TopoMap) -> np.ndarray:
    """``(N,)`` int64 descriptor code of each node: ``kind + len(NodeKind) · class`` with
    ``class = min(clearance // CLEARANCE_STEP, CLEARANCE_CLASSES − 1)``."""
    cls = np.minimum((m.clearance / CLEARANCE_STEP).astype(np.int64), CLEARANCE_CLASSES - 1)
    return m.kinds.astype(np.int64) + _N_KINDS * cls


def matchable(m: TopoMap) -> tuple[TopoMap, np.ndarray]:
    """The part of ``m`` a merge matches, and the index in ``m`` of each of its nodes: the
    nodes not flagged :attr:`topo.TopoMap.frontier` and the paths between them (a node on the
    frontier moves as its robot explores on)."""
    keep = ~m.frontier
    if keep.all():
        return m, np.arange(m.n_nodes)
    index = np.flatnonzero(keep)
    renumber = np.full(m.n_nodes, -1, dtype=np.int64)
    renumber[index] = np.arange(len(index))
    kept = keep[m.edges].all(axis=1) if m.n_edges else np.zeros(0, dtype=bool)
    paths = None if m.paths is None else [q for q, k in zip(m.paths, kept, strict=True) if k]
    view = TopoMap.from_arrays(m.xy[index], renumber[m.edges[kept]], m.kinds[index],
                               m.lengths[kept], paths, m.clearance[index], m.frontier[index])
    return view, index


_KIND_PRIORITY = {NodeKind.JUNCTION: 0, NodeKind.CORNER: 1, NodeKind.DEAD_END: 2,
                  NodeKind.GATEWAY: 3}
_RANK_OF_KIND = np.array([_KIND_PRIORITY[NodeKind(k)] for k in range(len(NodeKind))])
_KIND_OF_RANK = np.array(sorted(_KIND_PRIORITY, key=_KIND_PRIORITY.get), dtype=np.int64)


@dataclass(frozen=True, slots=True)
class MergeConfig:
    """Parameters of :func:`merge_maps` (lengths in metres, angles in degrees).

    Attributes:
        eps: match tolerance: nodes of A and moved B within ``eps`` may be the same place (the
            paper's ω tolerance); also the gate of the ICP refinement and the conflict distance.
        fit_eps: the final least-squares fit pairs mutually nearest nodes of any kinds within
            this (a node at the edge of explored space may have another kind in each map).
        near_miss: see :attr:`MergeEvidence.near_misses`.
        pair_tolerance: most difference between an A pair's and a B pair's length for a 2-point
            hypothesis (about 2σ of the difference for node noise σ = 0.15 and more).
        min_pair_distance: node pairs closer than this fix the angle too poorly to be used.
        knn: each node is also paired with its ``knn`` nearest nodes.
        coarse_tolerance: hit radius of the coarse hypothesis score.
        max_hypotheses: most hypotheses scored (the longest pairs are kept; 1500 rather than
            1000 finds the right one of a few more low-overlap pairs, 2000 one more in 450).
        path_pool: distinct hypotheses (the best by coarse score) re-ranked by adding their
            path evidence (:attr:`MergeEvidence.path_agree`, ``path_off``) in the coarse score's
            units (a matched node ≈ the ``closeness`` + ``inliers`` weights) before the
            ``candidates`` best are refined (96 rather than 24: at σ = 0.15 m the right
            alignment was found for 62.5% instead of 59.2% of 20–40% overlap pairs, seed 100;
            64 does as well as 96, 48 lost a pair).
        sparse_pool: the best distinct hypotheses landing ``min_inliers`` but fewer than 4 B
            nodes on A nodes (the coarse score refits and ranks those with 4 or more), joined to
            the ``path_pool`` for the re-ranking: pairs sharing exactly 3 nodes (their right
            hypothesis, scored ~2.9, would rank among the chance 3-node landings of corridor
            lattices, and those crowd the right ones of other pairs out of a shared pool: 3
            in the pool was +1.3 points at σ = 0.05 m, 20–40%, −1.4 at σ = 0.15 m, 40–60%).
            16 (with the ties of ``scored`` below): search misses of seed 100 (best wrong,
            refined truth scoring higher) 25 → 8, ceiling at 20–40% 84.2 → 90.1 (σ = 0.05 m)
            and 66.4 → 69.7 (σ = 0.15 m), success at the default rule +1.3 points (σ = 0.05 m,
            20–40%), false accepts unchanged; 8 found fewer, 32 no more successes (a higher
            ceiling, more to score). 0 switches it off.
        candidates: distinct hypotheses refined (24: the refitted coarse score ranks the right
            one high enough that 48 found no more), best re-ranked gain first.
        scored: of those, how many (the most matched after refinement; ties to the better
            re-ranked gain: the right hypothesis of a small overlap often ties at 3–4 matched
            nodes with chance ones) are fully scored.
        distinct_angle_deg, distinct_distance: two alignments are distinct when their angles
            differ by at least ``distinct_angle_deg`` or they put B's centroid at least
            ``distinct_distance`` apart.
        icp_max_iter: iteration cap of the ICP-SVD refinement.
        min_inliers: accept only with at least this many matched nodes, not collinear (hard
            gates: fewer do not fix a rotation) ...
        min_margin: ... the best *distinct* alternative scoring at least this much less
            (log-odds; a hard gate: else the merge is ambiguous — a symmetric map, repeated
            corridors — however strong the evidence for both) ...
        accept_threshold: ... and a calibrated :attr:`MergeEvidence.confidence` (probability
            of being right) at least this: :data:`DEFAULT_ACCEPT_THRESHOLD`, the smallest with
            at most 1 % false and 1 % wrong accepts on the tuning pairs (symmetric maps, whose
            distinct alternatives score as well, get a low confidence).
        multistart_starts: starting rotations of ``"multistart_icp"``.
        exhaustive_step_deg: rotation step of ``"exhaustive"`` (the paper's 2°).
    """

    eps: float = 0.5
    fit_eps: float = 0.9
    near_miss: float = 2.0
    pair_tolerance: float = 0.7
    min_pair_distance: float = 1.0
    knn: int = 4
    coarse_tolerance: float = 0.7
    max_hypotheses: int = 1500
    path_pool: int = 64
    sparse_pool: int = 16
    candidates: int = 24
    scored: int = 20
    distinct_angle_deg: float = 10.0
    distinct_distance: float = 1.5
    icp_max_iter: int = 30
    min_inliers: int = 3
    min_margin: float = 1.0
    accept_threshold: float = DEFAULT_ACCEPT_THRESHOLD
    multistart_starts: int = 12
    exhaustive_step_deg: float = 2.0

    def __post_init__(self) -> None:
        for name in ("eps", "fit_eps", "near_miss", "pair_tolerance", "coarse_tolerance",
                     "distinct_angle_deg", "distinct_distance"):
            check_real(getattr(self, name), name, low=0.0)
        check_real(self.min_pair_distance, "min_pair_distance", low=0.0, low_inclusive=True)
        check_real(self.exhaustive_step_deg, "exhaustive_step_deg", low=0.0, high=360.0)
        check_real(self.accept_threshold, "accept_threshold", low=0.0, low_inclusive=True,
                   high=1.0)
        check_real(self.min_margin, "min_margin", low=0.0, low_inclusive=True)
        for name, low in (("knn", 0), ("max_hypotheses", 1), ("path_pool", 1), ("sparse_pool", 0),
                          ("candidates", 1), ("icp_max_iter", 1), ("scored", 1),
                          ("min_inliers", 3), ("multistart_starts", 1)):
            check_int(getattr(self, name), name, low=low)

    @classmethod
    def from_dict(cls, data: dict) -> MergeConfig:
        """From a dict of field values; unknown keys are a ``ValueError`` listing the allowed."""
        return config_from(cls, data, "MergeConfig")

    @classmethod
    def for_noise(cls, sigma: float, **overrides) -> MergeConfig:
        """Tolerances for maps whose nodes are off by ``sigma`` metres (per axis, each map):
        the defaults (tuned for σ ≤ 0.15 m) or, for noisier maps, ``eps = 3σ``,
        ``fit_eps = pair_tolerance = 4σ``, ``coarse_tolerance = 3.3σ`` and ``min_score = 2.5``
        (wider tolerances let more chance alignments score: at σ = 0.3 m the best of 900
        no-overlap pairs, seed 9100, scored 2.31). At σ = 0.3 m ``auto``'s success on ≥ 40%
        overlap is then 61.1% on 450 pairs of seed 100 (oracle 81.4%; the defaults: 18%).
        ``overrides`` replace any field.

        Only ``0 <= sigma <= 0.3`` was calibrated; larger values are refused (at σ = 0.5 m the
        scaled tolerances accepted a wrong merge of two sonar maps from the environment)."""
        sigma = check_real(sigma, "sigma", low=0.0, low_inclusive=True, high=0.3)
        base = cls()
        scaled = {}
        if 3.0 * sigma > base.eps:
            scaled = {"eps": 3.0 * sigma, "fit_eps": max(base.fit_eps, 4.0 * sigma),
                      "pair_tolerance": max(base.pair_tolerance, 4.0 * sigma),
                      "coarse_tolerance": max(base.coarse_tolerance, 10.0 * sigma / 3.0)}
        return config_from(cls, {**scaled, **overrides}, "MergeConfig")


_DEFAULT_CONFIG = MergeConfig()
"""``MergeConfig()``, built once: validating a config costs ~17 µs, 1% of a small merge."""

CONFIDENCE_WEIGHTS: dict[str, float] = {
    "bias": -9.382,
    "closeness": 0.8123,
    "inliers": 0.717,
    "matched_edges": -0.3446,
    "conflicts": -0.9122,
    "crossings": -0.6341,
    "branches_agree": 0.1891,
    "branches_disagree": -0.3845,
    "near_misses": -0.2835,
    "log_pairs": -0.0014,
    "likelihood": 0.2887,
    "path_agree": 0.0799,
    "path_off": -0.0509,
}
"""Weights of :attr:`MergeEvidence.score`, which ranks the search's candidates: a logistic
regression (L2 on standardised features) of right (< 2°, < 0.3 m) against wrong candidates
of the search on synthetic pairs (seed 100 overlap, 9100 no-overlap; near misses within 5° and
1 m left out). Most candidates are wrong, so the score is low. The accept rule reads the
calibrated :attr:`MergeEvidence.confidence`, not the score. ``benchmarks/calibrate_merge.py
--model ranking`` refits the weights on env and synthetic pairs and compares them (a refit on
2026-12-02 was not kept: ``benchmarks/fusion.md``)."""

_SCORE_WEIGHTS = tuple(CONFIDENCE_WEIGHTS.values())

MARGIN_CAP = 10.0
"""The margin over the best distinct alternative counts up to this (log-odds)."""

CALIBRATION_FEATURES = ("score", "margin", "inliers", "rmse", "path_agree", "described",
                        "score_pos", "described_score", "described_margin",
                        "described_inliers")
"""What the structural merge's calibrated :attr:`MergeEvidence.confidence` weighs: the search's
score, its margin over a distinct alternative, the matches, their rmse (capped at 1 m), the
agreeing paths, and — for maps from ``topo.extract_topomap`` (``described``) — the score,
margin and matches again: their evidence weighs differently from hand-made maps' (in
cross-validation the products brought the largest calibration gap from 0.20 to 0.09)."""
"""The weights of :data:`CONFIDENCE_WEIGHTS` in order (:attr:`MergeEvidence.score`)."""


@dataclass(frozen=True, slots=True)
class MergeEvidence:
    """What an alignment is worth (:func:`decide` turns it into accept/reject).

    Attributes:
        inliers: one-to-one matched nodes (mutually nearest, compatible kinds, within ``eps``).
        closeness: ``Σ (1 − d²/eps²)`` over the matches (a match at distance ``d``): the
            paper's ω with a soft tolerance.
        matched_edges: paths of B whose two ends match A nodes joined by a path (or by two).
        conflicts: junctions/corners of either map with no node of the other within ``eps``
            but lying on one of its paths (the other robot passed there and saw no place).
        crossings: paths of A and B crossing away from their ends (corridors cross at a
            junction, so a crossing without one is a contradiction).
        branches_agree, branches_disagree: over matched nodes, paths leaving both nodes in the
            same direction (within 25°), and paths of either without a counterpart.
        near_misses: junctions/corners of either map farther than ``eps`` but nearer than
            ``near_miss`` to a path of the other, with no node there (corridors that close
            would be the same corridor).
        rmse: root-mean-square distance of the matched nodes (``inf`` without matches).
        collinear: fewer than 3 matches, or the matched nodes lie on a line (rotation not
            determined).
        n_a, n_b: node counts of the two maps (chance matches grow with them).
        runner_up: score of the best alignment distinct from this one (``nan`` if the method
            does not look for one).
        hypotheses: how many rigid hypotheses the method scored.
        likelihood: how much likelier the match distances are for copies of the same nodes
            than for chance matches: the best over the node noise levels of
            :data:`fusion._merge_kernels.LIKELIHOOD_SIGMAS` of the summed log-ratios (a
            generalised likelihood ratio; it adapts to the maps' noise, so tightly matched nodes
            of low-noise maps count for more than ``closeness`` alone gives them).
        path_agree: metres of path (polylines, or node-to-node segments for maps without them)
            of either map lying on a path of the other, soft within :data:`PATH_TOL`
            (``Σ (1 − d²/tol²)`` per metre): far denser evidence than the few nodes a small
            overlap shares, and hard for unrelated maps to fake.
        path_off: metres of path of either map between :data:`PATH_OFF` and
            :data:`PATH_REACH` from the other's paths (running beside a corridor of the other
            map: the same corridor, misplaced).
        described: share of the two maps' matched-from nodes that carry a clearance
            (``topo.extract_topomap`` maps: 1; hand-made or synthetic ones: 0): the kind of map
            the evidence comes from.
    """

    inliers: int
    closeness: float
    matched_edges: int
    conflicts: int
    crossings: int
    branches_agree: int
    branches_disagree: int
    near_misses: int
    rmse: float
    collinear: bool
    n_a: int
    n_b: int
    runner_up: float = math.nan
    hypotheses: int = 0
    likelihood: float = 0.0
    path_agree: float = 0.0
    path_off: float = 0.0
    described: float = 0.0

    def _feature_values(self) -> tuple[float, ...]:
        """The inputs of :attr:`score`, in the order of :data:`CONFIDENCE_WEIGHTS`."""
        return (1.0, self.closeness, float(self.inliers), float(self.matched_edges),
                float(self.conflicts), float(self.crossings), float(self.branches_agree),
                float(self.branches_disagree), float(self.near_misses),
                math.log(max(1, self.n_a * self.n_b)), self.likelihood, self.path_agree,
                self.path_off)

    def features(self) -> dict[str, float]:
        """The inputs of :attr:`score`, by the names of :data:`CONFIDENCE_WEIGHTS`."""
        return dict(zip(CONFIDENCE_WEIGHTS, self._feature_values(), strict=True))

    @property
    def score(self) -> float:
        """Log-odds that the alignment is right: ``Σ CONFIDENCE_WEIGHTS[f] × features()[f]``,
        summed in that order (a plain loop: a dict and a generator cost ~6 µs a score, and
        scores are read ~7 times a merge)."""
        total = 0.0
        for w, v in zip(_SCORE_WEIGHTS, self._feature_values(), strict=True):
            total += w * v
        return float(total)

    @property
    def margin(self) -> float:
        """How much the best distinct alternative scores less (:data:`MARGIN_CAP` when there is
        none, and at most that)."""
        if not math.isfinite(self.runner_up):
            return MARGIN_CAP
        return min(self.score - self.runner_up, MARGIN_CAP)

    def calibration_features(self) -> dict[str, float]:
        """The inputs of :attr:`confidence`, by the names of :data:`CALIBRATION_FEATURES`."""
        score, margin, inliers, described = self.score, self.margin, float(self.inliers), \
            self.described
        return {"score": score, "margin": margin, "inliers": inliers,
                "rmse": min(self.rmse, 1.0), "path_agree": self.path_agree,
                "described": described, "score_pos": max(score, 0.0),
                "described_score": described * score, "described_margin": described * margin,
                "described_inliers": described * inliers}

    @property
    def confidence(self) -> float:
        """The calibrated probability that the alignment is right (< 2°, < 0.3 m at B's
        centroid): the stored ``"structural"`` model of :mod:`fusion.calibration` of
        :meth:`calibration_features` (``benchmarks/calibrate_merge.py --model structural``).
        Fitted on maps that are rarely symmetric: an alignment with a distinct alternative
        nearly as good may read confident; :func:`decide` rejects it as ambiguous."""
        from fusion.calibration import load_model

        return load_model("structural")(self.calibration_features())


@dataclass(frozen=True, slots=True, eq=False)
class MergeResult:
    """What :func:`merge_maps` found.

    Attributes:
        transform: B → A motion (``p_A = R p_B + T``); the best estimate even when rejected.
        accepted: whether the merge passed :func:`decide` (``confidence >= accept_threshold``
            and the hard gates).
        score: :attr:`MergeEvidence.score` of ``transform``.
        matches: ``(K, 2)`` int node index pairs ``(a, b)`` matched at ``transform``.
        merged: if accepted, A with B moved onto it (matched nodes fused at their mean, other
            B nodes within ``eps`` of a node fused into it, paths united, polylines dropped);
            if rejected, ``map_a`` unchanged.
        method: the method used.
        time_s: wall time of the call in seconds.
        reason: why the merge was rejected (``None`` when accepted).
        evidence: the numbers behind the decision (``None`` for maps too small to try).
        confidence: calibrated probability that ``transform`` is right (< 2°, < 0.3 m at B's
            centroid; :attr:`MergeEvidence.confidence`); 0 when nothing was tried.
    """

    transform: Rigid2D
    accepted: bool
    score: float
    matches: np.ndarray
    merged: TopoMap
    method: str
    time_s: float
    reason: str | None = None
    evidence: MergeEvidence | None = None
    confidence: float = 0.0


# --------------------------------------------------------------------------- preparation
PATH_STEP = 1.2
"""Spacing (m) of the points along each map's paths that the path evidence moves."""
PATH_CELL = 0.4
"""Cell (m) of the distance-to-path raster of each map."""
PATH_REACH = 2.0
"""The raster's cap (m): a path point farther than this from every path of the other map
tells nothing (outside what the other robot explored)."""
PATH_TOL = 0.5
"""A path point within this of the other map's paths lies on one (soft: ``1 − d²/tol²``)."""
PATH_OFF = 0.9
"""A path point between this and :data:`PATH_REACH` from the other map's paths runs beside
one: two corridors that close would be the same corridor."""
PATH_CHORD = 0.4
"""Polylines (pixel-fine paths of extracted maps) are read as chords about this long (m): a
sample per :data:`PATH_STEP` at most, as for straight paths, and a fifth of the raster's work;
a chord strays from its pixels by a few centimetres, well inside :data:`PATH_TOL`."""
PATH_FIT_WEIGHT = 10.0
"""Weight of a metre of B's paths lying on A's against a matched node in the final fit."""


@dataclass(frozen=True, slots=True, eq=False)
class _Prepared:
    xy: np.ndarray
    kinds: np.ndarray
    edges: np.ndarray
    near: np.ndarray  # (n, n) bool: joined by a path or by two
    pair_i: np.ndarray
    pair_j: np.ndarray
    pair_len: np.ndarray
    both_i: np.ndarray  # the pairs in both orientations, by length (stable): B's hypotheses
    both_j: np.ndarray
    both_len: np.ndarray
    margin: np.ndarray  # (E,) fraction of each path within eps of its ends
    branches: np.ndarray  # (n, max degree) direction of each path leaving a node, nan padded
    segments: np.ndarray  # (S, 4) straight pieces of the paths (_segments)
    path_pts: np.ndarray  # (S, 2) points along the paths, every ~PATH_STEP
    path_w: np.ndarray  # (S,) metres of path each stands for
    field: np.ndarray  # squared distance to the nearest path (K.path_field), PATH_CELL cells
    field_origin: tuple[float, float]
    compat: np.ndarray  # [code, code] of the pair's codes (MATCH_COMPATIBLE, renumbered)
    loose: int  # the code of an undescribed dead end (makes no conflicts), -1 if unused


def _prepare_pair(map_a: TopoMap, map_b: TopoMap, cfg: MergeConfig
                  ) -> tuple[_Prepared, _Prepared]:
    """What the search and the evidence read of two maps. Their ``kinds`` are their
    :func:`descriptor_codes` renumbered over the codes the two maps use, ``compat`` the rows
    and columns of :data:`MATCH_COMPATIBLE` for those codes (a small table: the search's
    raster holds one entry per code)."""
    code_a, code_b = descriptor_codes(map_a), descriptor_codes(map_b)
    used = np.unique(np.concatenate([code_a, code_b]))
    compat = np.ascontiguousarray(MATCH_COMPATIBLE[np.ix_(used, used)])
    loose = np.flatnonzero(used == _LOOSE_KIND)
    loose = int(loose[0]) if len(loose) else -1
    return (_prepare(map_a, cfg, np.searchsorted(used, code_a), compat, loose),
            _prepare(map_b, cfg, np.searchsorted(used, code_b), compat, loose))


def _prepare(m: TopoMap, cfg: MergeConfig, codes: np.ndarray, compat: np.ndarray,
             loose: int) -> _Prepared:
    xy = np.ascontiguousarray(m.xy, dtype=np.float64)
    edges = np.ascontiguousarray(m.edges, dtype=np.int64)
    pieces = _segments(m)
    near, i, j, length, both_i, both_j, both_len, pts, w, margin, x0, y0, field, *slots = (
        K.map_fields(xy, edges, pieces, cfg.knn, max(cfg.min_pair_distance, 1e-9), PATH_STEP,
                     cfg.eps, PATH_REACH, PATH_CELL))
    return _Prepared(xy, codes.astype(np.int64), edges, near, i, j, length, both_i, both_j,
                     both_len, margin, _branches(len(xy), *slots), pieces, pts, w, field,
                     (x0, y0), compat, loose)


def _segments(m: TopoMap) -> np.ndarray:
    """``(S, 4)`` straight pieces ``(x1, y1, x2, y2)`` of the map's paths: chords of its
    polylines about :data:`PATH_CHORD` long, or the straight node-to-node segments of a map
    without polylines."""
    if m.paths is None or not len(m.paths):
        return np.hstack([m.xy[m.edges[:, 0]], m.xy[m.edges[:, 1]]]).reshape(-1, 4).astype(
            np.float64)
    pts = np.ascontiguousarray(np.concatenate(m.paths), dtype=np.float64)
    sizes = np.fromiter((len(q) for q in m.paths), dtype=np.int64, count=len(m.paths))
    return K.polyline_chords(pts, sizes, PATH_CHORD)


def _branches(n: int, node: np.ndarray, slot: np.ndarray, d: np.ndarray,
              degree: int) -> np.ndarray:
    """``(n, max degree)`` angle of each path leaving each node (toward its other end), from
    :func:`fusion._merge_kernels.branch_slots`."""
    out = np.full((n, max(1, degree)), np.nan)
    if len(node):  # numpy's arctan2 (numba's differs in the last bit), on the same layout
        out[node, slot] = np.arctan2(d[:, 1], d[:, 0])
    return out


@dataclass(frozen=True, slots=True, eq=False)
class _Eval:
    theta: float
    t: np.ndarray
    matches: np.ndarray
    evidence: MergeEvidence

    @property
    def transform(self) -> Rigid2D:
        return Rigid2D(self.theta, self.t)

    def key(self) -> tuple[float, float]:
        return (self.evidence.score, -self.evidence.rmse)


_BRANCH_TOL = math.radians(25.0)
_LOOSE_KIND = int(NodeKind.DEAD_END)  # the kind that makes no conflicts (frontier artefacts)
_MIN_CROSSING_SIN = 0.5  # paths within 30° of parallel are one corridor seen twice
_FEATURE_COLUMNS = {"closeness": 0, "inliers": 1, "matched_edges": 2, "conflicts": 3,
                   "crossings": 4, "branches_agree": 5, "branches_disagree": 6,
                   "near_misses": 8}
"""Where each :attr:`MergeEvidence.features` entry is in the compiled evidence vector
(``likelihood``: the best of the columns :data:`_LIKELIHOOD`)."""
_LIKELIHOOD = slice(9, K.N_FEATURES)


def _evidence_args(pa: _Prepared, pb: _Prepared) -> tuple:
    return (pa.xy, pa.kinds, pa.edges, pa.margin, pa.near, pa.branches, pb.xy, pb.kinds,
            pb.edges, pb.margin, pb.branches)


def _path_args(pa: _Prepared, pb: _Prepared) -> tuple:
    """What :func:`fusion._merge_kernels.path_agreement` reads of the two maps, and its
    constants."""
    return (pa.path_pts, pa.path_w, pa.field, *pa.field_origin, pb.path_pts, pb.path_w, pb.field,
            *pb.field_origin, 1.0 / PATH_CELL, PATH_TOL, PATH_OFF, PATH_REACH)


def _path_evidence(pa: _Prepared, pb: _Prepared, theta: np.ndarray, tx: np.ndarray,
                   ty: np.ndarray, both: bool = True) -> np.ndarray:
    """``(H, 2)`` :attr:`MergeEvidence.path_agree` and ``path_off`` of each hypothesis (without
    ``both``, twice what B's paths alone give: the quick estimate the re-ranking uses)."""
    return K.path_agreement(theta, tx, ty, *_path_args(pa, pb), both)


_FEATURE_COLS = list(_FEATURE_COLUMNS.values())
_FEATURE_WEIGHTS = np.array([CONFIDENCE_WEIGHTS[k] for k in _FEATURE_COLUMNS])
"""The columns of :data:`_FEATURE_COLUMNS` and their score weights (:func:`_scores`)."""
_PATH_WEIGHTS = np.array([CONFIDENCE_WEIGHTS["path_agree"], CONFIDENCE_WEIGHTS["path_off"]])
"""Score weights of the columns of :func:`_path_evidence` (``path_agree``, ``path_off``)."""


def _scores(features: np.ndarray, paths: np.ndarray, n_a: int, n_b: int) -> np.ndarray:
    """:attr:`MergeEvidence.score` of rows of :func:`fusion._merge_kernels.evidence` features
    and of :func:`_path_evidence`."""
    const = CONFIDENCE_WEIGHTS["bias"] + CONFIDENCE_WEIGHTS["log_pairs"] * math.log(n_a * n_b)
    return (features[:, _FEATURE_COLS] @ _FEATURE_WEIGHTS + const
            + CONFIDENCE_WEIGHTS["likelihood"] * features[:, _LIKELIHOOD].max(axis=1)
            + paths @ _PATH_WEIGHTS)


def _evaluate(pa: _Prepared, pb: _Prepared, theta: float, t: np.ndarray,
              cfg: MergeConfig) -> _Eval:
    """The full evidence (:class:`MergeEvidence`) and matches of B moved by ``(theta, t)``."""
    f, matches, (agree, off), moments = K.evaluation(
        *_evidence_args(pa, pb), float(theta), float(t[0]), float(t[1]), cfg.eps,
        pa.compat, pa.loose, _BRANCH_TOL, _MIN_CROSSING_SIN, cfg.near_miss,
        *_path_args(pa, pb))
    f = f.tolist()  # Python floats: cheaper to read one by one
    n = len(matches)
    collinear = n < 3 or moments_degeneracy(moments, "matches", 1e-3) is not None
    ev = MergeEvidence(n, f[0], int(f[2]), int(f[3]), int(f[4]), int(f[5]), int(f[6]),
                       int(f[8]), math.sqrt(f[7] / n) if n else math.inf, collinear, len(pa.xy),
                       len(pb.xy), likelihood=max(f[_LIKELIHOOD]), path_agree=agree,
                       path_off=off)
    return _Eval(float(wrap_angle(theta)), np.asarray(t, dtype=np.float64), matches, ev)


def _least_squares(pa: _Prepared, pb: _Prepared, matches: np.ndarray, theta: float,
                   t: np.ndarray) -> tuple[float, np.ndarray]:
    """The SVD fit of B's matched nodes onto A's (what the oracle does with true matches), with
    B's path points that lie within :data:`PATH_TOL` of A's paths (moved by ``(theta, t)``)
    paired with their nearest A path point, :data:`PATH_FIT_WEIGHT` per metre of path."""
    P, Q, w = K.fit_points(pa.xy, pb.xy, matches, pa.segments, pb.path_pts, pb.path_w,
                           PATH_FIT_WEIGHT, theta, t[0], t[1], PATH_TOL, pa.field,
                           *pa.field_origin, PATH_CELL)
    return rigid_fit(P, Q, w)


def _polish(pa: _Prepared, pb: _Prepared, start: _Eval, cfg: MergeConfig) -> _Eval:
    """Trimmed, gated ICP-SVD from ``start`` (kept if it scores better), then least-squares
    fits on mutually nearest nodes of any kinds within ``fit_eps`` (what the oracle does with
    the true matches; a node at the edge of explored space may have another kind in each
    map) and on B's path points lying on A's paths (:func:`_least_squares`: long corridors fix
    the rotation far better than the 3–6 nodes a small overlap shares)."""
    best = start
    if start.evidence.inliers >= 2:
        trim = min(1.0, max(start.evidence.inliers / len(pb.xy), 2.0 / len(pb.xy)))
        icp = icp_checked(pa.xy, pb.xy, None, cfg.icp_max_iter, start.transform, 1e-9,
                          cfg.eps, trim)  # the maps' nodes were checked by merge_maps
        ev = _evaluate(pa, pb, icp.transform.theta, icp.transform.T, cfg)
        best = max((best, ev), key=_Eval.key)
    theta, t, moved = best.theta, best.t, False
    for _ in range(3):
        pairs = K.mutual_pairs(pa.xy, pb.xy, theta, t[0], t[1], cfg.fit_eps)
        if len(pairs) < 3:
            break
        theta, t, moved = *_least_squares(pa, pb, pairs, theta, t), True
    return _evaluate(pa, pb, theta, t, cfg) if moved else best


def _centroid_image(theta: np.ndarray, tx: np.ndarray, ty: np.ndarray,
                    centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where each motion ``(theta, tx, ty)`` puts the point ``centre``: ``(cx, cy)``."""
    return K.centroid_image(np.cos(theta), np.sin(theta), tx, ty, centre[0], centre[1])


def _runner_up(best: _Eval, theta: np.ndarray, tx: np.ndarray, ty: np.ndarray,
               scores: np.ndarray, b_xy: np.ndarray, cfg: MergeConfig) -> float:
    """Best of ``scores`` among the alignments ``(theta, tx, ty)`` distinct from ``best``
    (``-inf`` if none).

    Distinct: rotated ``distinct_angle_deg`` or more apart, or moving the centre of B's matched
    nodes ``distinct_distance`` or more apart — where the evidence is, not at B's centroid,
    which may lie far outside the overlap (B's centroid when nothing matched).
    """
    centre = b_xy[best.matches[:, 1]].mean(axis=0) if len(best.matches) else b_xy.mean(axis=0)
    p = best.transform.apply(centre)
    cx, cy = _centroid_image(theta, tx, ty, centre)
    gap = np.abs(np.angle(np.exp(1j * (theta - best.theta))))
    return K.best_distinct_score(scores, gap, cx, cy, p[0], p[1],
                                 math.radians(cfg.distinct_angle_deg), cfg.distinct_distance)


def _runner_up_of(best: _Eval, others: list[_Eval], b_xy: np.ndarray, cfg: MergeConfig) -> float:
    """:func:`_runner_up` over evaluated alignments."""
    if not others:
        return -math.inf
    return _runner_up(best, np.array([o.theta for o in others]),
                      np.array([o.t[0] for o in others]), np.array([o.t[1] for o in others]),
                      np.array([o.evidence.score for o in others]), b_xy, cfg)


# ------------------------------------------------------------------------------- methods
def _hit_grid(pa: _Prepared, tol: float, path_tol: float
              ) -> tuple[np.ndarray, float, float, float]:
    """The raster of A that :func:`fusion._merge_kernels.refined_scores` reads, cells ``tol / 2``
    wide: ``table[iy, ix, k]`` (``k`` < 3) the A node of a kind compatible with B kind ``k``
    nearest to the cell within ~``tol`` (``-1`` if none); ``table[iy, ix, 3]`` the bits
    :data:`~fusion._merge_kernels.NEAR_ANY_NODE` (within ~``tol`` of an A node) and
    :data:`~fusion._merge_kernels.ON_PATH` (within ~``path_tol`` of an A path).
    Returns ``(table, x0, y0, 1 / cell)``."""
    # a small dtype keeps the table in cache (int16: scoring twice faster at 60 nodes than
    # int32; int8 another ~10%)
    n = len(pa.xy)
    like = _INT8 if n < 127 else _INT16 if n < 32767 else _INT32  # iinfo costs 10 µs
    return K.hit_table(pa.xy, pa.kinds, pa.edges, tol, path_tol, pa.compat, like)


_INT8, _INT16, _INT32 = (np.empty(0, dtype=t) for t in (np.int8, np.int16, np.int32))
"""Empty arrays of the :func:`_hit_grid` table's dtypes (a compiled kernel takes an array's
dtype, not a dtype)."""


_COARSE_MIN_PAIRS = 4
"""The coarse ranking holds the hypotheses landing at least this many B nodes on A nodes (3 in
the one ranking, like ``min_inliers``, measured +1.3 points at σ = 0.05 m, 20–40% overlap, −1.4
at σ = 0.15 m, 40–60%, seed 100, and 7% more time: not kept); those landing ``min_inliers`` to
this − 1 are refitted and scored too, and pooled apart (``MergeConfig.sparse_pool``)."""


_SPARSE_MIN = 0.7
"""A hypothesis of the ``sparse_pool`` must land its few nodes tightly: a coarse score of at
least this per landed node (mean distance ≲ 0.27 m at ``eps`` 0.5; the right ones of seed 100
score 0.89–1.0 per node at σ ≤ 0.15 m). Without it a chance 3-node alignment (σ = 0.3 m,
15–60 nodes) was one more false accept of the 4500 of seed 9007; with it as many as before on
the tuning and held-out no-overlap seeds, at the same success."""


def _candidates(pa: _Prepared, pb: _Prepared, cfg: MergeConfig) -> tuple | str:
    """Steps 1–4 of the module docstring: the ``scored`` candidates' motions, evidence
    features and path evidence, and how many hypotheses there were (or why there are none)."""
    b_i, b_j = pb.both_i, pb.both_j
    hyp_p, hyp_q, weight = K.pair_candidates(pa.kinds, pa.pair_i, pa.pair_j, pa.pair_len,
                                             pb.kinds, b_i, b_j, pb.both_len,
                                             cfg.pair_tolerance, pa.compat)
    n_hyp = len(hyp_p)
    if n_hyp == 0:
        return "no pair of nodes of B matches a pair of A in length and kinds"
    if n_hyp > cfg.max_hypotheses:  # the motions of the kept ones only
        keep = np.sort(np.argpartition(-weight, cfg.max_hypotheses - 1)[:cfg.max_hypotheses])
        hyp_p, hyp_q = hyp_p[keep], hyp_q[keep]
    theta, tx, ty, cos_t, sin_t = K.pair_motions(pa.xy, pa.pair_i, pa.pair_j, pb.xy, b_i, b_j,
                                                 hyp_p, hyp_q)
    table, x0, y0, inv_cell = _hit_grid(pa, cfg.coarse_tolerance, cfg.eps)
    landed = np.zeros(len(theta), dtype=np.int64)
    min_pairs = max(cfg.min_inliers, _COARSE_MIN_PAIRS)
    reserve = cfg.sparse_pool if cfg.min_inliers < min_pairs else 0
    coarse = K.refined_scores(theta, tx, ty, cos_t, sin_t, pa.xy, pb.xy, pb.kinds, table, x0,
                              y0, inv_cell, cfg.eps, pa.loose,
                              cfg.min_inliers if reserve else min_pairs, landed)
    centre = pb.xy.mean(axis=0)
    cx, cy = _centroid_image(theta, tx, ty, centre)
    # those landing fewer than min_pairs are ranked with the unscored ones (0), and pooled apart
    ranked, small = K.coarse_ranking(coarse, landed, min_pairs, _SPARSE_MIN)
    chosen = K.select_distinct(ranked, theta, cx, cy, math.radians(cfg.distinct_angle_deg),
                               cfg.distinct_distance, max(cfg.path_pool, cfg.candidates))
    if reserve:  # the best distinct ones landing only min_inliers..3 nodes: sparse_pool
        chosen = K.select_distinct(np.concatenate([chosen, small]), theta, cx, cy,
                                   math.radians(cfg.distinct_angle_deg), cfg.distinct_distance,
                                   len(chosen) + reserve)
    if len(chosen) > cfg.candidates:  # re-ranked with the path evidence, in node units
        w = CONFIDENCE_WEIGHTS
        paths = _path_evidence(pa, pb, theta[chosen], tx[chosen], ty[chosen], both=False)
        chosen = K.best_by_gain(chosen, coarse, paths @ _PATH_WEIGHTS,
                                w["closeness"] + w["inliers"], cfg.candidates)  # best first
    th, txc, tyc = K.refine_most_matched(theta, tx, ty, chosen, pa.xy, pa.kinds, pb.xy, pb.kinds,
                                         pa.compat,
                                         np.array([cfg.coarse_tolerance, cfg.eps]), cfg.scored)
    features = K.evidence_batch(*_evidence_args(pa, pb), th, txc, tyc, cfg.eps, pa.compat,
                                pa.loose, _BRANCH_TOL, _MIN_CROSSING_SIN,
                                cfg.near_miss)
    return th, txc, tyc, features, _path_evidence(pa, pb, th, txc, tyc), n_hyp


def _auto(pa: _Prepared, pb: _Prepared, cfg: MergeConfig) -> _Eval | str:
    found = _candidates(pa, pb, cfg)
    if isinstance(found, str):
        return found
    th, txc, tyc, features, paths, n_hyp = found
    scores = _scores(features, paths, len(pa.xy), len(pb.xy))
    k = int(np.argmax(scores))
    best = _polish(pa, pb, _evaluate(pa, pb, th[k], np.array([txc[k], tyc[k]]), cfg), cfg)
    runner = _runner_up(best, th, txc, tyc, scores, pb.xy, cfg)
    return _with(best, runner_up=runner, hypotheses=n_hyp)


def _score_matrix(features: np.ndarray, paths: np.ndarray, n_a: int, n_b: int) -> np.ndarray:
    """``(H, len(CONFIDENCE_WEIGHTS))`` rows of :meth:`MergeEvidence.features` values of the
    candidates (the inputs of their :attr:`MergeEvidence.score`)."""
    out = np.empty((len(features), len(CONFIDENCE_WEIGHTS)))
    out[:, 0] = 1.0
    for j, name in enumerate(CONFIDENCE_WEIGHTS):
        if name in _FEATURE_COLUMNS:
            out[:, j] = features[:, _FEATURE_COLUMNS[name]]
    names = list(CONFIDENCE_WEIGHTS)
    out[:, names.index("log_pairs")] = math.log(max(1, n_a * n_b))
    out[:, names.index("likelihood")] = features[:, _LIKELIHOOD].max(axis=1)
    out[:, names.index("path_agree")] = paths[:, 0]
    out[:, names.index("path_off")] = paths[:, 1]
    return out


def candidate_features(map_a: TopoMap, map_b: TopoMap, config: MergeConfig | dict | None = None
                       ) -> tuple[list[Rigid2D], np.ndarray]:
    """The alignments ``"auto"`` scores last before refining the best (its search's candidates)
    and their :meth:`MergeEvidence.features` values, one row each (columns in the order of
    :data:`CONFIDENCE_WEIGHTS`): what ``benchmarks/calibrate_merge.py --model ranking`` fits
    those weights on. Empty when ``merge_maps`` would not search (too few nodes, degenerate
    maps, no hypothesis).

    Raises:
        TypeError, ValueError: as :func:`merge_maps` for bad maps or config.
    """
    map_a, map_b = _check_map(map_a, "map_a"), _check_map(map_b, "map_b")
    cfg = _DEFAULT_CONFIG if config is None else config_from(MergeConfig, config)
    (view_a, _), (view_b, _) = matchable(map_a), matchable(map_b)
    empty = ([], np.empty((0, len(CONFIDENCE_WEIGHTS))))
    if min(view_a.n_nodes, view_b.n_nodes) < 3 or degeneracy(view_a.xy, "map_a") or \
            degeneracy(view_b.xy, "map_b"):
        return empty
    pa, pb = _prepare_pair(view_a, view_b, cfg)
    found = _candidates(pa, pb, cfg)
    if isinstance(found, str):
        return empty
    th, txc, tyc, features, paths, _ = found
    transforms = [Rigid2D(float(a), (float(x), float(y))) for a, x, y in zip(th, txc, tyc,
                                                                             strict=True)]
    return transforms, _score_matrix(features, paths, len(pa.xy), len(pb.xy))


def _with(ev: _Eval, **changes) -> _Eval:
    e = ev.evidence
    fields = {f: getattr(e, f) for f in MergeEvidence.__dataclass_fields__}
    fields.update(changes)
    return _Eval(ev.theta, ev.t, ev.matches, MergeEvidence(**fields))


def _points(m: TopoMap) -> np.ndarray:
    """The paper's point set (path endpoints), or all nodes when fewer than 2 end paths."""
    pts = m.endpoints()
    return pts if len(pts) >= 2 else m.xy


def _paper_icp(map_a: TopoMap, map_b: TopoMap, pa: _Prepared, pb: _Prepared,
               cfg: MergeConfig) -> _Eval:
    res = icp_svd(_points(map_a), _points(map_b), tau=0.1, max_iter=100)
    return _with(_evaluate(pa, pb, res.transform.theta, res.transform.T, cfg), hypotheses=1)


def _best_polished(pa: _Prepared, pb: _Prepared, starts: list[_Eval], cfg: MergeConfig,
                   top: int = 4) -> _Eval:
    """Polish the ``top`` best-scoring ``starts`` (:func:`_polish`); the best of them, with the
    runner-up among the other polished ones and the remaining starts."""
    ranked = sorted(starts, key=_Eval.key, reverse=True)
    polished = [_polish(pa, pb, e, cfg) for e in ranked[:top]]
    order = sorted(range(len(polished)), key=lambda i: polished[i].key(), reverse=True)
    best = polished[order[0]]
    others = [polished[i] for i in order[1:]] + ranked[top:]
    return _with(best, runner_up=_runner_up_of(best, others, pb.xy, cfg))


def _exhaustive(map_a: TopoMap, map_b: TopoMap, pa: _Prepared, pb: _Prepared,
                cfg: MergeConfig) -> _Eval:
    found = exhaustive_search(map_a if len(map_a.endpoints()) else map_a.xy,
                              map_b if len(map_b.endpoints()) else map_b.xy,
                              step_deg=cfg.exhaustive_step_deg, eps=cfg.eps)
    ties = [_evaluate(pa, pb, p.transform.theta, p.transform.T, cfg) for p in found.ties]
    return _with(_best_polished(pa, pb, ties, cfg, top=8), hypotheses=found.evaluations)


def _multistart(map_a: TopoMap, map_b: TopoMap, pa: _Prepared, pb: _Prepared,
                cfg: MergeConfig) -> _Eval:
    M, D = _points(map_a), _points(map_b)
    evals = []
    for k in range(cfg.multistart_starts):
        theta = 2 * math.pi * k / cfg.multistart_starts
        c, s = math.cos(theta), math.sin(theta)
        start = Rigid2D(theta, M.mean(axis=0) - np.array([[c, -s], [s, c]]) @ D.mean(axis=0))
        res = icp_svd(M, D, tau=0.1, max_iter=100, init=start)
        evals.append(_evaluate(pa, pb, res.transform.theta, res.transform.T, cfg))
    return _with(_best_polished(pa, pb, evals, cfg), hypotheses=cfg.multistart_starts)


# ------------------------------------------------------------------------------ decision
def decide(evidence: MergeEvidence, config: MergeConfig | None = None) -> str | None:
    """The accept rule: ``None`` to accept, else the reasons to reject (``"; "``-joined).

    Rejects when: fewer than ``min_inliers`` matched nodes; the matched nodes are collinear
    (the rotation is not determined); a distinct alternative within ``min_margin`` of the
    score (ambiguous); or the calibrated :attr:`MergeEvidence.confidence` is below
    ``accept_threshold`` (weak evidence).
    """
    cfg = _DEFAULT_CONFIG if config is None else config_from(MergeConfig, config)
    e = evidence
    reasons = []
    if e.inliers < cfg.min_inliers:
        reasons.append(f"too few matched nodes: {e.inliers} < min_inliers={cfg.min_inliers}")
    if e.collinear:
        reasons.append("matched nodes are collinear: rotation not determined")
    if e.margin < cfg.min_margin:
        reasons.append(f"ambiguous: a distinct alignment scores {e.runner_up:.2f} against "
                       f"{e.score:.2f} (margin < min_margin={cfg.min_margin})")
    confidence = e.confidence
    if confidence < cfg.accept_threshold:
        reasons.append(f"weak evidence: confidence {confidence:.2f} < accept_threshold="
                       f"{cfg.accept_threshold} (score {e.score:.2f}, {e.inliers} matches, "
                       f"{e.matched_edges} matched paths, {e.conflicts} conflicts, "
                       f"{e.crossings} crossings, rmse {e.rmse:.2f} m)")
    return "; ".join(reasons) or None


# ---------------------------------------------------------------------------------- fusion
def fuse_maps(map_a: TopoMap, map_b: TopoMap, transform: Rigid2D, matches: np.ndarray,
              eps: float) -> TopoMap:
    """A in its frame with B moved by ``transform`` onto it.

    Matched pairs ``(a, b)`` are fused at their mean position; any other node (of B, or of A)
    within ``eps`` of a node is fused into it, so the result has no two nodes within ``eps``.
    A fused node keeps the most connected kind (junction > corner > dead end); paths are united
    (a path joining two fused nodes once), lengths kept (at least the new straight line).
    """
    n_a = map_a.n_nodes
    moved = transform.apply(map_b.xy)
    xy = np.vstack([map_a.xy, moved])
    matches = np.asarray(matches, dtype=np.int64).reshape(-1, 2)
    xy[matches[:, 0]] = 0.5 * (map_a.xy[matches[:, 0]] + moved[matches[:, 1]])
    n = len(xy)
    close = cKDTree(xy).query_pairs(eps, output_type="ndarray").reshape(-1, 2)
    rows = np.concatenate([matches[:, 0], close[:, 0]])
    cols = np.concatenate([matches[:, 1] + n_a, close[:, 1]])
    node, first = K.components_by_first(n, rows, cols)
    fields = K.fused_graph(node, first, xy, np.concatenate([map_a.kinds, map_b.kinds]),
                           np.concatenate([map_a.edges, map_b.edges + n_a]).astype(np.int64),
                           np.concatenate([map_a.lengths, map_b.lengths]).astype(np.float64),
                           _RANK_OF_KIND, _KIND_OF_RANK)
    # Built directly: every field is valid by construction (from_arrays re-parses each kind).
    for f in fields:
        f.setflags(write=False)
    return TopoMap(*fields)


# ---------------------------------------------------------------------------- public entry
def _check_map(value: object, name: str) -> TopoMap:
    if not isinstance(value, TopoMap):
        raise TypeError(f"{name} must be a topo.TopoMap, got {type(value).__name__}")
    if not np.all(np.isfinite(value.xy)):
        row = int(np.argwhere(~np.isfinite(value.xy))[0, 0])
        raise ValueError(f"{name}.xy must be finite, got {value.xy[row].tolist()} at node {row}")
    return value


def _not_tried(map_a: TopoMap, method: str, start: float, reason: str) -> MergeResult:
    """The result when no alignment could be tried (too small, degenerate, no hypothesis)."""
    return MergeResult(Rigid2D.identity(), False, 0.0, np.empty((0, 2), dtype=np.int64), map_a,
                       method, time.perf_counter() - start, reason)


def merge_maps(map_a: TopoMap, map_b: TopoMap, method: str = "auto",
               config: MergeConfig | dict | None = None) -> MergeResult:
    """Align ``map_b`` onto ``map_a`` and merge them, or say why not.

    Args:
        map_a: the fixed map (its frame is the result's frame).
        map_b: the map moved onto A.
        method: ``"auto"`` (the global structural merge of the module doc), ``"paper_icp"``,
            ``"exhaustive"`` or ``"multistart_icp"`` (:data:`METHODS`).
        config: :class:`MergeConfig`, a dict of its fields, or ``None`` for the defaults.

    Returns:
        :class:`MergeResult`. Maps with fewer than 3 nodes, degenerate geometry (coincident or
        collinear nodes) and maps that do not overlap give ``accepted=False`` with a ``reason``,
        never an exception.

    Raises:
        TypeError: a map that is not a :class:`topo.TopoMap`, a config of the wrong type.
        ValueError: NaN/inf node positions, an unknown ``method``, invalid config values or
            unknown config keys.

    Example:
        >>> from fusion.synthetic import make_pair
        >>> pair = make_pair(np.random.default_rng(3), overlap=0.8, nodes=(30, 30))
        >>> result = merge_maps(pair.map_a, pair.map_b)
        >>> result.accepted, result.transform.rotation_error(pair.transform) < 0.035
        (True, True)
    """
    start = time.perf_counter()
    map_a = _check_map(map_a, "map_a")
    map_b = _check_map(map_b, "map_b")
    if method not in METHODS:
        raise ValueError(f"method must be one of {list(METHODS)}, got {method!r}")
    cfg = _DEFAULT_CONFIG if config is None else config_from(MergeConfig, config)

    (view_a, index_a), (view_b, index_b) = matchable(map_a), matchable(map_b)
    small = [f"{name} has {v.n_nodes} node(s) off the frontier (of {m.n_nodes}); at least 3 "
             f"are needed" for name, m, v in (("map_a", map_a, view_a), ("map_b", map_b, view_b))
             if v.n_nodes < 3]
    if small:
        return _not_tried(map_a, method, start, "; ".join(small))
    flat = [d for name, v in (("map_a", view_a), ("map_b", view_b))
            if (d := degeneracy(v.xy, name)) is not None]
    if flat:
        return _not_tried(map_a, method, start, "; ".join(flat))
    pa, pb = _prepare_pair(view_a, view_b, cfg)
    if method == "auto":
        found = _auto(pa, pb, cfg)
    elif method == "paper_icp":
        found = _paper_icp(view_a, view_b, pa, pb, cfg)
    elif method == "exhaustive":
        found = _exhaustive(view_a, view_b, pa, pb, cfg)
    else:
        found = _multistart(view_a, view_b, pa, pb, cfg)
    if isinstance(found, str):
        return _not_tried(map_a, method, start, found)
    described = float(np.mean(np.concatenate([view_a.clearance, view_b.clearance]) > 0))
    found = _with(found, described=described)
    reason = decide(found.evidence, cfg)
    transform = found.transform
    matches = np.stack([index_a[found.matches[:, 0]], index_b[found.matches[:, 1]]], axis=1)
    merged = map_a if reason else fuse_maps(map_a, map_b, transform, matches, cfg.eps)
    return MergeResult(transform, reason is None, found.evidence.score, matches, merged,
                       method, time.perf_counter() - start, reason, found.evidence,
                       found.evidence.confidence)
