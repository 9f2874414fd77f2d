"""The baseline methods of :func:`fusion.merge_maps`, sharing ``"auto"``'s refinement and
scoring so that they differ by their search alone: ``"paper_icp"`` (the paper's ICP-SVD from
its own start), ``"exhaustive"`` (the paper's search) and ``"multistart_icp"``."""

from __future__ import annotations

import math

import numpy as np

from fusion.icp import icp_svd
from fusion.merge.config import MergeConfig
from fusion.merge.evidence import Evaluated, evaluate, with_evidence
from fusion.merge.hypotheses import runner_up_of
from fusion.merge.prepare import Prepared
from fusion.merge.refine import polish
from fusion.rigid import Rigid2D
from fusion.search import exhaustive_search
from topo.graph import TopoMap


def _points(m: TopoMap) -> np.ndarray:
    """The paper's point set (path endpoints), or all nodes when fewer than 2 end paths."""
    pts = m.endpoints()
    return pts if len(pts) >= 2 else m.xy


def paper_icp(map_a: TopoMap, map_b: TopoMap, pa: Prepared, pb: Prepared,
              cfg: MergeConfig) -> Evaluated:
    res = icp_svd(_points(map_a), _points(map_b), tau=0.1, max_iter=100)
    return with_evidence(evaluate(pa, pb, res.transform.theta, res.transform.T, cfg), hypotheses=1)


def best_polished(pa: Prepared, pb: Prepared, starts: list[Evaluated], cfg: MergeConfig,
                  top: int = 4) -> Evaluated:
    """Polish the ``top`` best-scoring ``starts`` (:func:`polish`); the best of them, with the
    runner-up among the other polished ones and the remaining starts."""
    ranked = sorted(starts, key=Evaluated.key, reverse=True)
    polished = [polish(pa, pb, e, cfg) for e in ranked[:top]]
    order = sorted(range(len(polished)), key=lambda i: polished[i].key(), reverse=True)
    best = polished[order[0]]
    others = [polished[i] for i in order[1:]] + ranked[top:]
    return with_evidence(best, runner_up=runner_up_of(best, others, pb.xy, cfg))


def exhaustive(map_a: TopoMap, map_b: TopoMap, pa: Prepared, pb: Prepared,
               cfg: MergeConfig) -> Evaluated:
    found = exhaustive_search(map_a if len(map_a.endpoints()) else map_a.xy,
                              map_b if len(map_b.endpoints()) else map_b.xy,
                              step_deg=cfg.exhaustive_step_deg, eps=cfg.eps)
    ties = [evaluate(pa, pb, p.transform.theta, p.transform.T, cfg) for p in found.ties]
    return with_evidence(best_polished(pa, pb, ties, cfg, top=8), hypotheses=found.evaluations)


def multistart_icp(map_a: TopoMap, map_b: TopoMap, pa: Prepared, pb: Prepared,
                   cfg: MergeConfig) -> Evaluated:
    M, D = _points(map_a), _points(map_b)
    evals = []
    for k in range(cfg.multistart_starts):
        theta = 2 * math.pi * k / cfg.multistart_starts
        c, s = math.cos(theta), math.sin(theta)
        start = Rigid2D(theta, M.mean(axis=0) - np.array([[c, -s], [s, c]]) @ D.mean(axis=0))
        res = icp_svd(M, D, tau=0.1, max_iter=100, init=start)
        evals.append(evaluate(pa, pb, res.transform.theta, res.transform.T, cfg))
    return with_evidence(best_polished(pa, pb, evals, cfg), hypotheses=cfg.multistart_starts)
