"""The one frame type and the base of every frame source; a recording's frames read one pair at a time.

:class:`StereoFrame` (a stereo pair in memory, its stamp, index and poses), :class:`FrameSource`
(an iterator of frames plus what the source knows as a whole) and :class:`RecordingSource` (the frames
of a :class:`~mrstereo.recordings.manifest.Manifest`). Cameras, videos and :func:`open_source`:
:mod:`.sources`; bags: :mod:`.bag`. Conventions: docs/conventions.md.
"""
from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from .. import _checks
from ..camera import CameraMount, StereoCamera
from ..io import matching_image, read_image
from ..profiling import stage
from .manifest import Manifest

__all__ = ["StereoFrame", "FrameSource", "RecordingSource", "frame_image"]


@dataclass(frozen=True)
class StereoFrame:
    """One stereo pair from a source.

    Attributes
    ----------
    index : int
        Position in the source (0, 1, ...), counting every frame the source delivered.
    stamp_s : float
        Time stamp [s]: the recording's, the video's presentation time or the camera's grab time.
    left, right : ndarray (H, W) or (H, W, 3)
        The pair as delivered (uint8, or float32 for 16-bit recordings).
    rectified : bool
        The pair is already rectified.
    T_world_from_base : ndarray (4, 4), optional
        The robot's pose from the recording's odometry (None: the source has none).
    pan_rad : float
        Head pan of the frame (recordings of a panning head).
    T_world_from_base_true : ndarray (4, 4), optional
        The robot's true pose (a recording's ground truth; None: unknown).
    """

    index: int
    stamp_s: float
    left: np.ndarray
    right: np.ndarray
    rectified: bool = False
    T_world_from_base: np.ndarray | None = None
    pan_rad: float = 0.0
    T_world_from_base_true: np.ndarray | None = None

    def __post_init__(self) -> None:
        _checks.same_shape(f"frame {self.index} (stamp {self.stamp_s:.3f} s): left", np.asarray(self.left),
                           "right", np.asarray(self.right))


class FrameSource:
    """Base of every source: iterate it for :class:`StereoFrame`; close it (or use ``with``) when done.

    Attributes
    ----------
    name : str
        What it reads, for messages.
    realtime : bool
        Frames arrive at their own pace whatever the reader does (a camera): the newest one
        wins. A file or recording is read as fast as it is asked for.
    calibration : StereoCamera or None
        The calibration the source carries (a recording's), else None.
    mount : CameraMount or None
        The camera mount the source carries, else None.
    has_poses : bool
        Every frame has the recording's robot pose.
    rate_hz : float or None
        The nominal frame rate, when known.
    n_frames : int or None
        How many frames the source holds, when known (None: a camera).
    root : Path or None
        The recording's folder or file (None: cameras, videos).
    layout : str
        What was read (``"dataset"``, ``"EuRoC/ASL"``, ``"KITTI odometry"``, ``"KITTI raw"``, ``"ROS bag"``,
        ``"video"``, ...).
    ground_truth_map : Path or None
        ROS map YAML of the true map, when the recording has one.
    pose_frame_mount : CameraMount or None
        The left camera in the frame the poses are of, when that frame is not a base on the floor
        (see :attr:`mrstereo.recordings.manifest.Manifest.pose_frame_mount`).
    notes : tuple of str
        What the reader left out or assumed, one line each.
    rectified : bool
        The frames arrive rectified.
    stamps_s : ndarray (N,) or None
        Every frame's stamp [s], when known before the frames are read (recordings, bags).
    true_poses : tuple of ndarray (4, 4) or None
        Every frame's true ``T_world_from_base``, when the recording has truth for all of them.
    """

    name: str = "source"
    realtime: bool = False
    calibration: StereoCamera | None = None
    mount: CameraMount | None = None
    has_poses: bool = False
    rate_hz: float | None = None
    n_frames: int | None = None
    root: Path | None = None
    layout: str = ""
    ground_truth_map: Path | None = None
    pose_frame_mount: CameraMount | None = None
    notes: tuple[str, ...] = ()
    rectified: bool = False
    stamps_s: np.ndarray | None = None
    true_poses: tuple[np.ndarray, ...] | None = None

    def __iter__(self) -> Iterator[StereoFrame]:
        raise NotImplementedError

    def close(self) -> None:
        """Release the devices or files (idempotent)."""

    def __enter__(self) -> FrameSource:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def frame_image(image: np.ndarray) -> np.ndarray:
    """An image as a :class:`StereoFrame` carries it: on the matcher's 8-bit scale
    (:func:`mrstereo.io.matching_image`), colour turned gray."""
    return _gray(matching_image(image))


def _gray(image: np.ndarray) -> np.ndarray:
    """Colour frames to the gray levels the chain matches (BT.601, as ``cv2.cvtColor``); a gray frame
    stored as three equal channels comes back exactly."""
    if image.ndim == 3 and image.shape[2] == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    if image.ndim == 3 and image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2GRAY)
    return np.ascontiguousarray(image)


class RecordingSource(FrameSource):
    """The frames of a recording (:class:`~mrstereo.recordings.manifest.Manifest`) with stamps and poses.

    A frame without a stamp is ``1 / rate_hz`` after the previous one. The rectified images are
    used where the recording has them, unless ``prefer_raw`` (a calibration of one's own).
    """

    def __init__(self, manifest: Manifest, *, prefer_raw: bool = False, rate_hz: float | None = None) -> None:
        if not isinstance(manifest, Manifest):
            raise TypeError(f"manifest must be a Manifest, got {type(manifest).__name__}")
        self.manifest = manifest
        self.name = str(manifest.root)
        self.calibration = manifest.calibration
        self.mount = manifest.mount
        self.has_poses = manifest.has_poses
        self.root = Path(manifest.root)
        self.layout = manifest.layout
        self.ground_truth_map = manifest.ground_truth_map
        self.pose_frame_mount = manifest.pose_frame_mount
        self.notes = tuple(manifest.notes)
        self.prefer_raw = prefer_raw
        self.n_frames = len(manifest.frames)
        self.stamps_s = manifest.stamps_s
        if self.stamps_s is not None and self.n_frames > 1 and np.ptp(self.stamps_s) > 0:
            self.rate_hz = float(1.0 / np.median(np.diff(self.stamps_s)))
        else:
            self.rate_hz = 10.0 if rate_hz is None else float(rate_hz)
        first = manifest.frames[0] if manifest.frames else None
        self.rectified = first is not None and first.has_rectified and not (prefer_raw and first.has_raw)
        truth = [f.T_world_from_base_true for f in manifest.frames]
        self.true_poses = tuple(truth) if truth and all(T is not None for T in truth) else None

    def __iter__(self) -> Iterator[StereoFrame]:
        last = None
        for k, record in enumerate(self.manifest.frames):
            rectified = record.has_rectified and not (self.prefer_raw and record.has_raw)
            paths = (record.left_rect, record.right_rect) if rectified else (record.left, record.right)
            with stage("read"):
                left, right = (frame_image(read_image(p)) for p in paths)
            _checks.same_shape(str(paths[0]), left, str(paths[1]), right)
            stamp = record.stamp_s if record.stamp_s is not None else \
                (0.0 if last is None else last + 1.0 / self.rate_hz)
            last = stamp
            yield StereoFrame(index=k, stamp_s=float(stamp), left=left, right=right, rectified=rectified,
                              T_world_from_base=record.T_world_from_base, pan_rad=float(record.pan_rad),
                              T_world_from_base_true=record.T_world_from_base_true)
