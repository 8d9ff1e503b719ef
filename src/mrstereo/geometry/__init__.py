"""3D from disparity: triangulation (eq. 14-16), ground plane, obstacles, free-space boundary, top view,
laser scan, PLY; one stereo pair to obstacles and a scan: :mod:`.pair` (the map of many pairs:
:class:`mrstereo.StereoMapper`).

Conventions: docs/conventions.md.
"""
from .freespace import FreeSpaceBoundary, FreeSpaceConfig, free_space_boundary
from .ground import (GroundPlane, T_robot_from_cam_ground, estimate_ground, fit_ground_plane, fit_ground_v_disparity,
                     ground_from_mount, height_above_ground_m, v_disparity)
from .obstacles import ObstacleConfig, ObstacleResult, detect_obstacles, ground_for_frame, points_robot_from_disparity
from .ply import PointCloud, read_ply, write_ply
from .scan import (LaserScan, laser_scan_from_points, near_limit_range_m, plot_top_view, read_scan_json,
                   scan_angles_of_camera, top_view, write_scan_csv, write_scan_json)
from .triangulation import (depth_m_from_disparity_px, disparity_px_from_depth_m, points_cam_from_disparity,
                            points_cam_from_raw_px)

__all__ = [
    "depth_m_from_disparity_px",
    "disparity_px_from_depth_m", "points_cam_from_disparity", "points_cam_from_raw_px",
    "GroundPlane", "T_robot_from_cam_ground", "estimate_ground", "fit_ground_plane", "fit_ground_v_disparity",
    "ground_from_mount", "height_above_ground_m", "v_disparity",
    "ObstacleConfig", "ObstacleResult", "detect_obstacles", "ground_for_frame", "points_robot_from_disparity",
    "FreeSpaceConfig", "FreeSpaceBoundary", "free_space_boundary",
    "PointCloud", "read_ply", "write_ply",
    "LaserScan", "laser_scan_from_points", "near_limit_range_m", "plot_top_view", "read_scan_json",
    "scan_angles_of_camera", "top_view", "write_scan_csv", "write_scan_json",
]
