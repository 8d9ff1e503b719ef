"""ROS bags as frame sources: read ROS 1 ``.bag`` and ROS 2 (sqlite3 / mcap) bags without ROS.

Reading uses ``rosbags``, message by message. A bag is a :class:`BagSource` of in-memory stereo
frames (and, with :func:`export_bag`, a dataset directory in the manifest format,
docs/dataset.md): left and right images paired by stamp (within ``sync_tolerance_s``), the
calibration from camera_info (``P_right[0, 3] = -fx * baseline``) or a stereo YAML, the robot
pose from odometry or TF interpolated at each left stamp, the camera mount given, from the YAML or
from TF, and the head pan from ``camera_frame``. The rules in full: docs/scale-out.md ("ROS bags").
Conventions: docs/conventions.md.
"""
from __future__ import annotations

import contextlib
import math
import os
import warnings
import weakref
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from .. import _checks, _limits
from .._interrupt import reached
from ..camera import CameraInfo, CameraMount, StereoCamera
from ..io import check_output_dir, decode_image, note_inputs
from ..transforms import R_BODY_FROM_OPTICAL, T_from_position_quaternion, rotation_from_quaternion, slerp, wrap_angle
from ._bagfiles import bag_errors, bag_inputs, check_bag_file
from .manifest import FrameRecord, Manifest, pose_3d_of, staged_dataset
from .frames import FrameSource, StereoFrame, frame_image
from .truth import TRUTH_FRAMES, TRUTH_TOLERANCE_S, check_truth, match_stamps, read_poses_file

__all__ = ["BagSource", "BagExport", "TransformTrack", "TfTree", "bag_topics", "image_from_message",
           "SUPPORTED_ENCODINGS", "camera_info_from_message", "stereo_from_camera_info", "stereo_from_bag",
           "pair_by_stamp", "export_bag", "bag_inputs"]

IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
CAMERA_INFO_TYPE = "sensor_msgs/msg/CameraInfo"
ODOMETRY_TYPE = "nav_msgs/msg/Odometry"
TF_TYPES = ("tf2_msgs/msg/TFMessage", "tf/msg/tfMessage")
TF_TOPICS = ("/tf", "/tf_static")
CALIBRATION_NAME = "stereo.yaml"


# --------------------------------------------------------------------------------------------- reading

def _bag_paths(path: str | os.PathLike) -> list[Path]:
    """What rosbags' AnyReader opens: a ROS 1 ``.bag`` file or a ROS 2 bag directory."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"bag not found: {path}")
    if path.is_file() and path.suffix in (".db3", ".mcap") and (path.parent / "metadata.yaml").is_file():
        path = path.parent                  # a ROS 2 storage file: open its bag directory
    if path.is_file() and path.suffix != ".bag":
        raise ValueError(f"{path} is not a bag: expected a ROS 1 .bag file or a ROS 2 bag directory "
                         "(with metadata.yaml)")
    if path.is_dir() and not (path / "metadata.yaml").is_file():
        raise ValueError(f"{path} is not a ROS 2 bag: no metadata.yaml in the directory")
    return [path]


@contextlib.contextmanager
def _open_bag(path: str | os.PathLike):
    """The rosbags reader of a bag whose records were checked first (:func:`._bagfiles.check_bag_file`);
    every error of the reader, then and while reading, is one ``ValueError`` naming the bag."""
    from rosbags.highlevel import AnyReader, AnyReaderError
    from rosbags.typesys import Stores, get_typestore

    paths = _bag_paths(path)
    note_inputs(bag_inputs(path))
    check_bag_file(paths[0])
    try:
        with bag_errors(path):
            reader = AnyReader(paths, default_typestore=get_typestore(Stores.ROS2_HUMBLE))
            reader.open()
    except (AnyReaderError, UnicodeDecodeError) as exc:   # corrupt or unsupported file (readers' errors wrapped)
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ValueError(f"cannot read bag {path}: {first}") from None
    try:
        with bag_errors(path):
            yield reader
    finally:
        with contextlib.suppress(Exception):
            reader.close()


def bag_topics(path: str | os.PathLike) -> dict[str, str]:
    """``{topic: message type}`` of a bag (types as ``pkg/msg/Name``)."""
    with _open_bag(path) as reader:
        return {c.topic: c.msgtype for c in reader.connections}


def pick_stereo_topics(topics: dict[str, str], *, need_camera_info: bool = True) -> tuple[str, str]:
    """The left and right image topics of a bag's one stereo pair.

    Two image topics (with a ``camera_info`` beside them when ``need_camera_info``) whose names differ
    only in ``left``/``right`` or a number form a pair, the left sorting first; exactly one is picked.

    Raises
    ------
    ValueError
        No pair or several, naming the candidates.
    """
    import re

    images = sorted(t for t, m in topics.items() if m in IMAGE_TYPES and
                    (not need_camera_info or topics.get(t.rsplit("/", 1)[0] + "/camera_info") == CAMERA_INFO_TYPE))
    groups: dict[str, list[str]] = {}
    for t in images:
        groups.setdefault(re.sub(r"\d+", "#", re.sub(r"left|right", "*", t)), []).append(t)
    pairs = [tuple(sorted(g)) for g in groups.values() if len(g) == 2]
    if len(pairs) == 1:
        return pairs[0]
    what = "image topics with a camera_info beside them" if need_camera_info else "image topics"
    listed = ", ".join(images) or "none"
    raise ValueError(f"cannot pick the stereo pair: {len(pairs) or 'no'} pair(s) among the {what} ({listed}); "
                     "give --left-topic and --right-topic" + (" (or --calib)" if need_camera_info and not pairs else ""))


def describe_bag(bag: str | os.PathLike) -> list[tuple[str, str]]:
    """``(what, value)`` lines of a bag without exporting it: topics with message counts, the stereo pair."""
    with _open_bag(bag) as reader:
        counts: dict[str, int] = {}
        for c in reader.connections:
            counts[c.topic] = counts.get(c.topic, 0) + int(c.msgcount)
        topics = {c.topic: c.msgtype for c in reader.connections}
        duration = (reader.end_time - reader.start_time) / 1e9 if reader.end_time > reader.start_time else 0.0
    lines = [("layout", f"ROS bag: {bag}"), ("duration", f"{duration:.1f} s")]
    lines += [("topic", f"{t} ({m}, {counts[t]} messages)") for t, m in sorted(topics.items())]
    for need_info in (True, False):
        try:
            left, right = pick_stereo_topics(topics, need_camera_info=need_info)
        except ValueError as exc:
            if not need_info:
                lines.append(("stereo pair", str(exc)))
            continue
        lines.append(("stereo pair", f"{left}, {right}" + ("" if need_info else " (no camera_info: give --calib)")))
        break
    odometry = [t for t, m in topics.items() if m == ODOMETRY_TYPE]
    lines.append(("odometry", ", ".join(odometry) if odometry else "none (poses from /tf with --tf, or visual odometry)"))
    lines.append(("tf", ", ".join(t for t in TF_TOPICS if t in topics) or "none"))
    return lines


def with_picked_topics(bag: str | os.PathLike, options: dict) -> dict:
    """``options`` of :func:`export_bag` with the left and right topics picked when not given
    (:func:`pick_stereo_topics`), and the bag's one odometry topic when neither it nor TF is named."""
    options = dict(options)
    if options.get("left_topic") and options.get("right_topic"):
        return options
    if options.get("left_topic") or options.get("right_topic"):
        raise ValueError("give both --left-topic and --right-topic, or neither (the bag's stereo pair is picked)")
    topics = bag_topics(bag)
    options["left_topic"], options["right_topic"] = pick_stereo_topics(
        topics, need_camera_info=options.get("calibration") is None and not options.get("camera_info_topics"))
    odometry = [t for t, m in topics.items() if m == ODOMETRY_TYPE]
    if not options.get("odom_topic") and not options.get("use_tf") and len(odometry) == 1:
        options["odom_topic"] = odometry[0]
    return options


