"""The KITTI odometry layout as a recording: rectified pairs, stamps, calibration and 3-D truth.

``ROOT/sequences/NN/{image_0,image_1,calib.txt,times.txt}`` and optionally ``ROOT/poses/NN.txt``.
:func:`read_kitti_odometry` returns a :class:`~mrstereo.recordings.manifest.Manifest`: the
calibration as a pre-rectified :class:`~mrstereo.camera.StereoCamera` (``P1[0, 3] = -fx *
baseline_m``), and KITTI's ``T_cam0_from_camk`` converted to the REP 103 base frame,
``T_world_from_base_k = M T_cam0_from_camk inv(M)`` with the mount ``M = T_base_from_cam``.
The layout: docs/dataset.md ("KITTI odometry folders"). Conventions: docs/conventions.md.

References
----------
A. Geiger, P. Lenz, R. Urtasun. Are we ready for autonomous driving? The KITTI vision benchmark
suite. CVPR 2012.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .. import _limits
from ..camera import Camera, CameraInfo, StereoCamera
from ..camera.mount import CameraMount
from ..io import note_inputs, read_image, read_text
from .manifest import FrameRecord, Manifest, pose_3d_of
from .truth import camera_to_base, check_truth, with_truth

__all__ = ["read_kitti_odometry", "is_kitti_odometry", "KITTI_MOUNT", "calib_rows", "stereo_from_projections",
           "numbers_file"]

KITTI_MOUNT = CameraMount.from_xyz_rpy((0.0, 0.0, 1.65), (0.0, 0.0, 0.0))
"""The left camera of the KITTI car: 1.65 m above the road, level, looking forward (Geiger et al. 2012)."""


def _sequence_dir(path: Path, sequence: str | None) -> Path:
    """``sequences/NN`` of a KITTI root, or ``path`` itself when it is a sequence folder."""
    if (path / "image_0").is_dir():
        return path
    seqs = path / "sequences"
    if not seqs.is_dir():
        raise ValueError(f"{path} is not a KITTI odometry folder: no image_0/ and no sequences/")
    if sequence is not None:
        folder = seqs / sequence
        if not (folder / "image_0").is_dir():
            raise FileNotFoundError(f"KITTI sequence {sequence!r} not found: {folder}/image_0")
        return folder
    found = sorted(p for p in seqs.iterdir() if (p / "image_0").is_dir())
    if len(found) != 1:
        names = ", ".join(p.name for p in found) or "none"
        raise ValueError(f"{seqs} holds {len(found)} sequences ({names}): name one (sequence='NN')")
    return found[0]


def is_kitti_odometry(path: str | os.PathLike) -> bool:
    """True when ``path`` is a KITTI odometry root (``sequences/NN/``) or a sequence folder (``image_0/``,
    ``image_1/``, ``calib.txt``)."""
    path = Path(path)
    if not path.is_dir():
        return False
    folders = [path] if (path / "image_0").is_dir() else \
        [p for p in (path / "sequences").glob("*") if p.is_dir()] if (path / "sequences").is_dir() else []
    return any((f / "image_0").is_dir() and (f / "image_1").is_dir() and (f / "calib.txt").is_file()
               for f in folders)


def frame_numbers(images) -> list[int]:
    """The frame numbers of KITTI image names (``000042.png``: 42); a name that is no number (``-1.png``,
    ``a.png``) is an error naming the image."""
    numbers = []
    for p in images:
        if not (p.stem.isascii() and p.stem.isdigit()):
            raise ValueError(f"{p}: a KITTI image name must be its frame number (000042.png), got {p.name}")
        numbers.append(int(p.stem))
    return numbers


def calib_rows(path: Path, sizes: dict[str, int], what: str = "KITTI calibration") -> dict[str, np.ndarray]:
    """The rows ``key: numbers`` of a KITTI calibration file named in ``sizes`` (key -> count of numbers);
    other lines (``calib_time: ...``) are not read. Raises ``ValueError`` naming the file, line and key."""
    lines = {}
    for n, line in enumerate(read_text(path, what, max_bytes=1 << 20).splitlines(), 1):
        if ":" in line:
            key, values = line.split(":", 1)
            lines[key.strip()] = (n, values)
    rows = {}
    for key, size in sizes.items():
        if key not in lines:
            raise ValueError(f"{path}: needs '{key}:' with {size} numbers")
        n, values = lines[key]
        try:
            rows[key] = np.array([float(v) for v in values.split()], dtype=np.float64)
        except ValueError:
            raise ValueError(f"{path} line {n}: {key} must be numbers") from None
        if rows[key].size != size or not np.isfinite(rows[key]).all():
            raise ValueError(f"{path} line {n}: '{key}:' needs {size} numbers (finite), got {rows[key].size}")
    return rows


def stereo_from_projections(P0: np.ndarray, P1: np.ndarray, size: tuple[int, int], where: Path) -> StereoCamera:
    """A pre-rectified pair from the left and right 3x4 projections (``P1[0, 3] = -fx * baseline_m``)."""
    width, height = size
    try:
        camera = Camera(width=width, height=height, fx=P0[0, 0], fy=P0[1, 1], cx=P0[0, 2], cy=P0[1, 2])
        right = Camera(width=width, height=height, fx=P1[0, 0], fy=P1[1, 1], cx=P1[0, 2], cy=P1[1, 2])
        return StereoCamera(left=CameraInfo(camera, P=P0, name="left"), right=CameraInfo(right, P=P1, name="right"))
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None


def _calibration(path: Path, size: tuple[int, int]) -> StereoCamera:
    """P0 (left) and P1 (right) of ``calib.txt`` as a pre-rectified pair."""
    rows = calib_rows(path, {"P0": 12, "P1": 12})
    return stereo_from_projections(rows["P0"].reshape(3, 4), rows["P1"].reshape(3, 4), size, path)


def numbers_file(path: Path, columns: int, what: str) -> np.ndarray:
    try:
        values = np.loadtxt(path, dtype=np.float64, ndmin=2)
    except ValueError as exc:
        raise ValueError(f"{what} {path}: {exc}") from None
    if values.shape[1] != columns or not np.isfinite(values).all():
        raise ValueError(f"{what} {path}: expected {columns} finite numbers per line, got {values.shape[1]}")
    return values


def read_kitti_odometry(path: str | os.PathLike, *, sequence: str | None = None,
                        mount: CameraMount | None = None, truth=None) -> Manifest:
    """Read a KITTI odometry sequence as a recording (a :class:`Manifest`).

    KITTI's rotations hold 7 digits; as unit quaternions they agree with the file to 1e-8.

    Parameters
    ----------
    path : path
        The KITTI root (``sequences/NN/``, ``poses/NN.txt``) or one sequence folder
        (``image_0/``, ``image_1/``, ``calib.txt``, ``times.txt``; its poses are looked for in
        ``../../poses/NN.txt``).
    sequence : str, optional
        ``"06"`` etc.; needed when the root holds several sequences.
    mount : CameraMount, optional
        The left camera on the base (default :data:`KITTI_MOUNT`).
    truth : None, False or path
        None: ``poses/NN.txt``; False: no truth (not even read); a TUM or EuRoC csv file of the left
        camera's poses instead, matched by stamp (:func:`mrstereo.recordings.truth.with_truth`).

    Returns
    -------
    Manifest
        Frames (``left_rect``/``right_rect``, ``stamp_s`` from times.txt, ``pose_3d`` and
        ``true_pose_3d`` from the poses file, else the origin and no truth), the calibration
        (``calibration_path``: calib.txt) and the mount.

    Raises
    ------
    FileNotFoundError
        A missing calib.txt or image.
    ValueError
        Not a KITTI layout, unreadable numbers, stamps or poses that do not match the images.
    """
    check_truth(truth)
    root = Path(path)
    if not root.is_dir():
        raise FileNotFoundError(f"KITTI odometry folder not found: {root}")
    mount = KITTI_MOUNT if mount is None else mount
    if not isinstance(mount, CameraMount):
        raise TypeError(f"mount must be a CameraMount, got {type(mount).__name__}")
    seq = _sequence_dir(root, sequence)
    lefts = sorted((seq / "image_0").glob("*.png"))
    if not lefts:
        raise ValueError(f"{seq / 'image_0'} has no PNG images")
    _limits.within("MRSTEREO_MAX_FRAMES", len(lefts), f"KITTI sequence {seq}: frames")
    rights = [seq / "image_1" / p.name for p in lefts]
    missing = [p for p in rights if not p.is_file()]
    if missing:
        raise FileNotFoundError(f"right image not found: {missing[0]} (image_1 must match image_0)")
    calib_path = seq / "calib.txt"
    if not calib_path.is_file():
        raise FileNotFoundError(f"KITTI calibration not found: {calib_path}")
    first = read_image(lefts[0])
    stereo = _calibration(calib_path, (first.shape[1], first.shape[0]))
    indices = frame_numbers(lefts)
    stamps = None
    if (seq / "times.txt").is_file():
        times = numbers_file(seq / "times.txt", 1, "KITTI times").ravel()
        if max(indices) >= len(times):
            raise ValueError(f"{seq / 'times.txt'} has {len(times)} stamps but image_0 has frame {max(indices)}")
        stamps = times[indices]
    poses = None
    poses_path = seq.parent.parent / "poses" / f"{seq.name}.txt"
    if truth is None and poses_path.is_file():
        rows = numbers_file(poses_path, 12, "KITTI poses")
        if max(indices) >= len(rows):
            raise ValueError(f"{poses_path} has {len(rows)} poses but image_0 has frame {max(indices)}")
        poses = []
        for k in indices:
            R = rows[k].reshape(3, 4)[:, :3]
            if not (np.allclose(R @ R.T, np.eye(3), atol=1e-3) and np.linalg.det(R) > 0):
                raise ValueError(f"{poses_path}: line {k + 1} (frame {k}) is no pose: its 3x3 part is not a rotation "
                                 f"(R R^T = I, det R = 1; det {np.linalg.det(R):.3g})")
            poses.append(pose_3d_of(camera_to_base(np.vstack([rows[k].reshape(3, 4), [0.0, 0.0, 0.0, 1.0]]), mount)))
    origin = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    frames = tuple(FrameRecord(pose=None, left_rect=left.resolve(), right_rect=right.resolve(),
                               stamp_s=None if stamps is None else float(stamps[i]),
                               pose_3d=origin if poses is None else poses[i],
                               true_pose_3d=None if poses is None else poses[i])
                   for i, (left, right) in enumerate(zip(lefts, rights)))
    manifest = Manifest(root=seq.resolve(), calibration=stereo, calibration_path=calib_path.resolve(), mount=mount,
                        ground_truth_map=None, frames=frames, layout="KITTI odometry", has_poses=poses is not None,
                        notes=() if poses is not None or truth is not None else
                        (f"no ground truth ({poses_path}): poses from visual odometry",))
    note_inputs(manifest.inputs().add(seq / "times.txt", poses_path))
    return with_truth(manifest, truth, to_base=lambda T: camera_to_base(T, mount))

