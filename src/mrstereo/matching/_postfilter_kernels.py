"""Numba kernels of the post-filters (:mod:`mrstereo.matching.postfilter`): the median's fixed-point code,
speckles, the depth-edge guard, gap filling.

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


@njit(nogil=True, cache=True, inline="always")
def _root(parent, i):
    """Union-find root of ``i`` (path halving)."""
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@njit(nogil=True, cache=True)
def drop_speckles(disparity, scale, max_code, max_diff_code, max_size, code, labels, parent, size, out):
    """``out = disparity`` with NaN on connected regions of at most ``max_size`` pixels.

    Pixels are coded ``clip(rint(d * scale), 0, max_code)``; 4-neighbours connect when
    both are valid and their codes differ by at most ``max_diff_code``: the regions of
    ``cv2.filterSpeckles`` on that code, found by union-find over the horizontal runs of
    connected pixels instead of a flood fill. Per row: links (a branch-free pass), run
    labels (a running count), then the unions with the row above where a
    vertical link joins two runs not yet seen joined. Scratch: ``code``, ``labels`` int32
    (H, W); ``parent``, ``size`` int32 (H * W).
    """
    height, width = disparity.shape
    encode_fixed(disparity, scale, 0, 0, max_code, -1, code)
    link = np.empty(width, np.bool_)          # link[x]: x - 1 and x connect
    n_runs = 0
    for y in range(height):
        cr = code[y]
        lr = labels[y]
        link[0] = False
        for x in range(1, width):
            c = cr[x]
            p = cr[x - 1]
            link[x] = (c >= 0) & (p >= 0) & (abs(c - p) <= max_diff_code)
        count = 0                        # pixels of the current run (in a register)
        for x in range(width):
            valid = cr[x] >= 0
            if valid and not link[x]:
                if count:
                    size[n_runs - 1] = count
                parent[n_runs] = n_runs
                n_runs += 1
                count = 0
            count += 1 if valid else 0
            lr[x] = n_runs - 1 if valid else -1
        if count:
            size[n_runs - 1] = count
        if y == 0:
            continue
        up_codes = code[y - 1]
        up_labels = labels[y - 1]
        for x in range(width):           # vertical links, in place of the row links
            c = cr[x]
            u = up_codes[x]
            link[x] = (c >= 0) & (u >= 0) & (abs(c - u) <= max_diff_code)
        prev_up, prev_here = -1, -1
        for x in range(width):           # unite where a link joins two runs not yet seen joined
            if not link[x]:
                continue
            up = up_labels[x]
            run = lr[x]
            if up == prev_up and run == prev_here:
                continue
            prev_up, prev_here = up, run
            a = _root(parent, up)
            b = _root(parent, run)
            if a != b:                   # the older run's root stays the root
                parent[max(a, b)] = min(a, b)
    # a root is the smallest run of its region: sizes add up into it going up, and the
    # flag "small" overwrites it last going down
    for run in range(n_runs):
        root = _root(parent, run)
        parent[run] = root
        if root != run:
            size[root] += size[run]
    for run in range(n_runs - 1, -1, -1):
        size[run] = 1 if size[parent[run]] <= max_size else 0
    nan = np.float32(np.nan)
    for y in range(height):
        dr = disparity[y]
        lr = labels[y]
        orow = out[y]
        for x in range(width):
            run = lr[x]
            orow[x] = nan if run >= 0 and size[run] != 0 else dr[x]


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
