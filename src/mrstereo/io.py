"""File formats: images, disparity maps (PFM, KITTI PNG), safe writes.

Every writer goes through :func:`atomic_write`: the data is written to a
temporary file beside the target and renamed into place, so a crash never
leaves a half-written output, and :func:`refuse_overwrite_input` keeps an
output from replacing one of the inputs. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

import cv2
import numpy as np

__all__ = [
    "atomic_write", "read_image", "write_image", "read_pfm", "write_pfm",
    "read_kitti_disparity", "write_kitti_disparity", "read_disparity",
    "write_disparity", "refuse_overwrite_input", "colorize_disparity",
]


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success.

    The temporary file keeps the target's suffix so that writers choosing a
    format by extension (OpenCV, matplotlib) still work.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp)
    try:
        yield tmp
        if tmp.is_file():   # mkstemp makes 0600 files; give the output the usual umask permissions
            os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def refuse_overwrite_input(output: str | os.PathLike, inputs: Iterable[str | os.PathLike]) -> None:
    """Raise ``ValueError`` if ``output`` is the same file as one of ``inputs``."""
    out = Path(output).resolve()
    for item in inputs:
        if Path(item).resolve() == out:
            raise ValueError(f"output {output} would overwrite the input {item}")


def _existing(path: str | os.PathLike, what: str) -> Path:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{what} not found: {path}")
    return path


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
    with atomic_write(path) as tmp:
        if not cv2.imwrite(str(tmp), image):
            raise ValueError(f"cannot write image {path}: unsupported suffix or dtype {image.dtype}")


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


def colorize_disparity(disparity_px: np.ndarray, *, max_disparity_px: float | None = None,
                       range_px: tuple[float, float] | None = None) -> np.ndarray:
    """Colour image (BGR uint8) of a disparity map: turbo, invalid pixels black.

    The colour scale spans ``range_px`` (low, high) in pixels; default: the 1st-99th percentile of
    the valid values (``mrstereo._plot.disparity_range_px``), or ``0 .. max_disparity_px`` when that
    is given. Same colours as the ``disparity --plot`` preview, which adds a colour bar.
    """
    from ._plot import disparity_colors, disparity_range_px

    d = np.asarray(disparity_px, dtype=np.float32)
    if range_px is None:
        range_px = (0.0, float(max_disparity_px)) if max_disparity_px else disparity_range_px(d)
    rgb = np.rint(disparity_colors(d, range_px=range_px)[..., :3] * 255).astype(np.uint8)
    return np.ascontiguousarray(rgb[..., ::-1])
