"""Recordings: what the pipeline reads (frames, stamps, poses, calibration, mount) and who writes it.

The dataset manifest (:mod:`.manifest`), ROS 1/2 bags (:mod:`.bag`), the KITTI odometry layout
(:mod:`.kitti`), the reader of whichever of these a path holds (:mod:`.layouts`) and the public
sample scenes (:mod:`.samples`). Conventions: docs/conventions.md; the manifest: docs/dataset.md.
"""
from .kitti import read_kitti_odometry
from .layouts import read_recording
from .manifest import MANIFEST_NAME, FrameRecord, Manifest, frame_pair, read_manifest, write_manifest

__all__ = ["MANIFEST_NAME", "FrameRecord", "Manifest", "frame_pair", "read_manifest", "write_manifest",
           "read_kitti_odometry", "read_recording"]
