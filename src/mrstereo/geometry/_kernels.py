"""Numba kernels of the 3D stage (no validation, preallocated outputs).

Each kernel does per element exactly the arithmetic of the numpy expression it replaces, in
the same order and dtype (no fastmath), so the results are bit-identical; ``nogil`` lets the
per-frame chain run on worker threads. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(nogil=True, cache=True)
def points_cam(disparity, focal_px, baseline_m, doffs_px, cx_px, cy_px, fy_px, out):
    """Eq. (14)-(16) per pixel into ``out`` (H, W, 3) float64; NaN where ``d + doffs <= 0`` or NaN.

    ``Z = (b f) / (d + doffs)``, ``X = ((u - cx) Z) / f``, ``Y = ((v - cy) Z) / fy``.
    """
    bf = baseline_m * focal_px
    h, w = disparity.shape
    for v in range(h):
        y_px = np.float64(v) - cy_px
        for u in range(w):
            d = np.float64(disparity[v, u]) + doffs_px
            z = bf / d if d > 0 else np.nan
            out[v, u, 0] = (np.float64(u) - cx_px) * z / focal_px
            out[v, u, 1] = y_px * z / fy_px
            out[v, u, 2] = z


@njit(nogil=True, cache=True)
def add_offset(points, offset):
    """``points[..., k] += offset[k]`` in place for (H, W, 3) points."""
    h, w, _ = points.shape
    for v in range(h):
        for u in range(w):
            for k in range(3):
                points[v, u, k] = points[v, u, k] + offset[k]


@njit(nogil=True, cache=True)
def classify(points, max_range_m, min_height_m, max_height_m, floor_tolerance_m, obstacle, floor):
    """Obstacle / floor masks of robot-frame points (H, W, 3); NaN points are neither.

    ``obstacle = hypot(x, y) <= max_range and min_height < z <= max_height``;
    ``floor = hypot(x, y) <= max_range and |z| <= floor_tolerance and not obstacle``.
    Returns ``(n_obstacle, n_floor_band)``, the latter counted before obstacles are removed.
    """
    h, w, _ = points.shape
    n_obstacle = 0
    n_floor = 0
    for v in range(h):
        for u in range(w):
            z = points[v, u, 2]
            in_range = math.hypot(points[v, u, 0], points[v, u, 1]) <= max_range_m
            is_obstacle = in_range and z > min_height_m and z <= max_height_m
            is_floor = in_range and abs(z) <= floor_tolerance_m
            obstacle[v, u] = is_obstacle
            floor[v, u] = is_floor and not is_obstacle
            n_obstacle += is_obstacle
            n_floor += is_floor
    return n_obstacle, n_floor


@njit(nogil=True, cache=True)
def count_true(mask):
    """Number of True pixels of an (H, W) mask."""
    n = 0
    h, w = mask.shape
    for v in range(h):
        for u in range(w):
            n += mask[v, u]
    return n


@njit(nogil=True, cache=True)
def gather_points(points, mask, out):
    """Rows of ``points`` (H, W, 3) where ``mask`` (H, W) is True, in raster order, into ``out`` (N, 3)."""
    h, w = mask.shape
    n = 0
    for v in range(h):
        for u in range(w):
            if mask[v, u]:
                for k in range(3):
                    out[n, k] = points[v, u, k]
                n += 1
    return n
