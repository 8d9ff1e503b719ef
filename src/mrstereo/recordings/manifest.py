"""Recordings on disk: the dataset manifest shared by bags, synthetic worlds and the pipeline.

``DIR/manifest.yaml`` (calibration, mount, ground-truth map, frames; paths relative to ``DIR``),
written with :func:`staged_dataset` by ``mrstereo export`` and the synthetic world, read by
``map``, ``batch`` and the pipeline. The layout: docs/dataset.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import contextlib
import math
import os
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from .. import _limits
from ..camera import CameraMount, StereoCamera, mount_entry, read_mount_entry, read_stereo, write_stereo
from ..io import Inputs, matching_image, note_inputs, read_image, read_yaml, staged_new_dir, write_image, write_pfm
from ..profiling import stage
from ..transforms import T_from_planar, T_from_position_quaternion, planar_from_T, quaternion_from_rotation

__all__ = ["FrameRecord", "Manifest", "read_manifest", "write_manifest", "frame_pair", "pose_3d_of", "staged_dataset",
           "DatasetWriter", "MANIFEST_NAME", "IMAGE_KEYS", "GT_KEYS", "rebased"]

MANIFEST_NAME = "manifest.yaml"
IMAGE_KEYS = ("left", "right", "left_rect", "right_rect")
GT_KEYS = ("gt_disparity", "gt_labels")


@dataclass(frozen=True)
class FrameRecord:
    """One frame of a dataset: absolute image paths (None when absent), stamp, poses and head pan.

    ``pose`` ``(x_m, y_m, yaw_rad)`` is the robot's odometry, ``true_pose`` the truth when known;
    ``pose_3d`` / ``true_pose_3d`` the same in 3-D, ``(x, y, z, qx, qy, qz, qw)`` (TUM order), of
    which the planar ones are the projection; ``stamp_s`` in seconds (None: unknown).
    """

    pose: tuple[float, float, float] | None
    pan_rad: float = 0.0
    left: Path | None = None
    right: Path | None = None
    left_rect: Path | None = None
    right_rect: Path | None = None
    gt_disparity: Path | None = None
    gt_labels: Path | None = None
    true_pose: tuple[float, float, float] | None = None
    stamp_s: float | None = None
    pose_3d: tuple[float, ...] | None = None
    true_pose_3d: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        for planar, full in (("pose", "pose_3d"), ("true_pose", "true_pose_3d")):
            T = getattr(self, full)
            if T is None:
                if planar == "pose" and self.pose is None:
                    raise ValueError("a frame needs pose (x_m, y_m, yaw_rad) or pose_3d")
                continue
            projected = tuple(float(v) for v in planar_from_T(_T_of_3d(full, T)))
            given = getattr(self, planar)
            if given is None:
                object.__setattr__(self, planar, projected)
            elif not np.allclose(given[:2], projected[:2], atol=1e-6) or \
                    abs(math.remainder(given[2] - projected[2], math.tau)) > 1e-6:
                raise ValueError(f"{planar} {tuple(given)} is not the floor projection {projected} of {full}: "
                                 f"give both from the same pose (or {full}=None)")

    @property
    def has_raw(self) -> bool:
        return self.left is not None and self.right is not None

    @property
    def has_rectified(self) -> bool:
        return self.left_rect is not None and self.right_rect is not None

    @property
    def T_world_from_base(self) -> np.ndarray:
        """The given pose as a 4x4 transform: ``pose_3d`` when known, else the planar ``pose``."""
        return _T_of_3d("pose_3d", self.pose_3d) if self.pose_3d is not None else T_from_planar(*self.pose)

    @property
    def T_world_from_base_true(self) -> np.ndarray | None:
        """The true pose as a 4x4 transform (3-D when known), None without one."""
        if self.true_pose_3d is not None:
            return _T_of_3d("true_pose_3d", self.true_pose_3d)
        return None if self.true_pose is None else T_from_planar(*self.true_pose)


def pose_3d_of(T_world_from_base) -> tuple[float, ...]:
    """``(x, y, z, qx, qy, qz, qw)`` of a 4x4 pose (the manifest's and TUM's order)."""
    T = np.asarray(T_world_from_base, dtype=np.float64)
    return tuple(float(v) for v in (*T[:3, 3], *quaternion_from_rotation(T[:3, :3])))


def _T_of_3d(name: str, pose) -> np.ndarray:
    values = tuple(pose) if isinstance(pose, (list, tuple, np.ndarray)) else ()
    if len(values) != 7 or not all(isinstance(v, (int, float, np.floating)) and math.isfinite(v) for v in values):
        raise ValueError(f"{name} must be 7 finite numbers (x, y, z, qx, qy, qz, qw), got {pose!r}")
    return T_from_position_quaternion(values[:3], values[3:])


MAX_SPEED_M_S = 100.0
"""The fastest step of given poses taken without a warning (360 km/h: no ground robot, no car on a road)."""
MAX_STEP_M = 50.0
"""Without stamps: the longest step of given poses from one frame to the next taken without a warning."""


@dataclass(frozen=True)
class Manifest:
    """A dataset read from ``manifest.yaml``.

    Attributes
    ----------
    root : Path
        The dataset directory (paths in the file are relative to it).
    calibration : StereoCamera
        Stereo calibration read from ``calibration_path``.
    calibration_path : Path
    mount : CameraMount or None
        Camera mount: the manifest's ``mount:`` (6-DoF) or ``rig:`` (the paper's height and
        tilt of the rectified camera), else the calibration's; None when no mount is known
        (the floor is then estimated, :func:`mrstereo.pipeline.build_map`).
    ground_truth_map : Path or None
        ROS map YAML of the true map.
    frames : tuple of FrameRecord
    layout : str
        What was read: ``"dataset"`` (this format), ``"KITTI odometry"``, ``"EuRoC/ASL"``,
        ``"image folders"``, ``"ROS bag"`` (:mod:`mrstereo.recordings.layouts`).
    has_poses : bool
        False when the recording knows no pose: every frame's ``pose`` is then the origin and a map
        takes its poses from visual odometry.
    pose_frame_mount : CameraMount or None
        The left camera in the frame the poses are of, when that frame is not a base on the floor
        (EuRoC's body frame, a drone's IMU): the run moves the poses to the floor frame it finds
        under the camera (:func:`rebased`). None: the poses are of the base of ``mount``.
    notes : tuple of str
        What the reader left out or assumed, one line each (printed by ``mrstereo info``).
    """

    root: Path
    calibration: StereoCamera
    calibration_path: Path
    mount: CameraMount | None
    ground_truth_map: Path | None
    frames: tuple[FrameRecord, ...]
    layout: str = "dataset"
    has_poses: bool = True
    pose_frame_mount: CameraMount | None = None
    notes: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        previous = None
        for k, frame in enumerate(self.frames):
            s = frame.stamp_s
            if s is None:
                continue
            if not math.isfinite(s):
                raise ValueError(f"{self.kind} {self.root}: frame {k} has the stamp {s!r}: stamps are finite seconds")
            if previous is not None and not s > previous[1]:
                raise ValueError(f"{self.kind} {self.root}: frame {k} has the stamp {s:.9g} s, not after frame "
                                 f"{previous[0]}'s {previous[1]:.9g} s: the stamps must increase")
            previous = (k, s)
        if self.has_poses and len(self.frames) > 1:
            self._warn_pose_jump()

    def _warn_pose_jump(self) -> None:
        """A warning at the first step of the given poses faster than :data:`MAX_SPEED_M_S` (with stamps) or longer
        than :data:`MAX_STEP_M` (without): a broken odometry, which the run would map as it is."""
        xyz = np.array([f.pose_3d[:3] if f.pose_3d is not None else (*f.pose[:2], 0.0) for f in self.frames])
        steps = np.linalg.norm(np.diff(xyz, axis=0), axis=1)
        stamps = self.stamps_s
        allowed = MAX_SPEED_M_S * np.diff(stamps) if stamps is not None else np.full(len(steps), MAX_STEP_M)
        over = np.flatnonzero(~(steps <= allowed))
        if over.size:
            k = int(over[0])
            speed = f", {steps[k] / (stamps[k + 1] - stamps[k]):.3g} m/s" if stamps is not None else ""
            warnings.warn(f"{self.kind} {self.root}: the given poses jump {steps[k]:.4g} m from frame {k} to frame "
                          f"{k + 1}{speed}: the odometry is broken there and the run maps it as it is (--odometry "
                          "visual replaces it)")

    @property
    def stamps_s(self) -> np.ndarray | None:
        """Every frame's stamp (seconds), or None when a frame has none."""
        stamps = [f.stamp_s for f in self.frames]
        return None if any(s is None for s in stamps) else np.array(stamps, dtype=np.float64)

    @property
    def kind(self) -> str:
        """What the recording is called in messages: ``"dataset"`` or ``"<layout> recording"``."""
        return "dataset" if self.layout == "dataset" else f"{self.layout} recording"

    def inputs(self) -> Inputs:
        """What a run over the dataset reads: its folder (no output may go inside it), the manifest, the
        calibration, the ground-truth map and every frame's files (wherever they lie)."""
        from ..mapping.rosmap import ros_map_files

        inputs = Inputs(folders=[self.root], kind=self.kind)
        inputs.add(self.root / MANIFEST_NAME, self.calibration_path)
        if self.ground_truth_map is not None:
            inputs.add(*ros_map_files(self.ground_truth_map))
        for r in self.frames:
            inputs.add(r.left, r.right, r.left_rect, r.right_rect, r.gt_disparity, r.gt_labels, resolved=True)
        return inputs


