"""ICP-SVD: the paper's point-set registration (Steps 1–4), faithful and fast.

The paper registers the path endpoints ``D`` of map B onto the fixed endpoints ``M`` of map A:

1. **Initialisation** ``R = I``, ``T = mean(M) - mean(D)`` (or a given ``init``).
2. **Correspondences and SVD**: each point of the moved ``D`` is paired with its nearest point
   of ``M``; both matched sets are centred, ``H = Σ M'_i D'_iᵀ = U Λ Vᵀ`` and ``R = U Vᵀ`` — with
   the sign of ``V``'s last column flipped when ``det(U Vᵀ) < 0``, so ``R`` is always a rotation
   (the paper only says "if det(X) = 1"); ``T = m - R d``.
3. ``D ← R D + T``.
4. Stop when the objective changes by less than ``tau`` between two iterations (``tau = 0.1``
   in the paper).

Where the paper is loose (PAPER_NOTES.md): eq. (4) as printed sums ``‖M_i - (R D_j + T)‖²``
over *all* pairs ``(i, j)``, which no longer depends on ``R`` once the centroids coincide. What
ICP minimises, and what is implemented, is the sum over nearest-neighbour pairs,
``f = Σ_j min_i ‖M_i - (R D_j + T)‖²``. ``tau`` is absolute and so depends on the map's units;
``rel_tol`` is a unit-free alternative.

Speed: in 2-D the SVD of Step 2 has a closed form, ``θ = atan2(Σ d'×m', Σ d'·m')``, identical to
the reflection-safe ``U Vᵀ`` (tests check it against :func:`svd_rotation`, the literal Step 2)
and free of LAPACK call overhead (:func:`rigid_fit`). Small sets find their nearest neighbours
by one compiled all-pairs pass (:func:`fusion._kernels.match_brute`), large ones by a KD-tree
(scipy's ``cKDTree``, one thread) built once on ``M`` (or passed in, ``tree``) and, with a gate,
searched no farther than it; both feed one loop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from fusion._kernels import match_brute
from fusion.inputs import check_point_count
from fusion.rigid import Rigid2D
from topo.validation import as_points, check_int, check_real

BRUTE_FORCE_MAX_PAIRS = 20_000
"""Below ``len(M) * len(D)`` of this many pairs, nearest neighbours are found by an all-pairs
distance matrix; above it by a KD-tree (crossover measured in ``benchmarks/icp_speed.py``)."""


@dataclass(frozen=True, slots=True, eq=False)
class IcpResult:
    """What :func:`icp_svd` found.

    Attributes:
        transform: the estimate ``p_M = R p_D + T`` (B onto A).
        iterations: number of Step 2–3 updates made.
        errors: the objective ``f`` (sum of squared nearest-neighbour distances, over the kept
            pairs) before the first update and after each one: ``iterations + 1`` values. This
            is the paper's Fig. 9 data (:attr:`deltas` is what that figure plots).
        converged: ``True`` if a stopping rule (``tau``, ``rel_tol`` or unchanged
            correspondences) fired before ``max_iter``.
        correspondences: ``(N_D,)`` index of the point of ``M`` paired with each point of ``D``
            at the final pose, ``-1`` where the pair was gated out by ``max_distance``/``trim``.
        degenerate: ``None``, or why the rotation is not determined by the data (coincident or
            collinear points, too few kept pairs). ``R`` is still a proper rotation then.
    """

    transform: Rigid2D
    iterations: int
    errors: np.ndarray
    converged: bool
    correspondences: np.ndarray
    degenerate: str | None = None

    @property
    def R(self) -> np.ndarray:  # noqa: N802 - the paper's name
        return self.transform.R

    @property
    def T(self) -> np.ndarray:  # noqa: N802 - the paper's name
        return self.transform.T

    @property
    def deltas(self) -> np.ndarray:
        """``|f_k - f_{k-1}|`` per iteration: the "error difference of two iterations" of Fig. 9."""
        return np.abs(np.diff(self.errors))

    @property
    def rmse(self) -> float:
        """Root mean square distance of the kept pairs at the final pose."""
        kept = int(np.count_nonzero(self.correspondences >= 0))
        return math.sqrt(self.errors[-1] / kept) if kept else math.inf


def svd_rotation(P: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """The paper's Step 2, literally: the rotation ``R`` best mapping centred ``P`` onto ``Q``.

    ``H = Σ Q'_i P'_iᵀ = U Λ Vᵀ``; ``R = U diag(1, det(U Vᵀ)) Vᵀ`` (reflection-safe). Kept as the
    reference that the closed form used by :func:`icp_svd` is tested against.
    """
    P0 = P - P.mean(axis=0)
    Q0 = Q - Q.mean(axis=0)
    U, _, Vt = np.linalg.svd(Q0.T @ P0)
    S = np.diag([1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    return U @ S @ Vt


def best_rotation_angle(P: np.ndarray, Q: np.ndarray) -> float:
    """Closed-form 2-D Step 2: the angle of the proper rotation best mapping centred ``P`` onto
    centred ``Q`` (equal to :func:`svd_rotation`; 0 when the cross-covariance vanishes)."""
    P0 = P - P.mean(axis=0)
    Q0 = Q - Q.mean(axis=0)
    s = float(np.sum(P0[:, 0] * Q0[:, 1] - P0[:, 1] * Q0[:, 0]))
    c = float(np.sum(P0 * Q0))
    return math.atan2(s, c)


def rigid_fit(P: np.ndarray, Q: np.ndarray,
              weights: np.ndarray | None = None) -> tuple[float, np.ndarray]:
    """``(theta, T)`` of the rigid motion ``q = R(theta) p + T`` best mapping the rows of ``P``
    onto those of ``Q`` in least squares (:func:`best_rotation_angle` about the centroids), each
    pair weighted by ``weights`` (non-negative, not all zero; ``None``: equally)."""
    if weights is None:
        theta = best_rotation_angle(P, Q)
        mp, mq = P.mean(axis=0), Q.mean(axis=0)
    else:
        w = weights / weights.sum()
        mp, mq = w @ P, w @ Q
        P0, Q0 = P - mp, Q - mq
        theta = math.atan2(float(w @ (P0[:, 0] * Q0[:, 1] - P0[:, 1] * Q0[:, 0])),
                           float(w @ (P0[:, 0] * Q0[:, 0] + P0[:, 1] * Q0[:, 1])))
    c, s = math.cos(theta), math.sin(theta)
    return theta, mq - np.array([[c, -s], [s, c]]) @ mp


def degeneracy(points: np.ndarray, name: str, rel: float = 1e-9) -> str | None:
    """``None`` if ``points`` spread in two dimensions; else why a rotation can't be fixed."""
    return moments_degeneracy(spread(points), name, rel)


