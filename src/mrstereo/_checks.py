"""Argument checks shared by the whole library.

Bad input raises ``ValueError`` or ``TypeError`` naming the argument, what was
expected and what arrived. The CLI turns these into one readable line.

Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math
import os
from numbers import Real

import numpy as np


def instance(name: str, value, types, what: str | None = None):
    """Return ``value``, raising ``TypeError`` naming the argument unless it is one of ``types`` (a type or a
    tuple of types; ``what`` names them in the message)."""
    if not isinstance(value, types):
        names = what or " or ".join(t.__name__ for t in (types if isinstance(types, tuple) else (types,)))
        article = "an" if names[0] in "AEIOU" else "a"
        raise TypeError(f"{name} must be {article} {names}, got {type(value).__name__}")
    return value


def finite_number(name: str, value, *, positive: bool = False, nonnegative: bool = False) -> float:
    """Return ``value`` as a float, raising if it is not a finite real number."""
    if isinstance(value, bool) or not isinstance(value, (Real, np.floating, np.integer)):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    out = float(value)
    if not math.isfinite(out):
        raise ValueError(f"{name} must be finite, got {out}")
    if positive and out <= 0:
        raise ValueError(f"{name} must be > 0, got {out}")
    if nonnegative and out < 0:
        raise ValueError(f"{name} must be >= 0, got {out}")
    return out


def positive_int(name: str, value, *, minimum: int = 1) -> int:
    """Return ``value`` as an int >= ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an integer, got {type(value).__name__}")
    if value < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value}")
    return int(value)


def instances(name: str, values, types):
    """``values`` when each is one of ``types``, else ``TypeError`` naming ``name[k]``."""
    for k, value in enumerate(values):
        instance(f"{name}[{k}]", value, types)
    return values


def image(name: str, value) -> np.ndarray:
    """Check an image: HxW or HxWx3, uint8 or floating, non-empty, finite."""
    if not isinstance(value, np.ndarray):
        raise TypeError(f"{name} must be a numpy array, got {type(value).__name__}")
    if value.ndim not in (2, 3) or (value.ndim == 3 and value.shape[2] not in (1, 3)):
        raise ValueError(f"{name} must have shape (H, W) or (H, W, 3), got {value.shape}")
    if value.shape[0] == 0 or value.shape[1] == 0:
        raise ValueError(f"{name} is empty: shape {value.shape}")
    if value.dtype != np.uint8 and not np.issubdtype(value.dtype, np.floating):
        if not np.issubdtype(value.dtype, np.integer):
            raise TypeError(f"{name} must be uint8 or float, got dtype {value.dtype}")
    return value


def image_dtype(name: str, value: np.ndarray, allowed=(np.uint8, np.uint16, np.float32, np.float64)) -> np.ndarray:
    """Check an image (:func:`image`) and that its dtype is one of ``allowed`` (what OpenCV's warps take)."""
    value = image(name, value)
    if value.dtype not in [np.dtype(t) for t in allowed]:
        raise TypeError(f"{name} must have dtype {', '.join(np.dtype(t).name for t in allowed)}; "
                        f"got {value.dtype} (convert it with .astype)")
    return value


def gray_float32(name: str, value) -> np.ndarray:
    """Return an image as float32 gray on the 8-bit scale (BGR colour, OpenCV order, with BT.601 weights).

    uint16 values are divided by 257 (65535 -> 255; an 8-bit image times 257 comes back exactly), as
    :func:`mrstereo.io.matching_image` does: every threshold of the matcher is in 8-bit gray levels.
    """
    value = image(name, value)
    if value.dtype == np.uint16:
        value = value.astype(np.float32) / np.float32(257.0)
    if value.ndim == 3:
        if value.shape[2] == 1:
            value = value[:, :, 0]
        else:
            value = value.astype(np.float32) @ np.array([0.114, 0.587, 0.299], np.float32)
    out = np.ascontiguousarray(value, dtype=np.float32)
    if not np.issubdtype(value.dtype, np.integer) and not np.isfinite(out).all():
        raise ValueError(f"{name} contains NaN or inf values")
    return out


