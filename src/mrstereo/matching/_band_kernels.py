"""Numba kernels of the band search (:mod:`mrstereo.matching.cost`): window cost + winner-take-all, eq. (9)-(10).

Private: no validation, no defaults; the caller (:mod:`mrstereo.matching.cost`)
pads, precomputes and allocates. An image arrives prepared as a tuple ``(padded, a, b)``:
padded by the window radius ``r`` on every side, and its per-pixel window terms.
Conventions: docs/conventions.md.

:func:`band_winners` and :func:`band_checked` search one disparity band ``[d_lo, d_hi]`` on
one image pair. Rows are split into strips, one per thread (``prange``). Inside a strip the
rows are visited in order; for every disparity ``d`` a row of running column sums
``sum_j I_L(y + j, c) I_R(y + j, c - d)`` is updated by adding the row entering the
window and subtracting the row leaving it, and a row of window sums is the sum of
``W`` shifted column-sum rows (in few passes, :func:`box_sum`). Every inner loop runs along the image row over
contiguous memory (one disparity at a time), so it vectorizes; the cost of one
pixel and disparity is O(1) in the window size. The window sums of ``I^2`` (and
``I``) do not depend on the disparity and arrive as per-pixel terms ``a`` and ``b``:

    NSSD (eq. 9):  c = (a_L + a_R - 2 S_LR) * b_L * b_R,  a = sum I^2, b = 1/sqrt(sum I^2)
    ZNCC:          c = 1 - (S_LR - a_L a_R) * b_L * b_R,  a = sum I / sqrt(n), b = 1/sigma sqrt(n)

A strip holds the costs of one image row (all disparities of the band), never a cost
volume. Integer-valued images (the x-Sobel pre-filter) are summed exactly in float32.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

# Finite "infinity": costs are finite by construction (b uses max(energy, eps)).
BIG = np.float32(3.0e38)
# fast-math without "nnan"/"ninf": the kernels write NaN (invalid) on purpose
FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}
# float32 constants: a Python float would promote float32 expressions to float64
ONE = np.float32(1.0)
TWO = np.float32(2.0)
# The cost a kernel evaluates (``kind``): NSSD (eq. 9) or ZNCC.
NSSD, ZNCC = 0, 1


@njit(nogil=True, cache=True, fastmath=FASTMATH, inline="always")
def _blend(m, a, b):
    """``a`` where the float32 mask ``m`` is 1, ``b`` where it is 0; exact for finite values.
    Arithmetic on purpose: numba lowers ``a if c else b`` to branches that LLVM turns into
    predicated scalar stores, which stops a loop from vectorizing."""
    return a * m + b * (ONE - m)


# The cost of one pixel and disparity from the window sum S_LR and the two pixels' window
# terms (module docstring). The part that depends on S_LR is rounded to float32 first, so
# float64 sums (non-integer images) still cost float32 arithmetic. The parameters come in the
# order the formula reads them: under fast-math the compiler may reassociate the products, and
# it orders the operands by where they were loaded, so that order decides the rounding.
@njit(nogil=True, cache=True, fastmath=FASTMATH, inline="always")
def zncc_cost(window_sum, a_l, a_r, b_l, b_r):
    """ZNCC: ``1 - (S_LR - a_L a_R) b_L b_R``."""
    return ONE - np.float32(window_sum - a_l * a_r) * b_l * b_r


@njit(nogil=True, cache=True, fastmath=FASTMATH, inline="always")
def nssd_cost(a_l, a_r, window_sum, b_l, b_r):
    """NSSD, eq. (9): ``(a_L + a_R - 2 S_LR) b_L b_R``."""
    return np.float32(a_l + a_r - TWO * window_sum) * b_l * b_r


@njit(nogil=True, cache=True, fastmath=FASTMATH, inline="always")
def column_winners(cost, rows, n, best_cost, best_k, cost_before, cost_after):
    """Eq. (10) per column of ``cost[:rows, :n]``: the first minimum ``best_cost`` and its row
    ``best_k`` (float32, -1 where no row is below BIG), then the costs of the rows beside it
    for the parabola, ``cost_before`` (row ``best_k - 1``) and ``cost_after`` (row
    ``best_k + 1``), BIG where none."""
    for i in range(n):
        best_cost[i] = BIG
        best_k[i] = -1.0
    for k in range(rows):
        crow = cost[k]
        kf = np.float32(k)
        for i in range(n):
            m = np.float32(crow[i] < best_cost[i])
            best_k[i] = _blend(m, kf, best_k[i])
            best_cost[i] = _blend(m, crow[i], best_cost[i])
    for i in range(n):
        b = np.int64(best_k[i])
        cost_before[i] = cost[b - 1, i] if b > 0 else BIG
        cost_after[i] = cost[b + 1, i] if 0 <= b < rows - 1 else BIG


@njit(nogil=True, cache=True, fastmath=FASTMATH, inline="always")
def parabola_offset(cb, cm, cp):
    """Sub-pixel offset of the parabola through (-1, cm), (0, cb), (1, cp), clipped to +-0.5;
    0 when a neighbour is missing or the parabola is not convex."""
    den = cm - TWO * cb + cp
    fine = (cm < BIG) and (cp < BIG) and (den > 0)
    sub = np.float32(0.5) * (cm - cp) / (den if fine else np.float32(1.0))
    return min(max(sub, np.float32(-0.5)), np.float32(0.5)) if fine else np.float32(0.0)


@njit(nogil=True, cache=True, fastmath=FASTMATH, inline="always")
def box_sum(col, out, partial, m, win):
    """``out[i] = sum_{j < win} col[i + j]`` for ``i < m`` (``win < 32``), in few vector passes:
    for a multiple of 3 (9, the default) sums of 3 neighbours then ``win / 3`` of those;
    otherwise a binary decomposition of ``win`` into sums of 1, 2, 4, 8, 16 neighbours.
    ``partial`` (4, len(col)) is scratch: row ``j`` holds the sums of ``2^(j + 1)``
    neighbours (row 0 those of 3 for the 3-split).
    The 3-split is used only for float32 and integers (``col.itemsize <= 4``): the matcher's
    float32 inputs are integer-valued and their sums exact in any grouping, as are integer
    sums; float64 (non-integer images) keeps the binary grouping, so results do not depend on
    the split."""
    length = m + win - 1
    if win % 3 == 0 and col.itemsize <= 4:
        sum3 = partial[0]
        for i in range(length - 2):
            sum3[i] = col[i] + col[i + 1] + col[i + 2]
        if win == 3:
            for i in range(m):
                out[i] = sum3[i]
        elif win == 9:
            s0 = sum3[0:m]
            s1 = sum3[3:3 + m]
            s2 = sum3[6:6 + m]
            for i in range(m):
                out[i] = s0[i] + s1[i] + s2[i]
        else:
            for i in range(m):
                out[i] = sum3[i] + sum3[i + 3]
            for j in range(6, win, 3):
                seg = sum3[j:j + m]
                for i in range(m):
                    out[i] += seg[i]
        return
    sum2 = partial[0]
    sum4 = partial[1]
    sum8 = partial[2]
    sum16 = partial[3]
    if win >= 2:
        for i in range(length - 1):
            sum2[i] = col[i] + col[i + 1]
    if win >= 4:
        for i in range(length - 3):
            sum4[i] = sum2[i] + sum2[i + 2]
    if win >= 8:
        for i in range(length - 7):
            sum8[i] = sum4[i] + sum4[i + 4]
    if win >= 16:
        for i in range(length - 15):
            sum16[i] = sum8[i] + sum8[i + 8]
    # win is odd: the first term is col itself
    for i in range(m):
        out[i] = col[i]
    off = 1
    if win & 2:
        seg = sum2[off:off + m]
        for i in range(m):
            out[i] += seg[i]
        off += 2
    if win & 4:
        seg = sum4[off:off + m]
        for i in range(m):
            out[i] += seg[i]
        off += 4
    if win & 8:
        seg = sum8[off:off + m]
        for i in range(m):
            out[i] += seg[i]
        off += 8
    if win & 16:
        seg = sum16[off:off + m]
        for i in range(m):
            out[i] += seg[i]


@njit(nogil=True, cache=True, fastmath=FASTMATH)
def window_terms(padded, radius, zncc, out_a, out_b):
    """Per-pixel terms ``a``, ``b`` (module docstring) of the ``W x W`` windows of an image
    padded by ``radius``: running column sums of ``I`` and ``I^2`` down the image plus
    :func:`box_sum` along the row."""
    height, width = out_a.shape
    wp = width + 2 * radius
    win = 2 * radius + 1
    n = np.float32(win * win)
    inv_sqrt_n = np.float32(1.0 / np.sqrt(win * win))
    col1 = np.zeros(wp, padded.dtype)
    col2 = np.zeros(wp, padded.dtype)
    box1 = np.empty(width, padded.dtype)
    box2 = np.empty(width, padded.dtype)
    partial = np.empty((4, wp), padded.dtype)
    for yy in range(2 * radius):
        row = padded[yy]
        for c in range(wp):
            col1[c] += row[c]
            col2[c] += row[c] * row[c]
    for y in range(height):
        add = padded[y + 2 * radius]
        if y > 0:
            sub = padded[y - 1]
            for c in range(wp):
                col1[c] += add[c] - sub[c]
                col2[c] += add[c] * add[c] - sub[c] * sub[c]
        else:
            for c in range(wp):
                col1[c] += add[c]
                col2[c] += add[c] * add[c]
        oa = out_a[y]
        ob = out_b[y]
        if zncc and win == 9 and col1.itemsize == 4:
            # the default window on exact (integer-valued float32) sums: both boxes as
            # 3 x 3 neighbours inside the per-pixel loop (2 passes instead of 6)
            sum3_1 = partial[0]
            sum3_2 = partial[1]
            for i in range(width + 6):
                sum3_1[i] = col1[i] + col1[i + 1] + col1[i + 2]
                sum3_2[i] = col2[i] + col2[i + 1] + col2[i + 2]
            for x in range(width):
                b1 = sum3_1[x] + sum3_1[x + 3] + sum3_1[x + 6]
                b2 = sum3_2[x] + sum3_2[x + 3] + sum3_2[x + 6]
                var_n = max(np.float32(b2 - b1 * b1 / n), np.float32(1e-6))
                oa[x] = b1 * inv_sqrt_n
                ob[x] = np.float32(1.0) / np.sqrt(np.float32(var_n))
            continue
        box_sum(col2, box2, partial, width, win)
        if zncc:
            box_sum(col1, box1, partial, width, win)
            for x in range(width):
                var_n = max(np.float32(box2[x] - box1[x] * box1[x] / n), np.float32(1e-6))
                oa[x] = box1[x] * inv_sqrt_n
                ob[x] = np.float32(1.0) / np.sqrt(np.float32(var_n))
        else:
            for x in range(width):
                oa[x] = box2[x]
                ob[x] = np.float32(1.0) / np.sqrt(max(np.float32(box2[x]), np.float32(1e-6)))


@njit(nogil=True, cache=True, inline="always")
def replicate_border(padded, radius):
    """Fill the ``radius``-wide border of ``padded`` with copies of its inner edge pixels."""
    height = padded.shape[0] - 2 * radius
    width = padded.shape[1] - 2 * radius
    for y in range(radius, radius + height):
        row = padded[y]
        for x in range(radius):
            row[x] = row[radius]
            row[width + radius + x] = row[width + radius - 1]
    for y in range(radius):
        padded[y] = padded[radius]
        padded[height + radius + y] = padded[height + radius - 1]


@njit(nogil=True, cache=True, fastmath=FASTMATH)
def xsobel_padded(gray, radius, cap, out_pad):
    """OpenCV StereoBM's pre-filter, ``clip(rint(Sobel_x(gray) / 4), -cap, cap)`` (3x3,
    replicated border), written into ``out_pad`` padded by ``radius`` (replicated)."""
    height, width = gray.shape
    for y in range(height):
        up = gray[max(y - 1, 0)]
        mid = gray[y]
        down = gray[min(y + 1, height - 1)]
        row = out_pad[y + radius]
        if width >= 3:
            m = width - 2
            u0 = up[:m]
            u2 = up[2:]
            m0 = mid[:m]
            m2 = mid[2:]
            d0 = down[:m]
            d2 = down[2:]
            dst = row[radius + 1:radius + 1 + m]
            for i in range(m):
                v = np.float32(0.25) * ((u2[i] - u0[i]) + np.float32(2.0) * (m2[i] - m0[i]) + (d2[i] - d0[i]))
                dst[i] = min(max(np.rint(v), -cap), cap)
        for x in (0, width - 1):
            xm = max(x - 1, 0)
            xp = min(x + 1, width - 1)
            v = np.float32(0.25) * ((up[xp] - up[xm]) + np.float32(2.0) * (mid[xp] - mid[xm]) + (down[xp] - down[xm]))
            row[radius + x] = min(max(np.rint(v), -cap), cap)
    replicate_border(out_pad, radius)


@njit(nogil=True, cache=True, inline="always")
def check_constants(lr_tol, ratio, max_cost):
    """``(lr_int, keep, max_c)`` of the checks ``(lr_max_diff, uniqueness_ratio, max_cost)``: the
    left-right tolerance in whole pixels (-1: off) and the float32 factors of :func:`verdict`."""
    return (int(np.floor(lr_tol)) if lr_tol >= 0 else -1), np.float32(1.0 - ratio), np.float32(max_cost)


@njit(nogil=True, cache=True, fastmath=FASTMATH, inline="always")
def verdict(found, d, sub, cb, c2, ratio, keep, max_cost, max_c, parabola):
    """One winner through the checks: ``(d + sub, clip(1 - c1 / c2, 0, 1))`` where ``found`` (a
    winner, left-right consistent) and it passes the uniqueness test ``c1 <= keep c2`` (``ratio``
    0: off) and ``c1 <= max_c`` (``max_cost`` < 0: off), else ``(NaN, 0)``; the confidence is 1
    without a second candidate."""
    ok = found and (ratio <= 0 or cb <= keep * c2)
    ok = ok and (max_cost < 0 or cb <= max_c)
    conf = np.float32(1.0) - cb / (c2 if c2 > 0 else np.float32(1.0))
    conf = min(max(conf, np.float32(0.0)), np.float32(1.0))
    conf = np.float32(1.0) if c2 >= BIG else conf
    conf = np.float32(0.0) if c2 <= 0 else conf
    value = d + (sub if parabola else np.float32(0.0))
    return (value if ok else np.float32(np.nan)), (conf if ok else np.float32(0.0))


# ----------------------------------------------------------------------------- band search
@njit(nogil=True, cache=True, inline="always")
def strip_rows(s, n_strips, row0, row1):
    """Rows ``start .. end - 1`` of strip ``s`` of ``n_strips`` over ``row0 .. row1 - 1``."""
    n_rows = row1 - row0
    return row0 + (s * n_rows) // n_strips, row0 + ((s + 1) * n_rows) // n_strips


@njit(nogil=True, cache=True, inline="always")
def _band_scratch(like, nd, width, radius):
    """A strip's buffers: running column sums (one row per disparity, padded width), the
    window sums of a row, :func:`box_sum`'s partial sums, and the costs of an image row."""
    wp = width + 2 * radius
    return (np.zeros((nd, wp), like.dtype), np.empty(width, like.dtype), np.empty((4, wp), like.dtype),
            np.empty((nd, width), np.float32))


