"""topo: occupancy grids, topological maps and their extraction (pure numpy/scipy)."""

from topo.graph import KIND_LABELS, NodeKind, TopoMap, kinds_from_degree

__all__ = ["KIND_LABELS", "NodeKind", "TopoMap", "kinds_from_degree"]
