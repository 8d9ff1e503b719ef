"""Numba kernels of the eq. (13) rejection (:mod:`mrstereo.rejection`; no validation, preallocated outputs).

Each kernel does per element exactly the arithmetic of the numpy expression it stands for, in
the same order and dtype (no fastmath), so that its results do not depend on which image
type supplied the window sums; ``nogil`` lets the per-frame chain run on worker threads.

Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(nogil=True, cache=True, inline="always")
def _moments(sum1, sum2, scale):
    """``(mu, sigma)`` as float32 from the window sums of ``I`` and ``I^2``: ``E[.] = sum * scale``
    and ``sigma = sqrt(max(E[I^2] - mu^2, 0))`` in float64 (a NaN stays NaN, as ``np.maximum``)."""
    m = np.float64(sum1) * scale
    var = np.float64(sum2) * scale - m * m
    var = 0.0 if var < 0.0 else var
    return np.float32(m), np.float32(math.sqrt(var))


@njit(nogil=True, cache=True)
def moments_from_sums(sum1, sum2, scale, mean_out, std_out):
    """``mu_patch`` and ``sigma_patch`` of every pixel (:func:`_moments`)."""
    h, w = sum1.shape
    for v in range(h):
        for u in range(w):
            mean_out[v, u], std_out[v, u] = _moments(sum1[v, u], sum2[v, u], scale)


@njit(nogil=True, cache=True)
def reject_uniform(sum1, sum2, scale, threshold, mean_lo, mean_hi, floor, disparity, out, rejected, uniform):
    """Eq. (13) in one pass over the window sums.

    ``uniform``: the texture reading, ``sigma <= T`` (all False for ``T <= 0``) with ``mean_lo <=
    mu <= mean_hi``, compared in float32 as numpy compares the float32 statistics with Python
    floats; or ``floor`` (a learned floor model's mask; None: none). ``out``: the disparity as
    float32 with NaN where uniform and finite, those pixels marked in ``rejected``.
    """
    h, w = sum1.shape
    t = np.float32(threshold)
    lo = np.float32(mean_lo)
    hi = np.float32(mean_hi)
    on = threshold > 0
    nan = np.float32(np.nan)
    for v in range(h):
        for u in range(w):
            mu, sigma = _moments(sum1[v, u], sum2[v, u], scale)
            flat = on & (sigma <= t) & (mu >= lo) & (mu <= hi)      # branch-free: vectorizes
            if floor is not None:
                flat = flat | floor[v, u]
            d = np.float32(disparity[v, u])
            r = flat & math.isfinite(d)
            uniform[v, u] = flat
            rejected[v, u] = r
            out[v, u] = nan if r else d


@njit(nogil=True, cache=True, inline="always")
def _reflect(k, n):
    """Index ``k`` reflected into ``0 .. n - 1`` without repeating the border (OpenCV's BORDER_REFLECT_101)."""
    if n == 1:
        return 0
    while k < 0 or k >= n:
        k = -k if k < 0 else 2 * n - 2 - k
    return k


@njit(nogil=True, cache=True, inline="always")
def _squared_sobel_x(gray, i, out):
    """The squared 3x3 horizontal Sobel derivative of row ``i`` of ``gray`` into ``out`` (W,), borders reflected
    (101: the first and last columns' derivative is 0)."""
    h, w = gray.shape
    u, d = _reflect(i - 1, h), _reflect(i + 1, h)
    out[0] = 0.0
    out[w - 1] = 0.0
    for j in range(1, w - 1):
        g = ((np.float32(gray[u, j + 1]) - np.float32(gray[u, j - 1]))
             + np.float32(2.0) * (np.float32(gray[i, j + 1]) - np.float32(gray[i, j - 1]))
             + (np.float32(gray[d, j + 1]) - np.float32(gray[d, j - 1])))
        out[j] = g * g


@njit(nogil=True, cache=True)
def row_texture(gray, rows, cols, scale, first_row, out):
    """``out`` (H, W) = ``scale`` times the RMS of the horizontal Sobel derivative of ``gray`` (H, W) over windows
    of ``rows`` x ``cols`` pixels (odd; borders reflected, 101): window sums running down the rows (each column's;
    a row's squared derivative added as the window reaches it, again dropped as it leaves: no image-sized
    scratch but the window's rows, each computed once) and, as differences of prefix sums, along them. OpenCV's
    ``Sobel`` and ``sqrBoxFilter`` (the same borders) give the same to float32 rounding. The rows above
    ``first_row`` are NaN, not computed."""
    h, w = gray.shape
    hr, hc = rows // 2, cols // 2
    root_scale = np.float32(scale / math.sqrt(rows * cols))
    column_sums = np.zeros(w)
    window = np.empty((rows, w), np.float32)        # the window's rows' squared derivatives: row k in k % rows
    added = np.empty(w, np.float32)
    prefix = np.zeros(w + 2 * hc + 1)
    for i in range(min(first_row, h)):
        out[i, :] = np.nan
    for k in range(first_row - hr, first_row + hr + 1):
        kept = window[k % rows]
        _squared_sobel_x(gray, _reflect(k, h), kept)
        for j in range(w):
            column_sums[j] += kept[j]
    for i in range(first_row, h):
        if i > first_row:                           # slide the rows' window down by one: row i + hr replaces
            _squared_sobel_x(gray, _reflect(i + hr, h), added)      # row i - 1 - hr in its place
            kept = window[(i + hr) % rows]
            for j in range(w):
                column_sums[j] += np.float64(added[j]) - np.float64(kept[j])
                kept[j] = added[j]
        total = 0.0
        for k in range(-hc, w + hc):                # the row's window sums, as differences of its prefix sums
            total += column_sums[k] if 0 <= k < w else column_sums[_reflect(k, w)]
            prefix[k + hc + 1] = total
        row = out[i]
        for j in range(w):
            row[j] = prefix[j + cols] - prefix[j]
        for j in range(w):                          # float32 square roots: vectorized
            row[j] = root_scale * np.sqrt(max(row[j], np.float32(0.0)))


@njit(nogil=True, cache=True)
def noise_responses(gray, step, out):
    """``|N * gray|`` at every ``step``-th row and column inside the border (``N``: the difference of two
    Laplacians, [[1, -2, 1], [-2, 4, -2], [1, -2, 1]]) into ``out``; returns the number written."""
    h, w = gray.shape
    n = 0
    for i in range(1, h - 1, step):
        for j in range(1, w - 1, step):
            r = (np.float64(gray[i - 1, j - 1]) + gray[i - 1, j + 1] + gray[i + 1, j - 1] + gray[i + 1, j + 1]
                 - 2.0 * (np.float64(gray[i - 1, j]) + gray[i + 1, j] + gray[i, j - 1] + gray[i, j + 1])
                 + 4.0 * gray[i, j])
            out[n] = abs(r)
            n += 1
    return n


@njit(nogil=True, cache=True)
def integer_median(values, n, top):
    """The median of the first ``n`` of ``values``, whole numbers in ``0 .. top`` (as ``np.median``: the mean of
    the two middle ones for an even count), by counting: O(n + top)."""
    counts = np.zeros(top + 1, np.int64)
    for k in range(n):
        counts[int(values[k])] += 1
    lo_rank, hi_rank = (n - 1) // 2, n // 2
    seen = 0
    lo = -1
    for v in range(top + 1):
        seen += counts[v]
        if lo < 0 and seen > lo_rank:
            lo = v
        if seen > hi_rank:
            return 0.5 * (lo + v)
    return 0.0
