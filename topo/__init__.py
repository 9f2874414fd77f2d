"""topo: occupancy grids, topological maps and their extraction (pure numpy/scipy/numba)."""

from topo.graph import KIND_LABELS, NodeKind, TopoMap, kinds_from_degree
from topo.grid import CellState, OccupancyGrid, SensorModel
from topo.maps import FloorPlan, MapFileError, load_dungeon_png, load_floor_plan, load_ros_map

__all__ = [
    "KIND_LABELS",
    "CellState",
    "FloorPlan",
    "MapFileError",
    "NodeKind",
    "OccupancyGrid",
    "SensorModel",
    "TopoMap",
    "kinds_from_degree",
    "load_dungeon_png",
    "load_floor_plan",
    "load_ros_map",
]
