"""Ground truth from a file of one's own, or none: what ``--truth FILE`` and ``--no-truth`` do to a recording.

Every recording reader takes ``truth``: ``None`` reads the recording's own truth (EuRoC's
``state_groundtruth_estimate0/data.csv``, KITTI's ``poses/NN.txt``, KITTI raw's OXTS records, a
dataset's poses, a bag's odometry topic or TF); ``False`` reads none (the poses then come from visual
odometry); a path reads the poses of that file instead (:func:`read_poses_file`: TUM
``t x y z qx qy qz qw``, t in seconds, or a EuRoC csv ``t_ns, px, py, pz, qw, qx, qy, qz, ...``, as
evo reads them). The file's poses are matched to the frames by stamp, the nearest within
``tolerance_s`` (:data:`TRUTH_TOLERANCE_S`); frames without one are left out and a note says how many
got one. The frame the file's poses are of is the one the recording's own truth is of
(:data:`TRUTH_FRAMES`), moved to the robot base as the reader moves its own. docs/dataset.md.
Conventions: docs/conventions.md.
"""
from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..camera import CameraMount
from ..io import note_inputs, read_text
from ..transforms import T_from_position_quaternion
from .manifest import Manifest, pose_3d_of

__all__ = ["TRUTH_TOLERANCE_S", "TRUTH_FRAMES", "read_poses_file", "match_stamps", "check_truth", "with_truth",
           "camera_to_base"]

TRUTH_TOLERANCE_S = 0.02
"""Largest stamp difference [s] between a frame and the pose of a ``--truth`` file it gets (20 ms: half a
frame at 25 Hz; EuRoC's truth is at 200 Hz, a TUM file of a run at the frame rate)."""

TRUTH_FRAMES = {
    "EuRoC/ASL": "the EuRoC body (IMU) frame, in the file's world",
    "KITTI odometry": "the left camera (cam0: x right, y down, z forward), in the first camera's frame as "
                      "KITTI's poses/NN.txt",
    "KITTI raw": "the left camera (cam0: x right, y down, z forward), in the first camera's frame as "
                 "KITTI's poses/NN.txt",
    "image folders": "the left camera (x right, y down, z forward), in the first camera's frame",
    "dataset": "the robot base (x forward, y left, z up), in a world with z up",
    "ROS bag": "the robot base (--base-frame), in a world with z up",
}
"""The frame the poses of a ``--truth`` file are of, per layout (the recording's own truth's)."""


def check_truth(truth) -> None:
    """Raise ``TypeError``/``ValueError`` naming ``truth`` unless it is None, False or an existing file."""
    if truth is None or truth is False:
        return
    if truth is True or not isinstance(truth, (str, os.PathLike)):
        raise TypeError(f"truth must be None (the recording's own), False (none) or a TUM/EuRoC csv file, got {truth!r}")
    if not Path(truth).is_file():
        raise FileNotFoundError(f"ground truth file not found: {truth}")


