"""Occupancy-grid mapping (paper section 5.2), ROS map files and path planning.

Conventions: docs/conventions.md.
"""
from .grid import GridSpec
from .rosmap import RosMap, read_ros_map, write_ros_map

__all__ = ["GridSpec", "RosMap", "read_ros_map", "write_ros_map"]