def spread(P: np.ndarray) -> tuple[float, float, float, float, float]:
    """Centroid and principal second moments of the points ``P``: ``(cx, cy, big, small,
    scale)`` with ``big >= small`` the eigenvalues of the centred scatter matrix and
    ``scale = n · max|P|²``."""
    centre = P.mean(axis=0)
    X = P - centre
    small, big = np.linalg.eigvalsh(X.T @ X).tolist()
    top = float(np.abs(P).max())
    return float(centre[0]), float(centre[1]), big, small, len(P) * top * top


def moments_degeneracy(moments: tuple[float, ...], name: str, rel: float = 1e-9) -> str | None:
    """:func:`degeneracy` of points from their :func:`spread` moments."""
    _, _, big, small, scale = moments
    if big <= 1e-24 * scale + 1e-300:
        return f"all points of {name} coincide: rotation undetermined, identity used"
    if small <= rel * big:
        return f"{name} is collinear: rotation about the line is ambiguous"
    return None


class _BruteMatcher:
    """All-pairs nearest neighbours (small sets): one compiled pass,
    :func:`fusion._kernels.match_brute`."""

    def __init__(self, M: np.ndarray, D: np.ndarray, max_d2: float) -> None:
        self.M, self.D, self.max_d2 = M, D, max_d2

    def __call__(self, theta: float, t: np.ndarray, prev_idx: np.ndarray,
                 prev_keep: np.ndarray, idx: np.ndarray, d2: np.ndarray,
                 keep: np.ndarray) -> tuple[float, bool]:
        return match_brute(self.D, self.M, theta, t[0], t[1], self.max_d2, prev_idx, prev_keep,
                           idx, d2, keep)


