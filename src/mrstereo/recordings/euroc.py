"""The EuRoC MAV / ASL folder layout as a recording: stereo frames, stamps, calibration and truth.

``ROOT`` (the folder holding ``mav0/`` or ``mav0/`` itself) has ``cam0/`` and ``cam1/`` (``data.csv``,
``data/<ns>.png``, ``sensor.yaml``) and optionally ``state_groundtruth_estimate0/data.csv``. Images
are paired by stamp, the calibration is the two ``sensor.yaml`` (a raw pair), the truth is the body
(IMU) pose interpolated to each frame; frames outside its span are left out. No mount: the floor is
found when mapping (``Manifest.pose_frame_mount``). The layout: docs/dataset.md.
Conventions: docs/conventions.md.

References
----------
M. Burri, J. Nikolic, P. Gohl, T. Schneider, J. Rehder, S. Omari, M. W. Achtelik, R. Siegwart.
The EuRoC micro aerial vehicle datasets. IJRR 35(10), 2016.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..camera import CameraMount
from ..camera.formats import euroc_body_from_camera, import_calibration
from ..io import note_inputs, read_text
from ..transforms import quaternion_from_rotation
from .bag import TransformTrack, pair_by_stamp
from .manifest import FrameRecord, Manifest, pose_3d_of
from .truth import check_truth, read_poses_file, with_truth

__all__ = ["read_euroc", "is_euroc", "GROUND_TRUTH_CSV"]

GROUND_TRUTH_CSV = Path("state_groundtruth_estimate0") / "data.csv"
_PAIR_TOLERANCE_NS = 1_000_000          # 1 ms: the two cameras of a EuRoC rig are triggered together
_TRUTH_EDGE_NS = 10_000_000             # a frame up to 10 ms outside the truth's span still gets its end pose


def _mav_dir(path: Path) -> Path | None:
    for folder in (path, path / "mav0"):
        if (folder / "cam0" / "data.csv").is_file() and (folder / "cam1" / "data.csv").is_file():
            return folder
    return None


def is_euroc(path: str | os.PathLike) -> bool:
    """True when ``path`` is a EuRoC/ASL folder (``mav0/`` or its parent) with cam0 and cam1."""
    path = Path(path)
    return path.is_dir() and _mav_dir(path) is not None


def _csv_rows(path: Path, what: str) -> list[list[str]]:
    rows = []
    for line in read_text(path, what).splitlines():
        line = line.strip()
        if line and not line.startswith("#"):
            rows.append([v.strip() for v in line.split(",")])
    return rows


def _stamp_ns(text: str, path: Path, row: int) -> int:
    """A stamp in nanoseconds that numpy's int64 (and a ROS time) holds."""
    stamp = int(text)
    if not 0 <= stamp < 2**63:
        raise ValueError(f"{path}: row {row} has the stamp {text} ns, beyond the 2^63 ns (year 2262) a stamp may be")
    return stamp


def _camera_list(cam: Path) -> tuple[np.ndarray, list[Path]]:
    """Stamps [ns] and image paths of ``cam/data.csv``."""
    csv = cam / "data.csv"
    stamps, files = [], []
    for n, row in enumerate(_csv_rows(csv, "EuRoC camera list"), 1):
        if len(row) < 2 or not row[0].isdigit():
            raise ValueError(f"EuRoC camera list {csv}: row {n} must be 'timestamp_ns,filename', got {','.join(row)!r}")
        stamp = _stamp_ns(row[0], csv, n)
        if stamps and stamp <= stamps[-1]:
            raise ValueError(f"EuRoC camera list {csv}: row {n} has the stamp {stamp} ns, not after row {n - 1}'s "
                             f"{stamps[-1]} ns: the stamps must increase")
        stamps.append(stamp)
        files.append(cam / "data" / row[1])
    if not stamps:
        raise ValueError(f"EuRoC camera list {csv} lists no image")
    return np.array(stamps, dtype=np.int64), files


def _truth_track(path: Path) -> TransformTrack:
    """The body poses of ``state_groundtruth_estimate0/data.csv`` (t, p xyz, q wxyz, ...)."""
    try:
        stamps_ns, T = read_poses_file(path)
    except ValueError as exc:
        raise ValueError(f"{exc}; --no-truth (truth=False) reads the folder without it") from None
    return TransformTrack.from_samples([(int(t), T_k[:3, 3], quaternion_from_rotation(T_k[:3, :3]))
                                       for t, T_k in zip(stamps_ns, T)])


