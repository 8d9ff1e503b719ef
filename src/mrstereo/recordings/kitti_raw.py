"""The KITTI raw layout as a recording: the rectified gray pair, real stamps and the OXTS truth.

``DATE/`` holds ``calib_cam_to_cam.txt``, ``calib_imu_to_velo.txt``, ``calib_velo_to_cam.txt`` and
``DATE_drive_NNNN_sync/`` with ``image_00/data/*.png``, ``image_01/data/*.png`` (rectified, gray
cameras 0 and 1), ``image_00/timestamps.txt`` and ``oxts/data/*.txt`` (GPS/IMU records).
:func:`read_kitti_raw` returns a :class:`~mrstereo.recordings.manifest.Manifest`:

- the calibration: ``P_rect_00`` / ``P_rect_01`` as a pre-rectified pair (``P_rect_01[0, 3] = -fx b``);
- the stamps: the left camera's ``timestamps.txt`` (UTC, seconds since 1970);
- the base: the OXTS unit's frame (x forward, y left, z up, as REP 103) moved down to the road by the
  unit's height (:data:`OXTS_HEIGHT_M`); its pose at every frame from the OXTS record as the KITTI
  devkit's ``convertOxtsToPose`` makes it (Mercator projection scaled by the cosine of the first
  latitude, ``R = Rz(yaw) Ry(pitch) Rx(roll)``), moved from the record's stamp to the image's (the
  synced records are the 100 Hz unit's nearest, up to 5 ms off: 14 cm at 100 km/h) along the record's
  own velocity and angular rates, relative to the first frame (the first pose is the identity); these
  are the frames' given and true poses;
- the mount: the rectified left camera in that base, through the calibration chain
  ``T_rect_from_imu = R_rect_00 T_cam0_from_velo T_velo_from_imu``.

The layout: docs/dataset.md ("KITTI raw drives"). Conventions: docs/conventions.md.

References
----------
A. Geiger, P. Lenz, C. Stiller, R. Urtasun. Vision meets robotics: the KITTI dataset. IJRR 32(11), 2013
(the sensor setup, the OXTS record format and the devkit).
"""
from __future__ import annotations

import math
import os
import re
from pathlib import Path

import numpy as np

from .. import _limits
from ..camera.mount import CameraMount
from ..io import note_inputs, read_image, read_text
from ..transforms import T_from_R_t, rotation_from_rpy, rotations_from_rvecs
from .kitti import calib_rows, frame_numbers, stereo_from_projections
from .manifest import FrameRecord, Manifest, pose_3d_of
from .truth import camera_to_base, check_truth, with_truth

__all__ = ["read_kitti_raw", "is_kitti_raw", "oxts_poses", "oxts_velocity_positions", "OXTS_HEIGHT_M",
           "EARTH_RADIUS_M"]

OXTS_HEIGHT_M = 0.93
"""Height of the OXTS RT 3003 unit above the road [m] (the KITTI car's sensor setup, Geiger et al. 2013)."""

EARTH_RADIUS_M = 6378137.0
"""The equatorial radius of the devkit's Mercator projection (WGS 84) [m]."""

_CALIB_NAMES = ("calib_cam_to_cam.txt", "calib_imu_to_velo.txt", "calib_velo_to_cam.txt")
_DRIVE = re.compile(r".*_drive_\d+_sync$")


def _is_drive(path: Path) -> bool:
    return (path / "image_00" / "data").is_dir() and (path / "image_01" / "data").is_dir()


def _drive_dir(path: Path, drive: str | None) -> Path:
    """The drive folder of a date folder (the one, or the one named ``drive``), or ``path`` itself."""
    if _is_drive(path):
        return path
    found = sorted(p for p in path.iterdir() if p.is_dir() and _DRIVE.match(p.name) and _is_drive(p)) \
        if path.is_dir() else []
    if drive is not None:
        named = [p for p in found if p.name == drive or p.name.endswith(f"_drive_{drive}_sync")]
        if not named:
            raise FileNotFoundError(f"KITTI raw drive {drive!r} not found in {path} "
                                    f"(drives: {', '.join(p.name for p in found) or 'none'})")
        return named[0]
    if len(found) != 1:
        raise ValueError(f"{path} holds {len(found)} KITTI raw drives ({', '.join(p.name for p in found) or 'none'}): "
                         "give the drive folder")
    return found[0]


