"""fusion: align two robots' topological maps (the paper's ICP-SVD and global merges)."""

from fusion.icp import IcpResult, icp_svd, svd_rotation
from fusion.rigid import Rigid2D, wrap_angle

__all__ = ["IcpResult", "Rigid2D", "icp_svd", "svd_rotation", "wrap_angle"]
