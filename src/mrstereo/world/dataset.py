"""Stereo datasets on disk: the manifest format and the synthetic corridor sequence.

Layout (docs/dataset.md)::

    DIR/manifest.yaml        calibration, rig, ground_truth_map, frames
    DIR/calibration.yaml     stereo calibration (mrstereo.camera.write_stereo)
    DIR/gt_map.yaml, .pgm    ROS map_server ground-truth map (optional)
    DIR/left/000000.png ...  raw images; left_rect/, right_rect/ rectified;
    DIR/gt_disparity/*.pfm   ground-truth disparity (optional); gt_labels/*.png

Paths in the manifest are relative to DIR. The same format describes users'
own recordings: a frame may give only raw or only rectified images, and every
ground-truth entry is optional. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from .. import _checks
from ..camera import RigMount, StereoCamera, read_stereo, write_stereo
from ..io import write_image, write_pfm
from ..mapping.rosmap import write_ros_map
from .groundtruth import ground_truth_map
from .render import default_stereo, render_stereo_frame
from .scene import default_scene

__all__ = ["FrameRecord", "Manifest", "read_manifest", "write_manifest", "write_synthetic_dataset",
           "corridor_path", "MANIFEST_NAME"]

MANIFEST_NAME = "manifest.yaml"
_IMAGE_KEYS = ("left", "right", "left_rect", "right_rect")
_GT_KEYS = ("gt_disparity", "gt_labels")


@dataclass(frozen=True)
class FrameRecord:
    """One frame of a dataset: absolute image paths (None when absent), pose and head pan."""

    pose: tuple[float, float, float]
    pan_rad: float = 0.0
    left: Path | None = None
    right: Path | None = None
    left_rect: Path | None = None
    right_rect: Path | None = None
    gt_disparity: Path | None = None
    gt_labels: Path | None = None

    @property
    def has_raw(self) -> bool:
        return self.left is not None and self.right is not None

    @property
    def has_rectified(self) -> bool:
        return self.left_rect is not None and self.right_rect is not None


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
    rig : RigMount
        Camera mount (the manifest's ``rig:``, else the calibration's).
    ground_truth_map : Path or None
        ROS map YAML of the true map.
    frames : tuple of FrameRecord
    """

    root: Path
    calibration: StereoCamera
    calibration_path: Path
    rig: RigMount
    ground_truth_map: Path | None
    frames: tuple[FrameRecord, ...]


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
        a bad pose or pan, or a bad rig -- naming the frame and field.
    """
    path = Path(path_or_dir)
    if path.is_dir():
        path = path / MANIFEST_NAME
    if not path.is_file():
        raise FileNotFoundError(f"dataset manifest not found: {path}")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1})" if mark is not None else ""
        raise ValueError(f"manifest {path} is not valid YAML{where}") from None
    except UnicodeDecodeError:
        raise ValueError(f"manifest {path} is not a text file") from None
    if not isinstance(data, dict):
        raise _fail(path, "expected a mapping with 'calibration' and 'frames'")
    root = path.parent.resolve()
    if "calibration" not in data:
        raise _fail(path, "missing 'calibration: <stereo YAML path>'")
    calib_path = _existing_file(root, data["calibration"], "calibration", path)
    calibration = read_stereo(calib_path)
    rig = calibration.rig
    if data.get("rig") is not None:
        r = data["rig"]
        if not isinstance(r, dict) or "height_m" not in r:
            raise _fail(path, "'rig' needs height_m (and optional tilt_rad)")
        try:
            rig = RigMount(height_m=r["height_m"], tilt_rad=r.get("tilt_rad", 0.0))
        except (TypeError, ValueError) as exc:
            raise _fail(path, f"rig: {exc}") from None
    if rig is None:
        raise _fail(path, "no rig mount: give 'rig: {height_m, tilt_rad}' in the manifest or the calibration")
    gt_map = None
    if data.get("ground_truth_map") is not None:
        gt_map = _existing_file(root, data["ground_truth_map"], "ground_truth_map", path)
    frames_data = data.get("frames")
    if not isinstance(frames_data, list) or not frames_data:
        raise _fail(path, "'frames' must be a non-empty list")
    frames = tuple(_frame(root, path, k, item) for k, item in enumerate(frames_data))
    return Manifest(root=root, calibration=calibration, calibration_path=calib_path, rig=rig,
                    ground_truth_map=gt_map, frames=frames)


def _frame(root: Path, manifest: Path, k: int, item) -> FrameRecord:
    where = f"frame {k}"
    if not isinstance(item, dict):
        raise _fail(manifest, f"{where} must be a mapping")
    unknown = set(item) - set(_IMAGE_KEYS) - set(_GT_KEYS) - {"pose", "pan_rad"}
    if unknown:
        raise _fail(manifest, f"{where}: unknown field(s) {sorted(unknown)}")
    pose = item.get("pose")
    if (not isinstance(pose, (list, tuple)) or len(pose) != 3
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in pose)
            or not all(math.isfinite(v) for v in pose)):
        raise _fail(manifest, f"{where}: pose must be [x_m, y_m, yaw_rad] (3 finite numbers), got {pose!r}")
    pan = item.get("pan_rad", 0.0)
    if isinstance(pan, bool) or not isinstance(pan, (int, float)) or not math.isfinite(pan):
        raise _fail(manifest, f"{where}: pan_rad must be a finite number, got {pan!r}")
    files = {key: _existing_file(root, item[key], f"{where}: {key}", manifest)
             for key in (*_IMAGE_KEYS, *_GT_KEYS) if item.get(key) is not None}
    record = FrameRecord(pose=tuple(float(v) for v in pose), pan_rad=float(pan), **files)
    for a, b in (("left", "right"), ("left_rect", "right_rect")):
        if (a in files) != (b in files):
            raise _fail(manifest, f"{where}: '{a}' and '{b}' must be given together")
    if not (record.has_raw or record.has_rectified):
        raise _fail(manifest, f"{where}: needs a raw pair (left, right) or a rectified pair "
                              "(left_rect, right_rect)")
    return record


def write_manifest(path: str | os.PathLike, *, calibration: str, rig: RigMount, frames: list[dict],
                   ground_truth_map: str | None = None, extra: dict | None = None) -> None:
    """Write ``manifest.yaml``; ``frames`` are dicts of relative paths, ``pose``, ``pan_rad``."""
    data = {"calibration": calibration,
            "rig": {"height_m": float(rig.height_m), "tilt_rad": float(rig.tilt_rad)}}
    if ground_truth_map is not None:
        data["ground_truth_map"] = ground_truth_map
    if extra:
        data.update(extra)
    data["frames"] = frames
    Path(path).write_text(yaml.safe_dump(data, sort_keys=False, default_flow_style=None))


def corridor_path(n_stops: int, *, x_end_m: float = 10.5) -> np.ndarray:
    """Robot poses (n_stops, 3) along the default corridor, detouring right of the 6 m obstacle.

    The path follows ``y = 0`` from ``x = 0``, swerves to ``y = -0.7`` between
    x = 5.7 and 6.8 m to pass the box in the middle of the corridor, and
    returns to the centre; the yaw follows the path direction.
    """
    n_stops = _checks.positive_int("n_stops", n_stops)
    way = np.array([[0.0, 0.0], [5.0, 0.0], [5.7, -0.7], [6.8, -0.7], [7.5, 0.0], [x_end_m, 0.0]])
    seg = np.diff(way, axis=0)
    seg_len = np.hypot(seg[:, 0], seg[:, 1])
    cum = np.concatenate([[0.0], np.cumsum(seg_len)])
    s = np.linspace(0.0, cum[-1], n_stops) if n_stops > 1 else np.zeros(1)
    poses = np.empty((n_stops, 3))
    for k, sk in enumerate(s):
        i = min(np.searchsorted(cum, sk, side="right") - 1, len(seg) - 1)
        a = (sk - cum[i]) / seg_len[i]
        poses[k, :2] = way[i] + a * seg[i]
        poses[k, 2] = math.atan2(seg[i, 1], seg[i, 0])
    return poses


_PANS = (0.0, math.pi / 4, -math.pi / 4)   # front, left and right views (paper Sec. 5.2)


def write_synthetic_dataset(out_dir: str | os.PathLike, *, seed: int = 0, n_frames: int = 30,
                            width: int = 320, height: int = 240, supersample: int = 2,
                            progress: bool = True) -> Path:
    """Render the default corridor along its path and write a dataset directory.

    At each stop along :func:`corridor_path` the head looks front, +45 and
    -45 degrees (paper Sec. 5.2, Figs. 11-13); frames cycle through these views.
    Written: raw and rectified images, GT disparity (PFM), GT labels (PNG),
    the true calibration, the GT map and ``manifest.yaml``. The directory is
    built beside ``out_dir`` and renamed into place when complete.

    Parameters
    ----------
    out_dir : path
        New (or empty) directory.
    seed : int
        Texture and noise seed.
    n_frames : int
        Number of frames (3 per stop).
    width, height : int
        Image size (320x240 or 640x480 rigs of :func:`default_stereo`).
    supersample : int
        Anti-aliasing rays per pixel along each axis.
    progress : bool
        Show a tqdm progress bar on stderr.

    Returns
    -------
    Path
        ``out_dir``.
    """
    from tqdm import tqdm

    out_dir = Path(out_dir)
    seed = _checks.positive_int("seed", seed, minimum=0)
    n_frames = _checks.positive_int("n_frames", n_frames)
    if out_dir.exists() and (not out_dir.is_dir() or any(out_dir.iterdir())):
        raise ValueError(f"output directory {out_dir} already exists and is not empty; "
                         "choose a new directory")
    stereo = default_stereo(width, height)
    scene = default_scene(seed)
    n_stops = -(-n_frames // len(_PANS))
    poses = corridor_path(n_stops)
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.", suffix=".tmp", dir=out_dir.parent))
    try:
        write_stereo(tmp / "calibration.yaml", stereo)
        write_ros_map(tmp / "gt_map.yaml", ground_truth_map(scene))
        frames = []
        for k in tqdm(range(n_frames), desc="rendering", unit="frame", disable=not progress):
            # Render with exactly the numbers the manifest stores.
            pose = tuple(round(float(v), 6) for v in poses[k // len(_PANS)])
            pan = round(_PANS[k % len(_PANS)], 9)
            frame = render_stereo_frame(scene, stereo, pose=pose, pan_rad=pan, seed=seed * 100003 + k,
                                        supersample=supersample)
            name = f"{k:06d}"
            entry = {}
            for key, image in (("left", frame.raw_left), ("right", frame.raw_right),
                               ("left_rect", frame.left_rect), ("right_rect", frame.right_rect),
                               ("gt_labels", frame.labels)):
                write_image(tmp / key / f"{name}.png", image)
                entry[key] = f"{key}/{name}.png"
            write_pfm(tmp / "gt_disparity" / f"{name}.pfm", frame.disparity_px)
            entry["gt_disparity"] = f"gt_disparity/{name}.pfm"
            entry["pose"] = list(pose)
            entry["pan_rad"] = pan
            frames.append({key: entry[key] for key in (*_IMAGE_KEYS, "gt_disparity", "gt_labels", "pose",
                                                        "pan_rad")})
        write_manifest(tmp / MANIFEST_NAME, calibration="calibration.yaml", rig=stereo.rig, frames=frames,
                       ground_truth_map="gt_map.yaml",
                       extra={"generator": {"name": "mrstereo.world", "seed": seed, "width": width,
                                            "height": height}})
        if out_dir.exists():
            out_dir.rmdir()          # empty, checked above
        os.replace(tmp, out_dir)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return out_dir
