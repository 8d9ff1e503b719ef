"""Frame sources: stereo pairs with time stamps from cameras, video files and recordings, one interface.

A :class:`FrameSource` is an iterator of :class:`StereoFrame` plus what the source knows as a whole
(calibration, mount, real time or not): :class:`VideoSource` (one or two ``cv2.VideoCapture``,
cameras or video files, optionally side by side), :class:`RecordingSource` (a recording's frames,
stamps and poses, images read one pair at a time) or :class:`mrstereo.recordings.bag.BagSource` (a ROS
bag, read message by message). :func:`open_source` picks one from what the user typed; :func:`paced` replays a
file at its recorded rate. The live loop: docs/live.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import itertools
import math
import os
import time
import warnings
from collections.abc import Iterator, Sequence
from contextlib import nullcontext
from pathlib import Path

import cv2
import numpy as np

from ..profiling import stage
from ..rejection.streams import StreamCheck
from .frames import FrameSource, RecordingSource, StereoFrame, _gray, frame_image
from .layouts import open_recording, read_recording
from .manifest import Manifest

__all__ = ["StereoFrame", "FrameSource", "VideoSource", "RecordingSource", "open_source", "paced", "is_camera",
           "frame_image", "MAX_STAMP_GAP_S", "recording_source", "check_pair_streams"]

VIDEO_SUFFIXES = (".avi", ".mkv", ".mp4", ".mov", ".webm", ".mpg", ".mpeg", ".m4v", ".ogv", ".wmv", ".flv",
                  ".ts", ".mjpeg", ".mjpg", ".h264", ".h265")
"""File name endings read as video files (anything else that exists is read as a recording)."""


def is_camera(spec: str | int) -> bool:
    """A camera index (``0``, ``"1"``) or a V4L2 device path (``/dev/video0``)."""
    text = str(spec)
    return text.isdigit() or text.startswith("/dev/")


def _known(value: float) -> float | None:
    """A capture property, None where the container or the driver does not know it (0, NaN)."""
    return float(value) if math.isfinite(value) and value > 0 else None


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
        self._names = [str(s) for s in specs]
        rates = [_known(c.get(cv2.CAP_PROP_FPS)) for c in self._captures]
        self.rate_hz = rates[0]
        n = _known(self._captures[0].get(cv2.CAP_PROP_FRAME_COUNT))
        self.n_frames = int(n) if not self.realtime and n is not None else None
        try:
            self._check_pair(rates)
        except BaseException:
            self.close()
            raise

    def _check_pair(self, rates: list[float | None]) -> None:
        """Two streams must be a pair: one image size, and (files) one frame rate -- they are paired frame by frame."""
        if len(self._captures) != 2:
            return
        sizes = [tuple(int(_known(c.get(p)) or 0) for p in (cv2.CAP_PROP_FRAME_WIDTH, cv2.CAP_PROP_FRAME_HEIGHT))
                 for c in self._captures]
        if all(all(s) for s in sizes) and sizes[0] != sizes[1]:
            raise ValueError(f"{self._names[0]} is {sizes[0][0]}x{sizes[0][1]} and {self._names[1]} "
                             f"{sizes[1][0]}x{sizes[1][1]}: the left and right images of a stereo pair have one size")
        if not self.realtime and None not in rates and abs(rates[0] - rates[1]) > 0.01 * max(rates):
            raise ValueError(f"{self._names[0]} runs at {rates[0]:g} fps and {self._names[1]} at {rates[1]:g} fps: "
                             "two videos are paired frame by frame, so they must have one frame rate")

    def __iter__(self) -> Iterator[StereoFrame]:
        index = 0
        while self._captures:
            with stage("read"):
                grabbed = [c.grab() for c in self._captures]      # grab both first: exposures close in time
                if not all(grabbed):
                    if any(grabbed) and not self.realtime:
                        ended, other = (self._names[k] for k in ((0, 1) if not grabbed[0] else (1, 0)))
                        warnings.warn(f"{ended} ended after {index} frames, {other} has more: the rest of "
                                      f"{other} is not used", stacklevel=2)
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


MAX_STAMP_GAP_S = 60.0
"""The longest wait :func:`paced` takes between two frames' stamps (at speed 1): a longer gap, or a stamp going
back further, is a jump in the recording's clock, not time to wait."""