def rebased(manifest: Manifest, mount: CameraMount) -> Manifest:
    """The recording with its poses moved to the base of ``mount``, the camera staying where it is.

    With the camera at ``P = T_posed_from_cam`` (``pose_frame_mount``, else ``mount``) and at
    ``M = T_base_from_cam`` on the new base, every pose becomes ``T_world_from_posed P M^-1``.
    """
    from dataclasses import replace

    posed = manifest.pose_frame_mount if manifest.pose_frame_mount is not None else manifest.mount
    if not manifest.has_poses or posed is None or posed == mount:
        return replace(manifest, mount=mount, pose_frame_mount=None)
    shift = posed.T_base_from_cam @ np.linalg.inv(mount.T_base_from_cam)
    frames = []
    for f in manifest.frames:
        true = None if f.T_world_from_base_true is None else pose_3d_of(f.T_world_from_base_true @ shift)
        frames.append(replace(f, pose=None, pose_3d=pose_3d_of(f.T_world_from_base @ shift),
                              true_pose=None, true_pose_3d=true))
    return replace(manifest, mount=mount, pose_frame_mount=None, frames=tuple(frames))


def _fail(path: Path, message: str) -> ValueError:
    return ValueError(f"manifest {path}: {message}")


def _existing_file(root: Path, rel, what: str, manifest: Path) -> Path:
    if not isinstance(rel, str) or not rel:
        raise _fail(manifest, f"{what} must be a file path, got {rel!r}")
    path = (root / rel).resolve()
    if not path.is_file():
        raise FileNotFoundError(f"manifest {manifest}: {what} not found: {path}")
    return path


