"""Numba kernels of the levels' union (:mod:`mrstereo.matching.multirange`, :mod:`mrstereo.matching.disparity`):
up-sampling and gating (eq. 11), the union (eq. 12), the cross-band ambiguity test, invalidation.

Private: no validation, no defaults. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ._band_kernels import FASTMATH


@njit(nogil=True, cache=True, fastmath=FASTMATH)
def upsample_gate(level_d, level_c, source_cols, scale, lo, hi, top, row0, row1, col0, col1, out_d, out_c):
    """Step 2 + eq. (11): nearest-neighbour up-sampling along x (full-resolution column
    ``x`` reads level column ``source_cols[x]``), disparity times ``scale``, kept where inside
    ``[lo, hi]`` and the AOI rows/cols (level rows start at full-resolution row ``top``)."""
    height, width = out_d.shape
    nan = np.float32(np.nan)
    zero = np.float32(0.0)
    for y in range(height):
        od = out_d[y]
        oc = out_c[y]
        if y < row0 or y >= row1:
            for x in range(width):
                od[x] = nan
                oc[x] = zero
            continue
        ld = level_d[y - top]
        lc = level_c[y - top]
        if level_d.shape[1] == width:       # full-resolution level: no gather (vectorizes)
            for x in range(width):
                d = ld[x] * scale
                ok = (d >= lo) and (d <= hi) and (x >= col0) and (x < col1)
                od[x] = d if ok else nan
                oc[x] = lc[x] if ok else zero
            continue
        for x in range(width):
            sx = source_cols[x]
            d = ld[sx] * scale
            ok = (d >= lo) and (d <= hi) and (x >= col0) and (x < col1)
            od[x] = d if ok else nan
            oc[x] = lc[sx] if ok else zero


@njit(nogil=True, cache=True)
def gate(disparity, confidence, lo, hi):
    """Eq. (11) in place: NaN / 0 outside ``[lo, hi]``."""
    height, width = disparity.shape
    for y in range(height):
        for x in range(width):
            d = disparity[y, x]
            if not (d >= lo and d <= hi):
                disparity[y, x] = np.nan
                confidence[y, x] = 0.0


@njit(nogil=True, cache=True)
def unite(disparity, confidence, first, out_d, out_c):
    """Eq. (12), one level at a time: the more confident value wins (a tie keeps the earlier,
    finer level's). ``first`` initializes the outputs (no prior value). Branch-free per pixel
    (the loops vectorize)."""
    height, width = disparity.shape
    nan = np.float32(np.nan)
    for y in range(height):
        dr = disparity[y]
        cr = confidence[y]
        od = out_d[y]
        oc = out_c[y]
        if first:
            for x in range(width):
                valid = np.isfinite(dr[x])
                od[x] = dr[x] if valid else nan
                oc[x] = cr[x] if valid else np.float32(0.0)
        else:
            for x in range(width):      # & and ~, not the branches of `and`: the loop vectorizes
                d, c, kept_d, kept_c = dr[x], cr[x], od[x], oc[x]
                take = np.isfinite(d) & ~(np.isfinite(kept_d) & (c <= kept_c))
                od[x] = d if take else kept_d
                oc[x] = c if take else kept_c


@njit(nogil=True, cache=True)
def band_value_cost(disparity, best_cost, source_cols, lo, hi, out_cost):
    """Cross-band ambiguity test, step 1: ``out_cost`` (inf = not yet) gets the level's winner
    cost ``best_cost[y, source_cols[x]]`` where the value lies in the level's band ``[lo, hi]``
    (NaN values compare false). Branch-free per pixel."""
    height, width = disparity.shape
    inf = np.float32(np.inf)
    for y in range(height):
        dr = disparity[y]
        br = best_cost[y]
        oc = out_cost[y]
        for x in range(width):
            d = dr[x]
            take = (d >= lo) & (d <= hi) & (oc[x] == inf)
            oc[x] = br[source_cols[x]] if take else oc[x]


@njit(nogil=True, cache=True)
def band_rivals(disparity, alt, alt_cost, source_cols, scale, lo, hi, min_apart, rival_max, margin, value_cost,
                out_mask):
    """Cross-band ambiguity test, step 2: ``out_mask`` is set where the level's band minimum
    ``alt * scale`` (level pixels -> full resolution) rivals a value outside the band: at least
    ``min_apart`` away, costing at most ``rival_max`` and less than the value's cost + ``margin``
    (NaN values and minima compare false). Branch-free per pixel."""
    height, width = disparity.shape
    for y in range(height):
        dr = disparity[y]
        ar = alt[y]
        cr = alt_cost[y]
        vr = value_cost[y]
        om = out_mask[y]
        for x in range(width):
            d = dr[x]
            s = source_cols[x]
            c = cr[s]
            rival = ((d < lo) | (d > hi)) & (abs(ar[s] * scale - d) >= min_apart) & (c <= rival_max) & \
                (c < vr[x] + margin)
            om[x] = om[x] | rival


@njit(nogil=True, cache=True)
def invalidate(disparity, confidence, mask):
    """In place: NaN / 0 where ``mask``."""
    height, width = disparity.shape
    nan = np.float32(np.nan)
    for y in range(height):
        dr = disparity[y]
        cr = confidence[y]
        mr = mask[y]
        for x in range(width):
            m = mr[x]
            dr[x] = nan if m else dr[x]
            cr[x] = np.float32(0.0) if m else cr[x]


@njit(nogil=True, cache=True)
def zero_where_invalid(disparity, confidence):
    """In place: ``confidence = 0`` where ``disparity`` is NaN."""
    height, width = disparity.shape
    for y in range(height):
        dr = disparity[y]
        cr = confidence[y]
        for x in range(width):
            cr[x] = cr[x] if np.isfinite(dr[x]) else np.float32(0.0)


@njit(nogil=True, cache=True)
def can_win(disparity, confidence, kept_d, kept_c, first, out):
    """``out``: the valid values of a level that :func:`unite` can take into ``kept_d``, ``kept_c``
    whatever they become (a valid kept value with at least their confidence keeps its place); all valid
    ones when ``first``. Branch-free per pixel."""
    height, width = disparity.shape
    for y in range(height):
        dr = disparity[y]
        cr = confidence[y]
        kd = kept_d[y]
        kc = kept_c[y]
        orow = out[y]
        if first:
            for x in range(width):
                orow[x] = np.isfinite(dr[x])
        else:
            for x in range(width):
                orow[x] = np.isfinite(dr[x]) & ~(np.isfinite(kd[x]) & (cr[x] <= kc[x]))
