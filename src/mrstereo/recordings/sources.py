"""Frame sources: stereo pairs with time stamps from cameras, video files and recordings, one interface.

A :class:`FrameSource` is an iterator of :class:`StereoFrame` plus what the source knows as a whole
(calibration, mount, real time or not): :class:`VideoSource` (one or two ``cv2.VideoCapture``,
cameras or video files, optionally side by side) or :class:`RecordingSource` (a recording's frames,
stamps and poses). :func:`open_source` picks one from what the user typed; :func:`paced` replays a
file at its recorded rate. The live loop: docs/live.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math
import os
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..camera import CameraMount, StereoCamera
from ..io import matching_image, read_image
from ..profiling import stage
from .manifest import Manifest

__all__ = ["StereoFrame", "FrameSource", "VideoSource", "RecordingSource", "open_source", "paced", "is_camera"]

VIDEO_SUFFIXES = (".avi", ".mkv", ".mp4", ".mov", ".webm", ".mpg", ".mpeg", ".m4v", ".ogv", ".wmv", ".flv",
                  ".ts", ".mjpeg", ".mjpg", ".h264", ".h265")
"""File name endings read as video files (anything else that exists is read as a recording)."""


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
        What was read (``"dataset"``, ``"EuRoC/ASL"``, ``"KITTI odometry"``, ``"ROS bag"``, ``"video"``, ...).
    ground_truth_map : Path or None
        ROS map YAML of the true map, when the recording has one.
    pose_frame_mount : CameraMount or None
        The left camera in the frame the poses are of, when that frame is not a base on the floor
        (see :attr:`mrstereo.recordings.manifest.Manifest.pose_frame_mount`).
    notes : tuple of str
        What the reader left out or assumed, one line each.
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

    def __iter__(self) -> Iterator[StereoFrame]:
        raise NotImplementedError

    def close(self) -> None:
        """Release the devices or files (idempotent)."""

    def __enter__(self) -> FrameSource:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def is_camera(spec: str | int) -> bool:
    """A camera index (``0``, ``"1"``) or a V4L2 device path (``/dev/video0``)."""
    text = str(spec)
    return text.isdigit() or text.startswith("/dev/")


def _open_capture(spec: str | int) -> cv2.VideoCapture:
    text = str(spec)
    if is_camera(text):
        capture = cv2.VideoCapture(int(text) if text.isdigit() else text)
        if not capture.isOpened():
            raise ValueError(f"camera {text} cannot be opened (not connected, busy, or no permission on the device)")
        return capture
    path = Path(text)
    if not path.is_file():
        raise FileNotFoundError(f"video file not found: {path}")
    capture = cv2.VideoCapture(str(path))
    if not capture.isOpened():
        raise ValueError(f"{path}: not a video file OpenCV can read (codec or container not supported)")
    return capture


class VideoSource(FrameSource):
    """Stereo pairs from ``cv2.VideoCapture``: two captures (left, right) or one side-by-side.

    Parameters
    ----------
    left : str or int
        A camera index, a device path or a video file.
    right : str or int, optional
        The right camera or video; None with ``side_by_side``.
    side_by_side : bool
        One capture whose frames hold the left image in their left half and the right image in
        their right half.
    size : (int, int), optional
        Ask the cameras for this ``(width, height)`` of each frame (a side-by-side camera: the
        whole frame); files keep theirs.
    rate_hz : float, optional
        Ask the cameras for this frame rate.
    """

    def __init__(self, left: str | int, right: str | int | None = None, *, side_by_side: bool = False,
                 size: tuple[int, int] | None = None, rate_hz: float | None = None) -> None:
        if side_by_side == (right is not None):
            raise ValueError("give a right camera/video, or side_by_side=True for one side-by-side stream "
                             "(one of them)")
        specs = [left] if right is None else [left, right]
        kinds = {is_camera(s) for s in specs}
        if len(kinds) != 1:
            raise ValueError(f"left and right must both be cameras or both video files, got {left!r} and {right!r}")
        self.realtime = kinds.pop()
        self.side_by_side = side_by_side
        self.name = " + ".join(str(s) for s in specs) + (" (side by side)" if side_by_side else "")
        self._captures: list[cv2.VideoCapture] = []
        try:
            for spec in specs:
                capture = _open_capture(spec)
                self._captures.append(capture)
                if self.realtime:
                    if size is not None:
                        capture.set(cv2.CAP_PROP_FRAME_WIDTH, int(size[0]))
                        capture.set(cv2.CAP_PROP_FRAME_HEIGHT, int(size[1]))
                    if rate_hz is not None:
                        capture.set(cv2.CAP_PROP_FPS, float(rate_hz))
                    capture.set(cv2.CAP_PROP_BUFFERSIZE, 1)       # the newest frame, not a driver queue
        except BaseException:
            self.close()
            raise
        fps = self._captures[0].get(cv2.CAP_PROP_FPS)
        self.rate_hz = float(fps) if math.isfinite(fps) and fps > 0 else None
        n = self._captures[0].get(cv2.CAP_PROP_FRAME_COUNT)
        self.n_frames = int(n) if not self.realtime and math.isfinite(n) and n > 0 else None

    def __iter__(self) -> Iterator[StereoFrame]:
        index = 0
        while self._captures:
            with stage("read"):
                if not all(c.grab() for c in self._captures):      # grab both first: exposures close in time
                    return
                stamp = time.monotonic() if self.realtime else self._file_stamp(index)
                images = []
                for capture in self._captures:
                    ok, image = capture.retrieve()
                    if not ok or image is None:
                        return
                    images.append(image)
                left, right = self._split(images, index)
            yield StereoFrame(index=index, stamp_s=stamp, left=left, right=right)
            index += 1

    def _file_stamp(self, index: int) -> float:
        ms = self._captures[0].get(cv2.CAP_PROP_POS_MSEC)
        if math.isfinite(ms) and (ms > 0 or index == 0):
            return ms / 1000.0
        return index / (self.rate_hz or 30.0)          # a container without time stamps

    def _split(self, images: list[np.ndarray], index: int) -> tuple[np.ndarray, np.ndarray]:
        if self.side_by_side:
            image = images[0]
            if image.shape[1] % 2:
                raise ValueError(f"{self.name}: frame {index} is {image.shape[1]} pixels wide: a side-by-side "
                                 "frame must have an even width")
            half = image.shape[1] // 2
            return _gray(image[:, :half]), _gray(image[:, half:])
        left, right = (_gray(im) for im in images)
        if left.shape != right.shape:
            raise ValueError(f"{self.name}: frame {index}: the left image is {left.shape[1]}x{left.shape[0]}, "
                             f"the right one {right.shape[1]}x{right.shape[0]}")
        return left, right

    def close(self) -> None:
        for capture in self._captures:
            capture.release()
        self._captures = []


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

    def __init__(self, manifest: Manifest, *, prefer_raw: bool = False, rate_hz: float = 10.0) -> None:
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
        self.rate_hz = float(rate_hz)
        self.n_frames = len(manifest.frames)
        self._opened = None             # the exported bag's temporary dataset, removed on close

    def close(self) -> None:
        opened, self._opened = self._opened, None
        if opened is not None:
            opened.__exit__(None, None, None)

    def __iter__(self) -> Iterator[StereoFrame]:
        last = None
        for k, record in enumerate(self.manifest.frames):
            rectified = record.has_rectified and not (self.prefer_raw and record.has_raw)
            paths = (record.left_rect, record.right_rect) if rectified else (record.left, record.right)
            with stage("read"):
                left, right = (_gray(matching_image(read_image(p))) for p in paths)
            stamp = record.stamp_s if record.stamp_s is not None else \
                (0.0 if last is None else last + 1.0 / self.rate_hz)
            last = stamp
            yield StereoFrame(index=k, stamp_s=float(stamp), left=left, right=right, rectified=rectified,
                              T_world_from_base=record.T_world_from_base, pan_rad=float(record.pan_rad),
                              T_world_from_base_true=record.T_world_from_base_true)


def paced(frames, *, speed: float = 1.0, clock=time.monotonic, sleep=time.sleep) -> Iterator[StereoFrame]:
    """Hand out ``frames`` at the rate of their stamps (``speed`` times faster): frame k no earlier than
    ``(stamp_k - stamp_0) / speed`` after the first. A reader that falls behind is not waited for."""
    if not (math.isfinite(speed) and speed > 0):
        raise ValueError(f"speed must be a finite number > 0, got {speed!r}")
    start = first = None
    for frame in frames:
        if start is None:
            start, first = clock(), frame.stamp_s
        delay = start + (frame.stamp_s - first) / speed - clock()
        if delay > 0:
            sleep(delay)
        yield frame


def open_source(sources: Sequence[str | os.PathLike], *, side_by_side: bool = False,
                prefer_raw: bool = False, size: tuple[int, int] | None = None,
                rate_hz: float | None = None) -> FrameSource:
    """The source the user named: cameras, video files or one recording.

    Parameters
    ----------
    sources : sequence of str or path
        One or two entries. Two: the left and right camera or video file. One: a side-by-side
        camera or video (``side_by_side``), or a recording (a dataset folder or its manifest, a
        KITTI odometry folder: whatever :func:`~mrstereo.recordings.read_recording` reads).
        A camera is an index (``0``) or a device path (``/dev/video0``); a ROS bag with one stereo
        pair is exported to a temporary dataset first (:func:`~mrstereo.recordings.opened_recording`).
    side_by_side : bool
        The one camera or video holds both images side by side.
    prefer_raw : bool
        A recording's raw images even where it has rectified ones (a calibration of one's own).
    size, rate_hz
        Asked of cameras (see :class:`VideoSource`).
    """
    from .layouts import opened_recording

    specs = [str(s) for s in sources]
    if len(specs) not in (1, 2):
        raise ValueError(f"give one or two sources (left and right), got {len(specs)}")
    if len(specs) == 2:
        if side_by_side:
            raise ValueError("side_by_side takes one source, got two")
        return VideoSource(specs[0], specs[1], size=size, rate_hz=rate_hz)
    spec = specs[0]
    if is_camera(spec) or Path(spec).suffix.lower() in VIDEO_SUFFIXES:
        if not side_by_side:
            kind = "camera" if is_camera(spec) else "video"
            raise ValueError(f"one {kind} ({spec}) holds one image: give the right one as a second source, or "
                             "side_by_side for a side-by-side stream")
        return VideoSource(spec, side_by_side=True, size=size, rate_hz=rate_hz)
    if side_by_side:
        raise ValueError(f"side_by_side is for a camera or a video file, not a recording ({spec})")
    # a ROS bag is exported to a temporary dataset that lives until the source is closed
    opened = opened_recording(spec)
    source = RecordingSource(opened.__enter__(), prefer_raw=prefer_raw)
    source._opened = opened
    return source