def same_shape(name_a: str, a: np.ndarray, name_b: str, b: np.ndarray) -> None:
    """Raise if two images do not have the same height and width."""
    if a.shape[:2] != b.shape[:2]:
        raise ValueError(
            f"{name_a} and {name_b} must have the same size, got "
            f"{a.shape[1]}x{a.shape[0]} and {b.shape[1]}x{b.shape[0]}")


def points3(name: str, value) -> np.ndarray:
    """Return an (N, 3) float64 array."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {arr.shape}")
    return arr


def matrix(name: str, value, shape: tuple[int, ...]) -> np.ndarray:
    """Return a finite float64 array of the given shape."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} contains NaN or inf values")
    return arr


def ordered_pair(name: str, value, *, strict: bool = True) -> tuple[float, float]:
    """Return ``(low, high)`` finite floats with ``low < high`` (``<=`` when not ``strict``)."""
    try:
        lo, hi = value
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a pair (low, high), got {value!r}") from None
    lo, hi = finite_number(f"{name}[0]", lo), finite_number(f"{name}[1]", hi)
    if hi < lo or (strict and hi == lo):
        raise ValueError(f"{name} must have low {'<' if strict else '<='} high, got ({lo}, {hi})")
    return lo, hi


def rng(value) -> np.random.Generator:
    """A numpy Generator from a Generator, an int seed or None."""
    if isinstance(value, np.random.Generator):
        return value
    if value is None or (isinstance(value, (int, np.integer)) and not isinstance(value, bool)):
        return np.random.default_rng(value)
    raise TypeError(f"rng must be a numpy Generator, an int seed or None, got {type(value).__name__}")


def memory_limit_bytes() -> int:
    """The memory available to a new allocation now, in bytes (the bound of :func:`fits_in_memory`).

    Linux's ``MemAvailable`` (free memory plus what the kernel can reclaim without swapping), else
    the free physical pages, else the physical memory; 16 GiB on a system that tells none of these.
    """
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    for pages in ("SC_AVPHYS_PAGES", "SC_PHYS_PAGES"):
        try:
            return os.sysconf("SC_PAGE_SIZE") * os.sysconf(pages)
        except (ValueError, OSError, AttributeError):
            continue
    return 16 << 30


def format_bytes(n: float) -> str:
    """``1.5 GiB``-style size."""
    n = float(n)
    for unit in ("bytes", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024 or unit == "PiB":
            break
        n /= 1024
    if unit == "bytes":
        return f"{n:.0f} bytes"
    return f"{n:.1f} {unit}" if abs(n) < 1e6 else f"{n:.3g} {unit}"


def fits_in_memory(name: str, nbytes: float, what: str, *, limit_bytes: int | None = None) -> None:
    """Raise ``ValueError`` naming ``name`` when ``nbytes`` for ``what`` exceed the available memory.

    Called before allocating, so that a mistyped size ends in a message with the size that
    would be needed instead of a MemoryError deep in a kernel (or the system swapping).
    """
    limit = memory_limit_bytes() if limit_bytes is None else limit_bytes
    if not math.isfinite(nbytes) or nbytes > limit:
        raise ValueError(f"{name}: {what} would need {format_bytes(nbytes)} of memory, more than the "
                         f"{format_bytes(limit)} available on this machine")


def fits_on_disk(name: str, nbytes: float, folder, what: str) -> None:
    """Raise ``ValueError`` naming ``name`` when writing ``nbytes`` for ``what`` into ``folder`` (or the
    nearest existing folder above it) would fill its file system."""
    from pathlib import Path

    parent = Path(folder)
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    try:
        st = os.statvfs(parent)
    except (OSError, AttributeError):
        return
    free = st.f_bavail * st.f_frsize
    if not math.isfinite(nbytes) or nbytes > free:
        raise ValueError(f"{name}: {what} would need about {format_bytes(nbytes)} of disk, more than the "
                         f"{format_bytes(free)} free in {parent}")


def workers(name: str, value) -> int:
    """A worker count: an int from 1 to :func:`mrstereo._limits.max_workers` (more workers than cores only
    slow a run down)."""
    from ._limits import max_workers

    value = positive_int(name, value)
    cap = max_workers()
    if value > cap:
        raise ValueError(f"{name} must be at most {cap} (the cores of this machine; more workers than cores "
                         f"only wait for each other), got {value}; set MRSTEREO_MAX_WORKERS to allow more")
    return value
