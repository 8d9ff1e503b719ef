"""Point clouds as binary little-endian PLY files (Open3D, MeshLab, CloudCompare read them).

``x y z`` float32 per vertex, then ``intensity`` or ``red green blue`` uchar, then an optional ``label``
uchar (:data:`LABELS`: what the chain made of the point); non-finite points are dropped. Layout: docs/obstacles.md (PLY). Conventions: docs/conventions.md.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from .. import _checks
from ..io import atomic_write

__all__ = ["PointCloud", "write_ply", "read_ply", "LABELS"]

LABELS = {0: "other", 1: "obstacle", 2: "floor"}
"""The ``label`` property of a point: 1 an obstacle point (in the height band, within range), 2 a floor point,
0 any other measured point (above the band, beyond the range, neither)."""

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}


@dataclass(frozen=True)
class PointCloud:
    """Points (N, 3) float32 with optional intensity (N,) uint8 or RGB colours (N, 3) uint8, and labels (N,)
    uint8 (:data:`LABELS`)."""

    points: np.ndarray
    intensity: np.ndarray | None = None
    colors_rgb: np.ndarray | None = None
    label: np.ndarray | None = None


def write_ply(path: str | os.PathLike, points, *, intensity=None, colors_rgb=None, label=None,
              comment: str = "mrstereo point cloud") -> int:
    """Write a binary little-endian PLY of ``x y z`` float32 (+ intensity or red green blue uchar), atomically.

    Parameters
    ----------
    path : path-like
    points : ndarray of shape (N, 3)
        Rows with NaN/inf are dropped with their attributes.
    intensity : ndarray of shape (N,), optional
        Gray value 0-255 per point.
    colors_rgb : ndarray of shape (N, 3), optional
        Colour per point in **RGB** order (OpenCV BGR: ``bgr[..., ::-1]``).
    label : ndarray of shape (N,), optional
        A class per point (:data:`LABELS`), written as the ``label`` property with the codes in a comment.
    comment : str
        One header line.

    Returns
    -------
    int
        The number of points written.
    """
    p = _checks.points3("points", points)
    if intensity is not None and colors_rgb is not None:
        raise ValueError("give intensity or colors_rgb, not both")
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    extra = np.empty((p.shape[0], 0), np.uint8)
    if intensity is not None:
        extra = _uint8("intensity", intensity, (p.shape[0],))[:, None]
        fields.append(("intensity", "u1"))
    elif colors_rgb is not None:
        extra = _uint8("colors_rgb", colors_rgb, (p.shape[0], 3))
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    if label is not None:
        extra = np.concatenate([extra, _uint8("label", label, (p.shape[0],))[:, None]], axis=1)
        fields.append(("label", "u1"))
        comment += "; label " + ", ".join(f"{k} {v}" for k, v in LABELS.items())
    if "\n" in comment:
        raise ValueError("comment must be one line")
    keep = np.isfinite(p).all(axis=1)
    records = np.empty(int(keep.sum()), dtype=np.dtype(fields))
    for j, (name, _) in enumerate(fields):
        records[name] = p[keep, j] if j < 3 else extra[keep, j - 3]
    header = "\n".join(["ply", "format binary_little_endian 1.0", f"comment {comment}",
                        f"element vertex {records.size}",
                        *(f"property {'float' if kind == '<f4' else 'uchar'} {name}" for name, kind in fields),
                        "end_header"]) + "\n"
    with atomic_write(path) as tmp, open(tmp, "wb") as fh:
        fh.write(header.encode("ascii"))
        fh.write(records.tobytes())
    return int(records.size)


def _uint8(name: str, value, shape: tuple[int, ...]) -> np.ndarray:
    arr = np.asarray(value)
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    if arr.dtype != np.uint8:
        arr = np.clip(np.rint(np.nan_to_num(arr.astype(np.float64))), 0, 255).astype(np.uint8)
    return arr


def read_ply(path: str | os.PathLike) -> PointCloud:
    """Read the vertices of a binary little-endian PLY (as written by :func:`write_ply` or Open3D).

    Only the first element must be ``vertex`` with scalar properties; ``x y z``
    are required, ``intensity``, ``red green blue`` and ``label`` are returned when present.
    """
    with open(path, "rb") as fh:
        if fh.readline().strip() != b"ply":
            raise ValueError(f"{path}: not a PLY file (no 'ply' magic)")
        fmt, n_vertex, props, element = None, None, [], None
        while True:
            line = fh.readline()
            if not line:
                raise ValueError(f"{path}: PLY header has no end_header")
            words = line.decode("ascii", "replace").split()
            if not words or words[0] in ("comment", "obj_info"):
                continue
            if words[0] == "end_header":
                break
            if words[0] == "format":
                fmt = words[1]
            elif words[0] == "element":
                element = words[1]
                if element == "vertex":
                    n_vertex = int(words[2])
                elif n_vertex is None:
                    raise ValueError(f"{path}: the first PLY element must be 'vertex', got {element!r}")
            elif words[0] == "property" and element == "vertex":
                if words[1] == "list" or words[1] not in _PLY_TYPES:
                    raise ValueError(f"{path}: unsupported vertex property {' '.join(words[1:])!r}")
                props.append((words[2], "<" + _PLY_TYPES[words[1]]))
        if fmt != "binary_little_endian":
            raise ValueError(f"{path}: only binary_little_endian PLY is supported, got {fmt!r}")
        if n_vertex is None:
            raise ValueError(f"{path}: PLY has no vertex element")
        dtype = np.dtype(props)
        data = fh.read(dtype.itemsize * n_vertex)
    if len(data) < dtype.itemsize * n_vertex:
        raise ValueError(f"{path}: PLY data is truncated ({len(data)} of {dtype.itemsize * n_vertex} bytes)")
    rec = np.frombuffer(data, dtype=dtype, count=n_vertex)
    names = dtype.names
    if not all(k in names for k in ("x", "y", "z")):
        raise ValueError(f"{path}: PLY vertices have no x, y, z")
    points = np.stack([rec["x"], rec["y"], rec["z"]], axis=1).astype(np.float32)
    intensity = rec["intensity"].copy() if "intensity" in names else None
    colors = (np.stack([rec["red"], rec["green"], rec["blue"]], axis=1).copy()
              if all(k in names for k in ("red", "green", "blue")) else None)
    label = rec["label"].copy() if "label" in names else None
    return PointCloud(points=points, intensity=intensity, colors_rgb=colors, label=label)
