"""Stereo visual odometry, trajectories and their metrics, scan-to-map alignment.

Conventions: docs/conventions.md; user guide: docs/odometry.md.
"""
from .run import OdometryResult, T_base_from_cam_of, odometry_from_manifest, visual_odometry
from .tracker import KEYFRAME, LOST, TRACKED, FrameEstimate, OdometryConfig, StereoOdometry

__all__ = ["OdometryConfig", "StereoOdometry", "FrameEstimate", "OdometryResult", "visual_odometry",
           "odometry_from_manifest", "T_base_from_cam_of", "TRACKED", "KEYFRAME", "LOST"]
