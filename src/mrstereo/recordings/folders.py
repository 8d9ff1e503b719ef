"""A plain pair of image folders with a calibration as a recording.

A left and a right folder (:data:`FOLDER_PAIRS`) and a calibration given or found by name
(:data:`CALIBRATION_NAMES`); images paired by name, else by order; stamps from the names
(:func:`stamps_from_names`) or ``rate_hz``. No poses, no mount unless the calibration holds one.
The layout: docs/dataset.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math
import os
import re
from pathlib import Path

import numpy as np

from ..camera import StereoCamera, read_stereo
from ..io import IMAGE_SUFFIXES, note_inputs
from .manifest import FrameRecord, Manifest
from .truth import camera_to_base, check_truth, with_truth

__all__ = ["read_image_folders", "is_image_folders", "image_folder_pair", "stamps_from_names", "FOLDER_PAIRS",
           "CALIBRATION_NAMES"]

FOLDER_PAIRS = (("left", "right"), ("cam0", "cam1"), ("image_0", "image_1"), ("image_2", "image_3"),
                ("left_rect", "right_rect"), ("fisheye1", "fisheye2"), ("infra1", "infra2"), ("l", "r"))
"""Names of a left and a right image folder, tried in this order."""

CALIBRATION_NAMES = ("stereo.yaml", "calibration.yaml", "calib.yaml", "camchain.yaml", "sensors.yaml")
"""Calibration files looked for in the folder when none is given."""


def _images(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)


def image_folder_pair(path: str | os.PathLike) -> tuple[Path, Path] | None:
    """The left and right image folders of ``path`` (the first pair of :data:`FOLDER_PAIRS` whose two
    folders hold images), or None."""
    path = Path(path)
    if not path.is_dir():
        return None
    for left, right in FOLDER_PAIRS:
        a, b = path / left, path / right
        if a.is_dir() and b.is_dir() and _images(a) and _images(b):
            return a, b
    return None


def is_image_folders(path: str | os.PathLike) -> bool:
    """True when ``path`` holds a left and a right image folder (:data:`FOLDER_PAIRS`)."""
    return image_folder_pair(path) is not None


def stamps_from_names(paths) -> np.ndarray | None:
    """Time stamps [s] read from file names, or None when the names are not time stamps.

    A stem of at least 9 digits before the decimal point is a time since 1970 (s, ms, us or ns:
    ``1403715273262142976`` ns, ``1560004885.437324`` s); frame numbers are not stamps.
    """
    stems = [Path(p).stem for p in paths]
    if stems and all(re.fullmatch(r"\d{9,10}\.\d+", s) for s in stems):
        stamps = np.array([float(s) for s in stems])
    elif stems and all(re.fullmatch(r"\d{9,19}", s) for s in stems):
        digits = max(len(s) for s in stems)            # seconds, ms, us or ns since 1970
        scale = 1.0 if digits <= 10 else 1e-3 if digits <= 13 else 1e-6 if digits <= 16 else 1e-9
        stamps = np.array([int(s) for s in stems], dtype=np.float64) * scale
    else:
        return None
    return stamps if np.all(np.diff(stamps) > 0) else None


def _calibration_file(path: Path) -> Path | None:
    found = [path / name for name in CALIBRATION_NAMES if (path / name).is_file()]
    return found[0] if found else None


def read_image_folders(path: str | os.PathLike, *, calibration: StereoCamera | str | os.PathLike | None = None,
                       rate_hz: float | None = None, truth=None) -> Manifest:
    """Read a folder with a left and a right image folder as a recording (a :class:`Manifest`).

    Parameters
    ----------
    path : path
        The folder (see the module docstring).
    calibration : StereoCamera or path, optional
        The stereo calibration, any format :func:`mrstereo.camera.read_stereo` reads (a
        pre-rectified camera: ``mrstereo calib convert --fx ...``); default a file of
        :data:`CALIBRATION_NAMES` in the folder.
    rate_hz : float, optional
        The frame rate, for names that are not time stamps (frames ``1 / rate_hz`` apart from 0).
    truth : None, False or path
        A TUM or EuRoC csv file of the left camera's poses in the first camera's frame, matched by
        stamp and moved to the base with the calibration's mount (which it needs)
        (:func:`mrstereo.recordings.truth.with_truth`); None or False: no poses.

    Returns
    -------
    Manifest
        Raw frames (``left``/``right``), stamps when known, no poses, ``layout="image folders"``.

    Raises
    ------
    ValueError
        No image folder pair, no calibration, images that cannot be paired, a bad rate.
    """
    check_truth(truth)
    root = Path(path)
    pair = image_folder_pair(root)
    if pair is None:
        names = ", ".join(f"{a}/ {b}/" for a, b in FOLDER_PAIRS)
        raise ValueError(f"{root} holds no pair of image folders ({names})")
    if rate_hz is not None and (isinstance(rate_hz, bool) or not isinstance(rate_hz, (int, float))
                                or not math.isfinite(rate_hz) or rate_hz <= 0):
        raise ValueError(f"rate_hz must be a positive number (frames per second), got {rate_hz!r}")
    if calibration is None:
        calibration = _calibration_file(root)
        if calibration is None:
            raise ValueError(f"{root}: image folders {pair[0].name}/ {pair[1].name}/ need a calibration: give one "
                             f"(--calib FILE; a pre-rectified camera: mrstereo calib convert --fx ...) or put "
                             f"{' or '.join(CALIBRATION_NAMES[:2])} in the folder")
    calibration_path = None if isinstance(calibration, StereoCamera) else Path(calibration)
    stereo = calibration if isinstance(calibration, StereoCamera) else read_stereo(calibration)
    lefts, rights = _images(pair[0]), _images(pair[1])
    by_name = {p.name: p for p in rights}
    if all(p.name in by_name for p in lefts):
        rights = [by_name[p.name] for p in lefts]
    elif len(lefts) != len(rights):
        raise ValueError(f"{root}: {pair[0].name}/ holds {len(lefts)} images and {pair[1].name}/ {len(rights)}, "
                         "with different names: cannot pair them")
    notes = []
    stamps = stamps_from_names(lefts)
    if stamps is None and rate_hz is not None:
        stamps = np.arange(len(lefts)) / float(rate_hz)
    elif stamps is None:
        notes.append("no stamps (file names are not time stamps and no rate was given)")
    if len(rights) < len(_images(pair[1])):
        notes.append(f"{len(_images(pair[1])) - len(rights)} right images without a left image left out")
    frames = tuple(FrameRecord(pose=(0.0, 0.0, 0.0), left=a.resolve(), right=b.resolve(),
                               stamp_s=None if stamps is None else float(stamps[k]))
                   for k, (a, b) in enumerate(zip(lefts, rights)))
    manifest = Manifest(root=root.resolve(), calibration=stereo,
                        calibration_path=(calibration_path or root).resolve(), mount=stereo.mount,
                        ground_truth_map=None, frames=frames, layout="image folders", has_poses=False,
                        notes=tuple(notes))
    note_inputs(manifest.inputs())
    if truth is None or truth is False:
        return manifest
    if stereo.mount is None:
        raise ValueError(f"ground truth {truth}: the poses of the left camera of image folders are moved to the robot "
                         f"base with the camera mount, and the calibration {manifest.calibration_path} has none "
                         "(add mount: to it)")
    return with_truth(manifest, truth, to_base=lambda T: camera_to_base(T, stereo.mount))