def _stamp_ns(msg, fallback_ns: int) -> int:
    header = getattr(msg, "header", None)
    if header is None:
        return int(fallback_ns)
    ns = int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
    return ns if ns > 0 else int(fallback_ns)


# ROS Image encoding -> (channels, dtype); sensor_msgs/image_encodings.h names
_ENCODINGS = {"mono8": (1, np.uint8), "8UC1": (1, np.uint8), "mono16": (1, np.uint16), "16UC1": (1, np.uint16),
              "bgr8": (3, np.uint8), "rgb8": (3, np.uint8), "8UC3": (3, np.uint8),
              "bgra8": (4, np.uint8), "rgba8": (4, np.uint8), "8UC4": (4, np.uint8),
              "bayer_rggb8": (1, np.uint8), "bayer_bggr8": (1, np.uint8), "bayer_gbrg8": (1, np.uint8),
              "bayer_grbg8": (1, np.uint8)}
# OpenCV names a Bayer pattern by the 2x2 block starting at the second row and column, ROS by the
# first: ROS rggb is OpenCV BG (known-answer test in tests/test_bag_encodings.py, as cv_bridge maps it).
_DEBAYER = {"bayer_rggb8": cv2.COLOR_BayerBG2BGR, "bayer_bggr8": cv2.COLOR_BayerRG2BGR,
            "bayer_gbrg8": cv2.COLOR_BayerGR2BGR, "bayer_grbg8": cv2.COLOR_BayerGB2BGR}
SUPPORTED_ENCODINGS = tuple(_ENCODINGS)


def image_from_message(msg, msgtype: str) -> np.ndarray:
    """A ``sensor_msgs/Image`` or ``CompressedImage`` as an OpenCV array.

    Gray and colour become uint8 gray or BGR, ``mono16``/``16UC1`` uint16, Bayer mosaics are
    debayered to BGR; a CompressedImage is whatever OpenCV decodes (encodings: docs/scale-out.md).

    Raises ``ValueError`` for an unsupported encoding or an undecodable payload.
    """
    data = np.asarray(msg.data, dtype=np.uint8).ravel()
    if msgtype.endswith("CompressedImage"):
        img = decode_image(data, where=f"a CompressedImage (format {msg.format!r})")
        if img is None:
            raise ValueError(f"cannot decode a CompressedImage (format {msg.format!r})")
        if img.dtype not in (np.uint8, np.uint16):
            raise ValueError(f"CompressedImage decodes to {img.dtype}; only 8- and 16-bit images are supported")
        return img[:, :, :3] if img.ndim == 3 and img.shape[2] == 4 else img
    enc = str(msg.encoding)
    if enc not in _ENCODINGS:
        raise ValueError(f"image encoding {enc!r} is not supported (supported: {', '.join(SUPPORTED_ENCODINGS)})")
    ch, dtype = _ENCODINGS[enc]
    itemsize = np.dtype(dtype).itemsize
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    _limits.within("MRSTEREO_MAX_IMAGE_PIXELS", h * w, f"an image message of {w}x{h} pixels")
    if h <= 0 or w <= 0 or step < w * ch * itemsize or data.size < h * step:
        raise ValueError(f"image message of {w}x{h} {enc} has step {step} and {data.size} bytes "
                         f"(needs step >= {w * ch * itemsize} and {h} rows of it)")
    rows = data[:h * step].reshape(h, step)[:, :w * ch * itemsize]
    if itemsize > 1:
        order = ">" if int(getattr(msg, "is_bigendian", 0)) else "<"
        img = np.ascontiguousarray(rows).view(np.dtype(dtype).newbyteorder(order)).astype(dtype)
    else:
        img = rows
    img = img.reshape(h, w, ch)
    if enc in _DEBAYER:
        return cv2.cvtColor(np.ascontiguousarray(img[:, :, 0]), _DEBAYER[enc])
    if ch == 1:
        return np.ascontiguousarray(img[:, :, 0])
    if enc.startswith("rgb"):
        img = img[:, :, 2::-1]
    return np.ascontiguousarray(img[:, :, :3])


