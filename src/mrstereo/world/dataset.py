"""The synthetic corridor sequence written as a dataset (format: :mod:`mrstereo.recordings.manifest`).

Layout and manifest: docs/dataset.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from .. import _checks, _limits
from .._interrupt import reached
from ..recordings.manifest import staged_dataset
from .groundtruth import drop_edges, floor_heights, ground_truth_map
from .paths import PATH_KINDS, drifted_poses, sequence_path, speed_path, waypoint_path
from .randomize import random_world
from .render import SensorModel, default_stereo, render_stereo_frame
from .scene import default_scene
from .street import street_world

BYTES_PER_PIXEL = 7.0
"""Disk space of one pixel of a written frame: ground-truth disparity (PFM, 4 bytes), four PNG images and the
labels (about 3 bytes of compressed texture)."""

__all__ = ["write_synthetic_dataset", "corridor_path", "poses_along"]


def corridor_path(n_stops: int) -> np.ndarray:
    """Robot poses (n_stops, 3) along the default corridor, detouring right of the 6 m obstacle.

    The path follows ``y = 0`` from ``x = 0``, swerves to ``y = -0.7`` between
    x = 5.7 and 6.8 m to pass the box in the middle of the corridor, and
    returns to the centre; the yaw follows the path direction.
    """
    way = np.array([[0.0, 0.0], [5.0, 0.0], [5.7, -0.7], [6.8, -0.7], [7.5, 0.0], [10.5, 0.0]])
    return poses_along(way, n_stops)


def poses_along(waypoints_xy, n_stops: int) -> np.ndarray:
    """``n_stops`` robot poses (n_stops, 3) evenly spaced along a polyline; yaw follows the path."""
    n_stops = _checks.positive_int("n_stops", n_stops)
    _checks.fits_in_memory("n_stops", 48.0 * n_stops, f"{n_stops} poses")
    way = np.asarray(waypoints_xy, dtype=np.float64)
    if way.ndim != 2 or way.shape[1] != 2 or len(way) < 2 or not np.isfinite(way).all():
        raise ValueError(f"waypoints_xy must be (K >= 2, 2) finite numbers, got shape {way.shape}")
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


def _check_world_options(path: str, randomize: bool, wall_texture, odometry_noise, drops: bool = False) -> None:
    if path not in PATH_KINDS:
        raise ValueError(f"path must be one of {', '.join(PATH_KINDS)}, got {path!r}")
    if randomize and path in ("s-curve", "street"):
        raise ValueError(f"path={path!r} has its own world; a randomized corridor's odometry sequence is "
                         "path='front' (along the world's own waypoints)")
    if wall_texture is not None and not randomize:
        raise ValueError("wall_texture applies to a randomized world only (randomize=True)")
    if drops and not randomize:
        raise ValueError("drops applies to a randomized world only (randomize=True)")
    if odometry_noise is not None and len(odometry_noise) != 2:
        raise ValueError(f"odometry_noise must be (scale_error, heading_drift_rad_per_m), got {odometry_noise!r}")


def _check_sizes(out_dir: Path, n_frames: int, width: int, height: int, supersample: int) -> None:
    _checks.fits_in_memory("width and height", 64.0 * width * height * supersample ** 2,
                           f"rendering {width}x{height} images")
    _checks.fits_on_disk("n_frames", BYTES_PER_PIXEL * width * height * n_frames, out_dir,
                         f"{n_frames} frames of {width}x{height}")


def _frame_poses(path: str, n_frames: int, waypoints_xy, step_m: float,
                 turn_rad_per_frame: float) -> tuple[np.ndarray, list[float]]:
    """Robot poses (n_frames, 3) and head pans of the frames along ``path`` (``waypoints_xy``: a randomized
    world's path, None: the built-in corridor's), rounded to the numbers the manifest stores."""
    if path == "stops":
        n_stops = -(-n_frames // len(_PANS))
        stops = corridor_path(n_stops) if waypoints_xy is None else poses_along(waypoints_xy, n_stops)
        poses = np.repeat(stops, len(_PANS), axis=0)[:n_frames]
        pans = [round(_PANS[k % len(_PANS)], 9) for k in range(n_frames)]
    else:
        poses = (speed_path(n_frames, step_m=step_m, turn_rad_per_frame=turn_rad_per_frame) if path == "street"
                 else sequence_path(path, n_frames, step_m=step_m) if waypoints_xy is None
                 else waypoint_path(waypoints_xy, n_frames, step_m=step_m))
        pans = [0.0] * n_frames
    return np.round(poses, 6), pans


def write_synthetic_dataset(out_dir: str | os.PathLike, *, seed: int = 0, n_frames: int = 30,
                            width: int = 320, height: int = 240, supersample: int = 2,
                            path: str = "stops", step_m: float = 0.1,
                            odometry_noise: tuple[float, float] | None = None,
                            progress: bool = True, randomize: bool = False,
                            wall_texture: str | None = None, turn_rad_per_frame: float = math.radians(3.0),
                            frame_rate_hz: float = 10.0, drops: bool = False) -> Path:
    """Render the default corridor (or a randomized world) along its path and write a dataset directory.

    Written: raw and rectified images, GT disparity (PFM), GT labels (PNG), the true calibration,
    the GT map and ``manifest.yaml``, staged beside ``out_dir`` and renamed into place when complete.
    The paths and the layout: docs/world.md and docs/dataset.md.

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
    path : {"stops", "front", "s-curve", "street"}
        The robot's path (:mod:`mrstereo.world.paths`): ``"stops"`` looks front, +45 and -45 degrees
        at each stop (paper Sec. 5.2); the others are odometry sequences, one frame every ``step_m``.
    step_m : float
        Path length between frames of a sequence (``street``: at full speed).
    odometry_noise : (scale_error, heading_drift_rad_per_m), optional
        Store drifted poses (:func:`mrstereo.world.paths.drifted_poses`) as ``pose`` and the true
        ones as ``true_pose``.
    progress : bool
        Show a tqdm progress bar on stderr.
    randomize : bool
        Render :func:`mrstereo.world.randomize.random_world` of ``seed`` instead of the built-in corridor.
    wall_texture : str, optional
        With ``randomize=True``: the walls' kind of material (``random_world(..., wall_texture=...)``).
    turn_rad_per_frame : float
        ``street``: the largest heading change per frame at full speed.
    frame_rate_hz : float
        Frames per second of a sequence (its ``stamp_s``).
    drops : bool
        With ``randomize=True``: a world with drops (``random_world(..., drops=True)``); their truth on the
        map's grid is written as ``gt_drops.npz`` (``floor_height_m``, ``drop_edge``; docs/world.md).

    Returns
    -------
    Path
        ``out_dir``.
    """
    from tqdm import tqdm

    seed = _checks.positive_int("seed", seed, minimum=0)
    n_frames = _limits.within("MRSTEREO_MAX_FRAMES", _checks.positive_int("n_frames", n_frames), "n_frames")
    width, height = _checks.positive_int("width", width, minimum=16), _checks.positive_int("height", height, minimum=16)
    supersample = _checks.positive_int("supersample", supersample)
    _check_sizes(Path(out_dir).absolute(), n_frames, width, height, supersample)
    _check_world_options(path, randomize, wall_texture, odometry_noise, drops)
    rate = _checks.finite_number("frame_rate_hz", frame_rate_hz, positive=True)
    generator = {"name": "mrstereo.world", "seed": seed, "width": width, "height": height, "path": path}
    if randomize or path == "street":
        world = (street_world(seed, width=width, height=height) if path == "street" else
                 random_world(seed, width=width, height=height, wall_texture=wall_texture, drops=drops))
        stereo, scene, sensors, waypoints = world.stereo, world.scene, world.sensors, world.waypoints_xy
        generator["street" if path == "street" else "randomized"] = world.summary
    else:
        stereo, scene, sensors = default_stereo(width, height), default_scene(seed), (SensorModel(), SensorModel())
        waypoints = None
    poses, pans = _frame_poses(path, n_frames, waypoints, step_m, turn_rad_per_frame)
    if path != "stops":
        generator["step_m"] = float(step_m)
        generator["frame_rate_hz"] = rate
    if path == "street":
        generator["turn_rad_per_frame"] = float(turn_rad_per_frame)
    given = poses
    if odometry_noise is not None:
        given = np.round(drifted_poses(poses, scale_error=odometry_noise[0],
                                       heading_drift_rad_per_m=odometry_noise[1]), 6)
        generator["odometry_noise"] = {"scale_error": float(odometry_noise[0]),
                                       "heading_drift_rad_per_m": float(odometry_noise[1])}
    with staged_dataset(out_dir, calibration=stereo, mount=stereo.mount, extra={"generator": generator}) as dataset:
        dataset.write_ground_truth_map(ground_truth_map(scene))
        if drops:
            np.savez_compressed(dataset.root / "gt_drops.npz", floor_height_m=floor_heights(scene),
                                drop_edge=drop_edges(scene))
        for k in tqdm(range(n_frames), desc="rendering", unit="frame", disable=not progress):
            reached("frame")
            pose = tuple(float(v) for v in poses[k])
            frame = render_stereo_frame(scene, stereo, pose=pose, pan_rad=pans[k], seed=seed * 100003 + k,
                                        supersample=supersample, sensors=sensors)
            for key, array in (("left", frame.raw_left), ("right", frame.raw_right), ("left_rect", frame.left_rect),
                               ("right_rect", frame.right_rect), ("gt_labels", frame.labels),
                               ("gt_disparity", frame.disparity_px)):
                dataset.write(key, k, array)
            dataset.add_frame(k, pose=given[k], pan_rad=pans[k], true_pose=pose if odometry_noise is not None else None,
                              stamp_s=None if path == "stops" else round(k / rate, 9))
    return Path(out_dir)
