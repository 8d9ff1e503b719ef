"""Visual odometry of a recording: its pairs read, rectified and tracked in order.

Conventions: docs/conventions.md; user guide: docs/odometry.md.
"""
from __future__ import annotations

import os

import numpy as np

from ..camera import CameraMount, StereoCamera
from ..odometry import OdometryConfig, OdometryResult, visual_odometry
from ..recordings.layouts import read_recording
from ..recordings.manifest import Manifest, frame_pair

__all__ = ["odometry_from_manifest"]


def odometry_from_manifest(manifest, *, config: OdometryConfig | None = None, calibration: StereoCamera | None = None,
                           initial_pose: str = "given", progress: bool = False) -> OdometryResult:
    """Visual odometry of a recording (docs/dataset.md): rectified pairs, or raw ones rectified; its stamps.

    Parameters
    ----------
    manifest : Manifest or path
        A recording (a dataset folder, its manifest.yaml or a KITTI odometry folder).
    calibration : StereoCamera, optional
        Overrides the manifest's (the raw images are then rectified with it).
    initial_pose : {"given", "identity"}
        Start at the first frame's pose in the manifest, or at the origin.
    """
    if not isinstance(manifest, Manifest):
        if not isinstance(manifest, (str, os.PathLike)):
            raise TypeError(f"manifest must be a Manifest or a path, got {type(manifest).__name__}")
        manifest = read_recording(manifest)
    if initial_pose not in ("given", "identity"):
        raise ValueError(f"initial_pose must be 'given' or 'identity', got {initial_pose!r}")
    stereo = manifest.calibration if calibration is None else calibration
    prefer_raw = calibration is not None

    def pairs():
        for record in manifest.frames:
            left, right, rectified = frame_pair(record, prefer_raw=prefer_raw)
            if not rectified and not stereo.is_rectified:
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
