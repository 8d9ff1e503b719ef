"""Visual odometry of a recording: its pairs read, rectified and tracked in order.

Conventions: docs/conventions.md; user guide: docs/odometry.md.
"""
from __future__ import annotations

import os

import numpy as np

from ..camera import CameraMount, StereoCamera
from ..odometry import OdometryConfig, OdometryResult, visual_odometry
from ..recordings.frames import FrameSource, RecordingSource
from ..recordings.layouts import read_recording
from ..recordings.manifest import Manifest

__all__ = ["odometry_from_manifest"]


def odometry_from_manifest(manifest, *, config: OdometryConfig | None = None, calibration: StereoCamera | None = None,
                           initial_pose: str = "given", progress: bool = False,
                           source: FrameSource | None = None) -> OdometryResult:
    """Visual odometry of a recording (docs/dataset.md): its pairs read one at a time, rectified; its stamps.

    Parameters
    ----------
    manifest : Manifest, FrameSource or path
        A recording (a dataset folder, its manifest.yaml, a KITTI odometry folder), or a source that
        knows its frames' poses up front (a :class:`~mrstereo.recordings.bag.BagSource`: read as a stream).
    calibration : StereoCamera, optional
        Overrides the recording's (the raw images are then rectified with it).
    initial_pose : {"given", "identity"}
        Start at the first frame's pose in the recording, or at the origin.
    source : FrameSource, optional
        Read the frames from this source instead of the manifest's files (the poses, pans and mount
        stay the manifest's: a bag's frames for a recording whose poses were moved, ``rebased``).
    """
    if isinstance(manifest, FrameSource):
        manifest, source = manifest_of(manifest), manifest if source is None else source
    elif not isinstance(manifest, Manifest):
        if not isinstance(manifest, (str, os.PathLike)):
            raise TypeError(f"manifest must be a Manifest, a FrameSource or a path, got {type(manifest).__name__}")
        manifest = read_recording(manifest)
    if initial_pose not in ("given", "identity"):
        raise ValueError(f"initial_pose must be 'given' or 'identity', got {initial_pose!r}")
    stereo = manifest.calibration if calibration is None else calibration
    if source is None:
        source = RecordingSource(manifest, prefer_raw=calibration is not None)

    def pairs():
        for frame in source:
            left, right = frame.left, frame.right
            if not frame.rectified and not stereo.is_rectified:
                left, right = stereo.rectify(left, right)
            yield left, right

    # no mount: a level camera on the floor (the base is the camera's REP 103 body frame)
    mount = manifest.mount or CameraMount.from_xyz_rpy((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    mounts = np.stack([mount.T_base_from_rectified(stereo.left.R, r.pan_rad) for r in manifest.frames])
    T0 = manifest.frames[0].T_world_from_base if initial_pose == "given" else np.eye(4)
    wrap = None
    if progress:
        from tqdm import tqdm

        def wrap(it):
            return tqdm(it, total=len(manifest.frames), desc="odometry", unit="frame")
    return visual_odometry(pairs(), stereo, T_base_from_cam=mounts, T_world_from_base0=T0, config=config,
                           stamps_s=manifest.stamps_s, progress=wrap)


def manifest_of(source: FrameSource) -> Manifest:
    """The :class:`~mrstereo.recordings.manifest.Manifest` of what a source knows before its frames are read
    (a recording's own; a bag's stamps, poses and pans without image files)."""
    manifest = getattr(source, "manifest", None)
    if not isinstance(manifest, Manifest):
        raise TypeError(f"a {type(source).__name__} does not know its frames up front: give a recording or a bag")
    return manifest
