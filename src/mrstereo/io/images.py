"""Images and disparity maps: OpenCV-decoded images, PFM (Middlebury) and 16-bit PNG (KITTI).

Every writer goes through :func:`mrstereo.io.files.atomic_write`. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import os
import tempfile
import threading
from pathlib import Path

import cv2
import numpy as np

from .. import _limits
from ._headers import image_size
from .files import _existing, atomic_write

__all__ = ["write_depth_png", "IMAGE_SUFFIXES", "matching_image", "read_image", "decode_image", "check_image_size", "quiet_decoders",
           "write_image", "read_pfm", "write_pfm", "read_kitti_disparity", "write_kitti_disparity", "read_disparity",
           "write_disparity"]

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".pbm", ".webp")
"""Suffixes :func:`write_image` writes (OpenCV's encoders present in every build)."""


def check_image_size(data, where: str) -> None:
    """Refuse encoded image ``data`` whose header claims more pixels than ``MRSTEREO_MAX_IMAGE_PIXELS``
    (or no pixel at all), before it is decoded; ``where`` names it. Data of a format the header reader
    does not know is left to OpenCV's own limit."""
    size = image_size(data)
    if size is None:
        return
    width, height = size
    if width <= 0 or height <= 0:
        raise ValueError(f"{where}: the image header claims {width}x{height} pixels: corrupt")
    _limits.within("MRSTEREO_MAX_IMAGE_PIXELS", width * height,
                   f"{where}: the image header claims {width}x{height} pixels")


_quiet = False
_decode_lock = threading.Lock()
_NOISE = (b"libpng ", b"[ WARN:", b"[ERROR:", b"[ INFO:", b"[FATAL:", b"Corrupt JPEG", b"Premature end of JPEG",
          b"JPEG", b"TIFF", b"libtiff", b"Warning,", b"Unknown field with tag")


def quiet_decoders(on: bool = True) -> None:
    """Keep what image decoders print (libpng's and libtiff's warnings, OpenCV's log) off stderr.

    For the ``mrstereo`` command, which reports every problem itself: decoder lines are dropped,
    anything else written meanwhile is passed on.
    """
    global _quiet
    _quiet = bool(on)
    if on:
        # FFmpeg's own log ("[mjpeg @ 0x...] ...") is read when OpenCV opens its first video, and the Rust
        # viewers' (rerun, foxglove) when they start: both before any of that happens here
        os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")
        os.environ.setdefault("RUST_LOG", "off")
        try:
            cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
        except AttributeError:
            pass


def decode_image(data, flag: int = cv2.IMREAD_UNCHANGED, *, where: str = "image"):
    """``cv2.imdecode`` of encoded bytes after :func:`check_image_size`; None when OpenCV cannot decode them."""
    check_image_size(data, where)
    buffer = np.frombuffer(data, np.uint8) if not isinstance(data, np.ndarray) else data
    if buffer.size == 0:
        return None
    if not _quiet:
        return _imdecode(buffer, flag)
    with _decode_lock, tempfile.TemporaryFile() as captured:
        try:
            saved = os.dup(2)
        except OSError:
            return _imdecode(buffer, flag)
        try:
            os.dup2(captured.fileno(), 2)
            return _imdecode(buffer, flag)
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            captured.seek(0)
            kept = [line for line in captured.read().splitlines(keepends=True) if not line.startswith(_NOISE)]
            if kept:
                os.write(2, b"".join(kept))


def _imdecode(buffer: np.ndarray, flag: int):
    try:
        return cv2.imdecode(buffer, flag)
    except cv2.error:
        return None


def read_image(path: str | os.PathLike, *, gray: bool = False) -> np.ndarray:
    """Read an image file as uint8 (or uint16) HxW or HxWx3 (BGR, OpenCV order).

    Raises ``FileNotFoundError`` for a missing file and ``ValueError`` for a file that is not a
    readable image or whose header claims more than ``MRSTEREO_MAX_IMAGE_PIXELS`` pixels (checked
    before decoding).
    """
    path = _existing(path, "image")
    data = path.read_bytes()
    flag = cv2.IMREAD_GRAYSCALE if gray else cv2.IMREAD_UNCHANGED
    img = decode_image(data, flag, where=f"image {path}")
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
    _limits.within("MRSTEREO_MAX_IMAGE_PIXELS", width * height,
                   f"PFM {path}: the header claims {width}x{height} pixels")
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


def write_depth_png(path: str | os.PathLike, depth_m: np.ndarray) -> None:
    """Write depth as a 16-bit PNG in millimetres, 0 invalid (RealSense and ROS ``depth_image_proc``'s 16UC1):
    NaN, non-positive and depths beyond 65.535 m are 0."""
    z = np.asarray(depth_m, dtype=np.float64)
    valid = np.isfinite(z) & (z > 0) & (z * 1000.0 <= 65535.0)
    value = np.zeros(z.shape, np.uint16)
    value[valid] = np.clip(np.round(z[valid] * 1000.0), 1, 65535).astype(np.uint16)
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

    A 16-bit image holding 8-bit data (every value a multiple of 257 or 256) becomes that 8-bit
    image; other 16-bit images become float32 ``v / 257`` (all levels distinct); other dtypes are
    returned as they are.
    """
    if not isinstance(image, np.ndarray):
        raise TypeError(f"image must be a numpy array, got {type(image).__name__}")
    if image.dtype != np.uint16:
        return image
    for step in (257, 256):
        if not np.any(image % np.uint16(step)):
            return (image // np.uint16(step)).astype(np.uint8)
    return image.astype(np.float32) / np.float32(257.0)
