"""3D from disparity: triangulation (eq. 14-16), ground plane, top view and laser scan.

Conventions: docs/conventions.md.
"""
from .frames import T_robot_from_cam, T_world_from_robot, transform_points
from .triangulation import depth_m_from_disparity_px, disparity_px_from_depth_m, points_cam_from_disparity

__all__ = ["T_robot_from_cam", "T_world_from_robot", "transform_points", "depth_m_from_disparity_px", "disparity_px_from_depth_m", "points_cam_from_disparity"]
