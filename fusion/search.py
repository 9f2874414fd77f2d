"""The paper's similarity ω (eq. 2–3) and its baseline: exhaustive search over placements.

The paper scores a fusion by ω(A, B) = Σ_i Σ_j Eq(E_A[i], E_B[j]), the number of coinciding path
endpoints. With floating-point maps "coinciding" must mean "within a tolerance": here
``‖a_i − (R b_j + T)‖ ≤ eps``.

The baseline (the paper's "exhaustive search") tries every rotation θ from 0° in ``step_deg``
steps and, for every vertex pair (a_i, b_j), the translation that places b_j on a_i, keeping the
placement with the largest ω. With a 4-vertex A, a 7-vertex B and 2° steps from 0° to 360°
*inclusive* that is the paper's 4 × 7 × 181 = 5068 fusions; 0° and 360° are the same rotation,
so only 4 × 7 × 180 = 5040 of them are distinct. The paper rotates map A; topomerge keeps its one
convention and moves B onto A (``p_A = R p_B + T``), so a paper angle θ corresponds to −θ here.

Its cost grows with the product of the map sizes (the placements counted above). Beyond
:data:`DEFAULT_MAX_EVALUATIONS` placements it refuses at once, before allocating anything,
with a ``ValueError`` stating the count, the estimated time and the two ways out:
``max_evaluations=None`` (or a larger limit), or a coarser ``step_deg``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from fusion.inputs import check_point_count
from fusion.rigid import Rigid2D
from topo.graph import TopoMap
from topo.validation import as_points, check_int, check_real

DEFAULT_EPS = 0.3
"""Default coincidence tolerance in metres (the evaluation's translation-success threshold)."""

DEFAULT_MAX_EVALUATIONS = 5_000_000
"""Placements :func:`exhaustive_search` scores before refusing unless told otherwise (the
paper's example has 5068; two 160-endpoint maps 4.6 M)."""

SECONDS_PER_EVALUATION = 2e-6
"""Cost of one placement (s) for the time estimate in :func:`exhaustive_search`'s refusal
(fitted in ``docs/notes/fusion.md``)."""


def endpoint_set(value: Any, name: str) -> np.ndarray:
    """The paper's point set of a map: :meth:`TopoMap.endpoints` or an ``(N, 2)`` array, of at
    most :data:`fusion.inputs.MAX_POINTS` points."""
    if isinstance(value, TopoMap):
        return check_point_count(value.endpoints(), name)
    return check_point_count(as_points(value, name), name)


def similarity(map_a: Any, map_b: Any, transform: Rigid2D, eps: float = DEFAULT_EPS) -> int:
    """ω of eq. (2)–(3): pairs of endpoints of A and of B moved by ``transform`` within ``eps``.

    Args:
        map_a, map_b: :class:`topo.TopoMap` (its :meth:`~topo.TopoMap.endpoints`) or ``(N, 2)``
            point arrays.
        transform: B → A (``p_A = R p_B + T``).
        eps: coincidence tolerance, ``> 0``, in the maps' units.

    Counts pairs, as the paper's double sum does: an endpoint of A near two endpoints of B counts
    twice.
    """
    a = endpoint_set(map_a, "map_a")
    b = endpoint_set(map_b, "map_b")
    if not isinstance(transform, Rigid2D):
        raise TypeError(f"transform must be a fusion.Rigid2D, got {type(transform).__name__}")
    eps = check_real(eps, "eps", low=0.0)
    if len(a) == 0 or len(b) == 0:
        return 0
    return int(cKDTree(a).count_neighbors(cKDTree(transform.apply(b)), eps))


@dataclass(frozen=True, slots=True)
class Placement:
    """One candidate fusion: B rotated by ``transform.theta`` with endpoint ``anchor[1]`` of B
    placed on endpoint ``anchor[0]`` of A, and its similarity ``score``."""

    transform: Rigid2D
    anchor: tuple[int, int]
    score: int


@dataclass(frozen=True, slots=True)
class SearchResult:
    """What :func:`exhaustive_search` found.

    Attributes:
        transform: the best placement's transform (the first of :attr:`ties`).
        score: its similarity ω.
        evaluations: fusions scored, ``n_A × n_B × n_angles`` (the paper's 5068 for 4 × 7 × 181).
        distinct_evaluations: the same count without the duplicated 360° (= 0°) angle (5040).
        ties: one placement per *distinct* optimum reaching ``score``. Tied placements linked
            by steps of at most one angle step and ``eps`` (at B's centroid) are one optimum,
            represented by its placement of least residual. More than one means the search is
            ambiguous, like the paper's two optima at 136° and 316°.
    """

    transform: Rigid2D
    score: int
    evaluations: int
    distinct_evaluations: int
    ties: tuple[Placement, ...]

    @property
    def ambiguous(self) -> bool:
        return len(self.ties) > 1


def angle_count(step_deg: float) -> int:
    """How many angles :func:`search_angles` gives for ``step_deg`` (181 for 2°), computed
    without building them, so that a search too fine to run is refused before it allocates.

    Raises:
        TypeError, ValueError: ``step_deg`` not a real number in ``(0, 360]``.
    """
    step = check_real(step_deg, "step_deg", low=0.0, high=360.0)
    return int(math.floor(360.0 / step + 1e-9)) + 1


def search_angles(step_deg: float) -> np.ndarray:
    """Angles in degrees from 0 to 360 inclusive, as the paper counts them (181 for 2°)."""
    return np.arange(angle_count(step_deg)) * float(step_deg)


def exhaustive_evaluations(n_a: int, n_b: int, step_deg: float = 2.0) -> int:
    """Placements :func:`exhaustive_search` scores on maps of ``n_a`` and ``n_b`` endpoints:
    ``n_a × n_b × len(search_angles(step_deg))`` (the paper's 4 × 7 × 181 = 5068)."""
    return int(n_a) * int(n_b) * angle_count(step_deg)


def fitting_step(n_a: int, n_b: int, max_evaluations: int) -> float | None:
    """The finest rotation step, in tenths of a degree, at which maps of ``n_a`` and ``n_b``
    endpoints stay within ``max_evaluations`` placements; ``None`` if no step does (even the
    two angles 0° and 360°)."""
    max_angles = max_evaluations // max(int(n_a) * int(n_b), 1)
    if max_angles < 2:
        return None
    for tenths in range(max(1, 3600 // max_angles), 3601):
        if exhaustive_evaluations(n_a, n_b, tenths / 10) <= max_evaluations:
            return tenths / 10
    return None  # unreachable: 360° gives 2 angles


def _duration(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.0f} min"


def too_many_evaluations(n_a: int, n_b: int, step_deg: float, max_evaluations: int,
                         step_name: str = "step_deg") -> str:
    """Why :func:`exhaustive_search` refuses maps of ``n_a`` and ``n_b`` endpoints at
    ``step_deg`` — the count, the estimated time and the coarsest step that fits, called
    ``step_name`` — or ``""`` when it does not refuse them."""
    count = exhaustive_evaluations(n_a, n_b, step_deg)
    if count <= max_evaluations:
        return ""
    fit = fitting_step(n_a, n_b, max_evaluations)
    coarser = (f"{step_name} >= {fit:g} fits" if fit is not None
               else f"no {step_name} fits: the maps are too large")
    return (f"{n_a} × {n_b} endpoints × {angle_count(step_deg)} angles ({step_name}="
            f"{step_deg:g}) = {count:,} placements, above max_evaluations={max_evaluations:,} "
            f"(about {_duration(count * SECONDS_PER_EVALUATION)} at "
            f"{SECONDS_PER_EVALUATION * 1e6:g} µs each; {coarser})")


def exhaustive_search(
    map_a: Any, map_b: Any, step_deg: float = 2.0, eps: float = DEFAULT_EPS,
    max_evaluations: int | None = DEFAULT_MAX_EVALUATIONS,
) -> SearchResult:
    """The paper's baseline: the best of every rotation step × every vertex-on-vertex placement.

    Args:
        map_a: the fixed map (:class:`topo.TopoMap` or ``(N, 2)`` endpoints), ``N >= 1``.
        map_b: the moved map, ``N >= 1``.
        step_deg: rotation step in degrees, in ``(0, 360]``; angles run 0..360 inclusive.
        eps: coincidence tolerance of ω, ``> 0``.
        max_evaluations: the most placements to score (:func:`exhaustive_evaluations`),
            ``>= 1``, or ``None`` for no limit. The default, :data:`DEFAULT_MAX_EVALUATIONS`, is
            about 10 s: the search's cost grows with the product of the map sizes, and it is
            better refused at once than minutes later.

    Raises:
        ValueError: an empty map, a bad ``step_deg``/``eps``/``max_evaluations``, or more
            placements than ``max_evaluations`` (the message gives the count, the estimated
            time and a ``step_deg`` that fits; ``merge_maps`` takes the step from
            ``MergeConfig.exhaustive_step_deg``).

    Every placement of one angle is scored at once: the candidate translations are the
    differences ``a_i − R b_j``, and ω of a translation is how many of those differences lie
    within ``eps`` of it (one KD-tree ball count per angle).
    """
    a = endpoint_set(map_a, "map_a")
    b = endpoint_set(map_b, "map_b")
    for name, pts in (("map_a", a), ("map_b", b)):
        if len(pts) == 0:
            raise ValueError(f"{name} must have at least 1 endpoint, got 0")
    eps = check_real(eps, "eps", low=0.0)
    angle_count(step_deg)  # checks step_deg; the angles are built only once the count is allowed
    n_a, n_b = len(a), len(b)
    if max_evaluations is not None:
        check_int(max_evaluations, "max_evaluations", low=1)
        why = too_many_evaluations(n_a, n_b, float(step_deg), max_evaluations)
        if why:
            raise ValueError(f"exhaustive_search: {why}; pass max_evaluations=None (or a larger "
                             f"limit) to run it anyway, or a coarser step_deg (merge_maps: "
                             f"MergeConfig.exhaustive_step_deg)")

    angles = search_angles(step_deg)
    best = -1
    tied: list[tuple[float, int, int, np.ndarray]] = []
    for deg in angles:
        theta = math.radians(deg)
        c, s = math.cos(theta), math.sin(theta)
        rb = b @ np.array([[c, s], [-s, c]])
        shifts = (a[:, None, :] - rb[None, :, :]).reshape(-1, 2)
        scores = cKDTree(shifts).query_ball_point(shifts, eps, return_length=True)
        top = int(scores.max())
        if top < best:
            continue
        if top > best:
            best, tied = top, []
        for k in np.flatnonzero(scores == top):
            tied.append((float(deg), int(k // n_b), int(k % n_b), shifts[k]))

    ties = _distinct_optima(tied, a, b, math.radians(float(step_deg)), eps, best)
    n_distinct_angles = len(angles) - (1 if math.isclose(angles[-1], 360.0) else 0)
    return SearchResult(
        transform=ties[0].transform,
        score=best,
        evaluations=n_a * n_b * len(angles),
        distinct_evaluations=n_a * n_b * n_distinct_angles,
        ties=tuple(ties),
    )


def _distinct_optima(
    tied: list[tuple[float, int, int, np.ndarray]], a: np.ndarray, b: np.ndarray,
    step_rad: float, eps: float, score: int,
) -> list[Placement]:
    """Group tied placements into optima (single linkage: within one angle step and ``eps`` at
    B's centroid) and return, per group in angle order, the placement whose coinciding pairs
    are closest (least squared distance): ω ties are broken by residual.

    Linking uses one KD-tree over (B's centroid image, scaled angle on the unit circle), so
    even maps with thousands of tied placements group in ``O(T log T)``."""
    placements = [Placement(Rigid2D(math.radians(deg), shift), (i, j), score)
                  for deg, i, j, shift in tied]
    centroid = b.mean(axis=0)
    where = np.array([p.transform.apply(centroid) for p in placements])
    theta = np.array([p.transform.theta for p in placements])
    # chord length on a circle of radius r ≈ r·Δθ; choose r so one step ≈ eps
    r = eps / max(step_rad, 1e-12)
    feats = np.column_stack([where, r * np.cos(theta), r * np.sin(theta)])
    pairs = cKDTree(feats).query_pairs(eps * math.sqrt(2) * (1 + 1e-9), output_type="ndarray")
    n = len(placements)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    tree = cKDTree(a)

    def residual(p: Placement) -> float:
        d, _ = tree.query(p.transform.apply(b), distance_upper_bound=eps)
        return float(np.sum(d[np.isfinite(d)] ** 2))

    groups: dict[int, list[Placement]] = {}
    for label, p in zip(labels, placements, strict=True):
        groups.setdefault(int(label), []).append(p)
    ordered = sorted(groups.values(), key=lambda g: min(q.transform.degrees % 360.0 for q in g))
    return [min(g, key=residual) for g in ordered]