@njit(nogil=True, cache=True, inline="always")
def winner_scratch(n):
    """Per column: best cost, its row, the costs of the rows before and after it (:func:`column_winners`),
    the second best (:func:`_second_best`)."""
    return (np.empty(n, np.float32), np.empty(n, np.float32), np.empty(n, np.float32), np.empty(n, np.float32),
            np.empty(n, np.float32))


@njit(nogil=True, cache=True, fastmath=FASTMATH, inline="always")
def add_row_terms(left_pad, right_pad, colsum, yy, d_lo, cols, radius):
    """``colsum[k] +=`` the products of padded row ``yy`` at disparity ``d_lo + k``, from column
    ``max(col0, d)`` on (a strip's first window rows)."""
    col0, col1 = cols
    c_end = col1 + 2 * radius
    for k in range(colsum.shape[0]):
        d = d_lo + k
        x0 = max(col0, d)
        col = colsum[k, x0:c_end]
        lrow = left_pad[yy, x0:c_end]
        rrow = right_pad[yy, x0 - d:c_end - d]
        for i in range(c_end - x0):
            col[i] += lrow[i] * rrow[i]


@njit(nogil=True, cache=True, fastmath=FASTMATH, inline="always")
def _row_costs(left, right, radius, zncc, d_lo, cols, y, first, scratch):
    """Slide the column sums down to image row ``y`` (its window covers padded rows ``y .. y +
    2r``; the strip's ``first`` row only gains a row) and write the costs of columns ``col0 ..
    col1 - 1`` at disparity ``d_lo + k`` into ``cost[k]``, BIG where ``x < d`` (no match inside
    the right image). Loops run over 0-based ranges of slices: their indices are provably
    >= 0 and the loops vectorize."""
    left_pad, a_left, b_left = left
    right_pad, a_right, b_right = right
    colsum, box, partial, cost = scratch
    col0, col1 = cols
    c_end = col1 + 2 * radius
    add = y + 2 * radius
    if first:
        add_row_terms(left_pad, right_pad, colsum, add, d_lo, cols, radius)
    for k in range(colsum.shape[0]):
        d = d_lo + k
        x0 = max(col0, d)
        col = colsum[k, x0:c_end]
        if not first:
            la = left_pad[add, x0:c_end]
            ra = right_pad[add, x0 - d:c_end - d]
            ls = left_pad[y - 1, x0:c_end]
            rs = right_pad[y - 1, x0 - d:c_end - d]
            for i in range(c_end - x0):
                col[i] += la[i] * ra[i] - ls[i] * rs[i]
        crow = cost[k, col0:col1]
        for i in range(min(x0, col1) - col0):
            crow[i] = BIG
        m = col1 - x0
        if m <= 0:
            continue
        box_sum(col, box, partial, m, 2 * radius + 1)
        al = a_left[y, x0:col1]
        bl = b_left[y, x0:col1]
        ar = a_right[y, x0 - d:col1 - d]
        br = b_right[y, x0 - d:col1 - d]
        cr = cost[k, x0:col1]
        if zncc:
            for i in range(m):
                cr[i] = zncc_cost(box[i], al[i], ar[i], bl[i], br[i])
        else:
            for i in range(m):
                cr[i] = nssd_cost(al[i], ar[i], box[i], bl[i], br[i])


