"""Recordings: what the pipeline reads (frames, stamps, poses, calibration, mount) and who writes it.

A recording is a :class:`~.sources.FrameSource` of in-memory :class:`~.sources.StereoFrame`:
:func:`open_recording` opens any layout (a dataset manifest, KITTI odometry, KITTI raw, EuRoC/ASL,
image folders, ROS 1/2 bags read message by message); :func:`read_recording` gives the
:class:`~.manifest.Manifest` (file paths) of the folder layouts. The public sample scenes:
:mod:`.samples`. Conventions: docs/conventions.md; the layouts: docs/dataset.md.
"""
from .kitti import read_kitti_odometry
from .kitti_raw import read_kitti_raw
from .layouts import open_recording, read_recording
from .manifest import MANIFEST_NAME, FrameRecord, Manifest, frame_pair, read_manifest, write_manifest
from .frames import FrameSource, StereoFrame

__all__ = ["MANIFEST_NAME", "FrameRecord", "Manifest", "frame_pair", "read_manifest", "write_manifest",
           "read_kitti_odometry", "read_kitti_raw", "read_recording", "open_recording", "FrameSource", "StereoFrame"]
