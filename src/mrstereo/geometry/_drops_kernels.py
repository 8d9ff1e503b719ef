"""Numba kernel of the drop test (:mod:`mrstereo.geometry.drops`): one pass up each image column.

Private: no validation, preallocated outputs. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(nogil=True, cache=True, inline="always")
def _sigma_h(x, y, z, tx, ty, tz, sigma_per_m2):
    """Height uncertainty of a point: ``sigma_Z |z - t_z| / D`` with ``sigma_Z = D^2 sigma_d / (b f)``."""
    dist = math.sqrt((x - tx) ** 2 + (y - ty) ** 2 + (z - tz) ** 2)
    return abs(z - tz) * dist * sigma_per_m2


@njit(nogil=True, cache=True, inline="always")
def _emit(out, n, x, y):
    """Append the floor-level point ``(x, y, 0)`` to ``out`` (capacity permitting); the new count."""
    if n >= out.shape[0]:
        return n
    out[n, 0] = x
    out[n, 1] = y
    out[n, 2] = 0.0
    return n + 1


@njit(nogil=True, cache=True)
def column_drops(points, t, max_step_m, tan_slope, sigma_per_m2, n_sigma, low_m, support, edge_reach_m,
                 spacing_m, out_edge, out_below, edge_columns):
    """Drop edges and negative obstacles of a robot-frame point image ``points`` (H, W, 3), NaN invalid.

    Up each column (from the image's bottom), consecutive measured points ``A`` (nearer) and ``B`` with
    floor-level ``A`` (``-thr < z_A < low_m``) and ``B`` below the floor (``z_B < -thr``, ``thr =
    max_step + n_sigma sigma_h``), followed by ``support - 1`` more such points, are a drop when no
    drivable surface joins them: ``z_A - z_B > max_step + n_sigma sigma + tan_slope d_AB``. The edge lies
    between ``A`` and ``E``, where the sight line to ``B`` passes floor level: points every ``spacing_m``
    over the last ``edge_reach_m`` of ``A -> E`` go to ``out_edge``, the run of below-floor points after it
    to ``out_below``, all at floor level. The mirrored rise (a far rim: below-floor
    points, then supported floor) marks the first floor point. ``t``: the camera in the robot frame.
    Returns the counts of ``out_edge`` and ``out_below``; ``edge_columns[j]`` counts column j's edges.
    """
    H, W = points.shape[0], points.shape[1]
    tx, ty, tz = t[0], t[1], t[2]
    n_edge = 0
    n_below = 0
    rows = np.empty(H, np.int64)
    for j in range(W):
        m = 0
        for i in range(H - 1, -1, -1):
            if not math.isnan(points[i, j, 2]):
                rows[m] = i
                m += 1
        k = 1
        while k < m:
            a = rows[k - 1]
            b = rows[k]
            xa, ya, za = points[a, j, 0], points[a, j, 1], points[a, j, 2]
            xb, yb, zb = points[b, j, 0], points[b, j, 1], points[b, j, 2]
            sa = n_sigma * _sigma_h(xa, ya, za, tx, ty, tz, sigma_per_m2)
            sb = n_sigma * _sigma_h(xb, yb, zb, tx, ty, tz, sigma_per_m2)
            d_ab = math.sqrt((xa - xb) ** 2 + (ya - yb) ** 2)
            jump = max_step_m + math.sqrt(sa * sa + sb * sb) + tan_slope * d_ab
            a_floor = -(max_step_m + sa) < za < low_m
            b_floor = -(max_step_m + sb) < zb < low_m
            if a_floor and zb < -(max_step_m + sb) and za - zb > jump:
                # a drop: B and the points after it below the floor?
                end = k
                while end < m:
                    p = rows[end]
                    zp = points[p, j, 2]
                    if zp >= -(max_step_m + n_sigma * _sigma_h(points[p, j, 0], points[p, j, 1], zp, tx, ty, tz,
                                                              sigma_per_m2)):
                        break
                    end += 1
                if end - k >= support:
                    s = tz / (tz - zb)                   # the sight line to B at floor level
                    ex, ey = tx + s * (xb - tx), ty + s * (yb - ty)
                    length = math.sqrt((ex - xa) ** 2 + (ey - ya) ** 2)
                    start = max(0.0, length - edge_reach_m)
                    n_steps = int((length - start) / spacing_m) + 1
                    for q in range(n_steps + 1):
                        f = 1.0 if length <= 0.0 else min(1.0, (start + q * spacing_m) / length)
                        n_edge = _emit(out_edge, n_edge, xa + f * (ex - xa), ya + f * (ey - ya))
                    for q in range(k, end):
                        p = rows[q]
                        if n_below < out_below.shape[0]:
                            out_below[n_below, 0] = points[p, j, 0]
                            out_below[n_below, 1] = points[p, j, 1]
                            out_below[n_below, 2] = 0.0
                            n_below += 1
                    edge_columns[j] += 1
                    k = end
                    continue
            elif b_floor and za < -(max_step_m + sa) and zb - za > jump:
                # a rise from below the floor to supported floor: the far rim
                end = k
                while end < m and end - k < support:
                    p = rows[end]
                    zp = points[p, j, 2]
                    if not (-(max_step_m + n_sigma * _sigma_h(points[p, j, 0], points[p, j, 1], zp, tx, ty, tz,
                                                               sigma_per_m2)) < zp < low_m):
                        break
                    end += 1
                if end - k >= support:
                    n_edge = _emit(out_edge, n_edge, xb, yb)
                    edge_columns[j] += 1
            k += 1
    return n_edge, n_below