def read_poses_file(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """The poses of a TUM file or a EuRoC csv: ``(stamps_ns (N,) int64, T_world_from_frame (N, 4, 4))``.

    A file whose first line starts with an integer stamp of more than 12 digits is EuRoC csv
    (``timestamp_ns, px, py, pz, qw, qx, qy, qz`` and any further columns, as
    ``state_groundtruth_estimate0/data.csv``); else TUM (``t_s x y z qx qy qz qw``). Blanks or commas
    separate the numbers; ``#`` lines are comments.

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        A line that is neither (naming the file and line), a zero quaternion, no pose.
    """
    path = Path(path)
    rows = [(n, line.replace(",", " ").split())
            for n, line in enumerate(read_text(path, "ground truth", max_bytes=1 << 30).splitlines(), 1)
            if line.strip() and not line.strip().startswith("#")]
    euroc = bool(rows) and rows[0][1][0].isdigit() and len(rows[0][1]) >= 8 and len(rows[0][1][0]) > 12
    stamps, poses = [], []
    for n, row in rows:
        try:
            if euroc:
                stamp, (px, py, pz, qw, qx, qy, qz) = int(row[0]), [float(v) for v in row[1:8]]
            else:
                if len(row) != 8:
                    raise ValueError
                t, px, py, pz, qx, qy, qz, qw = (float(v) for v in row)
                stamp = int(round(t * 1e9))
            values = np.array([px, py, pz, qx, qy, qz, qw])
            if not np.isfinite(values).all() or float(values[3:] @ values[3:]) < 1e-12:
                raise ValueError
        except (ValueError, IndexError):
            form = "'timestamp_ns, px, py, pz, qw, qx, qy, qz'" if euroc else "'t x y z qx qy qz qw' (TUM, t in s)"
            raise ValueError(f"ground truth {path} line {n}: expected {form}, finite numbers and a non-zero "
                             "quaternion") from None
        stamps.append(stamp)
        poses.append(T_from_position_quaternion(values[:3], values[3:]))
    if not poses:
        raise ValueError(f"ground truth {path} holds no pose (TUM 't x y z qx qy qz qw' or EuRoC csv lines)")
    stamps = np.array(stamps, dtype=np.int64)
    order = np.argsort(stamps, kind="stable")
    return stamps[order], np.stack(poses)[order]


def match_stamps(truth_ns: np.ndarray, frames_s: np.ndarray, tolerance_s: float) -> np.ndarray:
    """For each frame stamp [s] the index of the nearest truth stamp [ns] within ``tolerance_s``, else -1."""
    frames_ns = np.round(np.asarray(frames_s, dtype=np.float64) * 1e9).astype(np.int64)
    right = np.clip(np.searchsorted(truth_ns, frames_ns), 0, truth_ns.size - 1)
    left = np.clip(right - 1, 0, truth_ns.size - 1)
    nearest = np.where(np.abs(truth_ns[left] - frames_ns) <= np.abs(truth_ns[right] - frames_ns), left, right)
    ok = np.abs(truth_ns[nearest] - frames_ns) <= int(round(tolerance_s * 1e9))
    return np.where(ok, nearest, -1)


def camera_to_base(T_cam0_from_camk: np.ndarray, mount: CameraMount) -> np.ndarray:
    """A pose of the left camera in the first camera's frame (KITTI's poses, a visual odometry's TUM file) as the
    base's in the first base's frame: ``M T inv(M)``, ``M = T_base_from_cam``."""
    M = mount.T_base_from_cam
    return M @ T_cam0_from_camk @ np.linalg.inv(M)


def with_truth(manifest: Manifest, truth, *, to_base: Callable[[np.ndarray], np.ndarray] | None = None,
               pose_frame_mount: CameraMount | None = None,
               tolerance_s: float = TRUTH_TOLERANCE_S) -> Manifest:
    """The recording (read without its own truth) with the poses of the file ``truth``, or none (``False``).

    Every frame gets the pose of the file nearest to its stamp within ``tolerance_s`` as its given and true
    pose (``to_base`` turns the file's ``T_world_from_frame`` into the reader's pose: KITTI's
    ``M T inv(M)``); frames without one are left out; ``pose_frame_mount`` is the camera in the file's
    frame when that is not a base on the floor (EuRoC's body). ``truth`` False: no pose, a note says why.

    Raises
    ------
    ValueError
        A bad file (naming it), a recording without stamps, no frame within ``tolerance_s`` of a pose.
    """
    check_truth(truth)
    if truth is None:
        return manifest
    origin = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    if truth is False:
        frames = tuple(dataclasses.replace(f, pose=None, pose_3d=origin, true_pose=None, true_pose_3d=None)
                       for f in manifest.frames)
        return dataclasses.replace(manifest, frames=frames, has_poses=False, pose_frame_mount=None,
                                   notes=(*manifest.notes, "ground truth not read (--no-truth): poses from visual odometry"))
    path = Path(truth)
    stamps_ns, T = read_poses_file(path)
    note_inputs(manifest.inputs().add(path))
    frame_s = manifest.stamps_s
    if frame_s is None:
        raise ValueError(f"ground truth {path}: the recording {manifest.root} has no frame stamps to match its "
                         "poses to")
    index = match_stamps(stamps_ns, frame_s, tolerance_s)
    kept = np.flatnonzero(index >= 0)
    if kept.size == 0:
        raise ValueError(f"ground truth {path}: no pose within {tolerance_s * 1e3:g} ms of any of the "
                         f"{len(frame_s)} frames (frames {frame_s[0]:.3f}..{frame_s[-1]:.3f} s, poses "
                         f"{stamps_ns[0] / 1e9:.3f}..{stamps_ns[-1] / 1e9:.3f} s)")
    frames = []
    for k in kept:
        T_world = T[index[k]] if to_base is None else to_base(T[index[k]])
        pose = pose_3d_of(T_world)
        frames.append(dataclasses.replace(manifest.frames[k], pose=None, pose_3d=pose, true_pose=None,
                                          true_pose_3d=pose))
    left_out = len(frame_s) - kept.size
    note = (f"ground truth from {path}: {kept.size} of {len(frame_s)} frames got a pose within "
            f"{tolerance_s * 1e3:g} ms" + (f", {left_out} left out" if left_out else "") +
            f" (poses of {TRUTH_FRAMES.get(manifest.layout, 'the robot base')})")
    return dataclasses.replace(manifest, frames=tuple(frames), has_poses=True, pose_frame_mount=pose_frame_mount,
                               notes=(*manifest.notes, note))
