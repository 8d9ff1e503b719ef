"""Numba kernels of the full-resolution refinement (:func:`mrstereo.matching.cost.refine_candidates`).

Private: no validation, no defaults. Images arrive prepared as in :mod:`._band_kernels`.
Conventions: docs/conventions.md.

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

from ._band_kernels import (BIG, FASTMATH, ZNCC, box_sum, column_winners, nssd_cost, parabola_offset, replicate_border,
                            strip_rows, winner_scratch, zncc_cost)


@njit(nogil=True, cache=True, fastmath=FASTMATH, inline="always")
def _term(left, right):
    """A window term of pixel values ``left``, ``right``: their product, in float32."""
    return np.float32(left * right)


@njit(nogil=True, cache=True, fastmath=FASTMATH, inline="always")
def _costs(out, window_sums, a_l, b_l, a_r, b_r, n, kind):
    """The costs of ``n`` pixels in a row (contiguous slices; the test of ``kind`` outside the
    loops keeps them vectorized)."""
    if kind == ZNCC:
        for i in range(n):
            out[i] = zncc_cost(window_sums[i], a_l[i], a_r[i], b_l[i], b_r[i])
    else:
        for i in range(n):
            out[i] = nssd_cost(a_l[i], a_r[i], window_sums[i], b_l[i], b_r[i])


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


@njit(nogil=True, cache=True, fastmath=FASTMATH, inline="always")
def _refined(center, best_k, best_cost, cost_before, cost_after, half, max_cost):
    """A re-scored pixel's ``(disparity, cost)``: ``center + o* +`` the parabola offset, where
    the best offset ``o*`` is not on the edge of ``[-half, half]`` (else the true minimum may
    lie outside) and its cost is at most ``max_cost`` (< 0: off); else ``(NaN, inf)``."""
    inside = ((best_k > 0) and (best_k < 2 * half) and (best_cost < BIG)
              and (max_cost < 0 or best_cost <= np.float32(max_cost)))
    value = np.float32(center + best_k - half) + parabola_offset(best_cost, cost_before, cost_after)
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
# Not inlined into the parallel kernels: compiled once for both, and numba's parfor passes run
# over a short loop (the cold compile takes a fraction of the time).
@njit(nogil=True, cache=True, fastmath=FASTMATH)
def _refine_box(left, right, radius, kind, center_pad, want, box, half, max_cost, by_runs, out):
    """Re-score the wanted pixels of one box (:func:`refine_boxes`). ``by_runs`` (True for
    :func:`refine_strips`) gathers the products ``I_L(p) I_R(p - c(p) - o)`` and the right terms along runs
    of constant ``c`` (contiguous reads) or pixel by pixel (the right column clamped to the
    padded row; no bookkeeping). The products of the rows inside the window are kept in a ring
    buffer, so each is gathered once."""
    left_pad, a_left, b_left = left
    right_pad, a_right, b_right = right
    out_disp, out_cost = out
    nc = 2 * half + 1
    win = 2 * radius + 1
    wp = right_pad.shape[1]
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
    best_cost, best_k, cost_before, cost_after, _ = winner_scratch(nx)
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
                        fresh[i] = _term(lrow[i], rrow[0])
                    seg_l = lrow[lo:hi]
                    seg_r = rrow[base + lo:base + hi]
                    seg_f = fresh[lo:hi]
                    for i in range(hi - lo):
                        seg_f[i] = _term(seg_l[i], seg_r[i])
                    for i in range(hi, i1):
                        fresh[i] = _term(lrow[i], rrow[wp - 1])
            else:
                for i in range(ncol):
                    fresh[i] = _term(lrow[i], rrow[min(max(q0[i] - off, 0), wp - 1)])
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
            box_sum(colsum[o, wa - xa:], box_sums, partial, nw, win)
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
                            seg_c[i] = zncc_cost(seg_box[i], seg_al[i], seg_ar[i], seg_bl[i], seg_br[i])
                    else:
                        for i in range(i1 - k0):
                            seg_c[i] = nssd_cost(seg_al[i], seg_ar[i], seg_box[i], seg_bl[i], seg_br[i])
                continue
            for i in range(nw):
                xr = min(max(wa + i - cy[i] - off, 0), wa + i)
                ar_at[i] = ar[xr]
                br_at[i] = br[xr]
            _costs(crow_c, box_sums, al, bl, ar_at, br_at, nw, kind)
            for i in range(nw):
                d = cy[i] + off
                crow_c[i] = crow_c[i] if (d >= 0 and wa + i >= d) else BIG     # x_right < 0 or d < 0: none
        column_winners(cost, nc, nw, best_cost, best_k, cost_before, cost_after)
        od = out_disp[y, wa:wb]
        oc = out_cost[y, wa:wb]
        wy = want[y, wa:wb]
        for i in range(nw):             # branch-free: vectorizes
            value, c = _refined(cy[i], np.int64(best_k[i]), best_cost[i], cost_before[i], cost_after[i], half,
                                max_cost)
            od[i] = value if wy[i] else od[i]
            oc[i] = c if wy[i] else oc[i]


@njit(nogil=True, parallel=True, cache=True, fastmath=FASTMATH)
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


@njit(nogil=True, parallel=True, cache=True, fastmath=FASTMATH)
def refine_strips(left, right, radius, kind, center_pad, want, strips, half, max_cost, out):
    """:func:`refine_boxes` over row strips (``strips`` as ``boxes``), the products and costs
    gathered along runs of constant ``c`` (contiguous reads: fastest where ``c`` is constant over
    many pixels, a level's up-sampled field). Same sums, same results."""
    for j in prange(strips.shape[0]):
        _refine_box(left, right, radius, kind, center_pad, want, strips[j], half, max_cost, True, out)


@njit(nogil=True, parallel=True, cache=True, fastmath=FASTMATH)
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
    rflat = right_pad.reshape(right_pad.size)
    for s in prange(n_strips):
        j0, j1 = strip_rows(s, n_strips, 0, ys.size)
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
                        acc += _term(lv[t], np.float32(rflat[qs[t] - off]))
                else:                       # clamped to the padded row, as refine_boxes
                    for t in range(n):
                        yy = y + t // win
                        q = min(max(qs[t] - yy * wp - off, 0), wp - 1)
                        acc += _term(lv[t], np.float32(rflat[yy * wp + q]))
                cj[o] = acc
            al = a_left[y, x]
            bl = b_left[y, x]
            kb = -1
            cb = BIG
            for o in range(nc):
                d = cy + o - half
                if d < 0 or x < d:
                    c = BIG                 # x_right < 0 or d < 0: no candidate
                elif kind == ZNCC:
                    c = zncc_cost(cj[o], al, a_right[y, x - d], bl, b_right[y, x - d])
                else:
                    c = nssd_cost(al, a_right[y, x - d], cj[o], bl, b_right[y, x - d])
                cj[o] = c
                if c < cb:
                    cb = c
                    kb = o
            cm = cj[kb - 1] if kb > 0 else BIG
            cp = cj[kb + 1] if 0 <= kb < nc - 1 else BIG
            out_disp[y, x], out_cost[y, x] = _refined(cy, kb, cb, cm, cp, half, max_cost)
