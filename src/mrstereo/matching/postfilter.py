"""Post-filters of a disparity map: the paper's median (section 3.4), speckle removal, the
depth-edge guard, gap filling and the margin around too-near regions.

Disparity maps are float32 ``(H, W)`` in pixels, NaN invalid. Conventions:
docs/conventions.md.
"""
from __future__ import annotations

import cv2
import numpy as np

from . import _postfilter_kernels
from .cost import scratch

__all__ = ["median_filter", "remove_speckles", "guard_depth_edges", "fill_gaps", "near_side"]


_MEDIAN_SCALE = 64.0          # median in 1/64 px fixed point (uint16: up to 1023 px)


def median_filter(disparity_px: np.ndarray, *, size: int, max_px: float | None = None) -> np.ndarray:
    """Median filter of section 3.4 over valid and invalid pixels (invalid counts as -1).

    A valid pixel becomes invalid when most of its neighbours are; an invalid pixel stays
    invalid. ``max_px``: a bound on the disparities when the caller knows one.
    """
    if size == 0:
        return disparity_px
    if size not in (3, 5):          # what cv2.medianBlur takes for 16-bit and float images
        raise ValueError(f"size must be 0, 3 or 5, got {size!r}")
    disparity_px = np.ascontiguousarray(disparity_px, dtype=np.float32)
    if max_px is None:
        max_px = np.nanmax(disparity_px, initial=0.0)
    if max_px >= 65534 / _MEDIAN_SCALE:
        valid = np.isfinite(disparity_px)
        out = cv2.medianBlur(np.where(valid, disparity_px, -1.0).astype(np.float32), size)
        out[(out < 0) | ~valid] = np.nan
        return out
    coded = np.empty(disparity_px.shape, np.uint16)
    _postfilter_kernels.encode_fixed(disparity_px, _MEDIAN_SCALE, 1, 1, 65535, 0, coded)
    median = cv2.medianBlur(coded, size)
    out = np.empty(disparity_px.shape, np.float32)
    _postfilter_kernels.decode_median(median, disparity_px, _MEDIAN_SCALE, out)
    return out


def remove_speckles(disparity_px: np.ndarray, *, max_size_px: int, max_diff_px: float) -> np.ndarray:
    """Invalidate connected regions (4-neighbours within ``max_diff_px``) of at most
    ``max_size_px`` pixels: exactly ``cv2.filterSpeckles`` on a 1/16-pixel fixed-point copy, by
    union-find over row runs (each pixel visited a fixed number of times, no flood fill; faster
    than OpenCV's, docs/matching.md "Speed")."""
    if max_size_px <= 0:
        return disparity_px
    disparity_px = np.ascontiguousarray(disparity_px, dtype=np.float32)
    if disparity_px.ndim != 2:
        raise ValueError(f"disparity_px must be a 2-D map (H, W), got shape {disparity_px.shape}")
    h, w = disparity_px.shape
    out = np.empty((h, w), np.float32)
    _postfilter_kernels.drop_speckles(disparity_px, np.float32(_SPECKLE_SCALE), 2047 * _SPECKLE_SCALE,
                                      int(round(max_diff_px * _SPECKLE_SCALE)), int(max_size_px),
                                      scratch("speckle_code", (h, w), np.int32),
                                      scratch("speckle_labels", (h, w), np.int32),
                                      scratch("speckle_parent", (h * w,), np.int32),
                                      scratch("speckle_size", (h * w,), np.int32), out)
    return out


_SPECKLE_SCALE = 16           # the speckle filter's fixed point: 1/16 px, as StereoBM's output


def guard_depth_edges(disparity_px: np.ndarray, *, guard_px: int, jump_px: float) -> np.ndarray:
    """Invalidate the foreground side of depth edges, where window matching "fattens".

    A pixel is dropped when some valid pixel within ``guard_px`` columns (and one row) has a
    disparity smaller by more than ``jump_px``: it trades density for fewer wrong values.
    """
    if guard_px <= 0:
        return disparity_px
    disparity_px = np.ascontiguousarray(disparity_px, dtype=np.float32)
    filled = np.empty(disparity_px.shape, np.float32)
    _postfilter_kernels.fill_invalid(disparity_px, np.float32(1e9), filled)
    lowest = cv2.erode(filled, np.ones((3, 2 * guard_px + 1), np.uint8), borderType=cv2.BORDER_REPLICATE)
    out = np.empty(disparity_px.shape, np.float32)
    _postfilter_kernels.drop_above(disparity_px, lowest, np.float32(jump_px), out)     # NaN stays NaN
    return out


def fill_gaps(disparity_px: np.ndarray, confidence: np.ndarray, *, max_gap_px: int, max_diff_px: float,
              support_px: int) -> tuple[np.ndarray, np.ndarray]:
    """Fill short runs of invalid pixels that lie on one surface (beyond the paper).

    Rows, then columns: a run of at most ``max_gap_px`` invalid pixels is interpolated
    linearly when its two ends, each backed by ``support_px`` valid pixels, lie on one
    surface (within ``max_diff_px``); gaps at depth edges and borders stay invalid.
    ELAS's gap interpolation (Geiger et al. 2010), stricter.

    Parameters
    ----------
    disparity_px, confidence : ndarray float32 (H, W)
        The map (NaN invalid) and its confidence.
    max_gap_px : int
        Longest run filled; 0 returns the inputs.
    max_diff_px : float
        Largest difference between the two ends, and between an end and its support.
    support_px : int
        Consecutive valid pixels (the end included) that must back each end.

    Returns
    -------
    disparity_px, confidence : ndarray float32 (H, W)
        New arrays, the filled pixels with the lower confidence of their two ends.
    """
    if max_gap_px <= 0:
        return disparity_px, confidence
    disparity_px = np.ascontiguousarray(disparity_px, dtype=np.float32)
    confidence = np.ascontiguousarray(confidence, dtype=np.float32)
    if disparity_px.shape != confidence.shape:
        raise ValueError(f"confidence must have the disparity's shape {disparity_px.shape}, got {confidence.shape}")
    h, w = disparity_px.shape
    out_d, out_c = (np.empty((h, w), np.float32) for _ in range(2))
    np.copyto(out_d, disparity_px)
    np.copyto(out_c, confidence)
    args = int(max_gap_px), np.float32(max_diff_px), max(int(support_px), 1)
    # only the first pixels of valid runs (a gap's right end) do work; found with numpy
    valid = np.isfinite(out_d).ravel()
    _postfilter_kernels.fill_gap_rows(out_d, out_c, np.flatnonzero(valid[1:] > valid[:-1]) + 1, *args)
    valid = np.isfinite(out_d).ravel()
    _postfilter_kernels.fill_gap_columns(out_d, out_c, np.flatnonzero(valid[w:] > valid[:-w]) + w,
                              np.empty((w,), np.int32), *args)
    return out_d, out_c


def near_side(too_near: np.ndarray, *, margin_px: int) -> np.ndarray | None:
    """The too-near pixels and those within ``margin_px`` rows and columns of one (a
    ``2 margin + 1`` square dilation), or None when no pixel is too near.

    There windows are dominated by the background, whose disparity lies inside the search;
    like :func:`guard_depth_edges`, dropping them trades density for no wrong value.
    """
    if not too_near.any():
        return None
    if margin_px <= 0:
        return too_near
    kernel = np.ones((2 * margin_px + 1, 2 * margin_px + 1), np.uint8)
    grown = cv2.dilate(too_near.view(np.uint8), kernel)
    return grown.view(np.bool_)
