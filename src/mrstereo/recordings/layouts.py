"""Which recording a path holds, and its reader: the one entry point of commands that take a recording.

A path is read by the first layout whose detection hook accepts it:

- a dataset directory or its ``manifest.yaml`` (docs/dataset.md): :func:`.manifest.read_manifest`;
- a KITTI odometry folder (``sequences/NN/`` or one sequence folder): :func:`.kitti.read_kitti_odometry`.

Each layout is a pair ``(detect(path) -> bool, read(path) -> Manifest)`` in :data:`LAYOUTS`.
Conventions: docs/conventions.md; the formats: docs/dataset.md.
"""
from __future__ import annotations

import os
from pathlib import Path

from .kitti import is_kitti_odometry, read_kitti_odometry
from .manifest import MANIFEST_NAME, Manifest, read_manifest

__all__ = ["LAYOUTS", "read_recording"]


def _is_manifest(path: Path) -> bool:
    return path.is_file() or (path / MANIFEST_NAME).is_file()


LAYOUTS = (("dataset manifest", _is_manifest, read_manifest),
           ("KITTI odometry", is_kitti_odometry, read_kitti_odometry))
"""``(name, detect, read)`` of every recording layout, tried in order."""


def read_recording(path: str | os.PathLike) -> Manifest:
    """Read the recording at ``path`` with the reader of its layout (:data:`LAYOUTS`).

    Raises
    ------
    FileNotFoundError
        Nothing at ``path``.
    ValueError
        A folder of no known layout (the message lists what was looked for), or what its reader raises.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"recording not found: {path}")
    for _, detect, read in LAYOUTS:
        if detect(path):
            return read(path)
    raise ValueError(f"{path} is not a recording: no {MANIFEST_NAME} (dataset folder) and not a KITTI odometry "
                     "folder (sequences/NN/image_0, image_1, calib.txt)")
