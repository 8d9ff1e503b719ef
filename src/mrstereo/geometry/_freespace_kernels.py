"""Numba kernel of the free-space boundary (no validation, preallocated outputs).

Conventions: docs/conventions.md; the rules: docs/mapping.md (Free-space boundary).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._kernels import _point_robot


@njit(nogil=True, cache=True, inline="always")
def floor_point(u, v, focal_px, cx_px, cy_px, fy_px, R, t):
    """Robot-frame ``(x, y)`` where the ray of pixel ``(u, v)`` meets the floor ``z = 0``; NaN when it does not."""
    cx = (u - cx_px) / focal_px
    cy = (v - cy_px) / fy_px
    dz = R[2, 0] * cx + R[2, 1] * cy + R[2, 2]
    if not dz < -1e-9:
        return np.nan, np.nan
    s = -t[2] / dz
    return (t[0] + s * (R[0, 0] * cx + R[0, 1] * cy + R[0, 2]),
            t[1] + s * (R[1, 0] * cx + R[1, 1] * cy + R[1, 2]))


@njit(nogil=True, cache=True, inline="always")
def _range_at(disparity, doffs_px, u, v, bf, focal_px, cx_px, cy_px, fy_px, R, t):
    """``(range, x, y)`` of pixel ``(u, v)``'s measured point (robot frame); range NaN when unmeasured."""
    d = np.float64(disparity[u, v]) + doffs_px
    if not d > 0:
        return np.nan, np.nan, np.nan
    px, py, pz = _point_robot(d, u, v, bf, focal_px, cx_px, cy_px, fy_px, R, t)
    return math.hypot(px, py), px, py


@njit(nogil=True, cache=True)
def column_boundaries(smooth, floor, obstacle, uniform, disparity, doffs_px, bf, focal_px, cx_px, cy_px, fy_px, R, t,
                      max_range_m, min_range_m, edge_rows, persist_rows, check_rows, edge_threshold,
                      appearance_threshold, adapt, far_margin_m, gap_rows, start_lo, start_hi, measured_only,
                      base_row, top_row, base_xy):
    """Per column of the rectified left image, the row where the floor ends (rules: :mod:`..freespace`).

    The images are transposed, (W, H), so that a column is contiguous in memory: ``smooth``
    float32 is the smoothed gray image, ``floor`` / ``obstacle`` bool the measured floor / obstacle
    pixels, ``uniform`` bool the pixels without texture, ``disparity`` the disparity (NaN invalid).
    Writes ``base_row[u]`` (the edge lies between rows ``base_row - 1`` and ``base_row``; -1: no
    boundary), ``top_row[u]`` (the highest row of the obstacle's evidence) and ``base_xy[u]``
    (robot-frame base point).
    """
    w, h = smooth.shape
    k = edge_rows
    max_range2 = max_range_m * max_range_m
    min_range2 = min_range_m * min_range_m
    for u in range(w):
        base_row[u] = -1
        top_row[u] = -1
        # the floor's look where the column starts: its bottom rows, no measured obstacle
        start = h - persist_rows
        ok = True
        mu = 0.0
        for v in range(start, h):
            if obstacle[u, v]:
                ok = False
            mu += smooth[u, v]
        mu /= persist_rows
        if not ok or not start_lo <= mu <= start_hi:
            continue
        u0 = max(u - 1, 0)
        u1 = min(u + 1, w - 1)
        last_floor = -1
        last_fx = 0.0
        last_fy = 0.0
        textured = 0
        unexplained = 0
        for v in range(start - 1, check_rows + k, -1):
            fx, fy = floor_point(u, v - 0.5, focal_px, cx_px, cy_px, fy_px, R, t)
            if not math.isfinite(fx):
                break
            r2 = fx * fx + fy * fy
            if r2 > max_range2:
                break
            if obstacle[u, v] and obstacle[u, v - 1]:
                break                       # the stereo measured something standing here
            s = smooth[u, v]
            is_floor = floor[u, v]
            if is_floor:
                last_floor = v
                rr, last_fx, last_fy = _range_at(disparity, doffs_px, u, v, bf, focal_px, cx_px, cy_px, fy_px, R, t)
                textured = 0
            elif not uniform[u, v]:
                textured += 1
                if textured >= persist_rows:
                    break                   # texture that the matcher did not measure: nothing to follow
            else:
                textured = 0
            gap = last_floor - v
            near_floor = last_floor >= 0 and gap <= gap_rows
            allowed = (near_floor or not measured_only) and r2 >= min_range2 and \
                not (last_floor >= 0 and gap_rows < gap <= check_rows)
            step = 0.0
            for j in range(k):
                step += smooth[u, v - 1 - j] - smooth[u, v + j]
            step = abs(step) / k
            if allowed and step >= edge_threshold:
                # a local maximum of the step along the column
                up = 0.0
                down = 0.0
                for j in range(k):
                    up += smooth[u, v - 2 - j] - smooth[u, v - 1 + j]
                    down += smooth[u, v - j] - smooth[u, v + 1 + j]
                good = step >= abs(up) / k and step >= abs(down) / k
                r = math.sqrt(r2)
                # the look above stays unlike the floor's
                changed = 0
                for j in range(1, persist_rows + 1):
                    if abs(smooth[u, v - j] - mu) > appearance_threshold:
                        changed += 1
                good = good and 4 * changed >= 3 * persist_rows
                # no floor measured above it, no measured point above it at another range
                top = v - 1
                n_seen = 0
                sx = 0.0
                sy = 0.0
                if good:
                    for vv in range(v - 1, v - 1 - check_rows, -1):
                        for uu in range(u0, u1 + 1):
                            if floor[uu, vv]:
                                good = False
                        rr, px, py = _range_at(disparity, doffs_px, u, vv, bf, focal_px, cx_px, cy_px, fy_px, R, t)
                        if rr == rr:
                            if abs(rr - r) > far_margin_m:
                                good = False
                            elif obstacle[u, vv]:
                                n_seen += 1
                                sx += px
                                sy += py
                        if not good:
                            break
                        top = vv
                if good:
                    # the obstacle reaches up until the floor or something farther shows above it
                    for vv in range(v - 2 - check_rows, -1, -1):
                        if floor[u, vv]:
                            break
                        rr, px, py = _range_at(disparity, doffs_px, u, vv, bf, focal_px, cx_px, cy_px, fy_px, R, t)
                        if rr > r + far_margin_m:
                            break
                        top = vv
                    base_row[u] = v
                    top_row[u] = top
                    # the base: measured where possible -- the obstacle points above the edge,
                    # else the measured floor just below it, else the edge's floor point
                    if n_seen > 0:
                        base_xy[u, 0] = sx / n_seen
                        base_xy[u, 1] = sy / n_seen
                    elif near_floor:
                        base_xy[u, 0] = last_fx
                        base_xy[u, 1] = last_fy
                    else:
                        base_xy[u, 0] = fx
                        base_xy[u, 1] = fy
                    break
            # follow the floor: measured, or looking like it; a run of neither ends the column
            if is_floor or abs(s - mu) <= appearance_threshold:
                mu += adapt * (s - mu)
                unexplained = 0
            else:
                unexplained += 1
                if unexplained >= persist_rows:
                    break