def paced(frames, *, speed: float = 1.0, clock=time.monotonic, sleep=None, stop=None,
          max_gap_s: float = MAX_STAMP_GAP_S) -> Iterator[StereoFrame]:
    """Hand out ``frames`` at the rate of their stamps (``speed`` times faster): frame k no earlier than
    ``(stamp_k - stamp_0) / speed`` after the first. A reader that falls behind is not waited for.

    ``stop`` (a ``threading.Event``) ends a wait at once and the replay with it. Two stamps more than
    ``max_gap_s`` apart (or going back by more) are a jump of the recording's clock: a warning naming the
    frames, no wait, and the pacing starts again from that frame.
    """
    if not (math.isfinite(speed) and speed > 0):
        raise ValueError(f"speed must be a finite number > 0, got {speed!r}")
    wait = sleep or (stop.wait if stop is not None else time.sleep)
    start = first = previous = None
    for frame in frames:
        if stop is not None and stop.is_set():
            return
        gap = None if previous is None else frame.stamp_s - previous.stamp_s
        if gap is not None and not abs(gap) <= max_gap_s:
            warnings.warn(f"the stamps jump by {gap:.6g} s from frame {previous.index} to frame {frame.index} "
                          f"(more than {max_gap_s:g} s): replayed without waiting, the pacing restarts there",
                          stacklevel=2)
            start = None
        if start is None:
            start, first = clock(), frame.stamp_s
        previous = frame
        delay = start + (frame.stamp_s - first) / speed - clock()
        if delay > 0:
            wait(delay)
            if stop is not None and stop.is_set():
                return
        yield frame


def open_source(sources: Sequence[str | os.PathLike], *, side_by_side: bool = False,
                prefer_raw: bool = False, size: tuple[int, int] | None = None,
                rate_hz: float | None = None, truth=None) -> FrameSource:
    """The source the user named: cameras, video files or one recording.

    Parameters
    ----------
    sources : sequence of str or path
        One or two entries. Two: the left and right camera or video file. One: a side-by-side
        camera or video (``side_by_side``), or a recording (whatever
        :func:`~mrstereo.recordings.open_recording` opens: dataset, KITTI, EuRoC/ASL and image
        folders, a ROS bag with one stereo pair, read message by message).
        A camera is an index (``0``) or a device path (``/dev/video0``).
    side_by_side : bool
        The one camera or video holds both images side by side.
    prefer_raw : bool
        A recording's raw images even where it has rectified ones (a calibration of one's own).
    size, rate_hz
        Asked of cameras (see :class:`VideoSource`).
    truth : None, False or path
        A recording's own truth, none, or a file's (:func:`~mrstereo.recordings.read_recording`).
    """
    specs = [str(s) for s in sources]
    if len(specs) not in (1, 2):
        raise ValueError(f"give one or two sources (left and right), got {len(specs)}")
    if truth is not None and (len(specs) == 2 or is_camera(specs[0])
                              or Path(specs[0]).suffix.lower() in VIDEO_SUFFIXES):
        raise ValueError(f"truth (--truth/--no-truth) is for a recording, not for cameras or video files "
                         f"({', '.join(specs)})")
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
    return open_recording(spec, prefer_raw=prefer_raw, truth=truth)


def recording_source(recording, *, prefer_raw: bool = False):
    """The :class:`~mrstereo.recordings.sources.FrameSource` of a recording (a Manifest or a path): the one
    place a map run turns a recording into frames."""
    manifest = recording if isinstance(recording, Manifest) else read_recording(recording)
    return RecordingSource(manifest, prefer_raw=prefer_raw)


def check_pair_streams(manifest: Manifest | FrameSource) -> list[str]:
    """Warn (one ``mrstereo: warning:`` line on the command line) when the first frames of a recording (or a
    source that can be read twice, a bag) show identical or swapped left and right streams
    (:class:`~mrstereo.rejection.streams.StreamCheck`, as a :class:`~mrstereo.pipeline.mapper.StereoMapper` does); return the warnings."""
    check = StreamCheck(manifest.calibration, f"dataset {manifest.root}")
    try:
        with recording_source(manifest) if isinstance(manifest, Manifest) else nullcontext(manifest) as source:
            for frame in itertools.islice(source, check.n_frames):
                check.add(frame.index, frame.left, frame.right, rectified=frame.rectified)
    except (OSError, ValueError, TypeError):      # an unreadable frame: the run reports it itself
        pass
    return check.warn()