def read_manifest(path_or_dir: str | os.PathLike) -> Manifest:
    """Read and validate a dataset manifest (a directory or its ``manifest.yaml``).

    Raises
    ------
    FileNotFoundError
        The manifest, the calibration or a referenced image is missing.
    ValueError
        Corrupt YAML, no frames, a frame without a raw or rectified image pair,
        a bad pose or pan, or a bad mount -- naming the frame and field.
    """
    path = Path(path_or_dir)
    if path.is_dir():
        path = path / MANIFEST_NAME
    if not path.is_file():
        raise FileNotFoundError(f"dataset manifest not found: {path}")
    data = read_yaml(path, "manifest")
    if not isinstance(data, dict):
        raise _fail(path, "expected a mapping with 'calibration' and 'frames'")
    root = path.parent.resolve()
    if "calibration" not in data:
        raise _fail(path, "missing 'calibration: <stereo YAML path>'")
    calib_path = _existing_file(root, data["calibration"], "calibration", path)
    calibration = read_stereo(calib_path)
    mount = read_mount_entry(data, where=f"manifest {path}", R_rect_from_cam=calibration.left.R)
    if mount is None:
        mount = calibration.mount
    gt_map = None
    if data.get("ground_truth_map") is not None:
        gt_map = _existing_file(root, data["ground_truth_map"], "ground_truth_map", path)
    frames_data = data.get("frames")
    if not isinstance(frames_data, list) or not frames_data:
        raise _fail(path, "'frames' must be a non-empty list")
    _limits.within("MRSTEREO_MAX_FRAMES", len(frames_data), f"manifest {path}: frames")
    frames = tuple(_frame(root, path, k, item) for k, item in enumerate(frames_data))
    manifest = Manifest(root=root, calibration=calibration, calibration_path=calib_path, mount=mount,
                        ground_truth_map=gt_map, frames=frames)
    note_inputs(manifest.inputs())
    return manifest


