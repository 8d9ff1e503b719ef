"""Visual odometry of a recording: its pairs read, rectified and tracked in order by a
:class:`~mrstereo.pipeline.mapper.StereoMapper` that tracks only.

Conventions: docs/conventions.md; user guide: docs/odometry.md.
"""
from __future__ import annotations

import os
from dataclasses import replace

import numpy as np

from ..camera import StereoCamera
from ..odometry import OdometryConfig, OdometryResult
from ..recordings.frames import FrameSource, RecordingSource
from ..recordings.layouts import read_recording
from ..recordings.manifest import Manifest
from .mapper import PipelineConfig, StereoMapper
from .._interrupt import reached

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
    mapper = StereoMapper(stereo, manifest.mount, PipelineConfig(odometry=config or OdometryConfig()),
                          track_only=True, name=str(manifest.root))
    stamps = manifest.stamps_s
    records = manifest.frames
    if stamps is not None and (not np.isfinite(stamps).all() or (np.diff(stamps) <= 0).any()):
        raise ValueError("stamps_s must be finite and increasing")
    if progress:
        from tqdm import tqdm

        source = tqdm(source, total=len(records), desc="odometry", unit="frame")
    for k, frame in enumerate(source):
        if k >= len(records):
            raise ValueError(f"{manifest.root}: the source has more frames than the recording's {len(records)}")
        # the recording's pose (the start), pan and stamp (without stamps: config.frame_interval_s apart)
        mapper.step_frame(replace(frame, index=k, pan_rad=float(records[k].pan_rad),
                                  stamp_s=float(stamps[k]) if stamps is not None else
                                  k * mapper.config.odometry.frame_interval_s,
                                  T_world_from_base=records[k].T_world_from_base if initial_pose == "given" else None))
        reached("frame")
    mapper.finish()
    if not mapper.vo_status:
        raise ValueError(f"{manifest.root} has no frames: visual odometry needs at least one")
    return replace(mapper.odometry_run(), stamps_s=stamps)


def manifest_of(source: FrameSource) -> Manifest:
    """The :class:`~mrstereo.recordings.manifest.Manifest` of what a source knows before its frames are read
    (a recording's own; a bag's stamps, poses and pans without image files)."""
    manifest = getattr(source, "manifest", None)
    if not isinstance(manifest, Manifest):
        raise TypeError(f"a {type(source).__name__} does not know its frames up front: give a recording or a bag")
    return manifest
