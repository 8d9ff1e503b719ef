"""Numba kernels of the area matcher: window cost + winner-take-all, and full-resolution refinement.

Private: no validation, no defaults; the caller (:mod:`mrstereo.matching.cost`)
pads, precomputes and allocates. An image arrives prepared as a tuple ``(padded, a, b)``:
padded by the window radius ``r`` on every side, and its per-pixel window terms.
Conventions: docs/conventions.md.

:func:`band_winners` and :func:`band_checked` search one disparity band ``[d_lo, d_hi]`` on
one image pair. Rows are split into strips, one per thread (``prange``). Inside a strip the
rows are visited in order; for every disparity ``d`` a row of running column sums
``sum_j I_L(y + j, c) I_R(y + j, c - d)`` is updated by adding the row entering the
window and subtracting the row leaving it, and a row of window sums is the sum of
``W`` shifted column-sum rows (in few passes, :func:`_box`). Every inner loop runs along the image row over
contiguous memory (one disparity at a time), so it vectorizes; the cost of one
pixel and disparity is O(1) in the window size. The window sums of ``I^2`` (and
``I``) do not depend on the disparity and arrive as per-pixel terms ``a`` and ``b``:

    NSSD (eq. 9):  c = (a_L + a_R - 2 S_LR) * b_L * b_R,  a = sum I^2, b = 1/sqrt(sum I^2)
    ZNCC:          c = 1 - (S_LR - a_L a_R) * b_L * b_R,  a = sum I / sqrt(n), b = 1/sigma sqrt(n)

A strip holds the costs of one image row (all disparities of the band), never a cost
volume. Integer-valued images (the x-Sobel pre-filter) are summed exactly in float32.

:func:`refine_boxes` re-scores a coarse disparity field at full resolution: for each
offset ``o`` in ``[-half, half]`` the window sum ``sum I_L(p) I_R(p - c(p) - o)`` over the
window's pixels ``p`` (``c`` = the coarse disparity of ``p``) is computed with the same
running sums; where ``c`` is constant over the window this is exactly ``S_LR(x, c + o)``.
:func:`refine_strips` does so along runs of constant ``c``, and :func:`refine_pixels` adds the
same window sums up pixel by pixel, for scattered pixels.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

# Finite "infinity": costs are finite by construction (b uses max(energy, eps)).
BIG = np.float32(3.0e38)
# fast-math without "nnan"/"ninf": the kernels write NaN (invalid) on purpose
_FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}
# float32 constants: a Python float would promote float32 expressions to float64
ONE = np.float32(1.0)
TWO = np.float32(2.0)
# The cost a kernel evaluates (``kind``): NSSD (eq. 9), ZNCC, or the integer engine's SAD of
# normalized images (:mod:`._int_kernels`), whose window sums are ``sum |q_L - q_R|``.
NSSD, ZNCC, SAD = 0, 1, 2
# the integer engine's quantization: STEPS_PER_SIGMA steps per standard deviation, clipped at
# +-Q_MAX (4 standard deviations; 2 Q_MAX 31^2 < 2^16: a window's SAD fits 16 bits)
STEPS_PER_SIGMA = 8.0
Q_MAX = 31


@njit(nogil=True, cache=True, fastmath=_FASTMATH, inline="always")
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
@njit(nogil=True, cache=True, fastmath=_FASTMATH, inline="always")
def _zncc_cost(window_sum, a_l, a_r, b_l, b_r):
    """ZNCC: ``1 - (S_LR - a_L a_R) b_L b_R``."""
    return ONE - np.float32(window_sum - a_l * a_r) * b_l * b_r


@njit(nogil=True, cache=True, fastmath=_FASTMATH, inline="always")
def _nssd_cost(a_l, a_r, window_sum, b_l, b_r):
    """NSSD, eq. (9): ``(a_L + a_R - 2 S_LR) b_L b_R``."""
    return np.float32(a_l + a_r - TWO * window_sum) * b_l * b_r


@njit(nogil=True, cache=True, fastmath=_FASTMATH, inline="always")
def sad_unit(radius):
    """``1 / (n s)^2`` for a window of ``n = (2 radius + 1)^2`` pixels: ``unit * SAD^2`` of
    normalized images is in the units of ``1 - rho`` (:mod:`._int_kernels`)."""
    ns = np.float64((2 * radius + 1) ** 2) * STEPS_PER_SIGMA
    return np.float32(1.0 / (ns * ns))


@njit(nogil=True, cache=True, fastmath=_FASTMATH, inline="always")
def _sad_cost(window_sum, unit):
    """The integer engine's cost of a window SAD: ``unit * SAD^2`` (``1 - rho`` units)."""
    c = np.float32(window_sum)
    return unit * c * c


