"""Numba kernels of the post-filters (:mod:`mrstereo.matching.postfilter`): the median's fixed-point code,
speckles (marked by ``cv2.filterSpeckles``), the depth-edge guard, gap filling.

Private: no validation, no defaults. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(nogil=True, cache=True)
def encode_fixed(disparity, scale, offset, lo_code, hi_code, invalid_code, out):
    """``round(d * scale) + offset`` clipped to ``[lo_code, hi_code]``, ``invalid_code`` where NaN."""
    height, width = disparity.shape
    for y in range(height):
        dr = disparity[y]
        orow = out[y]
        for x in range(width):            # branch-free (vectorizes)
            d = dr[x]
            ok = np.isfinite(d)
            v = min(max(np.rint((d if ok else 0.0) * scale) + offset, lo_code), hi_code)
            orow[x] = v if ok else invalid_code


@njit(nogil=True, cache=True)
def decode_median(coded, disparity, scale, out):
    """Inverse of the median's code (0 = invalid): NaN where the input was invalid or
    the median is invalid, else ``(code - 1) / scale``."""
    height, width = coded.shape
    nan = np.float32(np.nan)
    for y in range(height):
        cr = coded[y]
        dr = disparity[y]
        orow = out[y]
        for x in range(width):       # branch-free (vectorizes)
            c = cr[x]
            v = np.float32((c - 1) / scale)
            orow[x] = v if (c != 0) & np.isfinite(dr[x]) else nan


@njit(nogil=True, cache=True)
def drop_marked(disparity, code, marked, out):
    """``out = disparity`` with NaN where ``code == marked`` (speckles marked by ``cv2.filterSpeckles``)."""
    height, width = disparity.shape
    nan = np.float32(np.nan)
    for y in range(height):
        dr = disparity[y]
        cr = code[y]
        orow = out[y]
        for x in range(width):           # branch-free (vectorizes)
            orow[x] = nan if cr[x] == marked else dr[x]


@njit(nogil=True, cache=True)
def fill_invalid(disparity, value, out):
    """``out = disparity`` with ``value`` where NaN."""
    height, width = disparity.shape
    for y in range(height):
        dr = disparity[y]
        orow = out[y]
        for x in range(width):
            d = dr[x]
            orow[x] = d if np.isfinite(d) else value


@njit(nogil=True, cache=True)
def drop_above(disparity, lowest, jump, out):
    """``out = disparity`` with NaN where ``disparity - lowest > jump`` (depth-edge guard)."""
    height, width = disparity.shape
    nan = np.float32(np.nan)
    for y in range(height):
        dr = disparity[y]
        lr = lowest[y]
        orow = out[y]
        for x in range(width):
            d = dr[x]
            orow[x] = nan if (d - lr[x] > jump) else d


@njit(nogil=True, cache=True, inline="always")
def _fill_gap(d, c, base, step, hi, start, n, max_gap, max_diff, support):
    """In place on one line of the flat maps ``d``, ``c`` (element ``i`` at ``base + i * step``,
    ``n`` elements): fill the gap before ``hi``, the first pixel of a valid run, when the rule
    of :func:`mrstereo.matching.postfilter.fill_gaps` allows. ``start``: the first pixel of the
    valid run before the gap, in which the left support must lie.
    """
    lo = hi - 1
    while lo >= 0 and hi - lo - 1 <= max_gap and not np.isfinite(d[base + lo * step]):
        lo -= 1
    gap = hi - lo - 1
    if lo < 0 or gap > max_gap or lo - support + 1 < start or hi + support > n:
        return
    a = d[base + lo * step]
    b = d[base + hi * step]
    if not abs(a - b) <= max_diff:
        return
    for j in range(1, support):              # both ends backed by `support` agreeing pixels
        if not (abs(d[base + (lo - j) * step] - a) <= max_diff and abs(d[base + (hi + j) * step] - b) <= max_diff):
            return
    c_end = min(c[base + lo * step], c[base + hi * step])
    slope = (b - a) / np.float32(gap + 1)
    for i in range(1, gap + 1):
        d[base + (lo + i) * step] = a + slope * np.float32(i)
        c[base + (lo + i) * step] = c_end


@njit(nogil=True, cache=True)
def fill_gap_rows(disparity, confidence, run_starts, max_gap, max_diff, support):
    """Gap filling along the rows, in place. ``run_starts``: ascending flat indices of the
    valid pixels that follow an invalid one (a gap's right end, or a row's first run)."""
    width = disparity.shape[1]
    d, c = disparity.ravel(), confidence.ravel()
    row, start = -1, 0
    for i in run_starts:
        y, x = i // width, i % width
        if y != row:
            row, start = y, 0
        if x > 0:
            _fill_gap(d, c, y * width, 1, x, start, width, max_gap, max_diff, support)
            start = x


@njit(nogil=True, cache=True)
def fill_gap_columns(disparity, confidence, run_starts, first_row, max_gap, max_diff, support):
    """Gap filling along the columns, in place. ``run_starts``: ascending flat indices of the
    valid pixels below an invalid one; ``first_row`` (int32, width) is scratch."""
    height, width = disparity.shape
    d, c = disparity.ravel(), confidence.ravel()
    first_row[:] = 0
    for i in run_starts:
        y, x = i // width, i % width
        _fill_gap(d, c, x, width, y, first_row[x], height, max_gap, max_diff, support)
        first_row[x] = y