@njit(nogil=True, cache=True, fastmath=FASTMATH, inline="always")
def _second_best(cost, cols, best_k, out):
    """Per column the lowest cost at least 2 disparities from the winner (uniqueness), BIG if none."""
    col0, col1 = cols
    for i in range(col1 - col0):
        out[i] = BIG
    for k in range(cost.shape[0]):
        crow = cost[k, col0:col1]
        kf = np.float32(k)
        for i in range(col1 - col0):
            far = np.float32(abs(kf - best_k[i]) > ONE)
            out[i] = np.fmin(out[i], _blend(far, crow[i], BIG))


@njit(nogil=True, cache=True, fastmath=FASTMATH, inline="always")
def _right_winners(cost, d_lo, cols, right_cost, right_d):
    """Eq. (10) for each pixel ``x_r`` of the right image from the same costs: the lowest
    ``c(x_r + d, d)`` and its ``d`` (float32, -1 where none)."""
    col0, col1 = cols
    for x in range(right_cost.size):
        right_cost[x] = BIG
        right_d[x] = -1.0
    for k in range(cost.shape[0]):
        d = d_lo + k
        x0 = max(col0, d)
        m = col1 - x0
        if m <= 0:
            continue
        df = np.float32(d)
        crow = cost[k, x0:col1]
        rc = right_cost[x0 - d:col1 - d]
        rd = right_d[x0 - d:col1 - d]
        for i in range(m):
            better = np.float32(crow[i] < rc[i])
            rd[i] = _blend(better, df, rd[i])
            rc[i] = _blend(better, crow[i], rc[i])