def camera_info_from_message(msg, *, name: str = "camera") -> CameraInfo:
    """A ``sensor_msgs/CameraInfo`` (ROS 1 ``K, D, R, P`` or ROS 2 ``k, d, r, p``) as :class:`CameraInfo`."""
    def field_(upper: str):
        value = getattr(msg, upper, None)
        return getattr(msg, upper.lower()) if value is None else value

    data = {"image_width": int(msg.width), "image_height": int(msg.height), "camera_name": name,
            "distortion_model": str(msg.distortion_model) or "plumb_bob",
            "camera_matrix": [float(v) for v in np.ravel(field_("K"))],
            "distortion_coefficients": [float(v) for v in np.ravel(field_("D"))] or [0.0] * 5,
            "rectification_matrix": [float(v) for v in np.ravel(field_("R"))],
            "projection_matrix": [float(v) for v in np.ravel(field_("P"))]}
    return CameraInfo.from_dict(data, where=f"camera_info of {name}")


def stereo_from_camera_info(left_msg, right_msg) -> StereoCamera:
    """A :class:`StereoCamera` from the left and right ``CameraInfo`` messages of a stereo head."""
    return StereoCamera(left=camera_info_from_message(left_msg, name="left"),
                        right=camera_info_from_message(right_msg, name="right"))


def pair_by_stamp(left_ns: Sequence[int], right_ns: Sequence[int], *, tolerance_ns: int) -> list[tuple[int, int]]:
    """Pair left and right image stamps one-to-one, closest pairs first, within ``tolerance_ns``.

    Returns
    -------
    list of (int, int)
        ``(left index, right index)`` sorted by left stamp.
    """
    left = np.asarray(left_ns, dtype=np.int64)
    right = np.asarray(right_ns, dtype=np.int64)
    if left.size == 0 or right.size == 0:
        return []
    order = np.argsort(right, kind="stable")
    rs = right[order]
    candidates = []
    for i, t in enumerate(left):
        j = int(np.searchsorted(rs, t))
        for jj in (j - 1, j):
            if 0 <= jj < rs.size and abs(int(rs[jj]) - int(t)) <= tolerance_ns:
                candidates.append((abs(int(rs[jj]) - int(t)), i, int(order[jj])))
    used_left, used_right, pairs = set(), set(), []
    for _, i, j in sorted(candidates):
        if i not in used_left and j not in used_right:
            used_left.add(i)
            used_right.add(j)
            pairs.append((i, j))
    return sorted(pairs, key=lambda p: (int(left[p[0]]), p[0]))


@dataclass(frozen=True)
class TransformTrack:
    """A time series of one transform ``T_parent_from_child`` (odometry or one TF edge).

    ``at(stamp_ns)`` interpolates linearly (slerp for the rotation) between the two nearest
    samples and holds the first / last sample outside the span.
    """

    stamps_ns: np.ndarray
    translations: np.ndarray          # (N, 3)
    quaternions: np.ndarray           # (N, 4) x, y, z, w

    @classmethod
    def from_samples(cls, samples: list[tuple[int, Sequence[float], Sequence[float]]]) -> TransformTrack:
        if not samples:
            raise ValueError("a transform track needs at least one sample")
        samples = sorted(samples, key=lambda s: s[0])
        dedup = {}
        for t, tr, q in samples:                       # the last sample of a stamp wins
            dedup[int(t)] = (tr, q)
        stamps = np.array(sorted(dedup), dtype=np.int64)
        return cls(stamps_ns=stamps, translations=np.array([dedup[t][0] for t in stamps], dtype=float),
                   quaternions=np.array([dedup[t][1] for t in stamps], dtype=float))

    def at(self, stamp_ns: int) -> np.ndarray:
        """``T_parent_from_child`` (4, 4) at ``stamp_ns``."""
        i = int(np.searchsorted(self.stamps_ns, stamp_ns, side="right")) - 1
        T = np.eye(4)
        if i < 0 or i >= self.stamps_ns.size - 1 or self.stamps_ns[i] == stamp_ns:
            k = min(max(i, 0), self.stamps_ns.size - 1)
            T[:3, :3] = rotation_from_quaternion(self.quaternions[k])
            T[:3, 3] = self.translations[k]
            return T
        t0, t1 = int(self.stamps_ns[i]), int(self.stamps_ns[i + 1])
        a = (int(stamp_ns) - t0) / (t1 - t0)
        T[:3, :3] = rotation_from_quaternion(slerp(self.quaternions[i], self.quaternions[i + 1], a))
        T[:3, 3] = self.translations[i] + a * (self.translations[i + 1] - self.translations[i])
        return T


