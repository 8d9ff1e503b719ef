"""Images and disparity maps: OpenCV-decoded images, PFM (Middlebury) and 16-bit PNG (KITTI).

Every writer goes through :func:`mrstereo.io.files.atomic_write`. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np

from .files import _existing, atomic_write

__all__ = ["IMAGE_SUFFIXES", "matching_image", "read_image", "write_image", "read_pfm", "write_pfm", "read_kitti_disparity",
           "write_kitti_disparity", "read_disparity", "write_disparity"]

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".pbm", ".webp")
"""Suffixes :func:`write_image` writes (OpenCV's encoders present in every build)."""


def read_image(path: str | os.PathLike, *, gray: bool = False) -> np.ndarray:
    """Read an image file as uint8 (or uint16) HxW or HxWx3 (BGR, OpenCV order).

    Raises ``FileNotFoundError`` for a missing file and ``ValueError`` for a
    file that is not a readable image.
    """
    path = _existing(path, "image")
    data = np.fromfile(path, dtype=np.uint8)
    flag = cv2.IMREAD_GRAYSCALE if gray else cv2.IMREAD_UNCHANGED
    img = cv2.imdecode(data, flag) if data.size else None
    if img is None:
        raise ValueError(f"cannot decode image {path}: corrupt or not an image")
    if img.ndim == 3 and img.shape[2] == 4:
        img = img[:, :, :3]
    return img


def write_image(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write an image atomically; the format follows the suffix."""
    path = Path(path)
    image = np.asarray(image)
    try:
        ok, data = cv2.imencode(path.suffix.lower(), image)
    except cv2.error:
        ok = False
    if not ok:
        raise ValueError(f"cannot write image {path}: unsupported suffix {path.suffix!r} or dtype {image.dtype}")
    with atomic_write(path) as tmp, open(tmp, "wb") as fh:
        fh.write(data.tobytes())


def read_pfm(path: str | os.PathLike) -> np.ndarray:
    """Read a PFM file (Middlebury): returns float32 HxW (or HxWx3), top row first.

    Infinite values (Middlebury's "unknown") are returned as NaN.
    """
    path = _existing(path, "PFM file")
    with open(path, "rb") as fh:
        try:
            header = fh.readline().strip()
            if header not in (b"Pf", b"PF"):
                raise ValueError
            dims = fh.readline().split()
            while not dims:
                dims = fh.readline().split()
            width, height = int(dims[0]), int(dims[1])
            scale = float(fh.readline().strip())
        except (ValueError, IndexError):
            raise ValueError(f"cannot read PFM {path}: bad header") from None
        channels = 3 if header == b"PF" else 1
        dtype = "<f4" if scale < 0 else ">f4"
        data = np.frombuffer(fh.read(), dtype=dtype)
    count = width * height * channels
    if width <= 0 or height <= 0 or data.size < count:
        raise ValueError(f"cannot read PFM {path}: expected {count} values, found {data.size}")
    shape = (height, width, 3) if channels == 3 else (height, width)
    out = np.flipud(data[:count].reshape(shape)).astype(np.float32)
    out[~np.isfinite(out)] = np.nan
    return out


def write_pfm(path: str | os.PathLike, array: np.ndarray) -> None:
    """Write float32 HxW as little-endian PFM, rows bottom-up, NaN stored as inf."""
    arr = np.asarray(array, dtype=np.float32)
    if arr.ndim != 2:
        raise ValueError(f"array must be HxW, got shape {arr.shape}")
    arr = np.where(np.isfinite(arr), arr, np.float32(np.inf)).astype("<f4")
    with atomic_write(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(b"Pf\n%d %d\n-1\n" % (arr.shape[1], arr.shape[0]))
            fh.write(np.flipud(arr).tobytes())


def read_kitti_disparity(path: str | os.PathLike) -> np.ndarray:
    """Read a KITTI uint16 disparity PNG: d = value / 256, 0 -> NaN."""
    img = read_image(path)
    if img.dtype != np.uint16 or img.ndim != 2:
        raise ValueError(f"{path} is not a 16-bit single-channel KITTI disparity PNG")
    out = img.astype(np.float32) / 256.0
    out[img == 0] = np.nan
    return out


def write_kitti_disparity(path: str | os.PathLike, disparity_px: np.ndarray) -> None:
    """Write disparity as KITTI uint16 PNG (value = round(d * 256), 0 = invalid)."""
    d = np.asarray(disparity_px, dtype=np.float64)
    valid = np.isfinite(d) & (d > 0)
    value = np.zeros(d.shape, np.uint16)
    value[valid] = np.clip(np.round(d[valid] * 256.0), 1, 65535).astype(np.uint16)
    write_image(path, value)


def read_disparity(path: str | os.PathLike) -> np.ndarray:
    """Read a disparity map by suffix: ``.pfm`` or KITTI ``.png``."""
    suffix = Path(path).suffix.lower()
    if suffix == ".pfm":
        return read_pfm(path)
    if suffix == ".png":
        return read_kitti_disparity(path)
    raise ValueError(f"disparity file must end in .pfm or .png, got {path}")


def write_disparity(path: str | os.PathLike, disparity_px: np.ndarray) -> None:
    """Write a disparity map by suffix: ``.pfm`` (inf invalid) or ``.png`` (KITTI)."""
    suffix = Path(path).suffix.lower()
    if suffix == ".pfm":
        write_pfm(path, disparity_px)
    elif suffix == ".png":
        write_kitti_disparity(path, disparity_px)
    else:
        raise ValueError(f"disparity output must end in .pfm or .png, got {path}")


def matching_image(image: np.ndarray) -> np.ndarray:
    """An image on the 8-bit gray-level scale the matcher's parameters use.

    16-bit images (``mono16`` cameras, 16-bit PNG) become float32 ``v / 257`` (0..255): every one
    of the 65536 levels stays distinct (float32 keeps 24 bits), and an 8-bit image scaled by 257
    comes back exactly; others are returned as they are.
    """
    if image.dtype == np.uint16:
        return image.astype(np.float32) / np.float32(257.0)
    return image