@njit(nogil=True, cache=True, fastmath=FASTMATH, inline="always")
def _band_minimum(cost, k_lo, k_hi, cols, min_k, min_cost):
    """Per column the lowest strict local minimum (``c(k - 1) >= c(k) < c(k + 1)``) among the
    rows ``k_lo .. k_hi``: its row (-1: none) and cost (BIG: none)."""
    col0, col1 = cols
    nx = col1 - col0
    for i in range(nx):
        min_cost[i] = BIG
        min_k[i] = -1.0
    for k in range(max(k_lo, 1), min(k_hi, cost.shape[0] - 2) + 1):
        c0 = cost[k, col0:col1]
        cm = cost[k - 1, col0:col1]
        cp = cost[k + 1, col0:col1]
        kf = np.float32(k)
        for i in range(nx):
            m = np.float32(c0[i] <= cm[i]) * np.float32(c0[i] < cp[i]) * np.float32(c0[i] < min_cost[i])
            min_k[i] = _blend(m, kf, min_k[i])
            min_cost[i] = _blend(m, c0[i], min_cost[i])


@njit(nogil=True, cache=True, fastmath=FASTMATH, inline="always")
def _row_winners(left, right, radius, zncc, d_lo, cols, y, first, scratch, winners):
    """Image row ``y``'s costs (:func:`_row_costs`), winners (eq. 10) with the costs beside them,
    and second best, into ``winners`` (:func:`winner_scratch`)."""
    _row_costs(left, right, radius, zncc, d_lo, cols, y, first, scratch)
    cost = scratch[3]
    col0, col1 = cols
    best_cost, best_k, cost_before, cost_after, second = winners
    column_winners(cost[:, col0:col1], cost.shape[0], col1 - col0, best_cost, best_k, cost_before, cost_after)
    _second_best(cost, cols, best_k, second)