class _TreeMatcher:
    """KD-tree nearest neighbours (built once on the fixed set ``M``; large sets).

    scipy's ``cKDTree`` on one thread, the squared distances recomputed from the pairs
    (``dx² + dy²``). One thread: a threaded KD-tree's workers wait for each other's cores on
    a busy machine, and a query then costs many times more. With a gate (``max_d2`` finite)
    the search stops just beyond it: a point of ``D`` with no point of ``M`` that near is
    left unpaired (index ``-1``) instead of searched for across the whole set — its pair
    would be gated out anyway, and the kept pairs, hence every update, are the same (the
    correspondences repeat as soon as the kept ones do, so ICP may stop one update earlier,
    on the same transform)."""

    def __init__(self, M: np.ndarray, D: np.ndarray, max_d2: float,
                 tree: cKDTree | None = None) -> None:
        self.tree = cKDTree(M) if tree is None else tree
        self.M, self.D, self.max_d2 = M, D, max_d2
        # a little beyond the gate, so that no pair within it is missed by rounding
        self.reach = math.sqrt(max_d2) * (1.0 + 1e-6) + 1e-12 if max_d2 < math.inf else math.inf

    def __call__(self, theta: float, t: np.ndarray, prev_idx: np.ndarray,
                 prev_keep: np.ndarray, idx: np.ndarray, d2: np.ndarray,
                 keep: np.ndarray) -> tuple[float, bool]:
        c, s = math.cos(theta), math.sin(theta)
        moved = self.D @ np.array([[c, s], [-s, c]]) + t
        if self.reach == math.inf:
            idx[:] = self.tree.query(moved, k=1, workers=1)[1]
            gap = moved - self.M[idx]
            np.add(gap[:, 0] * gap[:, 0], gap[:, 1] * gap[:, 1], out=d2)
        else:
            idx[:] = self.tree.query(moved, k=1, workers=1, distance_upper_bound=self.reach)[1]
            found = idx < len(self.M)
            idx[~found] = -1
            d2[~found] = math.inf
            gap = moved[found] - self.M[idx[found]]
            d2[found] = gap[:, 0] * gap[:, 0] + gap[:, 1] * gap[:, 1]
        np.less_equal(d2, self.max_d2, out=keep)
        same = np.array_equal(idx, prev_idx) and np.array_equal(keep, prev_keep)
        return float(d2[keep].sum()), bool(same)


def _check_options(tau, max_iter, rel_tol, max_distance, trim, init) -> None:
    if tau is not None:
        check_real(tau, "tau", low=0.0)
    check_int(max_iter, "max_iter", low=1)
    if rel_tol is not None:
        check_real(rel_tol, "rel_tol", low=0.0)
    if max_distance is not None:
        check_real(max_distance, "max_distance", low=0.0)
    if trim is not None:
        check_real(trim, "trim", low=0.0, high=1.0)
    if init is not None and not isinstance(init, Rigid2D):
        raise TypeError(f"init must be a fusion.Rigid2D or None, got {type(init).__name__}")


