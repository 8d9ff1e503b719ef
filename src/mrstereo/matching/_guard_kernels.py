"""Numba kernels of the near guard (:mod:`mrstereo.matching.near_guard`).

Private: no validation, no defaults. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import numpy as np
from numba import njit


# ----------------------------------------------------------------------------- near guard
@njit(nogil=True, cache=True)
def guard_candidates(winners, subpixel, scale, above, wide, checks, out):
    """Step 1 of the near guard in one pass (:mod:`.near_guard`).

    ``winners = (d_int, sub, c1, c2, d_right)``: the guard search's raw winners
    (:func:`band_winners`). ``out = (d_level, beyond, candidate)``: the level disparity ``d_int
    (+ sub)``; a winner with ``d scale > above``; and those that pass ``checks = (max_cost,
    wide_cost, lr_max_diff, keep, wide_keep)``: ``c1 <= max_cost`` (< 0: off), left-right
    consistent within ``lr_max_diff`` (< 0: off) and unique (``c1 <= keep c2``, ``keep`` < 0:
    off). ``wide`` (0, 1: the comparison, 2: also the product) and the ``wide_*`` flags evaluate
    in float64 where numpy's promotion of the settings' types would (float32 otherwise): the
    verdicts equal the numpy expressions of the checks (tests/test_matching_guard_kernels.py).
    """
    d_int, sub, c1, c2, d_right = winners
    max_cost, wide_cost, lr_max_diff, keep, wide_keep = checks
    out_d, out_beyond, out_candidate = out
    height, width = d_int.shape
    for y in range(height):
        for x in range(width):
            d = d_int[y, x]
            v = np.float32(np.float64(d) + np.float64(sub[y, x])) if subpixel else np.float32(d)
            out_d[y, x] = v
            if wide == 2:          # float64 product
                b = d >= 0 and np.float64(v) * np.float64(scale) > np.float64(above)
            elif wide == 1:        # float32 product, float64 comparison
                b = d >= 0 and np.float64(v * np.float32(scale)) > np.float64(above)
            else:
                b = d >= 0 and v * np.float32(scale) > np.float32(above)
            out_beyond[y, x] = b
            c = b
            cost = c1[y, x]
            if c and max_cost >= 0:
                c = np.float64(cost) <= max_cost if wide_cost else cost <= np.float32(max_cost)
            if c and lr_max_diff >= 0:
                xr = x - d
                if xr < 0:
                    c = False
                else:
                    back = d_right[y, xr]
                    c = back >= 0 and np.float64(abs(d - back)) <= lr_max_diff
            if c and keep >= 0:
                c = not (np.float64(cost) > keep * np.float64(c2[y, x]) if wide_keep
                         else cost > np.float32(keep) * c2[y, x])
            out_candidate[y, x] = c


@njit(nogil=True, cache=True)
def guard_upsample(beyond, d_level, labels_level, first_col, end_col, scale, out_field, out_want):
    """Step 2's up-sampling of the near guard: level column ``c`` spans the full-resolution
    columns ``first_col[c] .. end_col[c] - 1`` (nearest neighbour); ``out_field`` = the beyond
    winners' disparity times ``scale`` (float32, NaN elsewhere and outside the spans),
    ``out_want`` = the labelled clusters."""
    height, width = out_field.shape
    n = first_col.size
    nan = np.float32(np.nan)
    s = np.float32(scale)
    for y in range(height):
        field = out_field[y]
        want = out_want[y]
        field[:] = nan
        want[:] = False
        for c in range(n):
            if beyond[y, c]:
                v = d_level[y, c] * s
                for x in range(first_col[c], end_col[c]):
                    field[x] = v
            if labels_level[y, c] > 0:
                for x in range(first_col[c], end_col[c]):
                    want[x] = True


@njit(nogil=True, cache=True)
def guard_finite(values, labels_level, first_col, end_col, out_ys, out_xs, out_cluster):
    """The finite ``values`` at the full-resolution pixels of the labelled level pixels
    (``labels_level > 0``; level column ``c`` spans columns ``first_col[c] .. end_col[c] - 1``),
    in row-major order: their rows, columns and labels; returns their count."""
    n = 0
    height, w_level = labels_level.shape
    for y in range(height):
        for c in range(w_level):
            label = labels_level[y, c]
            if label == 0:
                continue
            for x in range(first_col[c], end_col[c]):
                if np.isfinite(values[y, x]):
                    out_ys[n] = y
                    out_xs[n] = x
                    out_cluster[n] = label
                    n += 1
    return n


@njit(nogil=True, cache=True)
def in_large_labels(labels, n_labels, size_px, out):
    """``out`` = the pixels whose label (0: none) counts more than ``size_px`` pixels."""
    count = np.zeros(n_labels, np.int64)
    height, width = labels.shape
    for y in range(height):
        for x in range(width):
            count[labels[y, x]] += 1
    count[0] = 0
    for y in range(height):
        for x in range(width):
            out[y, x] = count[labels[y, x]] > size_px


@njit(nogil=True, cache=True)
def map_labels(labels, table, out):
    """``out = table[labels]`` (a look-up per pixel)."""
    height, width = labels.shape
    for y in range(height):
        for x in range(width):
            out[y, x] = table[labels[y, x]]