@njit(nogil=True, cache=True, fastmath=_FASTMATH, inline="always")
def _term(left, right, kind):
    """A window term of pixel values ``left``, ``right``: ``|l - r|`` for SAD, else ``l r``."""
    return np.float32(abs(left - right)) if kind == SAD else np.float32(left * right)


@njit(nogil=True, cache=True, fastmath=_FASTMATH, inline="always")
def _costs(out, window_sums, a_l, b_l, a_r, b_r, n, kind, unit):
    """The costs of ``n`` pixels in a row (contiguous slices; the test of ``kind`` outside the
    loops keeps them vectorized)."""
    if kind == ZNCC:
        for i in range(n):
            out[i] = _zncc_cost(window_sums[i], a_l[i], a_r[i], b_l[i], b_r[i])
    elif kind == SAD:
        for i in range(n):
            out[i] = _sad_cost(window_sums[i], unit)
    else:
        for i in range(n):
            out[i] = _nssd_cost(a_l[i], a_r[i], window_sums[i], b_l[i], b_r[i])


@njit(nogil=True, cache=True, fastmath=_FASTMATH, inline="always")
def _winners(cost, rows, n, best_cost, best_k, cost_before, cost_after):
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


@njit(nogil=True, cache=True, fastmath=_FASTMATH, inline="always")
def _parabola(cb, cm, cp):
    """Sub-pixel offset of the parabola through (-1, cm), (0, cb), (1, cp), clipped to +-0.5;
    0 when a neighbour is missing or the parabola is not convex."""
    den = cm - TWO * cb + cp
    fine = (cm < BIG) and (cp < BIG) and (den > 0)
    sub = np.float32(0.5) * (cm - cp) / (den if fine else np.float32(1.0))
    return min(max(sub, np.float32(-0.5)), np.float32(0.5)) if fine else np.float32(0.0)


@njit(nogil=True, cache=True, fastmath=_FASTMATH, inline="always")
def _box(col, out, partial, m, win):
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


@njit(nogil=True, cache=True, fastmath=_FASTMATH)
def window_terms(padded, radius, zncc, out_a, out_b):
    """Per-pixel terms ``a``, ``b`` (module docstring) of the ``W x W`` windows of an image
    padded by ``radius``: running column sums of ``I`` and ``I^2`` down the image plus
    :func:`_box` along the row."""
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
        _box(col2, box2, partial, width, win)
        if zncc:
            _box(col1, box1, partial, width, win)
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


@njit(nogil=True, cache=True, fastmath=_FASTMATH)
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


@njit(nogil=True, cache=True, fastmath=_FASTMATH, inline="always")
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
def _strip_rows(s, n_strips, row0, row1):
    """Rows ``start .. end - 1`` of strip ``s`` of ``n_strips`` over ``row0 .. row1 - 1``."""
    n_rows = row1 - row0
    return row0 + (s * n_rows) // n_strips, row0 + ((s + 1) * n_rows) // n_strips


@njit(nogil=True, cache=True, inline="always")
def _band_scratch(like, nd, width, radius):
    """A strip's buffers: running column sums (one row per disparity, padded width), the
    window sums of a row, :func:`_box`'s partial sums, and the costs of an image row."""
    wp = width + 2 * radius
    return (np.zeros((nd, wp), like.dtype), np.empty(width, like.dtype), np.empty((4, wp), like.dtype),
            np.empty((nd, width), np.float32))