@dataclass
class TfTree:
    """Frames and transforms of ``/tf`` and ``/tf_static``: each child frame has one parent."""

    parent: dict[str, str] = field(default_factory=dict)
    samples: dict[str, list] = field(default_factory=dict)
    _tracks: dict[str, TransformTrack] = field(default_factory=dict)

    def add(self, parent: str, child: str, stamp_ns: int, translation, quaternion) -> None:
        parent, child = parent.lstrip("/"), child.lstrip("/")
        self.parent[child] = parent
        self.samples.setdefault(child, []).append((int(stamp_ns), tuple(translation), tuple(quaternion)))
        self._tracks.pop(child, None)

    def add_message(self, msg, *, static: bool) -> None:
        for tf in msg.transforms:
            tr, rot = tf.transform.translation, tf.transform.rotation
            stamp = 0 if static else _stamp_ns(tf, 0)
            self.add(tf.header.frame_id, tf.child_frame_id, stamp, (tr.x, tr.y, tr.z), (rot.x, rot.y, rot.z, rot.w))

    @property
    def frames(self) -> set[str]:
        return set(self.parent) | set(self.parent.values())

    def chain(self, target: str, source: str) -> list[str]:
        """Child frames from ``source`` up to (not including) ``target``; error if unconnected."""
        target, source = target.lstrip("/"), source.lstrip("/")
        chain, frame = [], source
        while frame != target:
            if frame not in self.parent or len(chain) > 1000:
                raise ValueError(f"TF has no chain from '{target}' down to '{source}' "
                                 f"(frames in the bag: {', '.join(sorted(self.frames)) or 'none'})")
            chain.append(frame)
            frame = self.parent[frame]
        return chain

    def lookup(self, target: str, source: str, stamp_ns: int) -> np.ndarray:
        """``T_target_from_source`` (4, 4) at ``stamp_ns``."""
        T = np.eye(4)
        for child in self.chain(target, source):
            if child not in self._tracks:
                self._tracks[child] = TransformTrack.from_samples(self.samples[child])
            T = self._tracks[child].at(stamp_ns) @ T
        return T


# -------------------------------------------------------------------------------------------- export

@dataclass(frozen=True)
class BagExport:
    """Result of :func:`export_bag`.

    Attributes
    ----------
    out_dir : Path
        The dataset directory (``manifest.yaml``, ``stereo.yaml``, images).
    n_frames : int
        Stereo pairs written.
    n_left, n_right : int
        Image messages on the two topics.
    stamps_ns : tuple of int
        Left image stamp of every frame.
    calibration : StereoCamera
        The calibration written as ``stereo.yaml``.
    mount : CameraMount or None
        The mount written to the manifest (None: none known, estimated when mapping).
    mount_source : str
        ``"calibration"``, ``"options"``, ``"tf <base> <- <camera>"`` or ``"none (...)"``.
    pose_source : str
        ``"odometry <topic>"``, ``"tf <world> <- <base>"`` or ``"none (origin)"``.
    """

    out_dir: Path
    n_frames: int
    n_left: int
    n_right: int
    stamps_ns: tuple[int, ...]
    calibration: StereoCamera
    mount: CameraMount | None
    mount_source: str
    pose_source: str


@dataclass
class _BagStream:
    """What the first pass over a bag collects: image stamps per topic, odometry samples and TF."""

    stamps: dict[str, list[int]]
    odom_samples: list = field(default_factory=list)
    tf: TfTree = field(default_factory=TfTree)


def _require_topic(topics: dict[str, str], topic: str, option: str, types: Sequence[str]) -> str:
    if topic not in topics:
        listed = ", ".join(f"{t} ({m})" for t, m in sorted(topics.items())) or "none"
        raise ValueError(f"{option}: topic {topic!r} is not in the bag; topics: {listed}")
    if topics[topic] not in types:
        raise ValueError(f"{option}: topic {topic!r} has type {topics[topic]}, expected {' or '.join(types)}")
    return topics[topic]


def _round_pose(values) -> tuple[float, ...]:
    # 1e-9 m / rad: far below any sensor, and a pose read back from YAML or
    # re-derived from a quaternion gives the very same number.
    return tuple(round(float(v), 9) + 0.0 for v in values)


def _camera_info_topics(topics: dict[str, str], left_topic: str, right_topic: str,
                        camera_info_topics: tuple[str, str] | None) -> tuple[str, str]:
    """The left and right CameraInfo topics: given, or ``<image topic namespace>/camera_info``."""
    if camera_info_topics is None:
        guess = tuple(t.rsplit("/", 1)[0] + "/camera_info" for t in (left_topic, right_topic))
        if not all(t in topics for t in guess):
            raise ValueError("no calibration: give the camera_info topics (left,right) or a stereo YAML "
                             f"(looked for {guess[0]} and {guess[1]})")
        camera_info_topics = guess
    if len(camera_info_topics) != 2:
        raise ValueError(f"camera_info_topics must be (left, right), got {camera_info_topics!r}")
    for t, side in zip(camera_info_topics, ("left", "right")):
        _require_topic(topics, t, f"{side} camera_info topic", (CAMERA_INFO_TYPE,))
    return tuple(camera_info_topics)


def _info_values(msg) -> tuple:
    """What a CameraInfo says of the camera (size, model, K, D, R, P): not its header."""
    fields = [getattr(msg, name, None) if getattr(msg, name, None) is not None else getattr(msg, name.lower())
              for name in ("K", "D", "R", "P")]
    return (int(msg.width), int(msg.height), str(msg.distortion_model), *(tuple(np.ravel(f).tolist()) for f in fields))