def icp_svd(
    M: np.ndarray,
    D: np.ndarray,
    tau: float | None = 0.1,
    max_iter: int = 100,
    init: Rigid2D | None = None,
    rel_tol: float | None = None,
    *,
    max_distance: float | None = None,
    trim: float | None = None,
    tree: cKDTree | None = None,
) -> IcpResult:
    """Register point set ``D`` onto the fixed point set ``M`` with the paper's ICP-SVD.

    Args:
        M: ``(N_M, 2)`` fixed points (the paper's M: map A's path endpoints), ``N_M >= 2``.
        D: ``(N_D, 2)`` moving points (the paper's D: map B's path endpoints), ``N_D >= 2``.
        tau: stop when ``|f_k - f_{k-1}| < tau`` (the paper's absolute threshold, 0.1); ``None``
            disables this rule.
        max_iter: most Step 2–3 updates; ``>= 1``.
        init: starting transform; ``None`` is the paper's Step 1 (``R = I``, centroids aligned).
        rel_tol: stop when ``|f_k - f_{k-1}| <= rel_tol * f_{k-1}``; ``None`` disables it.
        max_distance: pairs farther apart than this are left out of the update (correspondence
            gating, as Open3D's ``max_correspondence_distance``); ``None`` keeps all (the paper).
        trim: keep only this fraction of the closest pairs in each update (TrICP), in ``(0, 1]``;
            ``None`` keeps all (the paper).
        tree: a ``scipy.spatial.cKDTree`` already built on ``M`` (its default options), used
            instead of building one when the sets are large enough for a tree (results are the
            same): a caller aligning many sets onto one ``M`` builds it once.

    Whatever the rules, ICP also stops (converged) when the correspondences repeat, since the
    next update would then be the identity. Without ``max_distance``/``trim`` the objective
    never increases from one iteration to the next.

    Returns:
        :class:`IcpResult`.

    Raises:
        TypeError: ``M``/``D`` not numeric arrays, ``init`` not a ``Rigid2D``, ``tree`` not a
            ``cKDTree``.
        ValueError: shapes other than ``(N, 2)``, fewer than two points or more than
            :data:`fusion.inputs.MAX_POINTS`, NaN/inf, ``tau <= 0``,
            ``max_iter < 1``, ``rel_tol <= 0``, ``max_distance <= 0``, ``trim`` outside ``(0, 1]``,
            a ``tree`` not built on ``M``.

    Example (the paper's full-overlap case is recovered exactly):
        >>> import numpy as np
        >>> M = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [1.0, 5.0]])
        >>> truth = Rigid2D.from_degrees(17.44, (-36.461, -25.258))
        >>> res = icp_svd(M, truth.inverse().apply(M), tau=1e-9)
        >>> bool(res.transform.allclose(truth, atol=1e-6))
        True
    """
    M = check_point_count(as_points(M, "M", min_points=2), "M")
    D = check_point_count(as_points(D, "D", min_points=2), "D")
    _check_options(tau, max_iter, rel_tol, max_distance, trim, init)
    if tree is not None:
        _check_tree(tree, M)
    return icp_checked(M, D, tau, max_iter, init, rel_tol, max_distance, trim, tree)


def _check_tree(tree: object, M: np.ndarray) -> None:
    if not isinstance(tree, cKDTree):
        raise TypeError(f"tree must be a scipy.spatial.cKDTree or None, got "
                        f"{type(tree).__name__}")
    if tree.data.shape != M.shape or not np.array_equal(tree.data, M):
        raise ValueError(f"tree must be built on M: it holds {tree.data.shape[0]} points of "
                         f"dimension {tree.data.shape[1]}, M {M.shape[0]} other points")