@njit(nogil=True, parallel=True, cache=True, fastmath=FASTMATH)
def band_winners(left, right, radius, zncc, band, aoi, n_strips, right_check, out):
    """Winner-take-all (eq. 10) over ``d in [d_lo, d_hi]`` for the rows/cols of the AOI, raw.

    Parameters
    ----------
    left, right : tuple (padded, a, b)
        Prepared images (module docstring); ``padded`` (H + 2r, W + 2r) in the accumulator's
        dtype (float32 when exact, else float64), ``a`` in that dtype, ``b`` float32 (H, W).
    zncc : bool
        Cost formula: False NSSD (eq. 9), True ZNCC.
    band : (int, int)
        ``(d_lo, d_hi)``.
    aoi : (int, int, int, int)
        ``(row0, row1, col0, col1)``, half-open; the outputs elsewhere are left untouched.
    right_check : bool
        Also write the right image's winners.
    out : tuple of ndarray (H, W)
        ``disparity_int`` (int32: the winner ``d``, -1 where no candidate exists, ``x < d_lo``),
        ``subpixel`` (float32: the parabola's vertex offset in [-0.5, 0.5], 0 at band edges),
        ``best_cost``, ``second_cost`` (float32: the winner's cost and the best cost outside
        ``winner +- 1``, BIG if none), ``right_disparity_int`` (int32: the winner of each
        right-image pixel, -1 if none).
    """
    out_disp, out_sub, out_best, out_second, out_right = out
    d_lo, d_hi = band
    row0, row1, col0, col1 = aoi
    cols = (col0, col1)
    nd = d_hi - d_lo + 1
    width = left[1].shape[1]
    nx = col1 - col0
    for s in prange(n_strips):
        y_start, y_end = strip_rows(s, n_strips, row0, row1)
        if y_start >= y_end:
            continue
        scratch = _band_scratch(left[0], nd, width, radius)
        winners = winner_scratch(nx)
        best_cost, best_k, cost_before, cost_after, second = winners
        right_cost = np.empty(width, np.float32)
        right_d = np.empty(width, np.float32)
        for yy in range(y_start, y_start + 2 * radius):
            add_row_terms(left[0], right[0], scratch[0], yy, d_lo, cols, radius)
        for y in range(y_start, y_end):
            _row_winners(left, right, radius, zncc, d_lo, cols, y, y == y_start, scratch, winners)
            for i in range(nx):
                x = col0 + i
                kb = np.int32(best_k[i])
                out_disp[y, x] = d_lo + kb if kb >= 0 else -1
                out_sub[y, x] = parabola_offset(best_cost[i], cost_before[i], cost_after[i])
                out_best[y, x] = best_cost[i]
                out_second[y, x] = second[i]
            if right_check:
                _right_winners(scratch[3], d_lo, cols, right_cost, right_d)
                for x in range(width):
                    out_right[y, x] = np.int32(right_d[x])


