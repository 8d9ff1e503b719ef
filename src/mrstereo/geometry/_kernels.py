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


@njit(nogil=True, cache=True, inline="always")
def _point_robot(d, u, v, bf, focal_px, cx_px, cy_px, fy_px, R, t):
    """Eq. (14)-(16) of one pixel then ``R p + t``: the robot-frame point, or NaNs where ``d <= 0``.

    ``d`` already includes ``doffs``. The camera-frame point is exactly :func:`points_cam`'s;
    each robot coordinate is summed in the order ``((R[k,0] x + R[k,1] y) + R[k,2] z) + t[k]``.
    """
    z = bf / d if d > 0 else np.nan
    x = (np.float64(u) - cx_px) * z / focal_px
    y = (np.float64(v) - cy_px) * z / fy_px
    return (R[0, 0] * x + R[0, 1] * y + R[0, 2] * z + t[0],
            R[1, 0] * x + R[1, 1] * y + R[1, 2] * z + t[1],
            R[2, 0] * x + R[2, 1] * y + R[2, 2] * z + t[2])


@njit(nogil=True, cache=True, inline="always")
def _within(x, y, r):
    """``hypot(x, y) <= r``, exactly, mostly without the (slow) ``hypot``.

    ``x^2 + y^2`` is within a few ulp of ``hypot(x, y)^2``: outside a relative band of 1e-12
    around ``r^2`` its comparison decides; inside, ``hypot`` does.
    """
    s = x * x + y * y
    r2 = r * r
    if s < r2 * (1.0 - 1e-12):
        return True
    if s > r2 * (1.0 + 1e-12):
        return False
    return math.hypot(x, y) <= r


@njit(nogil=True, cache=True)
def points_robot_image(disparity, doffs_px, bf, focal_px, cx_px, cy_px, fy_px, R, t, out):
    """Robot-frame point of every pixel into ``out`` (H, W, 3) float64: :func:`_point_robot`, NaN invalid."""
    h, w = disparity.shape
    for v in range(h):
        for u in range(w):
            px, py, pz = _point_robot(np.float64(disparity[v, u]) + doffs_px, u, v, bf, focal_px, cx_px, cy_px,
                                      fy_px, R, t)
            out[v, u, 0] = px
            out[v, u, 1] = py
            out[v, u, 2] = pz


@njit(nogil=True, cache=True)
def count_points(disparity, doffs_px, too_near, near_limit_px):
    """Pixels with ``d + doffs > 0`` (a too-near pixel's disparity is the near limit): a bound on the points.

    ``too_near`` is an (H, W) bool mask, or (0, 0) for none.
    """
    h, w = disparity.shape
    has_near = too_near.shape[0] > 0
    n = 0
    for v in range(h):
        for u in range(w):
            d = near_limit_px if has_near and too_near[v, u] else np.float64(disparity[v, u])
            n += (d + doffs_px) > 0
    return n


