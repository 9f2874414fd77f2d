"""fusion: align two robots' topological maps (the paper's ICP-SVD and global merges) and decide
when to trust a merge (:class:`MergeRule`, :mod:`fusion.decision`)."""

from fusion.decision import MergeRule
from fusion.evaluation.synthetic import SyntheticConfig, SyntheticPair, generate_pairs, make_pair
from fusion.icp import IcpResult, icp_svd, svd_rotation
from fusion.paper import PaperExample, paper_example
from fusion.rigid import Rigid2D, wrap_angle
from fusion.search import Placement, SearchResult, exhaustive_search, similarity
from fusion.structural import (
    METHODS,
    MergeConfig,
    MergeEvidence,
    MergeResult,
    decide,
    fuse_maps,
    merge_maps,
)

__all__ = [
    "METHODS",
    "IcpResult",
    "MergeConfig",
    "MergeEvidence",
    "MergeResult",
    "MergeRule",
    "PaperExample",
    "Placement",
    "Rigid2D",
    "SearchResult",
    "SyntheticConfig",
    "SyntheticPair",
    "decide",
    "exhaustive_search",
    "fuse_maps",
    "generate_pairs",
    "icp_svd",
    "make_pair",
    "merge_maps",
    "paper_example",
    "similarity",
    "svd_rotation",
    "wrap_angle",
]
