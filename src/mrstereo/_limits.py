"""Bounds on what one input may ask for, each raised by an environment variable of its name.

A hostile or mistaken input (an image header claiming 10^10 pixels, a YAML alias bomb, a manifest of a
million frames, a bag chunk that decompresses to gigabytes) is refused with the size it asked for and the
variable that raises the bound, before memory is spent on it. Standard library only: ``import mrstereo``
hands the image limit to OpenCV before OpenCV is loaded. The table: docs/errors.md.
Conventions: docs/conventions.md.
"""
from __future__ import annotations

import os

__all__ = ["LIMITS", "limit", "within", "cpu_count", "max_workers"]

LIMITS = {
    "MRSTEREO_MAX_IMAGE_PIXELS": (1 << 26, "pixels of one image, read from its header before decoding"),
    "MRSTEREO_MAX_YAML_NODES": (2_000_000, "values of one YAML file, aliases expanded"),
    "MRSTEREO_MAX_FRAMES": (100_000, "frames of one recording or one synthetic run"),
    "MRSTEREO_MAX_MESSAGE_BYTES": (512 << 20, "bytes of one bag message or decompressed chunk"),
    "MRSTEREO_MAX_BAG_METADATA_BYTES": (256 << 10, "bytes of a ROS 2 bag's metadata.yaml (its reader parses about "
                                                   "150 KB a second)"),
    "MRSTEREO_MAX_WORKERS": (0, "workers of one run; 0: the cores of this machine"),
}
"""``name -> (default, what it bounds)``; the environment variable ``name`` overrides the default."""


def limit(name: str) -> int:
    """The limit ``name`` of :data:`LIMITS`: the environment variable of that name when set, else the default."""
    default, what = LIMITS[name]
    text = os.environ.get(name, "").strip()
    if not text:
        return default
    try:
        value = int(float(text))
    except (ValueError, OverflowError):
        raise ValueError(f"environment variable {name} ({what}) must be a number, got {text!r}") from None
    if value < 0:
        raise ValueError(f"environment variable {name} ({what}) must be >= 0, got {text!r}")
    return value


def within(name: str, value: float, what: str) -> float:
    """``value`` when it is at most the limit ``name``, else a ``ValueError`` saying ``what`` asked for it,
    the limit and how to raise it."""
    bound = limit(name)
    if value > bound:
        raise ValueError(f"{what}: {value:,.0f} is more than the limit of {bound:,} ({LIMITS[name][1]}); "
                         f"set {name} to raise it")
    return value


def cpu_count() -> int:
    """The cores this process may run on (its CPU affinity, else the machine's)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def max_workers() -> int:
    """The most workers a run may start: ``MRSTEREO_MAX_WORKERS`` when set (not 0), else :func:`cpu_count`."""
    return limit("MRSTEREO_MAX_WORKERS") or cpu_count()


def _hand_image_limit_to_opencv() -> None:
    """OpenCV reads ``OPENCV_IO_MAX_IMAGE_PIXELS`` once, when it is loaded: the backstop for image formats
    whose header mrstereo does not read (:func:`mrstereo.io.check_image_size`)."""
    try:
        value = limit("MRSTEREO_MAX_IMAGE_PIXELS")
    except ValueError:
        return
    os.environ.setdefault("OPENCV_IO_MAX_IMAGE_PIXELS", str(max(1, value)))
