"""Numba kernels of the integer cost engine: eq. (9)-(10) on 16-bit integers.

Private: no validation, no defaults (:mod:`mrstereo.matching.cost` prepares and allocates).
Conventions: docs/conventions.md.

The normalization of ZNCC moves out of the disparity loop. Each pre-filtered pixel is
normalized once per level by the mean and standard deviation of its own ``W x W`` window and
quantized, ``q = clip(rint(s (P - mu) / sigma), -Q, Q)`` (:func:`normalize_quantize`, int16),
so the window cost of a disparity is a plain sum of absolute differences

    SAD(x, y, d) = sum_ij |q_L(x + i, y + j) - q_R(x + i - d, y + j)|

added up on 16-bit lanes (``|diff| <= 2Q``, so a 31 x 31 window stays below 2**16). The
band search keeps per pixel what the checks need: the winner of eq. (10), its cost and its
neighbours' (parabola), the second best 2+ disparities away (uniqueness), the winner of
every right-image pixel (left-right check) and, on request, the band's lowest strict local
minimum (cross-band test), and applies the checks row by row. The costs leave the kernel in the units of the ZNCC cost ``1 -
rho``: for normalized values the difference ``e = q_L - q_R`` has variance ``2 s^2 (1 - rho)``
and, Laplace-distributed as differences of image derivatives are, mean absolute value
``sqrt(var / 2)``, so ``1 - rho = (SAD / (n s))^2`` with ``n = W^2`` (:func:`cost_of_sad`;
on Teddy and KITTI the winners' costs then match ZNCC's in distribution). The thresholds of
the checks (maximum cost, uniqueness, ambiguity margins) keep their meaning, and the parabola
fits a cost that is quadratic near its minimum (SAD itself is V-shaped there).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._kernels import (_FASTMATH, BIG, Q_MAX, STEPS_PER_SIGMA, _box, _parabola, _sad_cost, _strip_rows,
                       SAD, add_row_terms, check_constants, replicate_border, verdict)

# A window SAD that cannot occur (2 Q_MAX 31^2 < 2^16 - 1): "no candidate" (x < d, flat window).
SAD_NONE = np.uint16(65535)
# A window whose variance (times n) is below this is flat: ZNCC is undefined there and the
# normalized values are all 0, so its SAD would look like a perfect match.
FLAT_VARIANCE = 1e-4


@njit(nogil=True, cache=True, fastmath=_FASTMATH, inline="always")
def cost_of_sad(sad, unit):
    """The ZNCC-equivalent cost ``unit * SAD^2`` (module docstring), BIG for :data:`SAD_NONE`."""
    return _sad_cost(sad, unit) if sad != SAD_NONE else BIG


@njit(nogil=True, cache=True, fastmath=_FASTMATH)
def normalize_quantize(padded, a, b, radius, out_q, out_flat):
    """``out_q = clip(rint(s (P - mu) / sigma), -Q, Q)`` (int16) of a pre-filtered image
    ``padded`` by its window terms ``a = sum P / sqrt(n)``, ``b = 1 / (sigma n)`` (ZNCC's, see
    :func:`._kernels.window_terms`), padded by ``radius`` (replicated border) like ``padded``;
    ``out_flat`` (bool (H, W)): the windows whose variance is below :data:`FLAT_VARIANCE`."""
    height, width = a.shape
    n = (2 * radius + 1) ** 2
    inv_sqrt_n = np.float32(1.0 / math.sqrt(n))
    gain = np.float32(STEPS_PER_SIGMA * math.sqrt(n))
    lim = np.float32(Q_MAX)
    b_flat = np.float32(1.0 / math.sqrt(FLAT_VARIANCE))
    for y in range(height):
        p = padded[y + radius, radius:radius + width]
        ar = a[y]
        br = b[y]
        q = out_q[y + radius, radius:radius + width]
        flat = out_flat[y]
        for x in range(width):
            v = (np.float32(p[x]) - ar[x] * inv_sqrt_n) * br[x] * gain
            q[x] = np.int16(min(max(np.rint(v), -lim), lim))
            flat[x] = br[x] > b_flat
    replicate_border(out_q, radius)


@njit(nogil=True, cache=True, inline="always")
def _sad_row(left_q, right_q, flat, colsum, partial, cost, d_lo, cols, radius, y, first):
    """Slide the 16-bit column sums of ``|q_L - q_R|`` down to image row ``y`` (the strip's
    ``first`` row only gains a row) and write the window sums of columns ``col0 .. col1 - 1``
    at disparity ``d_lo + k`` into ``cost[k]`` (:data:`SAD_NONE` where ``x < d`` or where
    ``flat``, uint16 0 / 0xFFFF, is set). Every loop runs along a row over contiguous
    int16/uint16 slices: packed 16-bit arithmetic."""
    col0, col1 = cols
    c_end = col1 + 2 * radius
    add = y + 2 * radius
    win = 2 * radius + 1
    if first:
        add_row_terms(left_q, right_q, colsum, add, d_lo, cols, radius, SAD)
    for k in range(colsum.shape[0]):
        d = d_lo + k
        x0 = max(col0, d)
        col = colsum[k, x0:c_end]
        if not first:
            la = left_q[add, x0:c_end]
            ra = right_q[add, x0 - d:c_end - d]
            ls = left_q[y - 1, x0:c_end]
            rs = right_q[y - 1, x0 - d:c_end - d]
            for i in range(c_end - x0):
                col[i] += np.uint16(abs(np.int16(la[i] - ra[i]))) - np.uint16(abs(np.int16(ls[i] - rs[i])))
        crow = cost[k]
        for i in range(col0, min(x0, col1)):
            crow[i] = SAD_NONE
        if col1 > x0:
            seg = crow[x0:col1]
            _box(col, seg, partial, col1 - x0, win)
            fl = flat[x0:col1]
            for i in range(col1 - x0):
                seg[i] |= fl[i]


@njit(nogil=True, cache=True, inline="always")
def _sad_winners(cost, cols, best, best_k, second):
    """Eq. (10) per column of ``cost[:, col0:col1]``: the lowest SAD ``best`` and its first row
    ``best_k``, and ``second``, the lowest SAD 2+ rows away (uniqueness). Comparisons of
    int16 with int16 (no promotion to int64): the loops run on 16-bit lanes."""
    col0, col1 = cols
    nx = col1 - col0
    nd = cost.shape[0]
    for i in range(nx):
        best[i] = SAD_NONE
        best_k[i] = 0
        second[i] = SAD_NONE
    for k in range(nd):
        crow = cost[k, col0:col1]
        kk = np.int16(k)
        for i in range(nx):
            better = crow[i] < best[i]
            best_k[i] = kk if better else best_k[i]
            best[i] = min(best[i], crow[i])
    for k in range(nd):
        crow = cost[k, col0:col1]
        above = np.int16(k + 1)
        below = np.int16(k - 1)
        for i in range(nx):
            far = (best_k[i] > above) | (best_k[i] < below)
            second[i] = min(second[i], crow[i] if far else SAD_NONE)


@njit(nogil=True, cache=True, inline="always")
def _sad_right_winners(cost, d_lo, cols, right_best, right_k):
    """Eq. (10) for each right-image pixel ``x_r`` from the same costs: the lowest
    ``SAD(x_r + d, d)`` and its row (-1 where none)."""
    col0, col1 = cols
    right_best[:] = SAD_NONE
    right_k[:] = -1
    for k in range(cost.shape[0]):
        d = d_lo + k
        x0 = max(col0, d)
        if col1 <= x0:
            continue
        crow = cost[k, x0:col1]
        rb = right_best[x0 - d:col1 - d]
        rk = right_k[x0 - d:col1 - d]
        kk = np.int16(k)
        for i in range(col1 - x0):
            better = crow[i] < rb[i]
            rk[i] = kk if better else rk[i]
            rb[i] = min(crow[i], rb[i])


@njit(nogil=True, cache=True, inline="always")
def _sad_band_minimum(cost, k_lo, k_hi, cols, min_k, min_sad):
    """Per column the lowest strict local minimum (``c(k - 1) >= c(k) < c(k + 1)``) among the
    rows ``k_lo .. k_hi``: its row (-1: none) and SAD (:data:`SAD_NONE`: none)."""
    col0, col1 = cols
    nx = col1 - col0
    min_k[:nx] = -1
    min_sad[:nx] = SAD_NONE
    for k in range(max(k_lo, 1), min(k_hi, cost.shape[0] - 2) + 1):
        c0 = cost[k, col0:col1]
        cm = cost[k - 1, col0:col1]
        cp = cost[k + 1, col0:col1]
        kk = np.int16(k)
        for i in range(nx):
            m = (c0[i] <= cm[i]) & (c0[i] < cp[i]) & (c0[i] < min_sad[i])
            min_k[i] = kk if m else min_k[i]
            min_sad[i] = c0[i] if m else min_sad[i]


# One body for the whole row: the band search is the matcher's hot loop; the row's winners, checks
# and write-out run while its costs are in cache (a separate check pass over full-size maps of
# the winners cost 2 ms per 640x480 level more).
@njit(nogil=True, parallel=True, cache=True, fastmath=_FASTMATH)
def band_sad(left_q, right_q, flat_left, radius, band, aoi, n_strips, unit, checks, minimum_band, out, out_minimum):
    """Winner-take-all (eq. 10) of the SAD of normalized images over ``d in [d_lo, d_hi]``,
    raw or checked.

    Parameters
    ----------
    left_q, right_q : ndarray int16 (H + 2r, W + 2r)
        Normalized, quantized images padded by ``radius`` (:func:`normalize_quantize`).
    flat_left : ndarray bool (H, W)
        The left image's flat windows: no candidate (ZNCC is undefined there).
    band : (int, int)
        ``(d_lo, d_hi)``.
    aoi : (int, int, int, int)
        ``(row0, row1, col0, col1)``, half-open; rows outside are left untouched.
    unit : float32
        ``_kernels.sad_unit`` of the window.
    checks : (float, float, float, bool, bool)
        ``(lr_max_diff, uniqueness_ratio, max_cost, parabola, checked)``: with ``checked`` the
        checks of :func:`._kernels.band_checked` from the costs kept per pixel (the winner, the
        costs beside it, the second best 2+ disparities away, the right image's winners of the
        row), written as ``out = (disparity, confidence)`` float32 (H, W) (NaN / 0 rejected and
        outside ``col0:col1``); else ``out`` holds the raw winners: ``disparity_int`` (int32, -1
        where no candidate), ``subpixel`` (float32 parabola offset), ``best_cost``,
        ``second_cost`` (float32 ZNCC-equivalent costs, BIG if none), ``right_disparity_int``
        (int32, -1 if none), columns ``col0:col1`` (the right winners: whole rows).
    minimum_band : (int, int)
        When ``lo <= hi``: also the band's lowest strict local minimum at disparities ``lo ..
        hi`` (the cross-band ambiguity test) into ``out_minimum`` = (its disparity, NaN none;
        its cost, BIG none; the winner's cost), float32 (H, W), columns ``col0:col1``.
    """
    lr_tol, ratio, max_cost, parabola, checked = checks
    d_lo, d_hi = band
    row0, row1, col0, col1 = aoi
    cols = (col0, col1)
    nd = d_hi - d_lo + 1
    width = flat_left.shape[1]
    wp = width + 2 * radius
    nx = col1 - col0
    with_minimum = minimum_band[0] <= minimum_band[1]
    lr_int, keep, max_c = check_constants(lr_tol, ratio, max_cost)
    for s in prange(n_strips):
        y_start, y_end = _strip_rows(s, n_strips, row0, row1)
        if y_start >= y_end:
            continue
        colsum = np.zeros((nd, wp), np.uint16)
        partial = np.empty((4, wp), np.uint16)
        cost = np.empty((nd, width), np.uint16)
        best = np.empty(nx, np.uint16)
        second = np.empty(nx, np.uint16)
        best_k = np.empty(nx, np.int16)
        right_best = np.empty(width, np.uint16)
        right_k = np.empty(width, np.int16)
        min_k = np.empty(nx, np.int16)
        min_sad = np.empty(nx, np.uint16)
        flat = np.empty(width, np.uint16)
        row_d = np.empty(nx, np.int64)
        row_sub = np.empty(nx, np.float32)
        row_c1 = np.empty(nx, np.float32)
        row_c2 = np.empty(nx, np.float32)
        lr_ok = np.empty(nx, np.bool_)
        for yy in range(y_start, y_start + 2 * radius):       # the strip's first window rows
            add_row_terms(left_q, right_q, colsum, yy, d_lo, cols, radius, SAD)
        for y in range(y_start, y_end):
            fy = flat_left[y]
            for x in range(width):
                flat[x] = SAD_NONE if fy[x] else np.uint16(0)
            _sad_row(left_q, right_q, flat, colsum, partial, cost, d_lo, cols, radius, y, y == y_start)
            _sad_winners(cost, cols, best, best_k, second)
            _sad_right_winners(cost, d_lo, cols, right_best, right_k)
            for i in range(nx):
                k = np.int64(best_k[i])
                found = best[i] != SAD_NONE
                cb = cost_of_sad(best[i], unit)
                cm = cost_of_sad(cost[k - 1, col0 + i], unit) if found and k > 0 else BIG
                cp = cost_of_sad(cost[k + 1, col0 + i], unit) if found and k < nd - 1 else BIG
                row_d[i] = d_lo + k if found else -1
                row_sub[i] = _parabola(cb, cm, cp) if found else np.float32(0.0)
                row_c1[i] = cb
                row_c2[i] = cost_of_sad(second[i], unit)
            if checked:
                _checked_row(row_d, row_sub, row_c1, row_c2, right_k, d_lo, cols, (lr_tol, lr_int, ratio, keep,
                             max_cost, max_c, parabola), lr_ok, out[0][y], out[1][y])
            else:
                out[0][y, col0:col1] = row_d
                out[1][y, col0:col1] = row_sub
                out[2][y, col0:col1] = row_c1
                out[3][y, col0:col1] = row_c2
                orr = out[4][y]
                for x in range(width):
                    orr[x] = d_lo + right_k[x] if right_k[x] >= 0 else -1
            if with_minimum:
                _sad_band_minimum(cost, minimum_band[0] - d_lo, minimum_band[1] - d_lo, cols, min_k, min_sad)
                om = out_minimum[0][y, col0:col1]
                omc = out_minimum[1][y, col0:col1]
                for i in range(nx):
                    om[i] = np.float32(d_lo + min_k[i]) if min_k[i] >= 0 else np.float32(np.nan)
                    omc[i] = cost_of_sad(min_sad[i], unit)
                out_minimum[2][y, col0:col1] = row_c1


@njit(nogil=True, cache=True, fastmath=_FASTMATH, inline="always")
def _checked_row(row_d, row_sub, row_c1, row_c2, right_k, d_lo, cols, checks, lr_ok, od, oc):
    """One row's winners through the checks (:func:`._kernels.verdict`): left-right consistency
    with the right image's winner at ``x - d`` (row ``right_k``), uniqueness, maximum cost; into
    the row's ``od``, ``oc`` (NaN / 0 outside ``cols``)."""
    lr_tol, lr_int, ratio, keep, max_cost, max_c, parabola = checks
    col0, col1 = cols
    width = od.size
    for x in range(col0):
        od[x] = np.nan
        oc[x] = 0.0
    for x in range(col1, width):
        od[x] = np.nan
        oc[x] = 0.0
    for i in range(col1 - col0):        # the left-right gather apart: the loop below vectorizes
        d = row_d[i]
        kr = np.int64(right_k[min(max(col0 + i - d, 0), width - 1)])
        lr_ok[i] = (d >= 0) & ((lr_tol < 0) | ((kr >= 0) & (abs(d - d_lo - kr) <= lr_int)))
    odc = od[col0:col1]
    occ = oc[col0:col1]
    for i in range(col1 - col0):
        odc[i], occ[i] = verdict(lr_ok[i], np.float32(row_d[i]), row_sub[i], row_c1[i], row_c2[i], ratio, keep,
                                 max_cost, max_c, parabola)
