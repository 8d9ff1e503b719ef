"""Numba kernel of the virtual laser scan: points reduced to bearings in one pass (no validation).

Bearing ``k = rint((atan2(y, x) - angle_min) / increment)`` and horizontal range ``r = hypot(x, y)`` of
each point, as numpy computes them; each bearing keeps its ``m`` nearest points in a small sorted
list, so the ``m``-th nearest is found without sorting the points. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


_TOL = 1e-12
"""Relative margin within which ``sqrt(x^2 + y^2)`` leaves a decision to ``hypot``."""


@njit(nogil=True, cache=True, inline="always")
def _bearing(x, y, angle_min, increment):
    return np.int64(np.rint((math.atan2(y, x) - angle_min) / increment))


@njit(nogil=True, cache=True)
def nearest_per_bearing(points, angle_min, increment, range_min, range_max, m, near_r, near_i, count):
    """The ``m`` nearest returns of every bearing, in order of range (equal ranges: lower point index first).

    A return is a point with finite (x, y), ``range_min <= r <= range_max`` and a bearing in
    ``[0, n)``. ``near_r`` / ``near_i`` (n, m), filled with inf / -1 by the caller, receive the
    ranges and point indices; ``count`` (n,) zeroed, the returns per bearing.
    """
    n = count.shape[0]
    for i in range(points.shape[0]):
        x = np.float64(points[i, 0])
        y = np.float64(points[i, 1])
        if not (math.isfinite(x) and math.isfinite(y)):
            continue
        # sqrt(x^2 + y^2) is within a few ulp of hypot(x, y) (which costs as much as atan2): it decides
        # wherever it is clear by a relative 1e-12; hypot decides the rest and gives every kept range
        s = math.sqrt(x * x + y * y)
        if s < range_min * (1.0 - _TOL) or s > range_max * (1.0 + _TOL):
            continue
        r = -1.0
        if s < range_min * (1.0 + _TOL) or s > range_max * (1.0 - _TOL):
            r = math.hypot(x, y)
            if not (r >= range_min and r <= range_max):
                continue
        k = _bearing(x, y, angle_min, increment)
        if k < 0 or k >= n:
            continue
        count[k] += 1
        if s > near_r[k, m - 1] * (1.0 + _TOL):
            continue
        if r < 0.0:
            r = math.hypot(x, y)
        if not r < near_r[k, m - 1]:
            continue
        j = m - 1
        while j > 0 and near_r[k, j - 1] > r:     # keep earlier points ahead of equal ranges
            near_r[k, j] = near_r[k, j - 1]
            near_i[k, j] = near_i[k, j - 1]
            j -= 1
        near_r[k, j] = r
        near_i[k, j] = i


@njit(nogil=True, cache=True)
def seen_to_range(points, angle_min, increment, range_max, reach):
    """``reach[k] = True`` for each bearing ``k`` where a point with finite (x, y) lies at ``r >= range_max``
    (the bearing is computed only for those points)."""
    n = reach.shape[0]
    r2 = range_max * range_max
    for i in range(points.shape[0]):
        x = np.float64(points[i, 0])
        y = np.float64(points[i, 1])
        if not (math.isfinite(x) and math.isfinite(y)):
            continue
        if x * x + y * y < r2 * (1.0 - _TOL):       # surely nearer than range_max (hypot decides the rest)
            continue
        if not math.hypot(x, y) >= range_max:
            continue
        k = _bearing(x, y, angle_min, increment)
        if 0 <= k < n:
            reach[k] = True