def is_kitti_raw(path: str | os.PathLike) -> bool:
    """True for a KITTI raw drive folder (``image_00/data``, ``image_01/data``, the calibration files in its
    parent) or a date folder holding the calibration files and ``*_drive_NNNN_sync/`` folders."""
    path = Path(path)
    if not path.is_dir():
        return False
    if _is_drive(path):
        return (path.parent / _CALIB_NAMES[0]).is_file()
    return (path / _CALIB_NAMES[0]).is_file() and any(_DRIVE.match(p.name) and _is_drive(p) for p in path.iterdir())


def _rigid(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``[R t]`` with R made orthonormal (the files hold 7 digits)."""
    u, _, vt = np.linalg.svd(R.reshape(3, 3))
    return T_from_R_t(u @ vt, t)


def _T_rect_from_imu(date: Path) -> np.ndarray:
    """The rectified left camera from the OXTS unit: ``R_rect_00 T_cam0_from_velo T_velo_from_imu``."""
    rect = calib_rows(date / _CALIB_NAMES[0], {"R_rect_00": 9})
    velo_imu = calib_rows(date / _CALIB_NAMES[1], {"R": 9, "T": 3})
    cam_velo = calib_rows(date / _CALIB_NAMES[2], {"R": 9, "T": 3})
    return (_rigid(rect["R_rect_00"], np.zeros(3)) @ _rigid(cam_velo["R"], cam_velo["T"])
            @ _rigid(velo_imu["R"], velo_imu["T"]))


def oxts_poses(records: np.ndarray, shift_s=None) -> np.ndarray:
    """``T_first_from_oxts`` (N, 4, 4) of OXTS records (N, >= 6: lat, lon [deg], alt [m], roll, pitch, yaw [rad];
    >= 20 with ``shift_s``: ... vn, ve [m/s] at 6, 7, vu at 10, wx, wy, wz [rad/s] at 17-19).

    The KITTI devkit's ``convertOxtsToPose``: the Mercator projection scaled by ``cos(lat_0)`` (metres
    near the first latitude: x east, y north), altitude up, ``R = Rz(yaw) Ry(pitch) Rx(roll)``; every
    pose relative to the first, which is the identity. ``shift_s`` (N,) [s]: each pose first moved that
    far in time along its record's own motion, the position by ``(ve, vn, vu) shift``, the attitude by
    ``Exp((wx, wy, wz) shift)`` (rates in the unit's axes): the pose at an image's stamp of a record
    stamped a few ms from it.
    """
    records = np.asarray(records, dtype=np.float64)
    lat, lon, alt = records[:, 0], records[:, 1], records[:, 2]
    scale = math.cos(math.radians(lat[0]))
    x = scale * EARTH_RADIUS_M * np.radians(lon)
    y = scale * EARTH_RADIUS_M * np.log(np.tan(np.radians(90.0 + lat) / 2.0))
    R = rotation_from_rpy(records[:, 3], records[:, 4], records[:, 5])
    t = np.stack([x, y, alt], axis=1)
    if shift_s is not None:
        shift = np.asarray(shift_s, dtype=np.float64).reshape(-1, 1)
        t = t + records[:, [7, 6, 10]] * shift                   # (ve, vn, vu): east, north, up
        R = R @ rotations_from_rvecs(records[:, 17:20] * shift)
    T = np.zeros((len(records), 4, 4))
    T[:, :3, :3] = R[0].T @ R                                  # inv(T_0) T_k, the large offsets taken first
    T[:, :3, 3] = (t - t[0]) @ R[0]
    T[:, 3, 3] = 1.0
    return T


def oxts_velocity_positions(records: np.ndarray, stamps_s) -> np.ndarray:
    """The positions (N, 3) of :func:`oxts_poses` (in the first pose's axes) from the records' velocities
    ``(ve, vn, vu)`` integrated over ``stamps_s`` (trapezoids) instead of their GPS positions: the unit's own
    dead reckoning, to measure the positions' noise from frame to frame (their accuracy, ``pos_accuracy``,
    is 2 cm with RTK and metres without; the velocities' some cm/s)."""
    records = np.asarray(records, dtype=np.float64)
    v = records[:, [7, 6, 10]] @ rotation_from_rpy(*records[0, 3:6])
    steps = (v[1:] + v[:-1]) / 2.0 * np.diff(np.asarray(stamps_s, dtype=np.float64))[:, None]
    return np.concatenate([np.zeros((1, 3)), np.cumsum(steps, axis=0)])


def _stamps_s(path: Path, count: int) -> np.ndarray:
    """Seconds since 1970 of the ``YYYY-MM-DD HH:MM:SS.fffffffff`` lines of a KITTI ``timestamps.txt``."""
    lines = [line.strip() for line in read_text(path, "KITTI timestamps").splitlines() if line.strip()]
    if len(lines) < count:
        raise ValueError(f"KITTI timestamps {path}: {len(lines)} stamps for {count} frames")
    try:
        ns = np.array([np.datetime64(line.replace(" ", "T"), "ns") for line in lines], dtype="datetime64[ns]")
    except ValueError:
        raise ValueError(f"KITTI timestamps {path}: lines must be 'YYYY-MM-DD HH:MM:SS.fffffffff'") from None
    return ns.astype(np.int64) / 1e9


def _oxts_records(drive: Path, names: list[str]) -> np.ndarray:
    rows = []
    for name in names:
        path = drive / "oxts" / "data" / f"{name}.txt"
        try:
            values = np.array(read_text(path, "KITTI OXTS record").split(), dtype=np.float64)
        except ValueError:
            raise ValueError(f"KITTI OXTS record {path}: must be numbers") from None
        if values.size < 30 or not np.isfinite(values[:23]).all():
            raise ValueError(f"KITTI OXTS record {path}: needs 30 numbers (lat lon alt roll pitch yaw vn ve vf vl "
                             f"vu ...), got {values.size}")
        rows.append(values[:30])
    return np.array(rows)


def _oxts_truth(drive: Path, names: list[str], indices: list[int], stamps_s: np.ndarray, notes: list) -> np.ndarray:
    """``T_first_from_oxts`` at the images' stamps (:func:`oxts_poses` shifted by image minus record stamp);
    ``notes`` gets the shifts and the positions' noise from frame to frame against the records' velocities."""
    records = _oxts_records(drive, names)
    path = drive / "oxts" / "timestamps.txt"
    if not path.is_file():
        notes.append(f"no {path}: the OXTS poses are taken at the images' stamps")
        return oxts_poses(records)
    record_s = _stamps_s(path, max(indices) + 1)[indices]
    shift = stamps_s - record_s
    if len(records) > 1:
        steps = np.diff(oxts_poses(records)[:, :3, 3], axis=0)
        off = steps - np.diff(oxts_velocity_positions(records, record_s), axis=0)
        mean_step = float(np.mean(np.linalg.norm(steps, axis=1)))
        share = f" ({100 * _rms(off) / mean_step:.1f} % of the mean step)" if mean_step > 0 else ""
        notes.append(f"OXTS positions against the records' velocities integrated: {100 * _rms(off):.1f} cm RMS per "
                     f"frame{share}, the truth's own noise; poses moved to the images' stamps (records "
                     f"{1000 * np.abs(shift).max():.1f} ms off at most)")
    return oxts_poses(records, shift)


def _rms(v: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(np.square(v), axis=1))))