@njit(nogil=True, cache=True, inline="always")
def _winner_scratch(n):
    """Per column: best cost, its row, the costs of the rows before and after it (:func:`_winners`),
    the second best (:func:`_second_best`)."""
    return (np.empty(n, np.float32), np.empty(n, np.float32), np.empty(n, np.float32), np.empty(n, np.float32),
            np.empty(n, np.float32))


@njit(nogil=True, cache=True, fastmath=_FASTMATH, inline="always")
def add_row_terms(left_pad, right_pad, colsum, yy, d_lo, cols, radius, kind):
    """``colsum[k] +=`` the window terms of padded row ``yy`` at disparity ``d_lo + k`` (products;
    for SAD 16-bit absolute differences), from column ``max(col0, d)`` on (a strip's first window
    rows)."""
    col0, col1 = cols
    c_end = col1 + 2 * radius
    for k in range(colsum.shape[0]):
        d = d_lo + k
        x0 = max(col0, d)
        col = colsum[k, x0:c_end]
        lrow = left_pad[yy, x0:c_end]
        rrow = right_pad[yy, x0 - d:c_end - d]
        if kind == SAD:
            for i in range(c_end - x0):
                col[i] += np.uint16(abs(np.int16(lrow[i] - rrow[i])))
        else:
            for i in range(c_end - x0):
                col[i] += lrow[i] * rrow[i]


@njit(nogil=True, cache=True, fastmath=_FASTMATH, inline="always")
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
        add_row_terms(left_pad, right_pad, colsum, add, d_lo, cols, radius, NSSD)
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
        _box(col, box, partial, m, 2 * radius + 1)
        al = a_left[y, x0:col1]
        bl = b_left[y, x0:col1]
        ar = a_right[y, x0 - d:col1 - d]
        br = b_right[y, x0 - d:col1 - d]
        cr = cost[k, x0:col1]
        if zncc:
            for i in range(m):
                cr[i] = _zncc_cost(box[i], al[i], ar[i], bl[i], br[i])
        else:
            for i in range(m):
                cr[i] = _nssd_cost(al[i], ar[i], box[i], bl[i], br[i])


@njit(nogil=True, cache=True, fastmath=_FASTMATH, inline="always")
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


@njit(nogil=True, cache=True, fastmath=_FASTMATH, inline="always")
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


@njit(nogil=True, cache=True, fastmath=_FASTMATH, inline="always")
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


@njit(nogil=True, cache=True, fastmath=_FASTMATH, inline="always")
def _row_winners(left, right, radius, zncc, d_lo, cols, y, first, scratch, winners):
    """Image row ``y``'s costs (:func:`_row_costs`), winners (eq. 10) with the costs beside them,
    and second best, into ``winners`` (:func:`_winner_scratch`)."""
    _row_costs(left, right, radius, zncc, d_lo, cols, y, first, scratch)
    cost = scratch[3]
    col0, col1 = cols
    best_cost, best_k, cost_before, cost_after, second = winners
    _winners(cost[:, col0:col1], cost.shape[0], col1 - col0, best_cost, best_k, cost_before, cost_after)
    _second_best(cost, cols, best_k, second)


@njit(nogil=True, parallel=True, cache=True, fastmath=_FASTMATH)
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
        y_start, y_end = _strip_rows(s, n_strips, row0, row1)
        if y_start >= y_end:
            continue
        scratch = _band_scratch(left[0], nd, width, radius)
        winners = _winner_scratch(nx)
        best_cost, best_k, cost_before, cost_after, second = winners
        right_cost = np.empty(width, np.float32)
        right_d = np.empty(width, np.float32)
        for yy in range(y_start, y_start + 2 * radius):
            add_row_terms(left[0], right[0], scratch[0], yy, d_lo, cols, radius, NSSD)
        for y in range(y_start, y_end):
            _row_winners(left, right, radius, zncc, d_lo, cols, y, y == y_start, scratch, winners)
            for i in range(nx):
                x = col0 + i
                kb = np.int32(best_k[i])
                out_disp[y, x] = d_lo + kb if kb >= 0 else -1
                out_sub[y, x] = _parabola(best_cost[i], cost_before[i], cost_after[i])
                out_best[y, x] = best_cost[i]
                out_second[y, x] = second[i]
            if right_check:
                _right_winners(scratch[3], d_lo, cols, right_cost, right_d)
                for x in range(width):
                    out_right[y, x] = np.int32(right_d[x])


