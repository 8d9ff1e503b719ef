"""Which recording a path holds, and its reader: the one entry point of commands that take a recording.

The first layout of :data:`LAYOUTS` whose detection accepts the path reads it (a dataset
directory, KITTI odometry, EuRoC/ASL, image folders, a ROS bag exported by
:func:`opened_recording`); each returns a :class:`~mrstereo.recordings.manifest.Manifest`.
The layouts: docs/dataset.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

from .euroc import is_euroc, read_euroc
from .folders import FOLDER_PAIRS, is_image_folders, read_image_folders
from .kitti import is_kitti_odometry, read_kitti_odometry
from .manifest import MANIFEST_NAME, Manifest, read_manifest

__all__ = ["LAYOUTS", "read_recording", "opened_recording", "is_bag", "layout_of", "describe_recording"]


def _is_manifest(path: Path) -> bool:
    return (path.is_file() and path.suffix in (".yaml", ".yml")) or (path / MANIFEST_NAME).is_file()


def is_bag(path: str | os.PathLike) -> bool:
    """True for a ROS 1 ``.bag`` file, a ROS 2 bag directory (``metadata.yaml``) or one of its storage files."""
    path = Path(path)
    if path.is_file():
        return path.suffix == ".bag" or (path.suffix in (".db3", ".mcap") and (path.parent / "metadata.yaml").is_file())
    return path.is_dir() and (path / "metadata.yaml").is_file()


LAYOUTS = (("dataset", _is_manifest, "manifest.yaml"),
           ("KITTI odometry", is_kitti_odometry, "sequences/NN/image_0, image_1, calib.txt"),
           ("EuRoC/ASL", is_euroc, "mav0/cam0/data.csv, mav0/cam1/data.csv"),
           ("image folders", is_image_folders, ", ".join(f"{a}/ {b}/" for a, b in FOLDER_PAIRS[:3]) + " ..."),
           ("ROS bag", is_bag, "a .bag file or a ROS 2 bag folder with metadata.yaml"))
"""``(name, detect, what it looks for)`` of every recording layout, tried in order."""


def layout_of(path: str | os.PathLike) -> str:
    """The name of the layout of ``path`` (:data:`LAYOUTS`).

    Raises
    ------
    FileNotFoundError
        Nothing at ``path``.
    ValueError
        No known layout; the message names what was looked for.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"recording not found: {path}")
    for name, detect, _ in LAYOUTS:
        if detect(path):
            return name
    looked = "; ".join(f"{what} ({name})" for name, _, what in LAYOUTS)
    raise ValueError(f"{path} is not a recording mrstereo reads: looked for {looked}")


def read_recording(path: str | os.PathLike, *, calibration=None, rate_hz: float | None = None) -> Manifest:
    """Read the recording at ``path`` with the reader of its layout (:data:`LAYOUTS`).

    Parameters
    ----------
    path : path
        A dataset folder or manifest, a KITTI odometry or EuRoC/ASL folder, a folder of image folders.
        A ROS bag is read by :func:`opened_recording` (it is exported first).
    calibration : StereoCamera or path, optional
        The calibration of image folders (others carry their own; a command's ``--calib`` replaces it).
    rate_hz : float, optional
        The frame rate of image folders whose file names are not stamps.

    Raises
    ------
    FileNotFoundError
        Nothing at ``path``.
    ValueError
        A folder of no known layout (the message lists what was looked for), a bag, or what its reader raises.
    """
    layout = layout_of(path)
    if layout == "dataset":
        return read_manifest(path)
    if layout == "KITTI odometry":
        return read_kitti_odometry(path)
    if layout == "EuRoC/ASL":
        return read_euroc(path)
    if layout == "image folders":
        return read_image_folders(path, calibration=calibration, rate_hz=rate_hz)
    raise ValueError(f"{path} is a ROS bag: read it with mrstereo.recordings.opened_recording (it is exported "
                     "to a temporary dataset first)")


