"""Kernels of the scan-to-map alignment (no validation; the callers in alignment.py check and allocate).

Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math

from numba import njit

__all__ = ["score_poses"]


@njit(nogil=True, cache=True)
def score_poses(field, origin_x_m, origin_y_m, resolution_m, outside, points_xy, yaws, offsets_xy, out):
    """``out[i, j]`` = mean over points of ``field`` (bilinear) at ``R(yaws[i]) p + offsets_xy[j]``.

    ``field`` is sampled at cell centres (row = y, column = x); a point outside the grid scores
    ``outside``.
    """
    rows, cols = field.shape
    n = points_xy.shape[0]
    for i in range(yaws.shape[0]):
        c, s = math.cos(yaws[i]), math.sin(yaws[i])
        for j in range(offsets_xy.shape[0]):
            tx = (offsets_xy[j, 0] - origin_x_m) / resolution_m - 0.5
            ty = (offsets_xy[j, 1] - origin_y_m) / resolution_m - 0.5
            total = 0.0
            for k in range(n):
                px, py = points_xy[k, 0], points_xy[k, 1]
                u = (c * px - s * py) / resolution_m + tx
                v = (s * px + c * py) / resolution_m + ty
                c0, r0 = int(math.floor(u)), int(math.floor(v))
                if c0 < 0 or r0 < 0 or c0 >= cols - 1 or r0 >= rows - 1:
                    total += outside
                    continue
                a, b = u - c0, v - r0
                total += ((field[r0, c0] * (1.0 - a) + field[r0, c0 + 1] * a) * (1.0 - b)
                          + (field[r0 + 1, c0] * (1.0 - a) + field[r0 + 1, c0 + 1] * a) * b)
            out[i, j] = total / n
