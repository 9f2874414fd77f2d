"""What an alignment is worth: :class:`MergeEvidence`, its score (:data:`CONFIDENCE_WEIGHTS`)
and calibrated confidence, and the accept rule (:func:`decide`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fusion.calibration import load_weights
from fusion.decision import MergeRule
from fusion.icp import degeneracy
from fusion.rigid import Rigid2D, wrap_angle
from fusion.structural import _kernels as K
from fusion.structural.config import MergeConfig, config_of
from fusion.structural.prepare import PATH_CELL, PATH_OFF, PATH_REACH, PATH_TOL, Prepared

CONFIDENCE_WEIGHTS: dict[str, float] = load_weights("ranking")
"""Weights of :attr:`MergeEvidence.score`, which ranks the search's candidates: a logistic
regression of right (< 2°, < 0.3 m) against wrong candidates of the search, so the score is the
log-odds of a candidate being right, and low (most candidates are wrong). The accept rule reads
the calibrated :attr:`MergeEvidence.confidence`, not the score. Fitted data, read once from
``fusion/calibration.json`` (weights ``"ranking"``, with where they were fitted);
``python -m fusion.calibration fit --model ranking --write`` refits them."""


_SCORE_WEIGHTS = tuple(CONFIDENCE_WEIGHTS.values())
"""The weights of :data:`CONFIDENCE_WEIGHTS` in order (:attr:`MergeEvidence.score`)."""


MARGIN_CAP = 10.0
"""The margin over the best distinct alternative counts up to this (log-odds)."""


CALIBRATION_FEATURES = ("score", "margin", "inliers", "rmse", "path_agree", "described",
                        "score_pos", "described_score", "described_margin",
                        "described_inliers")
"""What the structural merge's calibrated :attr:`MergeEvidence.confidence` weighs: the search's
score, its margin over a distinct alternative, the matches, their rmse (capped at 1 m), the
agreeing paths, and — for maps from ``topo.extract_topomap`` (``described``) — the score,
margin and matches again: their evidence weighs differently from hand-made maps'."""


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
            :data:`fusion.structural._kernels.LIKELIHOOD_SIGMAS` of the summed log-ratios
            (a
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
        summed in that order (a plain loop: scores are read several times a merge)."""
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
        :meth:`calibration_features` (``python -m fusion.calibration fit --model structural``).
        Fitted on maps that are rarely symmetric: an alignment with a distinct alternative
        nearly as good may read confident; :func:`decide` rejects it as ambiguous."""
        from fusion.calibration import load_model

        return load_model("structural")(self.calibration_features())


@dataclass(frozen=True, slots=True, eq=False)
class Evaluated:
    theta: float
    t: np.ndarray
    matches: np.ndarray
    evidence: MergeEvidence

    @property
    def transform(self) -> Rigid2D:
        return Rigid2D(self.theta, self.t)

    def key(self) -> tuple[float, float]:
        return (self.evidence.score, -self.evidence.rmse)


BRANCH_TOL = math.radians(25.0)


MIN_CROSSING_SIN = 0.5  # paths within 30° of parallel are one corridor seen twice


_FEATURE_COLUMNS = {"closeness": 0, "inliers": 1, "matched_edges": 2, "conflicts": 3,
                    "crossings": 4, "branches_agree": 5, "branches_disagree": 6,
                    "near_misses": 8}
"""Where each :attr:`MergeEvidence.features` entry is in the compiled evidence vector
(``likelihood``: the best of the columns :data:`_LIKELIHOOD`)."""


_LIKELIHOOD = slice(9, K.N_FEATURES)


def evidence_args(pa: Prepared, pb: Prepared) -> tuple:
    return (pa.xy, pa.kinds, pa.edges, pa.margin, pa.near, pa.branches, pb.xy, pb.kinds,
            pb.edges, pb.margin, pb.branches)


def _path_args(pa: Prepared, pb: Prepared) -> tuple:
    """What :func:`fusion.structural._kernels.path_agreement` reads of the two maps, and its
    constants."""
    return (pa.path_pts, pa.path_w, pa.field, *pa.field_origin, pb.path_pts, pb.path_w, pb.field,
            *pb.field_origin, 1.0 / PATH_CELL, PATH_TOL, PATH_OFF, PATH_REACH)


def path_evidence(pa: Prepared, pb: Prepared, theta: np.ndarray, tx: np.ndarray,
                  ty: np.ndarray, both: bool = True) -> np.ndarray:
    """``(H, 2)`` :attr:`MergeEvidence.path_agree` and ``path_off`` of each hypothesis (without
    ``both``, twice what B's paths alone give: the quick estimate the re-ranking uses)."""
    return K.path_agreement(theta, tx, ty, *_path_args(pa, pb), both)


_FEATURE_COLS = list(_FEATURE_COLUMNS.values())


_FEATURE_WEIGHTS = np.array([CONFIDENCE_WEIGHTS[k] for k in _FEATURE_COLUMNS])
"""The columns of :data:`_FEATURE_COLUMNS` and their score weights (:func:`score_rows`)."""


PATH_WEIGHTS = np.array([CONFIDENCE_WEIGHTS["path_agree"], CONFIDENCE_WEIGHTS["path_off"]])
"""Score weights of the columns of :func:`path_evidence` (``path_agree``, ``path_off``)."""


def score_rows(features: np.ndarray, paths: np.ndarray, n_a: int, n_b: int) -> np.ndarray:
    """:attr:`MergeEvidence.score` of rows of :func:`fusion.structural._kernels.evidence`
    features and of :func:`path_evidence`."""
    const = CONFIDENCE_WEIGHTS["bias"] + CONFIDENCE_WEIGHTS["log_pairs"] * math.log(n_a * n_b)
    return (features[:, _FEATURE_COLS] @ _FEATURE_WEIGHTS + const
            + CONFIDENCE_WEIGHTS["likelihood"] * features[:, _LIKELIHOOD].max(axis=1)
            + paths @ PATH_WEIGHTS)


def evaluate(pa: Prepared, pb: Prepared, theta: float, t: np.ndarray,
             cfg: MergeConfig) -> Evaluated:
    """The full evidence (:class:`MergeEvidence`) and matches of B moved by ``(theta, t)``."""
    match_b = np.empty(len(pb.xy), dtype=np.int64)
    f = K.evidence(*evidence_args(pa, pb), float(theta), float(t[0]), float(t[1]), cfg.eps,
                   pa.compat, pa.loose, BRANCH_TOL, MIN_CROSSING_SIN, cfg.near_miss, match_b,
                   np.empty(len(pb.xy)))
    f = f.tolist()  # Python floats: cheaper to read one by one
    b = np.flatnonzero(match_b >= 0)
    matches = np.column_stack((match_b[b], b)).astype(np.int64)
    agree, off = path_evidence(pa, pb, np.array([float(theta)]), np.array([float(t[0])]),
                               np.array([float(t[1])]))[0].tolist()
    n = len(matches)
    collinear = n < 3 or degeneracy(pa.xy[matches[:, 0]], "matches", 1e-3) is not None
    ev = MergeEvidence(n, f[0], int(f[2]), int(f[3]), int(f[4]), int(f[5]), int(f[6]),
                       int(f[8]), math.sqrt(f[7] / n) if n else math.inf, collinear, len(pa.xy),
                       len(pb.xy), likelihood=max(f[_LIKELIHOOD]), path_agree=agree,
                       path_off=off)
    return Evaluated(float(wrap_angle(theta)), np.asarray(t, dtype=np.float64), matches, ev)


def feature_matrix(features: np.ndarray, paths: np.ndarray, n_a: int, n_b: int
                   ) -> np.ndarray:
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


def with_evidence(ev: Evaluated, **changes) -> Evaluated:
    e = ev.evidence
    fields = {f: getattr(e, f) for f in MergeEvidence.__dataclass_fields__}
    fields.update(changes)
    return Evaluated(ev.theta, ev.t, ev.matches, MergeEvidence(**fields))


def decide(evidence: MergeEvidence, config: MergeConfig | None = None) -> str | None:
    """The structural merge's accept rule: ``None`` to accept, else the reasons to reject
    (``"; "``-joined) — :meth:`fusion.decision.MergeRule.structural` of ``config``'s rule:
    too few matched nodes (``min_inliers``), collinear matches, a distinct alternative within
    ``min_margin`` (ambiguous), or a calibrated :attr:`MergeEvidence.confidence` below
    ``accept_threshold`` (weak evidence)."""
    return MergeRule.of(config_of(config)).structural(evidence)
