"""The merge rule: one frozen :class:`MergeRule` holding every threshold, margin and gate that
decides whether a merge is accepted, whether it replaces the transform in use, whether the
transform in use is dropped, when the grids must vouch, and which pairwise merges a team uses.

Every caller goes through it: :func:`fusion.merge_maps`' accept (:meth:`MergeRule.structural`,
the public :func:`fusion.decide`), :func:`fusion.grid_merge.merge_grids`' accept
(:meth:`MergeRule.grid`) and its check of a structural merge (:meth:`MergeRule.grid_check`),
the orchestration of :func:`fusion.hybrid.hybrid_merge` and :func:`fusion.hybrid.recheck`
(:meth:`MergeRule.keeps`, :meth:`MergeRule.vouches`, :meth:`MergeRule.drops`,
:meth:`MergeRule.refutes`), the env's pair merging (:meth:`MergeRule.first_merge_vouch`,
:func:`pair_verdict`) and the team (:meth:`MergeRule.team_min_unconfirmed`,
:data:`CYCLE_TOLERANCE_DEG`). Each step returns ``None`` to let the merge through, else the
reason it stops it (the text the results carry). Why one place: the rule was spread over five
modules and three configs, and a threshold changed in one was silently not the one applied.

The user-facing settings stay where users set them (:class:`fusion.MergeConfig`,
:class:`fusion.grid_merge.GridMergeConfig`, the env's ``MappingConfig``): their defaults are
this module's, and :meth:`MergeRule.of` reads a config into the rule.

**Accept thresholds.** One default, :data:`DEFAULT_ACCEPT_THRESHOLD`, is the one everything
that has the grids uses: the grid alignment, the hybrid merge (which also passes it to the
structural merge it runs first) and the env. The structural merge called alone, without grids
to check it, has its own default, :data:`STRUCTURAL_ACCEPT_THRESHOLD`: its calibrated
confidence is a different model, fitted and thresholded on its own (``python -m
fusion.calibration fit --model structural`` prints the threshold rule's choice), and the
fusion evaluation's results for ``merge_maps`` are made at it. The map-merge tool on real sensor
maps uses its own grid model, :data:`REAL_MAP_MODEL`, at the threshold stored with it
(:func:`model_threshold`); the env keeps ``"grid"`` at :data:`DEFAULT_ACCEPT_THRESHOLD`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from fusion.rigid import Rigid2D
from topo.validation import check_int, check_real

DEFAULT_ACCEPT_THRESHOLD = 0.9
"""The default accept threshold of every merge that has the grids (``GridMergeConfig``, the
hybrid merge, the env's ``mapping.accept_threshold``): the threshold rule's choice for the
``"grid"`` model on the noise-free tuning pairs (``python -m fusion.calibration fit --model
grid``: the smallest threshold on a 0.05 grid with few false accepts of no-overlap pairs and
few wrong accepts of all pairs in cross-validation)."""

STRUCTURAL_ACCEPT_THRESHOLD = 0.8
"""The default :attr:`fusion.MergeConfig.accept_threshold`: the structural merge called alone
(:func:`fusion.merge_maps`), whose confidence model is fitted and thresholded on its own
(``--model structural``); kept above the threshold rule's choice when that one sits at the
limit, for pairs unlike the tuning ones (``docs/notes/fusion.md``)."""

REAL_MAP_MODEL = "grid_real"
"""The grid alignment's confidence model for real sensor maps (separate scans of a building:
the map-merge tool's default, :mod:`fusion.mapmerge`), fitted on real laser-log map pairs
(``python -m fusion.calibration fit --model grid_real``) apart from the env's ``"grid"``,
whose model and :data:`DEFAULT_ACCEPT_THRESHOLD` the env keeps. Its threshold is the one the
threshold rule chose when it was fitted, stored with it (:func:`model_threshold`)."""


def model_threshold(name: str) -> float:
    """The accept threshold stored with the calibrated model ``name`` (its ``meta``'s
    ``accept_threshold``: the threshold rule's choice when it was fitted). Why stored: a fitted
    number is data, and the model and its threshold are refitted together.

    Raises:
        ValueError: no such model (the table's models are named), or it stores no threshold.
    """
    from fusion.calibration import load_model

    model = load_model(name)
    if "accept_threshold" not in model.meta:
        raise ValueError(f"calibration model {name!r} stores no accept_threshold in its meta")
    return float(model.meta["accept_threshold"])


TEAM_ACCEPT_THRESHOLD = 0.97
"""Default :attr:`MergeRule.team_accept_threshold` (the env's
``mapping.team_accept_threshold``)."""

CYCLE_TOLERANCE_DEG = 5.0
"""Largest rotation (degrees) a consistent triangle of merges may compose to
(:func:`fusion.team.consistent_edges`): two merges right to 2° each compose to at most 4°;
look-alikes are tens of degrees or whole metres off."""

CYCLE_TOLERANCE_M = 1.0
"""Largest displacement (metres) of a robot's map centre around a consistent triangle."""


def clearly_different(a: Rigid2D, b: Rigid2D, centre: Any, distinct_deg: float,
                      distinct_m: float) -> bool:
    """Whether two alignments of the same maps are clearly different: their rotations differ
    by more than ``distinct_deg`` degrees or they place ``centre`` (B's frame) more than
    ``distinct_m`` metres apart."""
    return (math.degrees(a.rotation_error(b)) > distinct_deg
            or a.translation_error(b, at=centre) > distinct_m)


@dataclass(frozen=True, slots=True)
class MergeRule:
    """Every threshold, margin and gate of the merge decision (module docstring), validated.

    Attributes:
        accept_threshold: a merge is accepted only when its calibrated confidence (the
            probability that its transform is right) reaches this.
        min_inliers: a structural merge needs at least this many matched nodes, not collinear
            (a hard gate: fewer do not fix a rotation) ...
        min_margin: ... and its best *distinct* alternative scoring at least this much less
            (log-odds; a symmetric map is ambiguous however strong the evidence for both).
        min_overlap_m2: a grid alignment, and the grids' check of a structural merge, needs
            this much of B's free space on A's known cells (too little shared space to check
            anything).
        min_wall_agreement, max_conflict: the grids' check of a structural merge: at least
            this fraction of B's wall cells on A's known cells meet an A wall, at most this
            fraction lie in A's free space.
        distinct_deg, distinct_m: two alignments are clearly different beyond these (degrees,
            metres at B's centre): only such a result replaces or refutes the one in use.
        tie_margin: a clearly different alignment scoring within this factor of the best
            ties with it: at most one of the two is right, so the grid confidence is capped at
            1/2 whatever the fitted model says (it can read more into a perfect tie, a
            symmetric room, than its tuning data held).
        in_use_margin: a confident result clearly different from the transform in use
            replaces it unless the grids support the one in use more than this many times
            better (:attr:`fusion.grid_merge.GridAgreement.support`; support grows with the
            area two maps overlap, so in a building of repeated rooms a look-alike placed over
            more of the other map can out-support the truth: only a clear difference
            overrules the merge's own evidence).
        drop_margin: with drift, the transform in use is dropped when the grids' confidence
            in it falls below ``accept_threshold − drop_margin`` (a margin, so that a merge is
            not dropped and re-accepted as the confidence wavers at the threshold).
        drift_prior: how far the maps' odometry may have drifted
            (:func:`fusion.grid_merge.drift_prior`; 0: perfect odometry). Above 0 a structural
            merge needs the grids to vouch for it and the drop rule is on.
        first_merge_check: a pair's first merge (no transform in use) from the structural
            merge needs the grids to vouch for it: early maps that share no place let a room
            row fit its twin with a high structural confidence.
        team_accept_threshold: with three or more robots, a pairwise merge that no consistent
            triangle confirms is used only at this confidence or more (a team has many pairs,
            hence many chances of one confident look-alike).
    """

    accept_threshold: float = DEFAULT_ACCEPT_THRESHOLD
    min_inliers: int = 3
    min_margin: float = 1.0
    min_overlap_m2: float = 6.0
    min_wall_agreement: float = 0.6
    max_conflict: float = 0.3
    distinct_deg: float = 15.0
    distinct_m: float = 1.5
    tie_margin: float = 1.05
    in_use_margin: float = 1.5
    drop_margin: float = 0.3
    drift_prior: float = 0.0
    first_merge_check: bool = True
    team_accept_threshold: float = TEAM_ACCEPT_THRESHOLD

    def __post_init__(self) -> None:
        for name in ("accept_threshold", "drop_margin", "team_accept_threshold",
                     "min_wall_agreement"):
            check_real(getattr(self, name), f"MergeRule.{name}", low=0.0, low_inclusive=True,
                       high=1.0)
        for name in ("min_margin", "min_overlap_m2", "max_conflict", "drift_prior"):
            check_real(getattr(self, name), f"MergeRule.{name}", low=0.0, low_inclusive=True)
        for name in ("distinct_deg", "distinct_m", "tie_margin", "in_use_margin"):
            check_real(getattr(self, name), f"MergeRule.{name}", low=0.0)
        check_int(self.min_inliers, "MergeRule.min_inliers", low=3)
        if not isinstance(self.first_merge_check, bool):
            raise TypeError(f"MergeRule.first_merge_check must be a bool, got "
                            f"{type(self.first_merge_check).__name__}")

    @classmethod
    def of(cls, config: Any = None, **overrides: Any) -> MergeRule:
        """The rule a config applies: the fields of :class:`MergeRule` that ``config`` (a
        :class:`fusion.MergeConfig`, a :class:`fusion.grid_merge.GridMergeConfig`, or
        ``None``) has, the defaults for the others, then ``overrides``.

        Raises:
            TypeError: an override that is not a field of :class:`MergeRule` (named).
        """
        unknown = sorted(set(overrides) - set(cls.__dataclass_fields__))
        if unknown:
            raise TypeError(f"MergeRule has no fields {unknown}; it has "
                            f"{sorted(cls.__dataclass_fields__)}")
        taken = {} if config is None else {
            f.name: getattr(config, f.name) for f in dataclasses.fields(cls)
            if hasattr(config, f.name)}
        return cls(**{**taken, **overrides})

    # ------------------------------------------------------------------- one-shot merges
    def structural(self, evidence: Any) -> str | None:
        """The structural merge's accept (:func:`fusion.decide`): ``None`` to accept, else the
        reasons to reject (``"; "``-joined) — fewer than ``min_inliers`` matched nodes; the
        matched nodes collinear (the rotation is not determined); a distinct alternative
        within ``min_margin`` of the score (ambiguous); a calibrated
        :attr:`fusion.MergeEvidence.confidence` below ``accept_threshold`` (weak evidence)."""
        e = evidence
        reasons = []
        if e.inliers < self.min_inliers:
            reasons.append(f"too few matched nodes: {e.inliers} < min_inliers={self.min_inliers}")
        if e.collinear:
            reasons.append("matched nodes are collinear: rotation not determined")
        if e.margin < self.min_margin:
            reasons.append(f"ambiguous: a distinct alignment scores {e.runner_up:.2f} against "
                           f"{e.score:.2f} (margin < min_margin={self.min_margin})")
        confidence = e.confidence
        if confidence < self.accept_threshold:
            reasons.append(f"weak evidence: confidence {confidence:.2f} < accept_threshold="
                           f"{self.accept_threshold} (score {e.score:.2f}, {e.inliers} matches, "
                           f"{e.matched_edges} matched paths, {e.conflicts} conflicts, "
                           f"{e.crossings} crossings, rmse {e.rmse:.2f} m)")
        return "; ".join(reasons) or None

    def tie_capped(self, confidence: float, margin: float) -> float:
        """A grid alignment's confidence, at most 1/2 when it ties with a clearly different
        rival (``margin`` below ``tie_margin``)."""
        return min(confidence, 0.5) if margin < self.tie_margin else confidence

    def grid(self, confidence: float, overlap_m2: float, margin: float, wall_agreement: float,
             conflict: float) -> str | None:
        """The grid alignment's accept (:func:`fusion.grid_merge.merge_grids`): ``None`` when
        at least ``min_overlap_m2`` overlaps and the (tie-capped) ``confidence`` reaches
        ``accept_threshold``, else why not (the other evidence is named in the reason)."""
        reasons = []
        if overlap_m2 < self.min_overlap_m2:
            reasons.append(f"overlap {overlap_m2:.1f} m² < min_overlap_m2={self.min_overlap_m2}")
        if confidence < self.accept_threshold:
            reasons.append(f"confidence {confidence:.2f} < accept_threshold="
                           f"{self.accept_threshold} (margin {margin:.2f} over a distinct "
                           f"alignment, wall agreement {wall_agreement:.2f}, conflict "
                           f"{conflict:.2f})")
        return "; ".join(reasons) or None

    def grid_check(self, agreement: Any) -> str | None:
        """The grids' check of a structural merge (:func:`fusion.grid_merge.check_with_grids`)
        from its :class:`fusion.grid_merge.GridAgreement` (``None``: a grid has no known
        cells): enough overlap, B's walls on A's walls, few in A's free space."""
        if agreement is None:
            return "a grid has no known cells"
        reasons = []
        if agreement.overlap_m2 < self.min_overlap_m2:
            reasons.append(f"overlap {agreement.overlap_m2:.1f} m² < min_overlap_m2="
                           f"{self.min_overlap_m2}")
        if agreement.wall_agreement < self.min_wall_agreement:
            reasons.append(f"wall agreement {agreement.wall_agreement:.2f} < "
                           f"min_wall_agreement={self.min_wall_agreement}")
        if agreement.conflict > self.max_conflict:
            reasons.append(f"conflict {agreement.conflict:.2f} > max_conflict="
                           f"{self.max_conflict}")
        return "; ".join(reasons) or None

    # ------------------------------------------------------------ the transform in use
    def distinct(self, a: Rigid2D, b: Rigid2D, centre: Any) -> bool:
        """Whether ``a`` and ``b`` are clearly different (:func:`clearly_different` at
        ``distinct_deg`` / ``distinct_m``)."""
        return clearly_different(a, b, centre, self.distinct_deg, self.distinct_m)

    def keeps(self, in_use: Any, new: Any) -> str | None:
        """Why the transform in use stays rather than a clearly different ``new`` one replacing
        it — the grids support it more than ``in_use_margin`` times better (``in_use``,
        ``new``: their :class:`fusion.grid_merge.GridAgreement`, ``None`` when unknown) — or
        ``None`` if ``new`` may replace it."""
        if in_use is None or new is None or in_use.support <= self.in_use_margin * new.support:
            return None
        return (f"the grids support the transform in use better ({in_use.support:.0f} net "
                f"wall cells against {new.support:.0f})")

    def needs_vouch(self, vouch: bool) -> bool:
        """Whether an accepted structural merge also needs the grids to vouch for it: asked
        (``vouch``: a pair's first merge) or on drifting odometry (``drift_prior > 0``: the
        structural confidence knows nothing of the drift, the grids' weighs it)."""
        return vouch or self.drift_prior > 0

    def vouches(self, grid: Any, transform: Rigid2D) -> str | None:
        """Why the grids do not vouch for a structural merge's ``transform`` (``grid``: their
        :class:`fusion.grid_merge.GridMergeResult`): their best alignment is another one, or
        the same one with a calibrated confidence below ``accept_threshold``; ``None`` if they
        do (or have no alignment to judge by)."""
        if grid.centre is None:
            return None
        if self.distinct(grid.transform, transform, grid.centre):
            return "the grids' best alignment is another one"
        if grid.confidence >= self.accept_threshold:
            return None
        return (f"the grids' confidence in it is {grid.confidence:.2f} < "
                f"accept_threshold={self.accept_threshold}"
                + (f" (drift_prior {self.drift_prior:g})" if self.drift_prior > 0 else ""))

    def drops(self, grid: Any) -> str | None:
        """Why the transform in use is dropped though the grids' best alignment (``grid``,
        rejected) is that same one: on drifting odometry (``drift_prior > 0``), with no rival
        it ties with (``margin`` above ``tie_margin``: a symmetric room's look-alikes keep
        it), its confidence below ``accept_threshold − drop_margin`` — drift bends the maps
        until no rigid transform is right. ``None``: kept (always without drift)."""
        floor = self.accept_threshold - self.drop_margin
        if self.drift_prior <= 0 or grid.confidence >= floor or not grid.margin > self.tie_margin:
            return None
        return (f"the grids no longer trust the transform in use: their alignment of it has "
                f"confidence {grid.confidence:.2f} < accept_threshold - drop_margin = "
                f"{floor:.2f}")

    def refutes(self, grid: Any, in_use: Rigid2D, kept: str | None) -> str | None:
        """Why the grids' best alignment (``grid``, rejected, clearly different from
        ``in_use``) refutes the transform in use — unless the grids support ``in_use``
        clearly better (``kept``, :meth:`keeps`' reason) — or ``None``."""
        if kept is not None:
            return None
        return (f"the grids refute the transform in use: their best alignment is "
                f"{math.degrees(grid.transform.rotation_error(in_use)):.0f}° / "
                f"{grid.transform.translation_error(in_use, at=grid.centre):.1f} m from it")

    # ------------------------------------------------------------------ the env and team
    def first_merge_vouch(self, in_use: Rigid2D | None) -> bool:
        """Whether this merge of a pair needs the grids to vouch (:meth:`needs_vouch`): its
        first (nothing ``in_use``), when ``first_merge_check``."""
        return self.first_merge_check and in_use is None

    def team_min_unconfirmed(self, n_robots: int) -> float:
        """The least confidence of a pairwise merge no consistent triangle confirms
        (:func:`fusion.team.consistent_edges` ``min_unconfirmed``): ``team_accept_threshold``
        with three or more robots; two robots have no cycle to confirm a merge, their pair
        is the accept rule alone (0)."""
        return self.team_accept_threshold if n_robots >= 3 else 0.0


DEFAULT_RULE = MergeRule()
"""``MergeRule()``: the configs' defaults of its fields."""


def pair_verdict(accepted: bool, transform: Rigid2D, confidence: float,
                 in_use: Rigid2D | None, in_use_confidence: float,
                 refuted: str | None) -> str | None:
    """What a merge call does to a robot pair's transform in use: ``"replace"`` (an accepted
    transform other than the one in use, or the first), ``"confirm"`` (the one in use
    accepted again with more confidence than it was), ``"drop"`` (the grids ``refuted`` the
    one in use) or ``None`` (nothing changes)."""
    if accepted and (in_use is None or not transform.allclose(in_use)):
        return "replace"
    if accepted and confidence > in_use_confidence:
        return "confirm"
    if refuted is not None and in_use is not None:
        return "drop"
    return None


__all__ = ["CYCLE_TOLERANCE_DEG", "CYCLE_TOLERANCE_M", "DEFAULT_ACCEPT_THRESHOLD", "DEFAULT_RULE",
           "REAL_MAP_MODEL", "STRUCTURAL_ACCEPT_THRESHOLD", "TEAM_ACCEPT_THRESHOLD", "MergeRule",
           "clearly_different", "model_threshold", "pair_verdict"]
