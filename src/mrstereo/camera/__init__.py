"""Camera model (paper eq. 1-3), ROS camera_info files and rectification.

Conventions: docs/conventions.md.
"""
from .camera_info import (CameraInfo, RigMount, StereoCamera, read_camera_info, read_stereo,
                          write_camera_info, write_stereo)
from .model import (Camera, PaperCamera, distort_normalized, euler_from_rotation,
                    normalized_from_pixels, pixels_from_normalized, project_points,
                    rotation_from_euler, undistort_normalized)
from .rectification import FusielloRectification, fusiello_rotation, rectify_fusiello

__all__ = [
    "Camera", "PaperCamera", "CameraInfo", "RigMount", "StereoCamera", "read_camera_info",
    "write_camera_info", "read_stereo", "write_stereo", "distort_normalized", "undistort_normalized",
    "project_points", "pixels_from_normalized", "normalized_from_pixels", "rotation_from_euler",
    "euler_from_rotation",
]
__all__ += ["FusielloRectification", "fusiello_rotation", "rectify_fusiello"]
