"""Camera models (paper eq. 1-3 and the ROS models), calibration files, rectification, the mount.

Conventions: docs/conventions.md.
"""
from .camera_info import CameraInfo, StereoCamera, read_camera_info, stereo_projections, write_camera_info, write_stereo
from .formats import read_stereo
from .model import (DISTORTION_MODELS, Camera, DistortionModel, PaperCamera, distort_normalized, get_distortion_model,
                    normalized_from_pixels, pixels_from_normalized, project_points, undistort_normalized)
from .mount import CameraMount, mount_entry, read_mount_entry
from .rectification import (MIN_BASELINE_M, FusielloRectification, check_baseline, check_not_swapped,
                            fusiello_rotation, raw_px_from_rectified_px, rectified_px_from_raw_px, rectify_fusiello)

__all__ = [
    "Camera", "PaperCamera", "CameraInfo", "CameraMount", "StereoCamera", "read_camera_info",
    "write_camera_info", "read_stereo", "write_stereo", "stereo_projections", "distort_normalized",
    "undistort_normalized", "project_points", "pixels_from_normalized", "normalized_from_pixels",
    "DistortionModel", "DISTORTION_MODELS", "get_distortion_model", "MIN_BASELINE_M",
    "mount_entry", "read_mount_entry",
    "FusielloRectification", "fusiello_rotation", "rectify_fusiello", "check_not_swapped",
    "check_baseline", "rectified_px_from_raw_px", "raw_px_from_rectified_px",
]