@njit(nogil=True, parallel=True, cache=True, fastmath=_FASTMATH)
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
        y_start, y_end = _strip_rows(s, n_strips, row0, row1)
        if y_start >= y_end:
            continue
        scratch = _band_scratch(left[0], nd, width, radius)
        cost = scratch[3]
        winners = _winner_scratch(nx)
        best_cost, best_k, cost_before, cost_after, second = winners
        min_k = np.empty(nx, np.float32)
        min_cost = np.empty(nx, np.float32)
        right_cost = np.empty(width, np.float32)
        right_d = np.empty(width, np.float32)
        lr_ok = np.empty(nx, np.bool_)
        sub = np.empty(nx, np.float32)
        for yy in range(y_start, y_start + 2 * radius):
            add_row_terms(left[0], right[0], scratch[0], yy, d_lo, cols, radius, NSSD)
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
                sub[i] = _parabola(best_cost[i], cost_before[i], cost_after[i])
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


# ----------------------------------------------------------------------------- refinement
@njit(nogil=True, cache=True)
def fill_center(disparity_px, radius, out_center_pad):
    """Integer coarse field for the refinement: ``round(d)``, NaNs filled with the nearest
    valid value to the left in the row (else to the right, else 0), padded by ``radius`` with
    replicated borders."""
    height, width = disparity_px.shape
    for y in range(height):
        first = -1
        for x in range(width):
            if np.isfinite(disparity_px[y, x]):
                first = x
                break
        last = 0 if first < 0 else np.int32(np.rint(disparity_px[y, first]))
        row = out_center_pad[y + radius]
        for x in range(width):
            v = disparity_px[y, x]
            if np.isfinite(v):
                last = np.int32(np.rint(v))
            row[x + radius] = last
    replicate_border(out_center_pad, radius)


@njit(nogil=True, cache=True, fastmath=_FASTMATH, inline="always")
def _refined(center, best_k, best_cost, cost_before, cost_after, half, max_cost):
    """A re-scored pixel's ``(disparity, cost)``: ``center + o* +`` the parabola offset, where
    the best offset ``o*`` is not on the edge of ``[-half, half]`` (else the true minimum may
    lie outside) and its cost is at most ``max_cost`` (< 0: off); else ``(NaN, inf)``."""
    inside = ((best_k > 0) and (best_k < 2 * half) and (best_cost < BIG)
              and (max_cost < 0 or best_cost <= np.float32(max_cost)))
    value = np.float32(center + best_k - half) + _parabola(best_cost, cost_before, cost_after)
    return (value if inside else np.float32(np.nan)), (best_cost if inside else np.float32(np.inf))


@njit(nogil=True, cache=True, inline="always")
def _wanted_span(want_row, xa, xb):
    """``(first, last + 1)`` of the wanted columns of ``want_row`` in ``xa .. xb - 1``; empty:
    ``(xb, xa)``."""
    wa = xb
    wb = xa
    for x in range(xa, xb):
        if want_row[x]:
            wa = min(wa, x)
            wb = x + 1
    return wa, wb


@njit(nogil=True, cache=True, inline="always")
def _runs(values, n, out_starts):
    """Starts of the runs of equal ``values[:n]`` into ``out_starts`` (then ``n``); their count."""
    count = 0
    for i in range(n):
        if i == 0 or values[i] != values[i - 1]:
            out_starts[count] = i
            count += 1
    out_starts[count] = n
    return count


@njit(nogil=True, cache=True, inline="always")
def _wanted_columns(want, box):
    """The columns ``(first, last + 1)`` spanned by the wanted pixels of ``box = (row0, row1,
    col0, col1)``; the running sums need no other (each column's sums are its own)."""
    xa, xb = box[3], box[2]
    for y in range(box[0], box[1]):
        wa, wb = _wanted_span(want[y], box[2], box[3])
        xa = min(xa, wa)
        xb = max(xb, wb)
    return xa, xb