@njit(nogil=True, parallel=True, cache=True, fastmath=FASTMATH)
def band_checked(left, right, radius, zncc, band, aoi, n_strips, checks, out, minimum_band, out_minimum):
    """:func:`band_winners` with the checks: the disparity of the winners that pass them.

    Parameters
    ----------
    left, right, zncc, band, aoi, n_strips
        As :func:`band_winners`.
    checks : (float, float, float, bool)
        ``(lr_max_diff, uniqueness_ratio, max_cost, parabola)``: the left-right tolerance
        (< 0 off), the uniqueness test ``c1 <= (1 - ratio) c2`` (0 off), ``c1 <= max_cost``
        (< 0 off), and whether the parabola offset is added.
    out : tuple of ndarray float32 (H, W)
        ``(disparity, confidence)``: ``d + sub`` (NaN rejected) and ``clip(1 - c1 / c2, 0, 1)``
        (0 rejected, 1 without a second candidate), rows ``row0:row1``, all columns.
    minimum_band : (int, int)
        When ``lo <= hi``: also find the band's own best minimum, the lowest cost among the
        strict local minima at disparities ``lo .. hi`` (whatever the winner and the checks),
        for the cross-band ambiguity test of the union (:mod:`mrstereo.matching.disparity`).
    out_minimum : tuple of ndarray float32 (H, W)
        That minimum's integer disparity (NaN: none) and cost (BIG: none), and the winner's
        cost ``c1``, rows ``row0:row1``, cols ``col0:col1``.
    """
    out_disparity, out_confidence = out
    lr_tol, ratio, max_cost, parabola = checks
    d_lo, d_hi = band
    row0, row1, col0, col1 = aoi
    cols = (col0, col1)
    nd = d_hi - d_lo + 1
    width = left[1].shape[1]
    nx = col1 - col0
    lr_int, keep, max_c = check_constants(lr_tol, ratio, max_cost)
    for s in prange(n_strips):
        y_start, y_end = strip_rows(s, n_strips, row0, row1)
        if y_start >= y_end:
            continue
        scratch = _band_scratch(left[0], nd, width, radius)
        cost = scratch[3]
        winners = winner_scratch(nx)
        best_cost, best_k, cost_before, cost_after, second = winners
        min_k = np.empty(nx, np.float32)
        min_cost = np.empty(nx, np.float32)
        right_cost = np.empty(width, np.float32)
        right_d = np.empty(width, np.float32)
        lr_ok = np.empty(nx, np.bool_)
        sub = np.empty(nx, np.float32)
        for yy in range(y_start, y_start + 2 * radius):
            add_row_terms(left[0], right[0], scratch[0], yy, d_lo, cols, radius)
        for y in range(y_start, y_end):
            _row_winners(left, right, radius, zncc, d_lo, cols, y, y == y_start, scratch, winners)
            if minimum_band[0] <= minimum_band[1]:
                _band_minimum(cost, minimum_band[0] - d_lo, minimum_band[1] - d_lo, cols, min_k, min_cost)
                om, omc, obc = out_minimum[0][y, col0:col1], out_minimum[1][y, col0:col1], out_minimum[2][y, col0:col1]
                for i in range(nx):
                    om[i] = np.float32(d_lo) + min_k[i] if min_k[i] >= 0 else np.float32(np.nan)
                    omc[i] = min_cost[i]
                    obc[i] = best_cost[i]
            if lr_tol >= 0:
                _right_winners(cost, d_lo, cols, right_cost, right_d)
            for i in range(nx):         # apart: the loop below then vectorizes
                sub[i] = parabola_offset(best_cost[i], cost_before[i], cost_after[i])
            od = out_disparity[y]
            oc = out_confidence[y]
            for x in range(col0):
                od[x] = np.nan
                oc[x] = 0.0
            for x in range(col1, width):
                od[x] = np.nan
                oc[x] = 0.0
            od = out_disparity[y, col0:col1]
            oc = out_confidence[y, col0:col1]
            # the left-right check's gather apart, so that the loop below vectorizes
            if lr_tol >= 0:
                for i in range(nx):
                    d = d_lo + np.int64(best_k[i])
                    back = np.int64(right_d[min(max(col0 + i - d, 0), width - 1)])
                    lr_ok[i] = (back >= 0) & (abs(d - back) <= lr_int)
            else:
                for i in range(nx):
                    lr_ok[i] = True
            for i in range(nx):
                kb = np.int64(best_k[i])
                od[i], oc[i] = verdict(kb >= 0 and lr_ok[i], np.float32(d_lo + kb), sub[i], best_cost[i], second[i],
                                        ratio, keep, max_cost, max_c, parabola)
