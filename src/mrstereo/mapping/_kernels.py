"""Numba kernels of the occupancy grid and the planner (no validation, preallocated outputs).

Grid coordinates are continuous cell units: ``gx = (x - origin_x) / resolution`` along the
columns and ``gy = (y - origin_y) / resolution`` along the rows, so cell ``[r, c]`` covers
``[c, c + 1) x [r, r + 1)``. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import heapq
import math

import numpy as np
from numba import njit

# Bits of the per-update ``flags`` array (uint8, one byte per cell).
HIT = np.uint8(1)        # an obstacle point ends in this cell
END_FREE = np.uint8(2)   # a ray ends here and clears its end cell (floor point, or clipped ray)
MISS = np.uint8(4)       # a ray crossed this cell


@njit(nogil=True, cache=True)
def _clip_segment(x0, y0, x1, y1, cols, rows):
    """Liang-Barsky: parameters ``(t0, t1)`` of the part of the segment inside the grid box."""
    dx = x1 - x0
    dy = y1 - y0
    t0 = 0.0
    t1 = 1.0
    for k in range(4):
        if k == 0:
            p, q = -dx, x0
        elif k == 1:
            p, q = dx, cols - x0
        elif k == 2:
            p, q = -dy, y0
        else:
            p, q = dy, rows - y0
        if p == 0.0:
            if q < 0.0:
                return 1.0, 0.0
        else:
            r = q / p
            if p < 0.0:
                if r > t0:
                    t0 = r
            elif r < t1:
                t1 = r
    return t0, t1


@njit(nogil=True, cache=True)
def _cell(v, n):
    c = int(math.floor(v))
    if c < 0:
        return 0
    if c > n - 1:
        return n - 1
    return c


@njit(nogil=True, cache=True)
def mark_endpoints(points, sx, sy, origin_x, origin_y, resolution, max_range_cells, is_obstacle, flags,
                   ends):
    """Flag the end cell of every ray; return the number of points ending outside the grid.

    ``points`` is (N, 2 or 3) in world metres (columns 0, 1 used; rows with NaN skipped);
    ``(sx, sy)`` is the sensor in grid units. Obstacle ends inside the grid and within
    ``max_range_cells`` (<= 0: unlimited) get ``HIT``, floor ends ``END_FREE``. A ray whose end
    lies outside the grid or beyond the range is cut there and its last cell gets ``END_FREE``.
    ``ends`` (rows, cols, 2) receives, per flagged cell, the grid coordinates of the last ray end
    that fell in it (the target of the one ray traced to that cell).
    """
    rows, cols = flags.shape
    outside = 0
    for i in range(points.shape[0]):
        x = (points[i, 0] - origin_x) / resolution
        y = (points[i, 1] - origin_y) / resolution
        if not (math.isfinite(x) and math.isfinite(y)):
            continue
        cut = False
        if max_range_cells > 0.0:
            d = math.hypot(x - sx, y - sy)
            if d > max_range_cells:
                s = max_range_cells / d
                x = sx + (x - sx) * s
                y = sy + (y - sy) * s
                cut = True
        if 0.0 <= x < cols and 0.0 <= y < rows:
            r = int(y)
            c = int(x)
            if is_obstacle and not cut:
                flags[r, c] |= HIT
            else:
                flags[r, c] |= END_FREE
            ends[r, c, 0] = x
            ends[r, c, 1] = y
            continue
        outside += 1
        t0, t1 = _clip_segment(sx, sy, x, y, cols, rows)
        if t0 > t1:
            continue
        ex = sx + (x - sx) * t1
        ey = sy + (y - sy) * t1
        r = _cell(ey, rows)
        c = _cell(ex, cols)
        flags[r, c] |= END_FREE
        ends[r, c, 0] = ex
        ends[r, c, 1] = ey
    return outside


@njit(nogil=True, cache=True)
def _axis_step(d, cell, start):
    """Amanatides-Woo set-up along one axis: step sign, t per cell, t to the first boundary."""
    if d > 0.0:
        return 1, 1.0 / d, (cell + 1 - start) / d
    if d < 0.0:
        return -1, -1.0 / d, (cell - start) / d
    return 0, np.inf, np.inf


@njit(nogil=True, cache=True)
def _trace(sx, sy, tx, ty, include_end, miss):
    """Amanatides-Woo traversal from ``(sx, sy)`` to the point ``(tx, ty)`` (grid units).

    Marks ``miss`` on every crossed cell inside the grid; the end cell only if ``include_end``.
    """
    rows, cols = miss.shape
    t0, t1 = _clip_segment(sx, sy, tx, ty, cols, rows)
    if t0 > t1:
        return
    dx = tx - sx
    dy = ty - sy
    ax = sx + dx * t0
    ay = sy + dy * t0
    bx = sx + dx * t1
    by = sy + dy * t1
    cx = _cell(ax, cols)
    cy = _cell(ay, rows)
    ex = _cell(bx, cols)
    ey = _cell(by, rows)
    if t1 < 1.0:        # the ray leaves the grid: its last inside cell is cleared
        include_end = True
    nx = abs(ex - cx)
    ny = abs(ey - cy)
    stepx, tdx, tmx = _axis_step(dx, cx, sx)
    stepy, tdy, tmy = _axis_step(dy, cy, sy)
    if nx + ny == 0:
        if include_end:
            miss[cy, cx] = 1
        return
    miss[cy, cx] = 1
    while True:
        if nx > 0 and (ny == 0 or tmx < tmy):
            cx += stepx
            tmx += tdx
            nx -= 1
        else:
            cy += stepy
            tmy += tdy
            ny -= 1
        if nx + ny == 0:
            if include_end:
                miss[cy, cx] = 1
            return
        miss[cy, cx] = 1


@njit(nogil=True, cache=True)
def cast_rays(flags, ends, sx, sy, miss):
    """Trace one ray from the sensor to each flagged end cell (deduplicated rays).

    The ray goes to the cell's representative end point ``ends[r, c]``, a measured point.
    """
    rows, cols = flags.shape
    for r in range(rows):
        for c in range(cols):
            f = flags[r, c]
            if f == 0:
                continue
            include_end = (f & HIT) == 0
            _trace(sx, sy, ends[r, c, 0], ends[r, c, 1], include_end, miss)


@njit(nogil=True, cache=True)
def apply_cells(log_odds, hit, miss, l_hit, l_miss, l_min, l_max, union):
    """Add one view to the flat log-odds (NaN = unknown): ``hit`` and ``miss`` are flat indices.

    ``union``: a hit sets ``l_max`` for good; a miss sets ``l_min`` unless the cell is occupied.
    """
    for i in hit:
        if union:
            log_odds[i] = l_max
            continue
        old = log_odds[i]
        if math.isnan(old):
            old = 0.0
        log_odds[i] = min(max(old + l_hit, l_min), l_max)
    for i in miss:
        old = log_odds[i]
        if union:
            if not old == l_max:
                log_odds[i] = l_min
            continue
        if math.isnan(old):
            old = 0.0
        log_odds[i] = min(max(old + l_miss, l_min), l_max)


@njit(nogil=True, cache=True)
def astar(blocked, start_r, start_c, goal_r, goal_c, came_from, g_cost):
    """A* on an 8-connected grid, octile heuristic, no corner cutting; costs in cells.

    ``came_from`` (int64, rows*cols) and ``g_cost`` (float64, rows*cols) are outputs, filled with
    -1 / inf by the caller. Returns the number of expanded cells, negated if the goal was not
    reached (``-expanded - 1``).
    """
    rows, cols = blocked.shape
    sqrt2 = math.sqrt(2.0)
    closed = np.zeros(rows * cols, np.uint8)
    start = start_r * cols + start_c
    goal = goal_r * cols + goal_c
    g_cost[start] = 0.0
    dr0 = abs(goal_r - start_r)
    dc0 = abs(goal_c - start_c)
    h0 = max(dr0, dc0) + (sqrt2 - 1.0) * min(dr0, dc0)
    heap = [(h0, h0, start)]
    expanded = 0
    while len(heap) > 0:
        f, h, idx = heapq.heappop(heap)
        if closed[idx]:
            continue
        closed[idx] = 1
        expanded += 1
        if idx == goal:
            return expanded
        r = idx // cols
        c = idx - r * cols
        g = g_cost[idx]
        for k in range(8):
            if k == 0:
                dr, dc = 0, 1
            elif k == 1:
                dr, dc = 0, -1
            elif k == 2:
                dr, dc = 1, 0
            elif k == 3:
                dr, dc = -1, 0
            elif k == 4:
                dr, dc = 1, 1
            elif k == 5:
                dr, dc = 1, -1
            elif k == 6:
                dr, dc = -1, 1
            else:
                dr, dc = -1, -1
            nr = r + dr
            nc = c + dc
            if nr < 0 or nr >= rows or nc < 0 or nc >= cols or blocked[nr, nc]:
                continue
            if dr != 0 and dc != 0:
                if blocked[r, nc] or blocked[nr, c]:      # no corner cutting
                    continue
                step = sqrt2
            else:
                step = 1.0
            nidx = nr * cols + nc
            if closed[nidx]:
                continue
            ng = g + step
            if ng < g_cost[nidx]:
                g_cost[nidx] = ng
                came_from[nidx] = idx
                ar = abs(goal_r - nr)
                ac = abs(goal_c - nc)
                nh = max(ar, ac) + (sqrt2 - 1.0) * min(ar, ac)
                heapq.heappush(heap, (ng + nh, nh, nidx))
    return -expanded - 1


@njit(nogil=True, cache=True)
def count_cells(points, origin_x, origin_y, resolution, counts, cell):
    """Count points per grid cell (``counts`` of grid.shape, zeroed); ``cell[i]`` = flat cell of point i.

    ``col = floor((x - origin_x) / resolution)``, ``row = floor((y - origin_y) / resolution)``;
    ``cell[i]`` is -1 for a non-finite point and -2 for a finite point outside the grid.
    Returns the number of finite points outside the grid.
    """
    rows, cols = counts.shape
    outside = 0
    for i in range(points.shape[0]):
        col = np.floor((points[i, 0] - origin_x) / resolution)
        row = np.floor((points[i, 1] - origin_y) / resolution)
        if not (np.isfinite(col) and np.isfinite(row)):
            cell[i] = -1
        elif 0 <= col < cols and 0 <= row < rows:
            r = int(row)
            c = int(col)
            counts[r, c] += 1
            cell[i] = r * cols + c
        else:
            cell[i] = -2
            outside += 1
    return outside


@njit(nogil=True, cache=True)
def keep_supported(cell, counts, min_points, keep):
    """``keep[i]`` = point i lies in a grid cell holding at least ``min_points`` points (outside: False)."""
    flat = counts.ravel()
    n = 0
    for i in range(cell.shape[0]):
        k = cell[i] >= 0 and flat[cell[i]] >= min_points
        keep[i] = k
        n += k
    return n
