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


@njit(nogil=True, cache=True, inline="always")
def _below(points, p, j, tx, ty, tz, max_step_m, sigma_per_m2, n_sigma):
    """Is point ``(p, j)`` below the floor by more than a step and its noise?"""
    z = points[p, j, 2]
    return z < -(max_step_m + n_sigma * _sigma_h(points[p, j, 0], points[p, j, 1], z, tx, ty, tz, sigma_per_m2))


@njit(nogil=True, cache=True)
def _steep(points, rows, j, k0, k1, max_step_m, tan_slope, noise_m):
    """Does the run ``rows[k0:k1]`` of column ``j`` start with a face steeper than the slope limit over a
    step (the far wall of a pit, a stair riser; later in the run a wall rising from a lower floor that a
    gentle slope led to)?"""
    for a in range(k0, min(k0 + 4, k1)):
        pa = rows[a]
        for b in range(a + 1, min(a + 12, k1)):
            pb = rows[b]
            dz = abs(points[pb, j, 2] - points[pa, j, 2])
            if dz >= max_step_m:
                d = math.sqrt((points[pb, j, 0] - points[pa, j, 0]) ** 2 + (points[pb, j, 1] - points[pa, j, 1]) ** 2)
                if dz > tan_slope * d + noise_m:
                    return True
    return False


@njit(nogil=True, cache=True)
def column_drops(points, t, max_step_m, tan_slope, sigma_per_m2, n_sigma, low_m, support, edge_reach_m,
                 spacing_m, out_edge, out_below, edge_columns):
    """Drop edges and negative obstacles of a robot-frame point image ``points`` (H, W, 3), NaN invalid.

    Up each column (from the image's bottom) a run of at least ``support`` measured points below the floor
    (``z < -(max_step + n_sigma sigma_h)``) is a drop when no drivable surface reaches it: it lies deeper
    than a step plus a slope of ``tan_slope`` from the last floor-level point ``A`` before it (``-thr < z <
    low_m``; none measured: the floor under the camera, where the robot stands), or it
    starts with a face steeper than that slope over a step and floor follows it (a hole's far wall, a stair
    riser). Its edge lies before
    ``E``, where the sight line to the run's first point passes floor level: points every ``spacing_m`` over
    the last ``edge_reach_m`` of ``A -> E`` go to ``out_edge``, the run's points to ``out_below``, all at floor
    level. A rise from a drop to supported floor-level points marks the first of them (a far rim). ``t``: the
    camera in the robot frame. Returns the counts of ``out_edge`` and ``out_below``; ``edge_columns[j]``
    counts column j's drops.
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
        xa, ya, za, sa = tx, ty, 0.0, 0.0
        in_drop = False
        k = 0
        while k < m:
            p = rows[k]
            xp, yp, zp = points[p, j, 0], points[p, j, 1], points[p, j, 2]
            sp = n_sigma * _sigma_h(xp, yp, zp, tx, ty, tz, sigma_per_m2)
            if -(max_step_m + sp) < zp < low_m:
                if in_drop:                          # back on the floor after a drop: its far rim
                    end = k
                    while end < m and end - k < support:
                        q = rows[end]
                        zq = points[q, j, 2]
                        sq = n_sigma * _sigma_h(points[q, j, 0], points[q, j, 1], zq, tx, ty, tz, sigma_per_m2)
                        if not -(max_step_m + sq) < zq < low_m:
                            break
                        end += 1
                    if end - k >= support:
                        n_edge = _emit(out_edge, n_edge, xp, yp)
                        in_drop = False
                xa, ya, za, sa = xp, yp, zp, sp
                k += 1
                continue
            if zp >= low_m or not _below(points, p, j, tx, ty, tz, max_step_m, sigma_per_m2, n_sigma):
                k += 1
                continue
            end = k                                  # the run of points below the floor
            deepest = 0.0
            while end < m and _below(points, rows[end], j, tx, ty, tz, max_step_m, sigma_per_m2, n_sigma):
                q = rows[end]
                sq = n_sigma * _sigma_h(points[q, j, 0], points[q, j, 1], points[q, j, 2], tx, ty, tz, sigma_per_m2)
                d = math.sqrt((points[q, j, 0] - xa) ** 2 + (points[q, j, 1] - ya) ** 2)
                deepest = max(deepest, za - points[q, j, 2] - math.sqrt(sa * sa + sq * sq) - tan_slope * d)
                end += 1
            # a steep face counts when floor follows it (a hole's far wall up to its far rim; a wall rising
            # from a lower floor goes on above the floor)
            rim = end < m and points[rows[end], j, 2] < low_m
            if end - k >= support and (deepest > max_step_m or (
                    rim and _steep(points, rows, j, k, end, max_step_m, tan_slope, sp))):
                s = tz / (tz - zp)                   # the sight line to the run's first point at floor level
                ex, ey = tx + s * (xp - tx), ty + s * (yp - ty)
                length = math.sqrt((ex - xa) ** 2 + (ey - ya) ** 2)
                start = max(0.0, length - edge_reach_m)
                n_steps = int((length - start) / spacing_m) + 1
                for q in range(n_steps + 1):
                    f = 1.0 if length <= 0.0 else min(1.0, (start + q * spacing_m) / length)
                    n_edge = _emit(out_edge, n_edge, xa + f * (ex - xa), ya + f * (ey - ya))
                for q in range(k, end):
                    r = rows[q]
                    if n_below < out_below.shape[0]:
                        out_below[n_below, 0] = points[r, j, 0]
                        out_below[n_below, 1] = points[r, j, 1]
                        out_below[n_below, 2] = points[r, j, 2]
                        n_below += 1
                edge_columns[j] += 1
                in_drop = True
            k = max(end, k + 1)
    return n_edge, n_below