def _stereo_of_reader(reader, camera_info_topics: tuple[str, str]) -> StereoCamera:
    """The calibration of the first left and right CameraInfo messages; a later message that says otherwise (a
    camera recalibrated or switched mid-bag) is a warning naming it, the first one still used."""
    infos: dict[str, object] = {}
    first: dict[str, tuple] = {}
    body: dict[str, bytes] = {}      # a message after its stamp (12 bytes: ROS 1 seq + stamp, CDR header + stamp)
    count: dict[str, int] = {}
    changed: list[str] = []
    for conn, _, raw in reader.messages(connections=[c for c in reader.connections if c.topic in camera_info_topics]):
        count[conn.topic] = count.get(conn.topic, 0) + 1
        if conn.topic in changed or bytes(raw[12:]) == body.get(conn.topic):
            continue
        msg = reader.deserialize(raw, conn.msgtype)
        if conn.topic not in infos:
            infos[conn.topic], first[conn.topic], body[conn.topic] = msg, _info_values(msg), bytes(raw[12:])
        elif _info_values(msg) != first[conn.topic]:
            changed.append(conn.topic)
            warnings.warn(f"camera_info {conn.topic} changes at its message {count[conn.topic] - 1} (stamp "
                          f"{msg.header.stamp.sec}.{msg.header.stamp.nanosec:09d} s): every frame is rectified with "
                          "its first message; give --calib if the camera changed", stacklevel=2)
    missing = [t for t in camera_info_topics if t not in infos]
    if missing:
        raise ValueError(f"camera_info topic {missing[0]} has no messages")
    return stereo_from_camera_info(infos[camera_info_topics[0]], infos[camera_info_topics[1]])


def stereo_from_bag(bag: str | os.PathLike, *, left_topic: str, right_topic: str,
                    camera_info_topics: tuple[str, str] | None = None) -> StereoCamera:
    """The calibration of a bag's stereo head: its first left and right ``CameraInfo`` messages.

    ``camera_info_topics`` default to ``<image topic namespace>/camera_info``.
    """
    with _open_bag(bag) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        return _stereo_of_reader(reader, _camera_info_topics(topics, left_topic, right_topic, camera_info_topics))


def _read_stream(reader, *, left_topic: str, right_topic: str, odom_topic: str | None,
                 tf_topics: Sequence[str]) -> _BagStream:
    """First pass: the header stamps of the images, the odometry samples and the TF tree."""
    stream = _BagStream(stamps={left_topic: [], right_topic: []})
    wanted = {left_topic, right_topic, odom_topic, *tf_topics}
    count: dict[str, int] = {}
    for conn, bag_ns, raw in reader.messages(connections=[c for c in reader.connections if c.topic in wanted]):
        index = count[conn.topic] = count.get(conn.topic, -1) + 1
        if conn.topic in (left_topic, right_topic):
            stream.stamps[conn.topic].append(_stamp_ns(reader.deserialize(raw, conn.msgtype), bag_ns))
            _limits.within("MRSTEREO_MAX_FRAMES", len(stream.stamps[conn.topic]), f"bag: images on {conn.topic}")
        elif conn.topic == odom_topic:
            msg = reader.deserialize(raw, conn.msgtype)
            p, q = msg.pose.pose.position, msg.pose.pose.orientation
            _finite_pose(conn.topic, index, (p.x, p.y, p.z), (q.x, q.y, q.z, q.w))
            stream.odom_samples.append((_stamp_ns(msg, bag_ns), (p.x, p.y, p.z), (q.x, q.y, q.z, q.w)))
        else:
            msg = reader.deserialize(raw, conn.msgtype)
            for tf in msg.transforms:
                tr, rot = tf.transform.translation, tf.transform.rotation
                _finite_pose(f"{conn.topic} ({tf.header.frame_id} -> {tf.child_frame_id})", index,
                             (tr.x, tr.y, tr.z), (rot.x, rot.y, rot.z, rot.w))
            stream.tf.add_message(msg, static=conn.topic == "/tf_static")
    return stream


def _finite_pose(topic: str, index: int, translation, quaternion) -> None:
    """A pose of message ``index`` (from 0) of ``topic``: finite numbers and a quaternion of non-zero length."""
    values = np.array([*translation, *quaternion], dtype=np.float64)
    if not np.isfinite(values).all():
        raise ValueError(f"bag topic {topic}: message {index} has a non-finite pose "
                         f"(position {list(translation)}, orientation {list(quaternion)})")
    if np.linalg.norm(values[3:]) < 1e-9:
        raise ValueError(f"bag topic {topic}: message {index} has a zero orientation quaternion")


def _stereo_pairs(stamps: dict[str, list[int]], left_topic: str, right_topic: str,
                  tolerance_s: float) -> list[tuple[int, int]]:
    """Left and right images paired by stamp; a named error when there are none."""
    n_left, n_right = len(stamps[left_topic]), len(stamps[right_topic])
    if n_left == 0 or n_right == 0:
        raise ValueError(f"no images: {n_left} messages on {left_topic}, {n_right} on {right_topic}")
    pairs = pair_by_stamp(stamps[left_topic], stamps[right_topic], tolerance_ns=int(round(tolerance_s * 1e9)))
    if not pairs:
        gaps = [abs(a - b) for a in stamps[left_topic][:50] for b in stamps[right_topic][:50]]
        raise ValueError(f"no left/right image pairs within {tolerance_s} s ({n_left} left, {n_right} right "
                         f"images; smallest stamp difference {min(gaps) / 1e9:.4f} s): raise --sync-tolerance")
    return pairs