def read_euroc(path: str | os.PathLike, *, truth=None) -> Manifest:
    """Read a EuRoC/ASL folder as a recording (a :class:`Manifest`).

    Parameters
    ----------
    path : path
        ``mav0/`` or the folder holding it.
    truth : None, False or path
        None: the folder's ``state_groundtruth_estimate0/data.csv``; False: no truth (not even read);
        a TUM or EuRoC csv file of body poses instead (:func:`mrstereo.recordings.truth.with_truth`).

    Returns
    -------
    Manifest
        Frames (raw ``left``/``right`` of cam0/cam1, ``stamp_s``; with truth ``pose_3d`` =
        ``true_pose_3d`` = the body pose), the calibration of the two ``sensor.yaml``, no mount,
        ``pose_frame_mount`` = cam0's ``T_BS`` (with truth), ``layout="EuRoC/ASL"``.

    Raises
    ------
    FileNotFoundError
        A listed image or a sensor.yaml is missing.
    ValueError
        Not a EuRoC folder, unreadable lists or truth, no pair of left/right stamps.
    """
    check_truth(truth)
    root = Path(path)
    mav = _mav_dir(root) if root.is_dir() else None
    if mav is None:
        raise ValueError(f"{root} is not a EuRoC/ASL folder: no mav0/cam0/data.csv and mav0/cam1/data.csv")
    sensors = [mav / cam / "sensor.yaml" for cam in ("cam0", "cam1")]
    for sensor in sensors:
        if not sensor.is_file():
            raise FileNotFoundError(f"EuRoC camera calibration not found: {sensor}")
    calibration = import_calibration(sensors).stereo
    T_body_from_cam0 = euroc_body_from_camera(sensors[0])
    (left_ns, left_files), (right_ns, right_files) = _camera_list(mav / "cam0"), _camera_list(mav / "cam1")
    pairs = pair_by_stamp(left_ns, right_ns, tolerance_ns=_PAIR_TOLERANCE_NS)
    if not pairs:
        raise ValueError(f"{mav}: no cam0 and cam1 images within {_PAIR_TOLERANCE_NS / 1e6:g} ms of each other")
    notes = []
    if len(pairs) < max(len(left_ns), len(right_ns)):
        notes.append(f"{len(left_ns) - len(pairs)} cam0 and {len(right_ns) - len(pairs)} cam1 images without a "
                     "partner image left out")
    truth_csv = mav / GROUND_TRUTH_CSV
    track = _truth_track(truth_csv) if truth is None and truth_csv.is_file() else None
    if track is not None:
        lo, hi = int(track.stamps_ns[0]) - _TRUTH_EDGE_NS, int(track.stamps_ns[-1]) + _TRUTH_EDGE_NS
        inside = [(i, j) for i, j in pairs if lo <= left_ns[i] <= hi]
        if not inside:
            raise ValueError(f"{truth_csv}: no image lies within the ground truth's time span")
        if len(inside) < len(pairs):
            notes.append(f"{len(pairs) - len(inside)} frames outside the ground truth's time span left out")
        pairs = inside
    elif truth is None:
        notes.append(f"no ground truth ({GROUND_TRUTH_CSV}): poses from visual odometry")
    frames = []
    for i, j in pairs:
        for image in (left_files[i], right_files[j]):
            if not image.is_file():
                raise FileNotFoundError(f"EuRoC image not found: {image}")
        pose = None if track is None else pose_3d_of(track.at(int(left_ns[i])))
        frames.append(FrameRecord(pose=(0.0, 0.0, 0.0) if pose is None else None, pose_3d=pose, true_pose_3d=pose,
                                  left=left_files[i].resolve(), right=right_files[j].resolve(),
                                  stamp_s=int(left_ns[i]) / 1e9))
    manifest = Manifest(root=mav.resolve(), calibration=calibration, calibration_path=sensors[0].resolve(), mount=None,
                        ground_truth_map=None, frames=tuple(frames), layout="EuRoC/ASL", has_poses=track is not None,
                        pose_frame_mount=CameraMount(T_body_from_cam0) if track is not None else None,
                        notes=tuple(notes))
    note_inputs(manifest.inputs().add(*sensors, mav / "cam0" / "data.csv", mav / "cam1" / "data.csv",
                                      truth_csv if track is not None else None))
    return with_truth(manifest, truth, pose_frame_mount=CameraMount(T_body_from_cam0))
