"""topo: occupancy grids, topological maps and their extraction (pure numpy/scipy/numba)."""

from topo.extract import ExtractConfig, extract_topomap
from topo.graph import KIND_LABELS, NodeKind, TopoMap, kinds_from_degree
from topo.grid import CellState, OccupancyGrid, SensorModel
from topo.maps import FloorPlan, MapFileError, load_dungeon_png, load_floor_plan, load_ros_map

__all__ = [
    "KIND_LABELS",
    "CellState",
    "ExtractConfig",
    "FloorPlan",
    "MapFileError",
    "NodeKind",
    "OccupancyGrid",
    "SensorModel",
    "TopoMap",
    "extract_topomap",
    "kinds_from_degree",
    "load_dungeon_png",
    "load_floor_plan",
    "load_ros_map",
]