@contextlib.contextmanager
def opened_recording(path: str | os.PathLike, *, calibration=None, rate_hz: float | None = None,
                     **bag_options) -> Iterator[Manifest]:
    """The recording at ``path`` for the length of a ``with`` block; a bag is exported to a temporary dataset.

    ``bag_options`` are those of :func:`mrstereo.recordings.bag.export_bag` (topics, odometry, TF
    frames); without ``left_topic``/``right_topic`` the bag's one stereo pair is picked
    (:func:`mrstereo.recordings.bag.pick_stereo_topics`). Other layouts: :func:`read_recording`.
    """
    import dataclasses

    if layout_of(path) != "ROS bag":
        if bag_options:
            raise ValueError(f"{path} is not a ROS bag: the bag options {', '.join(sorted(bag_options))} do not apply")
        yield read_recording(path, calibration=calibration, rate_hz=rate_hz)
        return
    from ..camera import StereoCamera, read_stereo
    from .bag import exported_bag, with_picked_topics

    if calibration is not None and not isinstance(calibration, StereoCamera):
        calibration = read_stereo(calibration)
    options = with_picked_topics(path, dict(bag_options, calibration=calibration))
    with exported_bag(path, **options) as manifest:
        yield dataclasses.replace(manifest, layout="ROS bag",
                                  has_poses=bool(options.get("odom_topic") or options.get("use_tf")))


def describe_recording(manifest: Manifest) -> list[tuple[str, str]]:
    """``(what, value)`` lines of what a recording holds: frames, rate, images, calibration, mount, truth, poses."""
    import numpy as np

    from ..geometry.ground import ground_from_mount

    frames, s = manifest.frames, manifest.calibration
    stamps = manifest.stamps_s
    if stamps is not None and len(stamps) > 1:
        rate = f"{1.0 / float(np.median(np.diff(stamps))):.3g} Hz over {stamps[-1] - stamps[0]:.1f} s"
    else:
        rate = "unknown (no stamps)" if stamps is None else "one frame"
    kind = "rectified" if frames[0].has_rectified else "raw (rectified with the calibration)"
    where = f" ({manifest.calibration_path})" if manifest.calibration_path.is_file() else ""
    lines = [("layout", f"{manifest.layout}: {manifest.root}"), ("frames", f"{len(frames)}, {kind}"),
             ("rate", rate), ("images", f"{s.size[0]}x{s.size[1]}"),
             ("calibration", f"focal {s.focal_px:.1f} px, baseline {s.baseline_m:.4f} m, b f {s.baseline_m * s.focal_px:.1f}"
                             f" m px{where}")]
    if manifest.mount is not None:
        floor = ground_from_mount(manifest.mount, R_rect_from_cam=s.left.R)
        lines.append(("mount", f"camera {floor.height_m:.3f} m above the floor, tilted down {np.degrees(floor.tilt_rad):.1f}"
                               f" deg (checked against the floor seen when mapping)"))
    else:
        lines.append(("mount", "none: the floor is found in the first frames when mapping"))
    truth = [f.T_world_from_base_true for f in frames]
    if all(T is not None for T in truth):
        length = float(np.sum(np.linalg.norm(np.diff([T[:3, 3] for T in truth], axis=0), axis=1))) if len(truth) > 1 else 0.0
        lines.append(("truth", f"poses of every frame, path {length:.1f} m"))
    else:
        lines.append(("truth", "none"))
    if manifest.has_poses:
        lines.append(("odometry", "given poses (map and odometry use them; --odometry visual to replace them)"))
    else:
        lines.append(("odometry", "none: map and odometry take the poses from stereo visual odometry"))
    lines.append(("ground-truth map", str(manifest.ground_truth_map) if manifest.ground_truth_map else "none"))
    lines += [("note", n) for n in manifest.notes]
    return lines
