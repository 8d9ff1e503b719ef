"""3D from disparity: triangulation (eq. 14-16), ground plane, top view and laser scan.

Conventions: docs/conventions.md.
"""
from .triangulation import depth_m_from_disparity_px, disparity_px_from_depth_m, points_cam_from_disparity

__all__ = ["depth_m_from_disparity_px", "disparity_px_from_depth_m", "points_cam_from_disparity"]
