"""fusion: align two robots' topological maps (the paper's ICP-SVD and global merges)."""

from fusion.icp import IcpResult, icp_svd, svd_rotation
from fusion.paper import PaperExample, paper_example
from fusion.rigid import Rigid2D, wrap_angle
from fusion.search import Placement, SearchResult, exhaustive_search, similarity

__all__ = [
    "IcpResult",
    "PaperExample",
    "Placement",
    "Rigid2D",
    "SearchResult",
    "exhaustive_search",
    "icp_svd",
    "paper_example",
    "similarity",
    "svd_rotation",
    "wrap_angle",
]
