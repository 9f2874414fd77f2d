"""Settings of :func:`fusion.merge_maps`: :class:`MergeConfig` and the accept threshold."""

from __future__ import annotations

from dataclasses import dataclass

from topo.validation import check_int, check_real, config_from

DEFAULT_ACCEPT_THRESHOLD = 0.8
"""Default :attr:`MergeConfig.accept_threshold`: the smallest (on a 0.05 grid) at which the
cross-validated tuning pairs of ``benchmarks/calibrate_merge.py --model structural`` (env pairs
and synthetic pairs) had at most 1 % false accepts on no-overlap pairs and 1 % wrong accepts of
all pairs."""


METHODS = ("auto", "paper_icp", "exhaustive", "multistart_icp")
"""Names accepted by :func:`merge_maps` ``method``."""


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


DEFAULT_CONFIG = MergeConfig()
"""``MergeConfig()``, built once: validating a config costs ~17 µs, 1% of a small merge."""


def config_of(config: MergeConfig | dict | None) -> MergeConfig:
    """``config`` as a :class:`MergeConfig`: ``None`` → :data:`DEFAULT_CONFIG`, a dict → its
    fields (unknown keys refused), a config as is.

    Raises:
        TypeError, ValueError: as :func:`topo.validation.config_from`.
    """
    return DEFAULT_CONFIG if config is None else config_from(MergeConfig, config)