def _robot_poses(stream: _BagStream, frame_stamps: list[int], *, odom_topic: str | None, use_tf: bool,
                 world_frame: str | None, base_frame: str) -> tuple[list, str]:
    """The robot pose at each frame stamp, from odometry or TF (else the origin), and where it came from."""
    if odom_topic is not None:
        if not stream.odom_samples:
            raise ValueError(f"odometry topic {odom_topic} has no messages")
        track = TransformTrack.from_samples(stream.odom_samples)
        return [_pose_of(track.at(t)) for t in frame_stamps], f"odometry {odom_topic}"
    if use_tf:
        if world_frame is None:
            world_frame = "map"
            try:
                stream.tf.chain("map", base_frame)
            except ValueError:
                world_frame = "odom"
        stream.tf.chain(world_frame, base_frame)
        return ([_pose_of(stream.tf.lookup(world_frame, base_frame, t)) for t in frame_stamps],
                f"tf {world_frame} <- {base_frame}")
    return [(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)] * len(frame_stamps), "none (every frame at the origin)"


def _mount_and_pans(tf: TfTree, frame_stamps: list[int], *, mount: CameraMount | None, calibration: StereoCamera,
                    base_frame: str, camera_frame: str | None) -> tuple[CameraMount | None, str, list[float]]:
    """The mount (given, the calibration's, else TF's), where it came from, and the head pan of every frame.

    A pan is the change of heading of ``camera_frame``'s optical axis: relative to the given mount's
    rectified optical axis, or to ``camera_frame`` at the first frame when the mount comes from TF.
    """
    source = "options" if mount is not None else "calibration"
    if mount is None:
        mount = calibration.mount
    pans = [0.0] * len(frame_stamps)
    if camera_frame is not None:
        T_cams = [_optical_in_base(tf.lookup(base_frame, camera_frame, t), camera_frame) for t in frame_stamps]
        if mount is None:
            mount, source = CameraMount(T_cams[0]), f"tf {base_frame} <- {camera_frame}"
            ref = _heading(T_cams[0], 2)
        else:
            ref = _heading(mount.T_base_from_rectified(calibration.left.R), 2)
        pans = [_round_pose([wrap_angle(_heading(T, 2) - ref)])[0] for T in T_cams]
    if mount is None:
        source = "none (the floor is estimated when mapping)"
    return mount, source, pans


def _decoded_pairs(reader, pairs: list[tuple[int, int]], *, topics: tuple[str, str],
                   calibration: StereoCamera) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
    """Second pass: ``(k, left, right)`` of the paired images in frame order, decoded in memory.

    Messages arrive in bag order; an image waits only until its partner is decoded and the frames
    before it are handed out, so memory holds a few images whatever the length of the bag.
    """
    slot = {topics[0]: {i: k for k, (i, _) in enumerate(pairs)}, topics[1]: {j: k for k, (_, j) in enumerate(pairs)}}
    side = {topics[0]: 0, topics[1]: 1}
    count = dict.fromkeys(topics, 0)
    waiting: dict[int, list] = {}
    next_k = 0
    for conn, _, raw in reader.messages(connections=[c for c in reader.connections if c.topic in topics]):
        n = count[conn.topic]
        count[conn.topic] += 1
        k = slot[conn.topic].get(n)
        if k is None:
            continue
        image = image_from_message(reader.deserialize(raw, conn.msgtype), conn.msgtype)
        if (image.shape[1], image.shape[0]) != tuple(calibration.size):
            raise ValueError(f"{conn.topic}: images are {image.shape[1]}x{image.shape[0]} but the "
                             f"calibration is {calibration.size[0]}x{calibration.size[1]}")
        waiting.setdefault(k, [None, None])[side[conn.topic]] = image
        while next_k in waiting and all(im is not None for im in waiting[next_k]):
            left, right = waiting.pop(next_k)
            yield next_k, left, right
            next_k += 1