# One body: the product and cost gathers as inlined helpers measured 3-6 % slower (numba counts
# the references of an inlined call's array arguments at every call, here per run and offset).
@njit(nogil=True, cache=True, fastmath=_FASTMATH, inline="always")
def _refine_box(left, right, radius, kind, center_pad, want, box, half, max_cost, by_runs, out):
    """Re-score the wanted pixels of one box (:func:`refine_boxes`). ``by_runs`` (a constant of
    each kernel) gathers the products ``I_L(p) I_R(p - c(p) - o)`` (SAD: ``|I_L - I_R|``) and the right terms along runs
    of constant ``c`` (contiguous reads) or pixel by pixel (the right column clamped to the
    padded row; no bookkeeping). The products of the rows inside the window are kept in a ring
    buffer, so each is gathered once."""
    left_pad, a_left, b_left = left
    right_pad, a_right, b_right = right
    out_disp, out_cost = out
    nc = 2 * half + 1
    win = 2 * radius + 1
    wp = right_pad.shape[1]
    unit = sad_unit(radius)
    y_start, y_end = box[0], box[1]
    xa, xb = _wanted_columns(want, box)
    if y_end <= y_start or xb <= xa:
        return
    nx = xb - xa                    # pixels xa .. xb - 1
    ncol = nx + 2 * radius          # padded columns xa .. xb - 1 + 2r
    colsum = np.zeros((nc, ncol), np.float32)
    ring = np.zeros((nc, win, ncol), np.float32)
    fresh = np.empty(ncol, np.float32)
    box_sums = np.empty(nx, np.float32)
    partial = np.empty((4, ncol), np.float32)
    cost = np.empty((nc, nx), np.float32)
    best_cost, best_k, cost_before, cost_after, _ = _winner_scratch(nx)
    run_at = np.empty(ncol + 1, np.int64)
    q0 = np.empty(ncol, np.int64)
    ar_at = np.empty(nx, a_right.dtype)
    br_at = np.empty(nx, np.float32)
    for yy in range(y_start, y_end + 2 * radius):
        slot = (yy - y_start) % win
        lrow = left_pad[yy, xa:xa + ncol]
        rrow = right_pad[yy]
        crow = center_pad[yy, xa:xa + ncol]
        n_runs = _runs(crow, ncol, run_at) if by_runs else 0
        if not by_runs:
            for i in range(ncol):
                q0[i] = xa + i - crow[i]
        for o in range(nc):
            off = o - half
            if by_runs:
                for r in range(n_runs):         # q = base + i along a run, clamped to the padded row
                    i0 = run_at[r]
                    i1 = run_at[r + 1]
                    base = xa - crow[i0] - off
                    lo = min(max(i0, -base), i1)
                    hi = max(min(i1, wp - base), lo)
                    for i in range(i0, lo):
                        fresh[i] = _term(lrow[i], rrow[0], kind)
                    seg_l = lrow[lo:hi]
                    seg_r = rrow[base + lo:base + hi]
                    seg_f = fresh[lo:hi]
                    for i in range(hi - lo):
                        seg_f[i] = _term(seg_l[i], seg_r[i], kind)
                    for i in range(hi, i1):
                        fresh[i] = _term(lrow[i], rrow[wp - 1], kind)
            else:
                for i in range(ncol):
                    fresh[i] = _term(lrow[i], rrow[min(max(q0[i] - off, 0), wp - 1)], kind)
            col = colsum[o]
            old = ring[o, slot]
            for i in range(ncol):
                col[i] += fresh[i] - old[i]
                old[i] = fresh[i]
        y = yy - 2 * radius
        if y < y_start:
            continue
        # window sums of row y are complete: costs over the columns of its wanted pixels
        wa, wb = _wanted_span(want[y], xa, xb)
        if wb <= wa:
            continue
        nw = wb - wa
        cy = center_pad[y + radius, radius + wa:radius + wb]
        al = a_left[y, wa:wb]
        bl = b_left[y, wa:wb]
        ar = a_right[y]
        br = b_right[y]
        n_runs = _runs(cy, nw, run_at) if by_runs else 0
        for o in range(nc):
            off = o - half
            _box(colsum[o, wa - xa:], box_sums, partial, nw, win)
            crow_c = cost[o]
            if by_runs:
                for r in range(n_runs):         # x_right = base + i along a run
                    i0 = run_at[r]
                    i1 = run_at[r + 1]
                    d = cy[i0] + off
                    k0 = min(max(i0, d - wa), i1) if d >= 0 else i1
                    for i in range(i0, k0):
                        crow_c[i] = BIG         # x_right < 0 or d < 0: no candidate
                    base = wa - d
                    seg_ar = ar[base + k0:base + i1]
                    seg_br = br[base + k0:base + i1]
                    seg_box = box_sums[k0:i1]
                    seg_al = al[k0:i1]
                    seg_bl = bl[k0:i1]
                    seg_c = crow_c[k0:i1]
                    if kind == ZNCC:
                        for i in range(i1 - k0):
                            seg_c[i] = _zncc_cost(seg_box[i], seg_al[i], seg_ar[i], seg_bl[i], seg_br[i])
                    elif kind == SAD:
                        for i in range(i1 - k0):
                            seg_c[i] = _sad_cost(seg_box[i], unit)
                    else:
                        for i in range(i1 - k0):
                            seg_c[i] = _nssd_cost(seg_al[i], seg_ar[i], seg_box[i], seg_bl[i], seg_br[i])
                continue
            for i in range(nw):
                xr = min(max(wa + i - cy[i] - off, 0), wa + i)
                ar_at[i] = ar[xr]
                br_at[i] = br[xr]
            _costs(crow_c, box_sums, al, bl, ar_at, br_at, nw, kind, unit)
            for i in range(nw):
                d = cy[i] + off
                crow_c[i] = crow_c[i] if (d >= 0 and wa + i >= d) else BIG     # x_right < 0 or d < 0: none
        _winners(cost, nc, nw, best_cost, best_k, cost_before, cost_after)
        od = out_disp[y, wa:wb]
        oc = out_cost[y, wa:wb]
        wy = want[y, wa:wb]
        for i in range(nw):             # branch-free: vectorizes
            value, c = _refined(cy[i], np.int64(best_k[i]), best_cost[i], cost_before[i], cost_after[i], half,
                                max_cost)
            od[i] = value if wy[i] else od[i]
            oc[i] = c if wy[i] else oc[i]