def icp_checked(M: np.ndarray, D: np.ndarray, tau: float | None, max_iter: int,
                init: Rigid2D | None, rel_tol: float | None, max_distance: float | None,
                trim: float | None, tree: cKDTree | None = None) -> IcpResult:
    """:func:`icp_svd` without its argument checks, for callers whose inputs are valid by
    construction (``M``, ``D``: finite float64 ``(N, 2)`` arrays of at least 2 points; options
    within :func:`icp_svd`'s ranges; ``tree`` ``None`` or a ``cKDTree`` built on ``M``): the
    merge refines many small alignments, where the checks would cost a good part of each."""
    m_moments, d_moments = spread(M), spread(D)
    degenerate = moments_degeneracy(m_moments, "M") or moments_degeneracy(d_moments, "D")

    if init is None:  # Step 1: R = I, T = mean(M) - mean(D)
        theta = 0.0
        t = np.array([m_moments[0] - d_moments[0], m_moments[1] - d_moments[1]])
    else:
        theta, t = init.theta, init.T.copy()
    max_d2 = math.inf if max_distance is None else max_distance * max_distance
    n_trim = len(D) if trim is None else max(2, math.ceil(trim * len(D)))
    rule_tau = -1.0 if tau is None else tau  # the stopping rules, off when negative
    rule_rel = -1.0 if rel_tol is None else rel_tol
    if len(M) * len(D) <= BRUTE_FORCE_MAX_PAIRS:
        matcher = _BruteMatcher(M, D, max_d2)
    else:
        matcher = _TreeMatcher(M, D, max_d2, tree)
    theta, t, iterations, errors, converged, idx, keep, short = _icp_loop(
        matcher, M, D, theta, t, n_trim, rule_tau, rule_rel, max_iter)
    if short >= 0:
        degenerate = degenerate or (
            f"only {short} pair(s) within max_distance/trim: transform not updated")
    return IcpResult(transform=Rigid2D.trusted(theta, t), iterations=iterations, errors=errors,
                     converged=converged,
                     correspondences=np.where(keep, idx, -1).astype(np.int64),
                     degenerate=degenerate)


def _stops(prev: float, f: float, same: bool, tau: float, rel_tol: float) -> bool:
    """ICP's stopping rules after an update: the pairs repeat, or the objective changed from
    ``prev`` to ``f`` by less than ``tau`` or by at most ``rel_tol × prev`` (each rule off when
    negative)."""
    change = abs(prev - f)
    return same or (tau >= 0.0 and change < tau) or (rel_tol >= 0.0 and change <= rel_tol * prev)


def _icp_loop(match, M: np.ndarray, D: np.ndarray, theta: float, t: np.ndarray, n_trim: int,
              tau: float, rel_tol: float, max_iter: int):
    """:func:`icp_svd`'s loop (Steps 2–4) with the nearest-neighbour pass ``match``
    (:class:`_BruteMatcher` or :class:`_TreeMatcher`); ``tau`` / ``rel_tol`` negative when
    unused. Returns ``(theta, t, iterations, errors, converged, idx, keep, short)``: ``short``
    the number of pairs of a fit that had fewer than 2 (the loop stopped there), else ``-1``."""
    idx = np.empty(len(D), dtype=np.int64)
    d2 = np.empty(len(D))
    keep = np.empty(len(D), dtype=bool)
    prev_idx = np.full(len(D), -1, dtype=np.int64)
    prev_keep = np.zeros(len(D), dtype=bool)
    errors: list[float] = []
    converged = False
    iterations = 0
    short = -1
    while True:
        f, same = match(theta, t, prev_idx, prev_keep, idx, d2, keep)
        if n_trim < len(D):  # TrICP: only the n_trim closest pairs take part
            keep[np.argsort(d2, kind="stable")[n_trim:]] = False
            f = float(d2[keep].sum())
            same = np.array_equal(idx, prev_idx) and np.array_equal(keep, prev_keep)
        errors.append(f)
        if iterations and _stops(errors[-2], f, same, tau, rel_tol):
            converged = True
            break
        if iterations == max_iter:
            break
        n_fit = int(np.count_nonzero(keep))
        if n_fit < 2:
            short = n_fit
            break
        theta, t = rigid_fit(D[keep], M[idx[keep]])
        iterations += 1
        idx, prev_idx = prev_idx, idx
        keep, prev_keep = prev_keep, keep
        # the buffers swapped: prev_* now hold this iteration's pairs, idx/keep get overwritten
    return theta, t, iterations, np.asarray(errors), converged, idx, keep, short