@njit(nogil=True, cache=True)
def obstacle_points(disparity, doffs_px, too_near, near_limit_px, bf, focal_px, cx_px, cy_px, fy_px, R, t,
                    max_range_m, min_height_m, max_height_m, floor_tolerance_m,
                    points, pixels, obstacle_points, floor_points, obstacle, floor, image, first_row):
    """Triangulation (eq. 14-16), robot transform and height band in one pass over the valid pixels.

    Each pixel with ``d + doffs > 0`` (a ``too_near`` pixel at ``near_limit_px``; ``too_near`` (H, W)
    or (0, 0)) and a finite point goes to ``points`` and its flat index to ``pixels`` (raster
    order); within ``max_range`` it is an obstacle for ``min_height < z <= max_height``, else floor
    for ``|z| <= floor_tolerance`` unless too near, copied to ``obstacle_points`` / ``floor_points``
    and marked in the masks. ``image`` (H - ``first_row``, W, 3), or (0, W, 3) for none: the point
    image of the rows from ``first_row`` on, NaN where no point and where too near (placed at the near
    limit, a too-near floor pixel lies below the floor: its surface is only known to lie nearer, no
    evidence for the drop test). Returns ``(n_points, n_obstacle,
    n_floor, n_floor_band, n_obstacle_too_near)``, ``n_floor_band`` counted before obstacles and
    too-near pixels are removed.
    """
    h, w = disparity.shape
    has_near = too_near.shape[0] > 0
    n = 0
    n_obstacle = 0
    n_floor = 0
    n_floor_band = 0
    n_near = 0
    for v in range(h):
        row = v - first_row
        imaged = 0 <= row < image.shape[0]
        for u in range(w):
            if imaged:
                image[row, u, 0] = np.nan
                image[row, u, 1] = np.nan
                image[row, u, 2] = np.nan
            near = has_near and too_near[v, u]
            d = (near_limit_px if near else np.float64(disparity[v, u])) + doffs_px
            obstacle[v, u] = False
            floor[v, u] = False
            if not d > 0:
                continue
            px, py, pz = _point_robot(d, u, v, bf, focal_px, cx_px, cy_px, fy_px, R, t)
            if not (math.isfinite(px) and math.isfinite(py) and math.isfinite(pz)):
                continue              # a disparity so small that Z overflows
            points[n, 0] = px
            points[n, 1] = py
            points[n, 2] = pz
            pixels[n] = v * w + u
            n += 1
            if imaged and not near:
                image[row, u, 0] = px
                image[row, u, 1] = py
                image[row, u, 2] = pz
            in_band = pz > min_height_m and pz <= max_height_m
            in_floor_band = abs(pz) <= floor_tolerance_m
            if not (in_band or in_floor_band):
                continue
            in_range = _within(px, py, max_range_m)
            is_obstacle = in_range and in_band
            is_floor_band = in_range and in_floor_band
            n_floor_band += is_floor_band
            if is_obstacle:
                obstacle[v, u] = True
                obstacle_points[n_obstacle, 0] = px
                obstacle_points[n_obstacle, 1] = py
                obstacle_points[n_obstacle, 2] = pz
                n_obstacle += 1
                n_near += near
            elif is_floor_band and not near:
                floor[v, u] = True
                floor_points[n_floor, 0] = px
                floor_points[n_floor, 1] = py
                floor_points[n_floor, 2] = pz
                n_floor += 1
    return n, n_obstacle, n_floor, n_floor_band, n_near


@njit(nogil=True, cache=True)
def scatter_points(points, pixels, out):
    """``out`` (H * W, 3) float64 = NaN, then ``out[pixels[i]] = points[i]``: a point image from the listed points.
    One pass over ``out`` when ``pixels`` increase (as :func:`obstacle_points` lists them); any order is right."""
    k = 0
    for i in range(pixels.shape[0]):
        p = pixels[i]
        while k < p:
            out[k, 0] = np.nan
            out[k, 1] = np.nan
            out[k, 2] = np.nan
            k += 1
        out[p, 0] = points[i, 0]
        out[p, 1] = points[i, 1]
        out[p, 2] = points[i, 2]
        k = max(k, p + 1)
    while k < out.shape[0]:
        out[k, 0] = np.nan
        out[k, 1] = np.nan
        out[k, 2] = np.nan
        k += 1


@njit(nogil=True, cache=True)
def points_ahead(points, max_depth_m, out):
    """The rows of ``points`` (N, 3) that are finite with ``0 < z <= max_depth_m``, in order, into ``out``; their
    number."""
    n = 0
    for i in range(points.shape[0]):
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        if math.isfinite(x) and math.isfinite(y) and 0.0 < z <= max_depth_m:
            out[n, 0] = x
            out[n, 1] = y
            out[n, 2] = z
            n += 1
    return n


@njit(nogil=True, cache=True)
def plane_scores(x, y, z, normals, dists, threshold_m, below_penalty, out):
    """RANSAC scores of the planes ``normals[k] . p = dists[k]`` on the points ``(x, y, z)`` (M,) each into ``out``
    (K,): the points within ``threshold_m`` of a plane less ``below_penalty`` times those farther than that on
    the side its normal points to (below the floor). Hypothesis after hypothesis, points in order, on one thread
    (within a frame as fast as two, and steadier). It replaces a matrix product, which BLAS may sum in another
    order: a point within a rounding error of the threshold could count otherwise."""
    for k in range(normals.shape[0]):
        nx, ny, nz, dist = normals[k, 0], normals[k, 1], normals[k, 2], dists[k]
        inside = 0
        beyond = 0
        for i in range(x.shape[0]):
            r = x[i] * nx + y[i] * ny + z[i] * nz - dist
            inside += abs(r) <= threshold_m
            beyond += r > threshold_m
        out[k] = inside - below_penalty * beyond