class BagSource(FrameSource):
    """A ROS 1 / ROS 2 bag read message by message as :class:`~mrstereo.recordings.sources.StereoFrame`.

    Opening reads what is small (image stamps, camera_info, odometry, TF) and pairs the left and
    right images by stamp; iterating decodes the paired images in memory, one pair at a time, so
    nothing is written to disk and memory stays flat however long the bag. The rules (pairing,
    calibration, pose, mount, pan): docs/scale-out.md ("ROS bags").

    Parameters
    ----------
    bag : path
        A ROS 1 ``.bag`` file or a ROS 2 bag directory (sqlite3 or mcap).
    left_topic, right_topic : str, optional
        ``sensor_msgs/Image`` or ``CompressedImage`` topics; neither: the bag's one stereo pair
        (:func:`pick_stereo_topics`), and its one odometry topic when no pose source is named.
    camera_info_topics : (str, str), optional
        Left and right ``CameraInfo`` topics. Default: ``calibration`` if given, else
        ``<image topic namespace>/camera_info`` when present.
    calibration : StereoCamera, optional
        Use this calibration (a stereo YAML) instead of camera_info messages.
    odom_topic : str, optional
        ``nav_msgs/Odometry`` topic giving the robot pose.
    use_tf : bool
        Take the pose of ``base_frame`` in ``world_frame`` from ``/tf`` and ``/tf_static`` instead.
    world_frame : str, optional
        TF world frame; default ``map`` when TF connects it to ``base_frame``, else ``odom``.
    base_frame : str
        The robot's TF frame.
    camera_frame : str, optional
        TF frame of the left camera (optical or body frame): its pose in ``base_frame`` is the mount
        when none is given, its change of heading the head pan (default: pan 0).
    sync_tolerance_s : float
        Largest left/right stamp difference of a pair.
    mount : CameraMount, optional
        Camera mount; default the calibration's, else from TF (``camera_frame``), else none (the
        floor is estimated when mapping).
    rectified : bool
        The images are already rectified.
    progress : bool
        Accepted for the keywords of :func:`export_bag` (a source draws no progress bar).
    truth : None, False or path
        None: the poses of the odometry topic or TF; False: none of them (visual odometry); a TUM or
        EuRoC csv file of the base's poses instead, matched to the frames by stamp (frames without one
        left out; :mod:`mrstereo.recordings.truth`), also the true poses.

    Attributes
    ----------
    stamps_ns : tuple of int
        The left image stamp of every frame.
    n_left, n_right : int
        Image messages on the two topics.
    pose_source, mount_source : str
        Where the poses and the mount came from (``"odometry /odom"``, ``"tf odom <- base_link"``,
        ``"calibration"``, ...).
    left_topic, right_topic : str
        The image topics read.
    """

    layout = "ROS bag"

    def __init__(self, bag: str | os.PathLike, *, left_topic: str | None = None, right_topic: str | None = None,
                 camera_info_topics: tuple[str, str] | None = None, calibration: StereoCamera | None = None,
                 odom_topic: str | None = None, use_tf: bool = False, world_frame: str | None = None,
                 base_frame: str = "base_link", camera_frame: str | None = None, sync_tolerance_s: float = 0.02,
                 mount: CameraMount | None = None, rectified: bool = False, progress: bool = False,
                 truth=None) -> None:
        tolerance = _checks.finite_number("sync_tolerance_s", sync_tolerance_s, nonnegative=True)
        check_truth(truth)
        if odom_topic is not None and use_tf:
            raise ValueError("give an odometry topic or use TF for the pose, not both")
        if calibration is not None and not isinstance(calibration, StereoCamera):
            raise TypeError(f"calibration must be a StereoCamera, got {type(calibration).__name__}")
        if mount is not None and not isinstance(mount, CameraMount):
            raise TypeError(f"mount must be a CameraMount, got {type(mount).__name__}")
        picked = with_picked_topics(bag, dict(left_topic=left_topic, right_topic=right_topic, odom_topic=odom_topic,
                                              use_tf=use_tf, calibration=calibration,
                                              camera_info_topics=camera_info_topics))
        left_topic, right_topic, odom_topic = picked["left_topic"], picked["right_topic"], picked["odom_topic"]
        if truth is not None:                          # --no-truth / --truth FILE: not the bag's odometry
            odom_topic, use_tf = None, False
        if left_topic == right_topic:
            raise ValueError(f"left and right topics must differ, both are {left_topic!r}")
        self.bag, self.name, self.root = bag, str(bag), Path(bag)
        self._readings: weakref.WeakSet = weakref.WeakSet()
        self.left_topic, self.right_topic, self.rectified = left_topic, right_topic, bool(rectified)
        with _open_bag(bag) as reader:
            topics = {c.topic: c.msgtype for c in reader.connections}
            for topic, side in ((left_topic, "left"), (right_topic, "right")):
                _require_topic(topics, topic, f"{side} topic", IMAGE_TYPES)
            if calibration is None:
                camera_info_topics = _camera_info_topics(topics, left_topic, right_topic, camera_info_topics)
            if odom_topic is not None:
                _require_topic(topics, odom_topic, "odometry topic", (ODOMETRY_TYPE,))
            tf_topics = [t for t in TF_TOPICS if topics.get(t) in TF_TYPES]
            if (use_tf or camera_frame is not None) and not tf_topics:
                raise ValueError("TF requested but the bag has no /tf or /tf_static topic of type "
                                 "tf2_msgs/msg/TFMessage")
            stream = _read_stream(reader, left_topic=left_topic, right_topic=right_topic, odom_topic=odom_topic,
                                  tf_topics=tf_topics if use_tf or camera_frame is not None else ())
            self._pairs = _stereo_pairs(stream.stamps, left_topic, right_topic, tolerance)
            truth_poses = self._match_truth(truth, stream.stamps[left_topic]) if truth else None
            if calibration is None:
                calibration = _stereo_of_reader(reader, camera_info_topics)
        self.calibration = calibration
        self.stamps_ns = tuple(stream.stamps[left_topic][i] for i, _ in self._pairs)
        self.n_left, self.n_right = len(stream.stamps[left_topic]), len(stream.stamps[right_topic])
        self.poses, self.pose_source = _robot_poses(stream, list(self.stamps_ns), odom_topic=odom_topic, use_tf=use_tf,
                                                    world_frame=world_frame, base_frame=base_frame)
        self.mount, self.mount_source, self.pans = _mount_and_pans(
            stream.tf, list(self.stamps_ns), mount=mount, calibration=calibration, base_frame=base_frame,
            camera_frame=camera_frame)
        self.has_poses = odom_topic is not None or use_tf or truth_poses is not None
        if truth_poses is not None:
            self.poses, self.pose_source = [_pose_of(T) for T in truth_poses], f"ground truth {truth}"
            self.true_poses = tuple(truth_poses)
        elif truth is False:
            self.pose_source = "none (--no-truth: the odometry topic and TF not read)"
        self.n_frames = len(self._pairs)
        self.stamps_s = np.asarray(self.stamps_ns, dtype=np.float64) / 1e9
        if self.n_frames > 1:
            self.rate_hz = float(1.0 / np.median(np.diff(self.stamps_s))) if np.ptp(self.stamps_s) > 0 else None
        self.notes = tuple(note for note in (
            f"{self.n_left - self.n_frames} left and {self.n_right - self.n_frames} right images without a "
            "partner image left out" if max(self.n_left, self.n_right) > self.n_frames else "",
            "" if self.has_poses else "no odometry topic and no --tf: poses from visual odometry",
            self._truth_note) if note)

    _truth_note = ""

    def _match_truth(self, truth, left_ns: list[int]) -> list[np.ndarray]:
        """The poses of the file ``truth`` at the frames (nearest stamp within :data:`TRUTH_TOLERANCE_S`); the
        frames without one are left out."""
        stamps_ns, T = read_poses_file(truth)
        frames_s = np.array([left_ns[i] for i, _ in self._pairs], dtype=np.float64) / 1e9
        index = match_stamps(stamps_ns, frames_s, TRUTH_TOLERANCE_S)
        if not (index >= 0).any():
            raise ValueError(f"ground truth {truth}: no pose within {TRUTH_TOLERANCE_S * 1e3:g} ms of any of the "
                             f"{len(frames_s)} stereo pairs of {self.bag}")
        self._truth_note = (f"ground truth from {truth}: {int((index >= 0).sum())} of {len(frames_s)} frames got "
                            f"a pose within {TRUTH_TOLERANCE_S * 1e3:g} ms (poses of {TRUTH_FRAMES['ROS bag']})")
        self._pairs = [pair for pair, i in zip(self._pairs, index) if i >= 0]
        return [T[i] for i in index if i >= 0]

    @property
    def manifest(self) -> Manifest:
        """What the bag knows of its frames before they are read, as a recording without image files:
        every frame's stamp, pose and pan, the calibration and mount (for a run's metrics and views)."""
        truth = self.true_poses is not None
        frames = tuple(FrameRecord(pose=None, pose_3d=tuple(float(v) for v in pose), pan_rad=float(pan),
                                   true_pose_3d=tuple(float(v) for v in pose) if truth else None,
                                   stamp_s=ns / 1e9) for pose, pan, ns in zip(self.poses, self.pans, self.stamps_ns))
        return Manifest(root=self.root, calibration=self.calibration, calibration_path=self.root, mount=self.mount,
                        ground_truth_map=None, frames=frames, layout=self.layout, has_poses=self.has_poses,
                        notes=self.notes)

    def decoded(self) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
        """``(k, left, right)`` of every frame as decoded (:func:`image_from_message`: uint8 gray or BGR, uint16)."""
        with _open_bag(self.bag) as reader:
            yield from _decoded_pairs(reader, self._pairs, topics=(self.left_topic, self.right_topic),
                                      calibration=self.calibration)

    def close(self) -> None:
        """Close the bag of every iteration still open (idempotent)."""
        readings, self._readings = self._readings, weakref.WeakSet()
        for reading in list(readings):
            reading.close()

    def __iter__(self) -> Iterator[StereoFrame]:
        reading = self.decoded()
        self._readings.add(reading)
        for k, left, right in reading:
            pose = self.poses[k]
            yield StereoFrame(index=k, stamp_s=self.stamps_ns[k] / 1e9, left=frame_image(left),
                              right=frame_image(right), rectified=self.rectified,
                              T_world_from_base=T_from_position_quaternion(pose[:3], pose[3:]),
                              pan_rad=float(self.pans[k]))