@njit(nogil=True, parallel=True, cache=True, fastmath=_FASTMATH)
def refine_boxes(left, right, radius, kind, center_pad, want, boxes, half, max_cost, out):
    """Full-resolution re-scoring of a coarse disparity field over ``c + o``, ``|o| <= half``,
    box by box in parallel, the products gathered pixel by pixel (the right column clamped to
    the padded row): the cost does not grow where ``c`` changes every few pixels (the near
    guard's fields).

    Parameters
    ----------
    left, right : tuple (padded, a, b)
        Pre-filtered full-resolution images (module docstring).
    center_pad : ndarray int32 (H + 2r, W + 2r)
        Coarse integer disparity ``c`` of every padded pixel (see :func:`fill_center`).
    want : ndarray bool (H, W)
        Pixels to refine; the others are left untouched.
    boxes : ndarray int64 (n, 4)
        ``(row0, row1, col0, col1)`` (half-open) that hold the wanted pixels; the running sums
        cover each box's wanted columns, from its first row on.
    max_cost : float
        Winners costing more are rejected (< 0: off).
    out : tuple of ndarray float32 (H, W)
        ``(disparity, cost)``: ``c + o* +`` parabola offset and its cost where the winner
        ``o*`` passes :func:`_refined`, else NaN and inf.

    The products of the rows inside the window are kept in a ring buffer, so each is
    gathered once.
    """
    for j in prange(boxes.shape[0]):
        _refine_box(left, right, radius, kind, center_pad, want, boxes[j], half, max_cost, False, out)


