"""mrstereo: two cameras in, a map of where a mobile robot can drive out.

Implements "Multi-Range Approach of Stereo Vision for Mobile Robot Navigation in
Uncertain Environments" (GA calibration, multi-range NSSD matching, ground
suppression, occupancy grids) and goes beyond it. Conventions (units, frames,
disparity sign): docs/conventions.md.
"""
from __future__ import annotations

from ._interrupt import guard_start

guard_start()                        # mrstereo's own process: Ctrl-C from here on is one line

from ._limits import _hand_image_limit_to_opencv  # noqa: E402

__version__ = "0.1.0"

_hand_image_limit_to_opencv()        # before anything loads OpenCV

# The public objects of the README and docs/api.md, imported lazily so that ``import mrstereo`` stays
# cheap (numba kernels compile only when a stage is used).
_LAZY = {
    # a map from stereo pairs
    "StereoMapper": "mrstereo.pipeline.mapper", "PipelineConfig": "mrstereo.pipeline.mapper",
    "MappedFrame": "mrstereo.pipeline.mapper",
    "build_map": "mrstereo.pipeline.run", "MapRun": "mrstereo.evaluation.outputs",
    "write_map_outputs": "mrstereo.evaluation.outputs",
    "run_live": "mrstereo.pipeline.live", "LiveConfig": "mrstereo.pipeline.live",
    "run_batch": "mrstereo.pipeline.batch",
    # the stages
    "StereoCamera": "mrstereo.camera", "CameraMount": "mrstereo.camera", "read_stereo": "mrstereo.camera",
    "compute_disparity": "mrstereo.matching",
    "obstacles_from_pair": "mrstereo.geometry.pair", "scan_from_pair": "mrstereo.geometry.pair",
    "FloorVote": "mrstereo.geometry.floor",
    "OccupancyGrid": "mrstereo.mapping", "GridSpec": "mrstereo.mapping", "MappingConfig": "mrstereo.mapping",
    "read_ros_map": "mrstereo.mapping", "write_ros_map": "mrstereo.mapping",
    "StereoOdometry": "mrstereo.odometry", "OdometryConfig": "mrstereo.odometry",
    "visual_odometry": "mrstereo.odometry",
    # recordings
    "StereoFrame": "mrstereo.recordings.sources", "FrameSource": "mrstereo.recordings.sources",
    "open_source": "mrstereo.recordings.sources",
    "read_recording": "mrstereo.recordings.layouts", "open_recording": "mrstereo.recordings.layouts",
    "read_image": "mrstereo.io",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str):
    if name in _LAZY:
        import importlib
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'mrstereo' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
