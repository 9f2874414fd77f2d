"""``merge_maps``: align two robots' topological maps from any relative pose, and know when not to.

The paper's ICP-SVD is local (it starts from ``R = I``), plain ICP is biased when maps overlap only
in part, and the paper's exhaustive search is slow and ambiguous. ``method="auto"`` is a global
merge built from the maps' structure:

1. **Node pairs** of each map: ends of a path, nodes two paths apart, and each node's ``knn``
   nearest nodes, at least ``min_pair_distance`` apart.
2. **2-point consensus**: every A pair and B pair whose lengths agree within ``pair_tolerance``
   and whose end kinds are compatible (:data:`KIND_COMPATIBLE`) gives one rigid hypothesis.
3. **Coarse score**: how many B nodes the hypothesis puts within ``coarse_tolerance`` of an A node
   of a compatible kind (a raster lookup per node, so thousands of hypotheses cost ~1 ms).
4. **Candidates**: the ``candidates`` best *distinct* hypotheses (non-maximum suppression on
   angle and on where B's centroid lands), each refined by gated nearest-compatible-node SVD fits.
5. **Evidence** per candidate (:class:`MergeEvidence`): mutual nearest matches within ``eps``
   (the paper's ω with a tolerance, one-to-one), matched paths (B paths whose ends match A nodes
   joined by a path, or two paths with a node between), and **conflicts** — junctions and corners
   of one map lying on a path of the other with no node there: the other robot was there and saw
   no such place. ``score = inliers + matched_edges − conflicts``.
6. **Refinement** of the best candidate with the paper's ICP-SVD (:func:`fusion.icp_svd`) gated at
   ``eps`` and trimmed (TrICP) to the estimated overlap, then a least-squares SVD fit on the
   final matches — what the oracle does with the true correspondences.
7. **Accept/reject** (:func:`decide`): enough inliers and matched paths, small residual, few
   conflicts, matched nodes not collinear, and a margin over the best *distinct* runner-up
   (a symmetric map has several equally good alignments: rejected as ambiguous).

The baselines share steps 5–7 so that their difference is the search alone: ``"paper_icp"`` is the
paper's ICP-SVD from its own initialisation (no refinement), ``"exhaustive"`` the paper's search
(:func:`fusion.exhaustive_search`, ``exhaustive_step_deg``) then the refinement, and
``"multistart_icp"`` the paper's ICP from ``multistart_starts`` rotations, best by score, then the
refinement. Thresholds were calibrated with ``python -m fusion.evaluate --synthetic`` (see the
issue report): false accepts on no-overlap pairs stay well under 1%.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from fusion import _merge_kernels as K
from fusion._config import config_from
from fusion.icp import best_rotation_angle, degeneracy, icp_svd
from fusion.rigid import Rigid2D, wrap_angle
from fusion.search import exhaustive_search
from topo._checks import check_int, check_real
from topo.graph import NodeKind, TopoMap

METHODS = ("auto", "paper_icp", "exhaustive", "multistart_icp")
"""Names accepted by :func:`merge_maps` ``method``."""

KIND_COMPATIBLE = np.zeros((len(NodeKind), len(NodeKind)), dtype=np.bool_)
"""``[kind_a, kind_b]``: may a node of A of ``kind_a`` be the same place as one of B of ``kind_b``?
Same kinds, and junction ↔ corner (a side branch one robot did not see). Dead ends match only dead
ends (a frontier dead end sits part-way along a corridor, not on a junction or corner)."""
for _a, _b in [(NodeKind.JUNCTION, NodeKind.JUNCTION), (NodeKind.CORNER, NodeKind.CORNER),
               (NodeKind.DEAD_END, NodeKind.DEAD_END), (NodeKind.JUNCTION, NodeKind.CORNER),
               (NodeKind.CORNER, NodeKind.JUNCTION)]:
    KIND_COMPATIBLE[_a, _b] = True
KIND_COMPATIBLE.setflags(write=False)

_KIND_PRIORITY = {NodeKind.JUNCTION: 0, NodeKind.CORNER: 1, NodeKind.DEAD_END: 2}


@dataclass(frozen=True, slots=True)
class MergeConfig:
    """Parameters of :func:`merge_maps` (lengths in metres, angles in degrees).

    Attributes:
        eps: match tolerance: nodes of A and moved B within ``eps`` may be the same place (the
            paper's ω tolerance); also the gate of the ICP refinement and the conflict distance.
        pair_tolerance: most difference between an A pair's and a B pair's length for a 2-point
            hypothesis (about 2σ of the difference for node noise σ = 0.15 and more).
        min_pair_distance: node pairs closer than this fix the angle too poorly to be used.
        knn: each node is also paired with its ``knn`` nearest nodes.
        coarse_tolerance: hit radius of the coarse hypothesis score.
        max_hypotheses: most hypotheses scored (the longest pairs are kept).
        candidates: distinct hypotheses refined and fully scored.
        distinct_angle_deg, distinct_distance: two alignments are distinct when their angles
            differ by at least ``distinct_angle_deg`` or they put B's centroid at least
            ``distinct_distance`` apart.
        icp_max_iter: iteration cap of the ICP-SVD refinement.
        min_inliers: accept only with at least this many matched nodes.
        min_matched_edges: ... and at least this many matched paths.
        max_rmse: ... a root-mean-square match distance at most this.
        min_consistency: ... ``inliers / (inliers + conflicts)`` at least this.
        max_runner_up: ... and the best distinct alternative scoring at most this fraction of the
            best (else the merge is ambiguous).
        multistart_starts: starting rotations of ``"multistart_icp"``.
        exhaustive_step_deg: rotation step of ``"exhaustive"`` (the paper's 2°).
    """

    eps: float = 0.5
    pair_tolerance: float = 0.7
    min_pair_distance: float = 1.0
    knn: int = 4
    coarse_tolerance: float = 1.0
    max_hypotheses: int = 4000
    candidates: int = 8
    distinct_angle_deg: float = 10.0
    distinct_distance: float = 1.5
    icp_max_iter: int = 30
    min_inliers: int = 5
    min_matched_edges: int = 3
    max_rmse: float = 0.6
    min_consistency: float = 0.6
    max_runner_up: float = 0.8
    multistart_starts: int = 12
    exhaustive_step_deg: float = 2.0

    def __post_init__(self) -> None:
        for name in ("eps", "pair_tolerance", "coarse_tolerance", "distinct_angle_deg",
                     "distinct_distance", "max_rmse"):
            check_real(getattr(self, name), name, low=0.0)
        check_real(self.min_pair_distance, "min_pair_distance", low=0.0, low_inclusive=True)
        check_real(self.exhaustive_step_deg, "exhaustive_step_deg", low=0.0, high=360.0)
        check_real(self.min_consistency, "min_consistency", low=0.0, low_inclusive=True,
                   high=1.0)
        check_real(self.max_runner_up, "max_runner_up", low=0.0, low_inclusive=True, high=1.0)
        for name, low in (("knn", 0), ("max_hypotheses", 1), ("candidates", 1),
                          ("icp_max_iter", 1), ("min_inliers", 2), ("min_matched_edges", 0),
                          ("multistart_starts", 1)):
            check_int(getattr(self, name), name, low=low)

    @classmethod
    def from_dict(cls, data: dict) -> MergeConfig:
        """From a dict of field values; unknown keys are a ``ValueError`` listing the allowed."""
        return config_from(cls, data, "MergeConfig")


@dataclass(frozen=True, slots=True)
class MergeEvidence:
    """What an alignment is worth (:func:`decide` turns it into accept/reject).

    Attributes:
        inliers: one-to-one matched nodes (mutually nearest, compatible kinds, within ``eps``).
        matched_edges: paths of B whose two ends match A nodes joined by a path (or by two).
        conflicts: junctions/corners of either map with no node of the other within ``eps``
            but lying on one of its paths (the other robot passed there and saw no place).
        crossings: paths of A and B crossing away from their ends (corridors cross at a
            junction, so a crossing without one is a contradiction).
        rmse: root-mean-square distance of the matched nodes (``inf`` without matches).
        collinear: the matched nodes of A lie on a line (rotation not determined).
        runner_up: score of the best alignment distinct from this one (``nan`` if the method
            does not look for one).
        hypotheses: how many rigid hypotheses the method scored.
    """

    inliers: int
    matched_edges: int
    conflicts: int
    crossings: int
    rmse: float
    collinear: bool
    runner_up: float = math.nan
    hypotheses: int = 0

    @property
    def score(self) -> float:
        """``inliers + matched_edges − conflicts − crossings``."""
        return float(self.inliers + self.matched_edges - self.conflicts - self.crossings)

    @property
    def consistency(self) -> float:
        """``inliers / (inliers + conflicts + crossings)`` (0 when all are 0)."""
        total = self.inliers + self.conflicts + self.crossings
        return self.inliers / total if total else 0.0


@dataclass(frozen=True, slots=True, eq=False)
class MergeResult:
    """What :func:`merge_maps` found.

    Attributes:
        transform: B → A motion (``p_A = R p_B + T``); the best estimate even when rejected.
        accepted: whether the merge passed :func:`decide`.
        score: :attr:`MergeEvidence.score` of ``transform``.
        matches: ``(K, 2)`` int node index pairs ``(a, b)`` matched at ``transform``.
        merged: if accepted, A with B moved onto it (matched nodes fused at their mean, other
            B nodes within ``eps`` of a node fused into it, paths united, polylines dropped);
            if rejected, ``map_a`` unchanged.
        method: the method used.
        time_s: wall time of the call in seconds.
        reason: why the merge was rejected (``None`` when accepted).
        evidence: the numbers behind the decision (``None`` for maps too small to try).
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


# --------------------------------------------------------------------------- preparation
@dataclass(frozen=True, slots=True, eq=False)
class _Prepared:
    xy: np.ndarray
    kinds: np.ndarray
    edges: np.ndarray
    near: np.ndarray  # (n, n) bool: joined by a path or by two
    pair_i: np.ndarray
    pair_j: np.ndarray
    pair_len: np.ndarray
    margin: np.ndarray  # (E,) fraction of each path within eps of its ends


def _prepare(m: TopoMap, cfg: MergeConfig) -> _Prepared:
    n = m.n_nodes
    xy = np.ascontiguousarray(m.xy, dtype=np.float64)
    adj = np.zeros((n, n), dtype=np.int32)
    adj[m.edges[:, 0], m.edges[:, 1]] = 1
    adj[m.edges[:, 1], m.edges[:, 0]] = 1
    near = (adj + adj @ adj) > 0
    dist = np.sqrt(((xy[:, None, :] - xy[None, :, :]) ** 2).sum(axis=-1))
    candidate = near.copy()
    k = min(cfg.knn, n - 1)
    if k > 0:
        nearest = np.argsort(dist, axis=1, kind="stable")[:, 1:k + 1]
        candidate[np.repeat(np.arange(n), k), nearest.ravel()] = True
    candidate |= candidate.T
    candidate &= dist >= max(cfg.min_pair_distance, 1e-9)
    i, j = np.nonzero(np.triu(candidate, 1))
    np.fill_diagonal(near, False)
    seg = dist[m.edges[:, 0], m.edges[:, 1]]
    margin = np.minimum(0.5, cfg.eps / np.maximum(seg, 1e-12))
    return _Prepared(xy, m.kinds.astype(np.int64), np.ascontiguousarray(m.edges, np.int64),
                     near, i.astype(np.int64), j.astype(np.int64), dist[i, j], margin)


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


def _evaluate(pa: _Prepared, pb: _Prepared, theta: float, t: np.ndarray,
              cfg: MergeConfig) -> _Eval:
    match_b, d2_b, conflicts, crossings = K.match_and_conflicts(
        pa.xy, pa.kinds, pa.edges, pb.xy, pb.kinds, pb.edges, float(theta), float(t[0]),
        float(t[1]), cfg.eps, KIND_COMPATIBLE, int(NodeKind.DEAD_END), pa.margin, pb.margin)
    b_idx = np.flatnonzero(match_b >= 0)
    matches = np.column_stack([match_b[b_idx], b_idx]).astype(np.int64)
    ends = match_b[pb.edges] if len(pb.edges) else np.empty((0, 2), dtype=np.int64)
    both = (ends >= 0).all(axis=1)
    matched_edges = int(pa.near[ends[both, 0], ends[both, 1]].sum())
    rmse = math.sqrt(float(d2_b[b_idx].mean())) if len(b_idx) else math.inf
    collinear = len(b_idx) < 3 or degeneracy(pa.xy[matches[:, 0]], "matches", 1e-3) is not None
    ev = MergeEvidence(len(b_idx), matched_edges, int(conflicts), int(crossings), rmse,
                       collinear)
    return _Eval(float(wrap_angle(theta)), np.asarray(t, dtype=np.float64), matches, ev)


def _least_squares(pa: _Prepared, pb: _Prepared, matches: np.ndarray) -> tuple[float, np.ndarray]:
    """The SVD fit of B's matched nodes onto A's (what the oracle does with true matches)."""
    P, Q = pb.xy[matches[:, 1]], pa.xy[matches[:, 0]]
    theta = best_rotation_angle(P, Q)
    c, s = math.cos(theta), math.sin(theta)
    return theta, Q.mean(axis=0) - np.array([[c, -s], [s, c]]) @ P.mean(axis=0)


def _polish(pa: _Prepared, pb: _Prepared, start: _Eval, cfg: MergeConfig) -> _Eval:
    """Trimmed, gated ICP-SVD from ``start``, then the least-squares fit on the matches; the
    best of the three by score (then residual)."""
    best = start
    if start.evidence.inliers >= 2:
        trim = min(1.0, max(start.evidence.inliers / len(pb.xy), 2.0 / len(pb.xy)))
        icp = icp_svd(pa.xy, pb.xy, tau=None, rel_tol=1e-9, max_iter=cfg.icp_max_iter,
                      init=start.transform, max_distance=cfg.eps, trim=trim)
        ev = _evaluate(pa, pb, icp.transform.theta, icp.transform.T, cfg)
        best = max((best, ev), key=_Eval.key)
    if best.evidence.inliers >= 2:
        theta, t = _least_squares(pa, pb, best.matches)
        best = max((best, _evaluate(pa, pb, theta, t, cfg)), key=_Eval.key)
    return best


def _centroid_image(theta: np.ndarray, tx: np.ndarray, ty: np.ndarray,
                    centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c, s = np.cos(theta), np.sin(theta)
    return c * centre[0] - s * centre[1] + tx, s * centre[0] + c * centre[1] + ty


def _runner_up(best: _Eval, others: list[_Eval], centre: np.ndarray, cfg: MergeConfig) -> float:
    """Score of the best alignment in ``others`` distinct from ``best`` (0 if none)."""
    p = best.transform.apply(centre)
    min_angle = math.radians(cfg.distinct_angle_deg)
    scores = [
        o.evidence.score for o in others
        if abs(wrap_angle(o.theta - best.theta)) >= min_angle
        or float(np.linalg.norm(o.transform.apply(centre) - p)) >= cfg.distinct_distance
    ]
    return max(scores, default=0.0)


# ------------------------------------------------------------------------------- methods
def _hit_grid(pa: _Prepared, tol: float, path_tol: float) -> tuple[np.ndarray, float, float, float]:
    """The bit raster of A scored by :func:`fusion._merge_kernels.raster_scores`: cells within
    ~``tol`` of an A node compatible with each B kind, of any A node, within ~``path_tol`` of
    an A path. Cells are ``tol / 2`` wide."""
    cell = tol / 2.0
    lo = pa.xy.min(axis=0) - tol - cell
    shape = (np.ceil((pa.xy.max(axis=0) - lo + tol) / cell) + 2).astype(np.int64)
    grid = np.zeros((shape[1], shape[0]), dtype=np.uint8)

    def mark(points: np.ndarray, radius: float, bit: int) -> None:
        r = max(0, math.ceil(radius / cell - 0.5))
        oy, ox = np.mgrid[-r:r + 1, -r:r + 1]
        disk = (ox ** 2 + oy ** 2) * cell * cell <= (radius + 0.5 * cell) ** 2
        c = np.floor((points - lo) / cell).astype(np.int64)
        iy = np.clip((c[:, 1, None] + oy[disk][None, :]).ravel(), 0, shape[1] - 1)
        ix = np.clip((c[:, 0, None] + ox[disk][None, :]).ravel(), 0, shape[0] - 1)
        grid[iy, ix] |= np.uint8(1 << bit)

    for kb in range(len(NodeKind)):
        mark(pa.xy[KIND_COMPATIBLE[pa.kinds, kb]], tol, kb)
    mark(pa.xy, tol, K.NEAR_ANY_NODE)
    if len(pa.edges):
        u, v = pa.xy[pa.edges[:, 0]], pa.xy[pa.edges[:, 1]]
        steps = np.maximum(1, np.ceil(np.linalg.norm(v - u, axis=1) / (0.5 * cell))).astype(int)
        f = np.concatenate([np.arange(k + 1) / k for k in steps])
        e = np.repeat(np.arange(len(u)), steps + 1)
        mark(u[e] + f[:, None] * (v[e] - u[e]), path_tol, K.ON_PATH)
    return grid, float(lo[0]), float(lo[1]), 1.0 / cell


def _auto(pa: _Prepared, pb: _Prepared, cfg: MergeConfig) -> _Eval | str:
    b_i = np.concatenate([pb.pair_i, pb.pair_j])
    b_j = np.concatenate([pb.pair_j, pb.pair_i])
    b_len = np.concatenate([pb.pair_len, pb.pair_len])
    order = np.argsort(b_len, kind="stable")
    theta, tx, ty, weight = K.pair_hypotheses(
        pa.xy, pa.kinds, pa.pair_i, pa.pair_j, pa.pair_len, pb.xy, pb.kinds, b_i[order],
        b_j[order], b_len[order], cfg.pair_tolerance, KIND_COMPATIBLE)
    n_hyp = len(theta)
    if n_hyp == 0:
        return "no pair of nodes of B matches a pair of A in length and kinds"
    if n_hyp > cfg.max_hypotheses:
        keep = np.sort(np.argsort(-weight, kind="stable")[:cfg.max_hypotheses])
        theta, tx, ty = theta[keep], tx[keep], ty[keep]
    grid, x0, y0, inv_cell = _hit_grid(pa, cfg.coarse_tolerance, cfg.eps)
    coarse = K.raster_scores(theta, tx, ty, pb.xy, pb.kinds, grid, x0, y0, inv_cell,
                             int(NodeKind.DEAD_END))
    centre = pb.xy.mean(axis=0)
    cx, cy = _centroid_image(theta, tx, ty, centre)
    ranked = np.argsort(-coarse, kind="stable")
    chosen = K.select_distinct(ranked, theta, cx, cy, math.radians(cfg.distinct_angle_deg),
                               cfg.distinct_distance, cfg.candidates)
    th, txc, tyc = theta[chosen].copy(), tx[chosen].copy(), ty[chosen].copy()
    gates = np.array([cfg.coarse_tolerance, 0.5 * (cfg.coarse_tolerance + cfg.eps), cfg.eps])
    K.refine_batch(th, txc, tyc, pa.xy, pa.kinds, pb.xy, pb.kinds, KIND_COMPATIBLE, gates)
    evals = [_evaluate(pa, pb, th[k], np.array([txc[k], tyc[k]]), cfg) for k in range(len(th))]
    first = max(evals, key=_Eval.key)
    best = _polish(pa, pb, first, cfg)
    runner = _runner_up(best, evals, centre, cfg)
    return _with(best, runner_up=runner, hypotheses=n_hyp)


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


def _exhaustive(map_a: TopoMap, map_b: TopoMap, pa: _Prepared, pb: _Prepared,
                cfg: MergeConfig) -> _Eval:
    found = exhaustive_search(map_a if len(map_a.endpoints()) else map_a.xy,
                              map_b if len(map_b.endpoints()) else map_b.xy,
                              step_deg=cfg.exhaustive_step_deg, eps=cfg.eps)
    placements = [_evaluate(pa, pb, p.transform.theta, p.transform.T, cfg) for p in found.ties]
    best = _polish(pa, pb, placements[0], cfg)
    runner = _runner_up(best, placements[1:], pb.xy.mean(axis=0), cfg)
    return _with(best, runner_up=runner, hypotheses=found.evaluations)


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
    best = _polish(pa, pb, max(evals, key=_Eval.key), cfg)
    runner = _runner_up(best, evals, pb.xy.mean(axis=0), cfg)
    return _with(best, runner_up=runner, hypotheses=cfg.multistart_starts)


# ------------------------------------------------------------------------------ decision
def decide(evidence: MergeEvidence, config: MergeConfig | None = None) -> str | None:
    """The accept rule: ``None`` to accept, else the reasons to reject (``"; "``-joined).

    Rejects when: fewer than ``min_inliers`` matched nodes or ``min_matched_edges`` matched
    paths; ``rmse > max_rmse``; ``consistency < min_consistency``; the matched nodes are
    collinear; or a distinct alternative scores more than ``max_runner_up`` × the best
    (ambiguous: symmetric maps, repeated corridors).
    """
    cfg = config_from(MergeConfig, config)
    e = evidence
    reasons = []
    if e.inliers < cfg.min_inliers:
        reasons.append(f"too few matched nodes: {e.inliers} < min_inliers={cfg.min_inliers}")
    if e.matched_edges < cfg.min_matched_edges:
        reasons.append(f"too few matched paths: {e.matched_edges} < "
                       f"min_matched_edges={cfg.min_matched_edges}")
    if e.rmse > cfg.max_rmse:
        reasons.append(f"residual too large: rmse {e.rmse:.3f} m > max_rmse={cfg.max_rmse}")
    if e.consistency < cfg.min_consistency:
        reasons.append(f"too many conflicts: {e.conflicts} conflicting nodes for {e.inliers} "
                       f"matches (consistency {e.consistency:.2f} < "
                       f"min_consistency={cfg.min_consistency})")
    if e.collinear:
        reasons.append("matched nodes are collinear: rotation not determined")
    if e.score > 0 and e.runner_up > cfg.max_runner_up * e.score:
        reasons.append(f"ambiguous: a distinct alignment scores {e.runner_up:g} against "
                       f"{e.score:g} (> max_runner_up={cfg.max_runner_up})")
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
    rows = [matches[:, 0], matches[:, 1] + n_a]
    close = cKDTree(xy).query_pairs(eps, output_type="ndarray")
    links = np.concatenate([np.column_stack(rows), close]) if len(close) else np.column_stack(rows)
    n = len(xy)
    graph = coo_matrix((np.ones(len(links)), (links[:, 0], links[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    first = np.full(label.max() + 1, n, dtype=np.int64)
    np.minimum.at(first, label, np.arange(n))
    order = np.argsort(first, kind="stable")
    new_id = np.empty_like(order)
    new_id[order] = np.arange(len(order))
    node = new_id[label]
    kinds = np.concatenate([map_a.kinds, map_b.kinds]).astype(np.int64)
    rank = np.array([_KIND_PRIORITY[NodeKind(k)] for k in range(len(NodeKind))])[kinds]
    best = np.full(len(order), 99, dtype=np.int64)
    np.minimum.at(best, node, rank)
    by_rank = np.array(sorted(_KIND_PRIORITY, key=_KIND_PRIORITY.get), dtype=np.int64)
    out_xy = xy[first[order]]
    edges = np.concatenate([map_a.edges, map_b.edges + n_a]).astype(np.int64)
    lengths = np.concatenate([map_a.lengths, map_b.lengths])
    e = np.sort(node[edges], axis=1) if len(edges) else np.empty((0, 2), dtype=np.int64)
    keep = e[:, 0] != e[:, 1]
    e, lengths = e[keep], lengths[keep]
    _, uniq = np.unique(e, axis=0, return_index=True)
    uniq = np.sort(uniq)
    e, lengths = e[uniq], lengths[uniq]
    straight = np.linalg.norm(out_xy[e[:, 0]] - out_xy[e[:, 1]], axis=1) if len(e) else lengths
    return TopoMap.from_arrays(out_xy, e, by_rank[best], np.maximum(lengths, straight))


# ---------------------------------------------------------------------------- public entry
def _check_map(value: object, name: str) -> TopoMap:
    if not isinstance(value, TopoMap):
        raise TypeError(f"{name} must be a topo.TopoMap, got {type(value).__name__}")
    if not np.all(np.isfinite(value.xy)):
        row = int(np.argwhere(~np.isfinite(value.xy))[0, 0])
        raise ValueError(f"{name}.xy must be finite, got {value.xy[row].tolist()} at node {row}")
    return value


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
    cfg = config_from(MergeConfig, config)

    small = [f"{name} has {m.n_nodes} node(s); at least 3 are needed"
             for name, m in (("map_a", map_a), ("map_b", map_b)) if m.n_nodes < 3]
    if small:
        return MergeResult(Rigid2D.identity(), False, 0.0, np.empty((0, 2), dtype=np.int64),
                           map_a, method, time.perf_counter() - start, "; ".join(small))
    pa, pb = _prepare(map_a, cfg), _prepare(map_b, cfg)
    if method == "auto":
        found = _auto(pa, pb, cfg)
    elif method == "paper_icp":
        found = _paper_icp(map_a, map_b, pa, pb, cfg)
    elif method == "exhaustive":
        found = _exhaustive(map_a, map_b, pa, pb, cfg)
    else:
        found = _multistart(map_a, map_b, pa, pb, cfg)
    if isinstance(found, str):
        return MergeResult(Rigid2D.identity(), False, 0.0, np.empty((0, 2), dtype=np.int64),
                           map_a, method, time.perf_counter() - start, found)
    reason = decide(found.evidence, cfg)
    transform = found.transform
    merged = map_a if reason else fuse_maps(map_a, map_b, transform, found.matches, cfg.eps)
    return MergeResult(transform, reason is None, found.evidence.score, found.matches, merged,
                       method, time.perf_counter() - start, reason, found.evidence)