@njit(nogil=True, parallel=True, cache=True, fastmath=_FASTMATH)
def refine_strips(left, right, radius, kind, center_pad, want, strips, half, max_cost, out):
    """:func:`refine_boxes` over row strips (``strips`` as ``boxes``), the products and costs
    gathered along runs of constant ``c`` (contiguous reads: fastest where ``c`` is constant over
    many pixels, a level's up-sampled field). Same sums, same results."""
    for j in prange(strips.shape[0]):
        _refine_box(left, right, radius, kind, center_pad, want, strips[j], half, max_cost, True, out)


@njit(nogil=True, parallel=True, cache=True, fastmath=_FASTMATH)
def refine_pixels(left, right, radius, kind, center_pad, pixels, half, max_cost, n_strips, out):
    """:func:`refine_boxes` for scattered pixels ``pixels = (ys, xs)`` (same arguments and
    outputs otherwise): each window sum ``sum I_L(p) I_R(p - c(p) - o)`` is added up directly,
    so the work is per wanted pixel rather than per pixel of the rows spanned. The sums are
    the same float32 sums (exact, so the results identical, for integer-valued images)."""
    left_pad, a_left, b_left = left
    right_pad, a_right, b_right = right
    ys, xs = pixels
    out_disp, out_cost = out
    nc = 2 * half + 1
    win = 2 * radius + 1
    n = win * win
    wp = right_pad.shape[1]
    unit = sad_unit(radius)
    rflat = right_pad.reshape(right_pad.size)
    for s in prange(n_strips):
        j0, j1 = _strip_rows(s, n_strips, 0, ys.size)
        lv = np.empty(n, np.float32)
        qs = np.empty(n, np.int64)
        cj = np.empty(nc, np.float32)
        for j in range(j0, j1):
            y = ys[j]
            x = xs[j]
            cy = center_pad[y + radius, x + radius]
            # the window's left values and right columns (flat) at offset 0
            t = 0
            q_lo = wp
            q_hi = -1
            for dy in range(win):
                lrow = left_pad[y + dy]
                crow = center_pad[y + dy]
                for dx in range(win):
                    q = x + dx - crow[x + dx]
                    q_lo = min(q_lo, q)
                    q_hi = max(q_hi, q)
                    lv[t] = lrow[x + dx]
                    qs[t] = (y + dy) * wp + q
                    t += 1
            for o in range(nc):
                off = o - half
                acc = np.float32(0.0)
                if q_lo - off >= 0 and q_hi - off < wp:
                    for t in range(n):
                        acc += _term(lv[t], np.float32(rflat[qs[t] - off]), kind)
                else:                       # clamped to the padded row, as refine_boxes
                    for t in range(n):
                        yy = y + t // win
                        q = min(max(qs[t] - yy * wp - off, 0), wp - 1)
                        acc += _term(lv[t], np.float32(rflat[yy * wp + q]), kind)
                cj[o] = acc
            al = a_left[y, x]
            bl = b_left[y, x]
            kb = -1
            cb = BIG
            for o in range(nc):
                d = cy + o - half
                if d < 0 or x < d:
                    c = BIG                 # x_right < 0 or d < 0: no candidate
                elif kind == SAD:
                    c = _sad_cost(cj[o], unit)
                elif kind == ZNCC:
                    c = _zncc_cost(cj[o], al, a_right[y, x - d], bl, b_right[y, x - d])
                else:
                    c = _nssd_cost(al, a_right[y, x - d], cj[o], bl, b_right[y, x - d])
                cj[o] = c
                if c < cb:
                    cb = c
                    kb = o
            cm = cj[kb - 1] if kb > 0 else BIG
            cp = cj[kb + 1] if 0 <= kb < nc - 1 else BIG
            out_disp[y, x], out_cost[y, x] = _refined(cy, kb, cb, cm, cp, half, max_cost)


@njit(nogil=True, cache=True, fastmath=_FASTMATH)
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


@njit(nogil=True, cache=True)
def zero_where_invalid(disparity, confidence):
    """In place: ``confidence = 0`` where ``disparity`` is NaN."""
    height, width = disparity.shape
    for y in range(height):
        dr = disparity[y]
        cr = confidence[y]
        for x in range(width):
            cr[x] = cr[x] if np.isfinite(dr[x]) else np.float32(0.0)


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
