"""Occupancy-grid mapping (paper section 5.2), ROS map files and path planning.

Conventions: docs/conventions.md. User guide: docs/mapping.md.
"""
from .figures import plot_map
from .fusion import FrameObservation, add_observation, fuse
from .grid import GridSpec
from .metrics import MapMetrics, cells_in_view, cells_near_path, map_metrics
from .occupancy import (GridUpdate, MappingConfig, OccupancyGrid, ViewCells, log_odds_from_probability,
                        probability_from_log_odds, view_cells)
from .planning import PlanResult, inflate_obstacles, plan_path
from .rosmap import RosMap, read_ros_map, write_ros_map

__all__ = ["GridSpec", "RosMap", "read_ros_map", "write_ros_map",
           "MappingConfig", "OccupancyGrid", "GridUpdate", "ViewCells", "view_cells", "log_odds_from_probability",
           "probability_from_log_odds", "MapMetrics", "map_metrics", "cells_near_path", "cells_in_view",
           "PlanResult", "plan_path", "inflate_obstacles", "plot_map", "FrameObservation", "fuse", "add_observation"]