def read_kitti_raw(path: str | os.PathLike, *, drive: str | None = None, truth=None) -> Manifest:
    """Read a KITTI raw drive as a recording (a :class:`Manifest`).

    Parameters
    ----------
    path : path
        The drive folder (``DATE_drive_NNNN_sync/``) or the date folder holding it.
    drive : str, optional
        The drive (``"0005"`` or its folder name) of a date folder holding several.
    truth : None, False or path
        None: the OXTS records; False: no truth (not even read); a TUM or EuRoC csv file of the left
        camera's poses instead, matched by stamp (:func:`mrstereo.recordings.truth.with_truth`).

    Returns
    -------
    Manifest
        Frames (``left_rect``/``right_rect`` of ``image_00``/``image_01``, ``stamp_s``, ``pose_3d`` =
        ``true_pose_3d`` = the base's OXTS pose at the image's stamp; without ``oxts/``: the origin, no truth), the
        calibration of ``P_rect_00``/``P_rect_01``, the mount from the calibration chain,
        ``layout="KITTI raw"``.

    Raises
    ------
    FileNotFoundError
        A missing calibration file or right image.
    ValueError
        Not a KITTI raw layout, unreadable numbers or stamps.
    """
    check_truth(truth)
    root = Path(path)
    if not root.is_dir():
        raise FileNotFoundError(f"KITTI raw folder not found: {root}")
    drive_dir = _drive_dir(root, drive)
    date = drive_dir.parent
    for name in _CALIB_NAMES:
        if not (date / name).is_file():
            raise FileNotFoundError(f"KITTI raw calibration not found: {date / name}")
    lefts = sorted((drive_dir / "image_00" / "data").glob("*.png"))
    if not lefts:
        raise ValueError(f"{drive_dir / 'image_00' / 'data'} has no PNG images")
    _limits.within("MRSTEREO_MAX_FRAMES", len(lefts), f"KITTI raw drive {drive_dir}: frames")
    rights = [drive_dir / "image_01" / "data" / p.name for p in lefts]
    missing = [p for p in rights if not p.is_file()]
    if missing:
        raise FileNotFoundError(f"right image not found: {missing[0]} (image_01 must match image_00)")
    first = read_image(lefts[0])
    rows = calib_rows(date / _CALIB_NAMES[0], {"P_rect_00": 12, "P_rect_01": 12, "S_rect_00": 2})
    if tuple(rows["S_rect_00"]) != (first.shape[1], first.shape[0]):
        raise ValueError(f"{lefts[0]} is {first.shape[1]}x{first.shape[0]} but the rectified size S_rect_00 of "
                         f"{date / _CALIB_NAMES[0]} is {rows['S_rect_00'][0]:g}x{rows['S_rect_00'][1]:g}: give a "
                         "synced and rectified drive (DATE_drive_NNNN_sync), not the raw images of an _extract one")
    stereo = stereo_from_projections(rows["P_rect_00"].reshape(3, 4), rows["P_rect_01"].reshape(3, 4),
                                     (first.shape[1], first.shape[0]), date / _CALIB_NAMES[0])
    T_base_from_imu = T_from_R_t(np.eye(3), [0.0, 0.0, OXTS_HEIGHT_M])
    mount = CameraMount(T_base_from_imu @ np.linalg.inv(_T_rect_from_imu(date)))
    indices = frame_numbers(lefts)
    stamps = _stamps_s(drive_dir / "image_00" / "timestamps.txt", max(indices) + 1)[indices]
    notes, poses = [], None
    if truth is None and (drive_dir / "oxts" / "data").is_dir():
        T_imu = _oxts_truth(drive_dir, [p.stem for p in lefts], indices, stamps, notes)
        poses = [pose_3d_of(T_base_from_imu @ T @ np.linalg.inv(T_base_from_imu)) for T in T_imu]
    elif truth is None:
        notes.append(f"no OXTS records ({drive_dir / 'oxts' / 'data'}): poses from visual odometry")
    origin = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    frames = tuple(FrameRecord(pose=None, left_rect=left.resolve(), right_rect=right.resolve(), stamp_s=float(stamps[i]),
                               pose_3d=origin if poses is None else poses[i],
                               true_pose_3d=None if poses is None else poses[i])
                   for i, (left, right) in enumerate(zip(lefts, rights)))
    manifest = Manifest(root=drive_dir.resolve(), calibration=stereo, calibration_path=(date / _CALIB_NAMES[0]).resolve(),
                        mount=mount, ground_truth_map=None, frames=frames, layout="KITTI raw",
                        has_poses=poses is not None, notes=tuple(notes))
    note_inputs(manifest.inputs().add(*(date / n for n in _CALIB_NAMES), drive_dir / "image_00" / "timestamps.txt"))
    return with_truth(manifest, truth, to_base=lambda T: camera_to_base(T, mount))
