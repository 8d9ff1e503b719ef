"""Which recording a path holds, and its reader: the one entry point of commands that take a recording.

The first layout of :data:`LAYOUTS` whose detection accepts the path reads it (a dataset
directory, KITTI odometry, KITTI raw, EuRoC/ASL, image folders, a ROS bag).
:func:`open_recording` opens any of them as a :class:`~mrstereo.recordings.sources.FrameSource`;
:func:`read_recording` returns the :class:`~mrstereo.recordings.manifest.Manifest` (file paths) of
those that are folders of images.
The layouts: docs/dataset.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import os
from pathlib import Path

from ..io import Inputs, note_inputs
from .euroc import is_euroc, read_euroc
from .folders import FOLDER_PAIRS, is_image_folders, read_image_folders
from .kitti import is_kitti_odometry, read_kitti_odometry
from .kitti_raw import is_kitti_raw, read_kitti_raw
from .manifest import MANIFEST_NAME, Manifest, read_manifest
from .frames import FrameSource, RecordingSource
from .truth import check_truth, with_truth

__all__ = ["LAYOUTS", "read_recording", "open_recording", "is_bag", "layout_of", "describe_recording"]


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
           ("KITTI raw", is_kitti_raw, "DATE/calib_cam_to_cam.txt, DATE/DATE_drive_NNNN_sync/image_00/data"),
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


def read_recording(path: str | os.PathLike, *, calibration=None, rate_hz: float | None = None,
                   truth=None) -> Manifest:
    """Read the recording at ``path`` with the reader of its layout (:data:`LAYOUTS`).

    Parameters
    ----------
    path : path
        A dataset folder or manifest, a KITTI odometry, KITTI raw or EuRoC/ASL folder, a folder of
        image folders. A ROS bag is opened by :func:`open_recording`.
    calibration : StereoCamera or path, optional
        The calibration of image folders (others carry their own; a command's ``--calib`` replaces it).
    rate_hz : float, optional
        The frame rate of image folders whose file names are not stamps.
    truth : None, False or path
        None: the recording's own truth (or poses); False: none, not even read (the poses then come from
        visual odometry); a TUM or EuRoC csv file of poses instead, matched to the frames by stamp
        (:mod:`mrstereo.recordings.truth`: the frame its poses are of, per layout).

    Raises
    ------
    FileNotFoundError
        Nothing at ``path``, no ``truth`` file.
    ValueError
        A folder of no known layout (the message lists what was looked for), a bag, or what its reader raises.
    """
    check_truth(truth)
    layout = layout_of(path)
    readers = {"dataset": lambda p, truth: with_truth(read_manifest(p), truth), "KITTI odometry": read_kitti_odometry,
               "KITTI raw": read_kitti_raw, "EuRoC/ASL": read_euroc}
    if layout in readers or layout == "image folders":
        manifest = readers[layout](path, truth=truth) if layout in readers else \
            read_image_folders(path, calibration=calibration, rate_hz=rate_hz, truth=truth)
        if Path(path).is_dir():         # the folder named (EuRoC's above mav0/, KITTI's above sequences/NN/)
            note_inputs(Inputs(folders=[path], kind=manifest.kind))
        return manifest
    raise ValueError(f"{path} is a ROS bag: open it with mrstereo.recordings.open_recording (read message by "
                     "message) or write it as a dataset with mrstereo.recordings.bag.export_bag")


def open_recording(path: str | os.PathLike, *, calibration=None, mount=None, prefer_raw: bool = False,
                   rate_hz: float | None = None, truth=None, **bag_options) -> FrameSource:
    """The recording at ``path`` as a :class:`~mrstereo.recordings.sources.FrameSource` of in-memory frames.

    Every layout of :data:`LAYOUTS`: a dataset, KITTI odometry, KITTI raw, EuRoC/ASL or image folders
    (a :class:`~mrstereo.recordings.sources.RecordingSource`: one pair read from disk at a time), or a
    ROS 1/2 bag (a :class:`~mrstereo.recordings.bag.BagSource`: read message by message, never exported).

    Parameters
    ----------
    path : path
        The recording (``mrstereo info PATH`` shows what is read).
    calibration : StereoCamera or path, optional
        The calibration of image folders and of a bag without camera_info; any other recording's
        is replaced by it (read its raw images with ``prefer_raw``).
    mount : CameraMount, optional
        Replaces the recording's camera mount.
    prefer_raw : bool
        A recording's raw images even where it has rectified ones (a calibration of one's own).
    rate_hz : float, optional
        The frame rate of image folders whose file names are not stamps.
    truth : None, False or path
        The recording's own truth, none, or a file's (:func:`read_recording`; a bag's: its odometry).
    **bag_options
        Those of :class:`~mrstereo.recordings.bag.BagSource` (topics, odometry, TF frames,
        ``sync_tolerance_s``, ``rectified``); without topics the bag's one stereo pair is picked.

    Raises
    ------
    FileNotFoundError
        Nothing at ``path``.
    ValueError
        No known layout (the message lists what was looked for), bag options for a recording that is
        not a bag, or what the layout's reader raises.
    """
    import dataclasses

    from ..camera import CameraMount, StereoCamera, read_stereo

    if calibration is not None and not isinstance(calibration, StereoCamera):
        calibration = read_stereo(calibration)
    if mount is not None and not isinstance(mount, CameraMount):
        raise TypeError(f"mount must be a CameraMount, got {type(mount).__name__}")
    if layout_of(path) == "ROS bag":
        from .bag import BagSource

        return BagSource(path, calibration=calibration, mount=mount, truth=truth, **bag_options)
    if bag_options:
        raise ValueError(f"{path} is not a ROS bag: the bag options {', '.join(sorted(bag_options))} do not apply")
    manifest = read_recording(path, calibration=calibration, rate_hz=rate_hz, truth=truth)
    if calibration is not None and manifest.layout != "image folders":
        manifest = dataclasses.replace(manifest, calibration=calibration)
    if mount is not None:
        manifest = dataclasses.replace(manifest, mount=mount)
    return RecordingSource(manifest, prefer_raw=prefer_raw, rate_hz=rate_hz)


def describe_recording(source: FrameSource | Manifest) -> list[tuple[str, str]]:
    """``(what, value)`` lines of what a recording holds: frames, rate, images, calibration, mount, truth, poses
    (a :class:`Manifest` is described as the :class:`RecordingSource` of it). Nothing is decoded."""
    import numpy as np

    from ..geometry.ground import ground_from_mount

    if isinstance(source, Manifest):
        source = RecordingSource(source)
    s, stamps = source.calibration, source.stamps_s
    if stamps is not None and len(stamps) > 1:
        rate = f"{1.0 / float(np.median(np.diff(stamps))):.3g} Hz over {stamps[-1] - stamps[0]:.1f} s"
    else:
        rate = "unknown (no stamps)" if stamps is None else "one frame"
    kind = "rectified" if source.rectified else "raw (rectified with the calibration)"
    path = getattr(getattr(source, "manifest", None), "calibration_path", None)
    where = f" ({path})" if path is not None and path.is_file() else ""
    lines = [("layout", f"{source.layout}: {source.root}"), ("frames", f"{source.n_frames}, {kind}"),
             ("rate", rate), ("images", f"{s.size[0]}x{s.size[1]}"),
             ("calibration", f"focal {s.focal_px:.1f} px, baseline {s.baseline_m:.4f} m, b f {s.baseline_m * s.focal_px:.1f}"
                             f" m px{where}")]
    if source.mount is not None:
        floor = ground_from_mount(source.mount, R_rect_from_cam=s.left.R)
        lines.append(("mount", f"camera {floor.height_m:.3f} m above the floor, tilted down {np.degrees(floor.tilt_rad):.1f}"
                               f" deg (checked against the floor seen when mapping)"))
    else:
        lines.append(("mount", "none: the floor is found in the first frames when mapping"))
    truth = source.true_poses
    if truth is not None:
        length = float(np.sum(np.linalg.norm(np.diff([T[:3, 3] for T in truth], axis=0), axis=1))) if len(truth) > 1 else 0.0
        lines.append(("truth", f"poses of every frame, path {length:.1f} m"))
    else:
        lines.append(("truth", "none"))
    if source.has_poses:
        lines.append(("odometry", "given poses (map and odometry use them; --odometry visual to replace them)"))
    else:
        lines.append(("odometry", "none: map and odometry take the poses from stereo visual odometry"))
    lines.append(("ground-truth map", str(source.ground_truth_map) if source.ground_truth_map else "none"))
    lines += [("note", n) for n in source.notes]
    return lines
