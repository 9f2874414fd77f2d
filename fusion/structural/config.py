"""Settings of :func:`fusion.merge_maps`: :class:`MergeConfig` and the accept threshold."""

from __future__ import annotations

from dataclasses import dataclass

from fusion.decision import DEFAULT_RULE, STRUCTURAL_ACCEPT_THRESHOLD
from topo.validation import check_int, check_real, config_from

DEFAULT_ACCEPT_THRESHOLD = STRUCTURAL_ACCEPT_THRESHOLD
"""Default :attr:`MergeConfig.accept_threshold`: the structural merge called alone
(:data:`fusion.decision.STRUCTURAL_ACCEPT_THRESHOLD`, where every accept threshold is
documented)."""


METHODS = ("auto", "paper_icp", "exhaustive", "multistart_icp", "ransac")
"""Names accepted by :func:`merge_maps` ``method``."""


@dataclass(frozen=True, slots=True)
class MergeConfig:
    """Parameters of :func:`merge_maps` (lengths in metres, angles in degrees).

    Attributes:
        eps: match tolerance: nodes of A and moved B within ``eps`` may be the same place (the
            paper's ω tolerance); also the gate of the ICP refinement and the conflict distance.
        fit_eps: the final least-squares fit pairs mutually nearest nodes of any kinds within
            this (a node at the edge of explored space may have another kind in each map),
            each pair ``d`` apart weighing ``1 − d²/fit_eps²``.
        near_miss: see :attr:`MergeEvidence.near_misses`.
        pair_tolerance: most difference between an A pair's and a B pair's length for a 2-point
            hypothesis (about 2σ of the difference for node noise σ = 0.15 m).
        min_pair_distance: node pairs closer than this fix the angle too poorly to be used.
        knn: each node is also paired with its ``knn`` nearest nodes.
        coarse_tolerance: hit radius of the coarse hypothesis score.
        max_hypotheses: most hypotheses scored (those of the longest pairs are kept).
        path_pool: distinct hypotheses (the best by coarse score) re-ranked by adding their
            path evidence (:attr:`MergeEvidence.path_agree`, ``path_off``) in the coarse score's
            units (a matched node ≈ the ``closeness`` + ``inliers`` weights) before the
            ``candidates`` best are refined.
        sparse_pool: the best distinct hypotheses landing ``min_inliers`` but fewer than 4 B
            nodes on A nodes, joined to the ``path_pool`` for the re-ranking (the coarse
            ranking holds those landing 4 or more; pairs sharing exactly 3 nodes would be
            crowded out of it by chance 3-node landings). 0 switches it off.
        candidates: distinct hypotheses refined, best re-ranked gain first.
        scored: of those, how many (the most matched after refinement; ties to the better
            re-ranked gain) are fully scored.
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
            of being right) at least this (:data:`DEFAULT_ACCEPT_THRESHOLD`).
        multistart_starts: starting rotations of ``"multistart_icp"``.
        exhaustive_step_deg: rotation step of ``"exhaustive"`` (the paper's 2°).
        ransac_iterations: minimal sets (two node pairs) ``"ransac"`` draws at most.
        ransac_seed: seed of the generator ``"ransac"`` draws them with (a merge is
            reproducible).

    How the defaults were chosen: ``docs/notes/merge_tuning.md``.
    """

    eps: float = 0.5
    fit_eps: float = 0.6
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
    min_inliers: int = DEFAULT_RULE.min_inliers
    min_margin: float = DEFAULT_RULE.min_margin
    accept_threshold: float = DEFAULT_ACCEPT_THRESHOLD
    multistart_starts: int = 12
    exhaustive_step_deg: float = 2.0
    ransac_iterations: int = 2000
    ransac_seed: int = 0

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
                          ("min_inliers", 3), ("multistart_starts", 1),
                          ("ransac_iterations", 1), ("ransac_seed", 0)):
            check_int(getattr(self, name), name, low=low)

    @classmethod
    def from_dict(cls, data: dict) -> MergeConfig:
        """From a dict of field values; unknown keys are a ``ValueError`` listing the allowed."""
        return config_from(cls, data, "MergeConfig")

    @classmethod
    def for_noise(cls, sigma: float, **overrides) -> MergeConfig:
        """Tolerances for maps whose nodes are off by ``sigma`` metres (per axis, each map):
        the defaults (tuned for σ ≤ 0.15 m) or, for noisier maps, ``eps = 3σ``,
        ``fit_eps = pair_tolerance = 4σ`` and ``coarse_tolerance = 3.3σ`` (each at least its
        default). ``overrides`` replace any field.

        Raises:
            ValueError: ``sigma`` outside ``[0, 0.3]``, the range it was calibrated on (wider
                tolerances let more chance alignments score; ``docs/notes/merge_tuning.md``).
        """
        sigma = check_real(sigma, "sigma", low=0.0, low_inclusive=True, high=0.3)
        base = cls()
        scaled = {}
        if 3.0 * sigma > base.eps:
            scaled = {"eps": 3.0 * sigma, "fit_eps": max(base.fit_eps, 4.0 * sigma),
                      "pair_tolerance": max(base.pair_tolerance, 4.0 * sigma),
                      "coarse_tolerance": max(base.coarse_tolerance, 10.0 * sigma / 3.0)}
        return config_from(cls, {**scaled, **overrides}, "MergeConfig")


DEFAULT_CONFIG = MergeConfig()
"""``MergeConfig()``, built once (validation is not free, and merges run every few steps)."""


def config_of(config: MergeConfig | dict | None) -> MergeConfig:
    """``config`` as a :class:`MergeConfig`: ``None`` → :data:`DEFAULT_CONFIG`, a dict → its
    fields (unknown keys refused), a config as is.

    Raises:
        TypeError, ValueError: as :func:`topo.validation.config_from`.
    """
    return DEFAULT_CONFIG if config is None else config_from(MergeConfig, config)