def _frame(root: Path, manifest: Path, k: int, item) -> FrameRecord:
    where = f"frame {k}"
    if not isinstance(item, dict):
        raise _fail(manifest, f"{where} must be a mapping")
    unknown = set(item) - set(IMAGE_KEYS) - set(GT_KEYS) - {"pose", "pan_rad", "true_pose", "stamp_s"}
    if unknown:
        raise _fail(manifest, f"{where}: unknown field(s) {sorted(unknown)}")
    poses = {}
    for key in ("pose", "true_pose"):
        if key == "pose" or item.get(key) is not None:
            poses[key], poses[f"{key}_3d"] = _pose_entry(manifest, where, key, item.get(key))
    pan = item.get("pan_rad", 0.0)
    if isinstance(pan, bool) or not isinstance(pan, (int, float)) or not math.isfinite(pan):
        raise _fail(manifest, f"{where}: pan_rad must be a finite number, got {pan!r}")
    stamp = item.get("stamp_s")
    if stamp is not None and (isinstance(stamp, bool) or not isinstance(stamp, (int, float))
                              or not math.isfinite(stamp)):
        raise _fail(manifest, f"{where}: stamp_s must be a finite number (seconds), got {stamp!r}")
    files = {key: _existing_file(root, item[key], f"{where}: {key}", manifest)
             for key in (*IMAGE_KEYS, *GT_KEYS) if item.get(key) is not None}
    record = FrameRecord(pan_rad=float(pan), stamp_s=None if stamp is None else float(stamp), **poses, **files)
    for a, b in (("left", "right"), ("left_rect", "right_rect")):
        if (a in files) != (b in files):
            raise _fail(manifest, f"{where}: '{a}' and '{b}' must be given together")
    if not (record.has_raw or record.has_rectified):
        raise _fail(manifest, f"{where}: needs a raw pair (left, right) or a rectified pair "
                              "(left_rect, right_rect)")
    return record


def _pose_entry(manifest: Path, where: str, key: str, pose):
    """``(planar, 3-D or None)`` of a pose entry: ``[x_m, y_m, yaw_rad]`` or ``[x, y, z, qx, qy, qz, qw]``."""
    if (not isinstance(pose, (list, tuple)) or len(pose) not in (3, 7)
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in pose)
            or not all(math.isfinite(v) for v in pose)):
        raise _fail(manifest, f"{where}: {key} must be [x_m, y_m, yaw_rad] or [x, y, z, qx, qy, qz, qw] "
                              f"(finite numbers), got {pose!r}")
    if len(pose) == 3:
        return tuple(float(v) for v in pose), None
    if sum(v * v for v in pose[3:]) < 1e-12:
        raise _fail(manifest, f"{where}: {key} has a zero quaternion")
    full = tuple(float(v) for v in pose)
    return tuple(float(v) for v in planar_from_T(_T_of_3d(key, full))), full


def write_manifest(path: str | os.PathLike, *, calibration: str, mount: CameraMount | None,
                   frames: list[dict], ground_truth_map: str | None = None, extra: dict | None = None) -> None:
    """Write ``manifest.yaml``; ``frames`` are dicts of relative paths, ``pose``, ``pan_rad`` (and optional
    ``true_pose``, ``stamp_s``; a pose is ``[x_m, y_m, yaw_rad]`` or 3-D ``[x, y, z, qx, qy, qz, qw]``).

    ``mount`` is written as ``mount: {xyz, rpy}``, or not at all (None).
    """
    data = {"calibration": calibration, **mount_entry(mount)}
    if ground_truth_map is not None:
        data["ground_truth_map"] = ground_truth_map
    if extra:
        data.update(extra)
    data["frames"] = frames
    Path(path).write_text(yaml.safe_dump(data, sort_keys=False, default_flow_style=None))