def export_bag(bag: str | os.PathLike, out_dir: str | os.PathLike, *, progress: bool = True,
               **options) -> BagExport:
    """Write the stereo pairs of a bag as a dataset directory (manifest format, PNG images).

    Parameters
    ----------
    bag : path
        A ROS 1 ``.bag`` file or a ROS 2 bag directory (sqlite3 or mcap).
    out_dir : path
        New (or empty) directory; built beside it and renamed into place.
    progress : bool
        tqdm progress bar on stderr.
    **options
        Those of :class:`BagSource` (topics, calibration, pose source, TF frames, mount, ``rectified``):
        the dataset holds the frames the source yields, as decoded (8-bit or 16-bit PNG).
    """
    from tqdm.auto import tqdm

    note_inputs(bag_inputs(bag))
    check_output_dir("out_dir", out_dir, must_be_empty=True)
    source = BagSource(bag, **options)
    info = {"bag": str(Path(bag).resolve()), "left_topic": source.left_topic, "right_topic": source.right_topic,
            "pose_source": source.pose_source, "mount_source": source.mount_source,
            "stamps_ns": list(source.stamps_ns)}
    keys = ("left_rect", "right_rect") if source.rectified else ("left", "right")
    with staged_dataset(out_dir, calibration=source.calibration, mount=source.mount, calibration_name=CALIBRATION_NAME,
                        extra={"source": info}) as dataset, \
            tqdm(total=source.n_frames, desc="exporting", unit="frame", disable=not progress) as bar:
        for k, left, right in source.decoded():
            dataset.write(keys[0], k, left)
            dataset.write(keys[1], k, right)
            dataset.add_frame(k, pose=source.poses[k], pan_rad=source.pans[k], stamp_s=source.stamps_ns[k] / 1e9)
            bar.update(1)
            reached("frame")
    return BagExport(out_dir=Path(out_dir), n_frames=source.n_frames, n_left=source.n_left, n_right=source.n_right,
                     stamps_ns=source.stamps_ns, calibration=source.calibration, mount=source.mount,
                     mount_source=source.mount_source, pose_source=source.pose_source)


def _pose_of(T: np.ndarray) -> tuple[float, ...]:
    """The manifest's 3-D pose ``(x, y, z, qx, qy, qz, qw)`` of a 4x4 transform."""
    return _round_pose(pose_3d_of(T))


def _heading(T: np.ndarray, axis: int) -> float:
    return math.atan2(T[1, axis], T[0, axis])


def _optical_in_base(T_base_from_frame: np.ndarray, frame: str) -> np.ndarray:
    """The optical frame's pose from a TF frame's: an ``*optical*`` frame is one (x right, y down,
    z forward); any other camera frame is taken as the camera body (x forward, y left, z up, REP 103)."""
    if "optical" in frame:
        return T_base_from_frame
    T = np.eye(4)
    T[:3, :3] = R_BODY_FROM_OPTICAL
    return T_base_from_frame @ T
