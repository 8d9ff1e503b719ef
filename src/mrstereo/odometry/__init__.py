"""Stereo visual odometry (a keyframe tracker refined over a window), trajectories and their metrics,
the given odometry fused with the visual one.

The odometry of a recording on disk is :func:`mrstereo.pipeline.odometry_from_manifest`.

Conventions: docs/conventions.md; user guide: docs/odometry.md.
"""
from .sequence import OdometryResult, visual_odometry
from .tracker import KEYFRAME, LOST, TRACKED, FrameEstimate, OdometryConfig, StereoOdometry

__all__ = ["OdometryConfig", "StereoOdometry", "FrameEstimate", "OdometryResult", "visual_odometry",
           "TRACKED", "KEYFRAME", "LOST"]