class DatasetWriter:
    """The files of a dataset being written by :func:`staged_dataset`: images, ground truth and frames."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.frames: list[dict] = []
        self.ground_truth_map: str | None = None
        self._files: dict[int, dict[str, str]] = {}

    def write(self, key: str, index: int, array: np.ndarray) -> None:
        """Frame ``index``'s file ``key``: an image (:data:`IMAGE_KEYS`, ``gt_labels``) or ``gt_disparity`` (PFM)."""
        if key not in (*IMAGE_KEYS, *GT_KEYS):
            raise ValueError(f"key must be one of {', '.join((*IMAGE_KEYS, *GT_KEYS))}, got {key!r}")
        relative = f"{key}/{index:06d}.{'pfm' if key == 'gt_disparity' else 'png'}"
        (write_pfm if key == "gt_disparity" else write_image)(self.root / relative, array)
        self._files.setdefault(index, {})[key] = relative

    def write_ground_truth_map(self, ros_map) -> None:
        """The ground-truth map (a :class:`mrstereo.mapping.rosmap.RosMap`) as ``gt_map.yaml`` + ``.pgm``."""
        from ..mapping.rosmap import write_ros_map

        write_ros_map(self.root / "gt_map.yaml", ros_map)
        self.ground_truth_map = "gt_map.yaml"

    def add_frame(self, index: int, *, pose, pan_rad: float = 0.0, true_pose=None, stamp_s: float | None = None
                  ) -> None:
        """The manifest entry of frame ``index``: the files written for it, its stamp, pose (planar or 3-D)
        and head pan."""
        files = self._files.pop(index, {})
        entry = {key: files[key] for key in (*IMAGE_KEYS, *GT_KEYS) if key in files}
        if stamp_s is not None:
            entry["stamp_s"] = float(stamp_s)
        entry["pose"] = [float(v) for v in pose]
        if true_pose is not None:
            entry["true_pose"] = [float(v) for v in true_pose]
        entry["pan_rad"] = float(pan_rad)
        self.frames.append(entry)


@contextlib.contextmanager
def staged_dataset(out_dir: str | os.PathLike, *, calibration: StereoCamera, mount: CameraMount | None,
                   calibration_name: str = "calibration.yaml", extra: dict | None = None) -> Iterator[DatasetWriter]:
    """Write a new dataset folder: the block adds frames, the end writes calibration and manifest.

    Built in a hidden folder and renamed into place on success (:func:`mrstereo.io.staged_new_dir`).

    Parameters
    ----------
    out_dir : path
        New (or empty) folder.
    calibration : StereoCamera
        Written as ``calibration_name`` (:func:`mrstereo.camera.write_stereo`).
    mount : CameraMount or None
        The manifest's ``mount:`` (None: none known).
    calibration_name : str
        File name of the calibration in the folder.
    extra : dict, optional
        Further top-level manifest entries (e.g. ``generator:``, ``source:``).
    """
    with staged_new_dir(out_dir) as tmp:
        dataset = DatasetWriter(tmp)
        yield dataset
        write_stereo(tmp / calibration_name, calibration)
        write_manifest(tmp / MANIFEST_NAME, calibration=calibration_name, mount=mount, frames=dataset.frames,
                       ground_truth_map=dataset.ground_truth_map, extra=extra)


def frame_pair(record: FrameRecord, *, prefer_raw: bool = False) -> tuple[np.ndarray, np.ndarray, bool]:
    """Load a frame's pair ``(left, right, rectified)``: the rectified one when listed.

    ``prefer_raw`` takes the raw pair even when a rectified one is listed (to test an estimated
    calibration). 16-bit images are scaled by :func:`matching_image`.
    """
    if not isinstance(record, FrameRecord):
        raise TypeError(f"record must be a FrameRecord, got {type(record).__name__}")
    rectified = record.has_rectified and not (prefer_raw and record.has_raw)
    left, right = (record.left_rect, record.right_rect) if rectified else (record.left, record.right)
    with stage("read"):
        return matching_image(read_image(left)), matching_image(read_image(right)), rectified
