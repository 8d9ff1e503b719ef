"""Stereo visual odometry (a keyframe tracker refined over a window), trajectories and their metrics,
the given odometry fused with the visual one.

The odometry of a recording on disk is :func:`mrstereo.pipeline.odometry_from_manifest`.

Conventions: docs/conventions.md; user guide: docs/odometry.md.
"""
from .fusion import FusedOdometry, FusionConfig, fuse_odometry
from .sequence import OdometryResult, visual_odometry
from .tracker import KEYFRAME, LOST, TRACKED, FrameEstimate, OdometryConfig, StereoOdometry
from .window import WindowResult, refine_window

__all__ = ["OdometryConfig", "StereoOdometry", "FrameEstimate", "OdometryResult", "visual_odometry",
           "TRACKED", "KEYFRAME", "LOST", "refine_window", "WindowResult", "FusionConfig", "FusedOdometry",
           "fuse_odometry"]
