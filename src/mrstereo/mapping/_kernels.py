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
FLOOR = np.uint8(8)      # a floor point ends in this cell
BLOCK = np.uint8(16)     # not hit in this view, but known occupied (stops rays like a hit)
_LATER = -1.0            # ``ends[r, c, 2]`` of an obstacle end whose margin mark_endpoints computes at its end


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
def mark_endpoints(points, keep, sx, sy, origin_x, origin_y, resolution, max_range_cells, is_obstacle,
                   margin_per_cell2, flags, ends, n_points, z_range):
    """Flag the end cell of every ray; return the number of points ending outside the grid.

    ``points`` (N, 2 or 3) float32 or float64 (taken as float64); ``keep`` (N,) bool selects the points
    (length 0: all).
    Obstacle ends inside the grid and range (``max_range_cells`` <= 0: unlimited) get ``HIT``, floor
    ends ``END_FREE | FLOOR``; a ray leaving the grid or range is cut and its last cell gets
    ``END_FREE``. ``ends`` (rows, cols, 4) receives per flagged cell the last end that fell in it (the
    target of its one ray), its clearing margin (``margin_per_cell2 * r^2`` cells for an obstacle end
    at ``r`` cells: a stereo point's range error grows with the square of the range) and its height
    (NaN for 2-column points); ``n_points`` counts the ends per cell and ``z_range`` the lowest and
    highest obstacle point of each hit cell.
    """
    rows, cols = flags.shape
    has_z = points.shape[1] > 2
    select = keep.shape[0] > 0
    outside = 0
    for i in range(points.shape[0]):
        if select and not keep[i]:
            continue
        x = (np.float64(points[i, 0]) - origin_x) / resolution
        y = (np.float64(points[i, 1]) - origin_y) / resolution
        if not (math.isfinite(x) and math.isfinite(y)):
            continue
        z = np.float64(points[i, 2]) if has_z else np.nan
        cut = False
        if max_range_cells > 0.0:
            d = math.hypot(x - sx, y - sy)
            if d > max_range_cells:
                s = max_range_cells / d
                x = sx + (x - sx) * s
                y = sy + (y - sy) * s
                cut = True
        # an uncut obstacle end's margin depends on its range: taken from the cell's last end below
        margin = _LATER if is_obstacle and not cut and margin_per_cell2 != 0.0 else 0.0
        if 0.0 <= x < cols and 0.0 <= y < rows:
            r = int(y)
            c = int(x)
            if is_obstacle and not cut:
                flags[r, c] |= HIT
                n_points[r, c] += 1
                if z < z_range[r, c, 0]:
                    z_range[r, c, 0] = z
                if z > z_range[r, c, 1]:
                    z_range[r, c, 1] = z
            elif not is_obstacle and not cut:
                flags[r, c] |= END_FREE | FLOOR
                n_points[r, c] += 1
            else:
                flags[r, c] |= END_FREE
            ends[r, c, 0] = x
            ends[r, c, 1] = y
            ends[r, c, 2] = margin
            ends[r, c, 3] = z if not cut else np.nan
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
        ends[r, c, 2] = 0.0
        ends[r, c, 3] = np.nan
    if margin_per_cell2 != 0.0:
        for r in range(rows):
            for c in range(cols):
                if flags[r, c] != 0 and ends[r, c, 2] == _LATER:
                    d = math.hypot(ends[r, c, 0] - sx, ends[r, c, 1] - sy)
                    ends[r, c, 2] = margin_per_cell2 * d * d
    return outside


@njit(nogil=True, cache=True)
def _axis_step(d, cell, start):
    """Amanatides-Woo set-up along one axis: step sign, t per cell, t to the first boundary."""
    if d > 0.0:
        return 1, 1.0 / d, (cell + 1 - start) / d
    if d < 0.0:
        return -1, -1.0 / d, (cell - start) / d
    return 0, np.inf, np.inf


@njit(nogil=True, cache=True, inline="always")
def _sight(z_range, r, c, sz, tz, t_a, t_b, z_tol):
    """Where does the sight line, at heights ``sz + t (tz - sz)`` for t in [t_a, t_b], pass a cell?

    1: it meets the cell's obstacle points (``z_range`` +- ``z_tol``); 2: it passes below them
    (the cell overhangs the line, e.g. a table top); 0: above them. Without heights (NaN) the
    line meets every cell.
    """
    if not (math.isfinite(sz) and math.isfinite(tz)):
        return 1
    za = sz + t_a * (tz - sz)
    zb = sz + t_b * (tz - sz)
    if min(za, zb) > z_range[r, c, 1] + z_tol:
        return 0
    if max(za, zb) < z_range[r, c, 0] - z_tol:
        return 2
    return 1


@njit(nogil=True, cache=True)
def _trace(sx, sy, sz, tx, ty, tz, t_cut, t_occ, flags, z_range, z_tol, shadow, z_clear, through, votes, miss):
    """Amanatides-Woo traversal from the sensor ``(sx, sy)`` towards the end ``(tx, ty)`` (grid units).

    *Solid* cells are those hit in this view (``HIT``) or known occupied (``BLOCK``), other than the
    end cell. With ``votes == 0``: marks ``miss`` on the cells entered before ``t_cut`` (> 1: up to the
    end cell) and returns True when the ray enters, before ``t_occ``, a solid cell whose obstacle
    points its sight line meets (:func:`_sight`: the end is occluded); with ``shadow`` a sight line
    passing below a solid cell's points marks no more misses, and cells where it runs higher than
    ``z_clear`` are not marked. With ``votes > 0``: adds ``votes`` to ``through`` of every solid cell
    met before ``t_occ`` and marks nothing.
    """
    rows, cols = miss.shape
    t0, t1 = _clip_segment(sx, sy, tx, ty, cols, rows)
    if t0 > t1:
        return False
    dx = tx - sx
    dy = ty - sy
    cx = _cell(sx + dx * t0, cols)
    cy = _cell(sy + dy * t0, rows)
    ex = _cell(sx + dx * t1, cols)
    ey = _cell(sy + dy * t1, rows)
    end_c = _cell(tx, cols) if t1 >= 1.0 else -1
    end_r = _cell(ty, rows) if t1 >= 1.0 else -1
    nx = abs(ex - cx)
    ny = abs(ey - cy)
    stepx, tdx, tmx = _axis_step(dx, cx, sx)
    stepy, tdy, tmy = _axis_step(dy, cy, sy)
    t_enter = t0
    while True:
        if t_enter >= t_cut and t_enter >= t_occ:
            return False
        last = nx + ny == 0
        step_x = not last and nx > 0 and (ny == 0 or tmx < tmy)
        t_exit = t1 if last else (tmx if step_x else tmy)
        mark = votes == 0.0 and t_enter < t_cut
        if mark and z_clear < np.inf and math.isfinite(sz) and math.isfinite(tz):
            mark = max(sz + t_enter * (tz - sz), sz + t_exit * (tz - sz)) <= z_clear
        if t_enter > 0.0 and (flags[cy, cx] & (HIT | BLOCK)) != 0 and not (cy == end_r and cx == end_c):
            where = _sight(z_range, cy, cx, sz, tz, t_enter, min(t_exit, t_occ) if t_enter < t_occ else t_exit, z_tol)
            if where == 1 and t_enter < t_occ:
                if votes == 0.0:
                    return True
                through[cy, cx] += votes
            elif votes == 0.0 and where == 2 and shadow:
                t_cut = -1.0
                mark = False
        if mark:
            miss[cy, cx] = 1
        if last:
            return False
        if step_x:
            t_enter = tmx
            cx += stepx
            tmx += tdx
            nx -= 1
        else:
            t_enter = tmy
            cy += stepy
            tmy += tdy
            ny -= 1


@njit(nogil=True, cache=True)
def drop_seen_through(flags, ends, n_points, z_range, sx, sy, sz, gap_cells, z_tol, ratio, through, miss, dropped):
    """Un-hit the cells through which the floor is seen more than they are seen occupied.

    Each floor end votes its points into ``through`` of every hit cell its sight line meets more than
    ``gap_cells`` before it; a cell with ``through > ratio * n_points`` becomes a free end, flagged in
    ``dropped`` (a floating mismatch). Returns the count.
    """
    rows, cols = flags.shape
    for r in range(rows):
        for c in range(cols):
            if (flags[r, c] & FLOOR) == 0:
                continue
            tx = ends[r, c, 0]
            ty = ends[r, c, 1]
            length = math.hypot(tx - sx, ty - sy)
            if length <= gap_cells:
                continue
            _trace(sx, sy, sz, tx, ty, ends[r, c, 3], -1.0, 1.0 - gap_cells / length, flags, z_range, z_tol, False,
                   np.inf, through, n_points[r, c], miss)
    n = 0
    for r in range(rows):
        for c in range(cols):
            if (flags[r, c] & HIT) != 0 and through[r, c] > ratio * n_points[r, c]:
                flags[r, c] = (flags[r, c] & ~HIT) | END_FREE
                ends[r, c, 2] = 0.0
                dropped[r, c] = 1
                n += 1
    return n


@njit(nogil=True, cache=True)
def cast_rays(flags, ends, z_range, sx, sy, sz, occlusion_gap_cells, z_tol, shadow, z_clear, miss, occluded):
    """Trace one ray from the sensor to each flagged end cell's representative point ``ends[r, c, :2]``.

    An obstacle ray clears up to its margin ``ends[r, c, 2]`` short of its end, a free ray up to and
    including its end cell. With ``occlusion_gap_cells >= 0`` a ray whose sight line meets the points
    of a cell hit in this view more than ``margin + occlusion_gap_cells`` before its end stops there
    and its end is flagged ``occluded``. Returns the number of occluded ends.
    """
    rows, cols = flags.shape
    unused = np.zeros((1, 1))
    n = 0
    for r in range(rows):
        for c in range(cols):
            f = flags[r, c]
            if (f & (HIT | END_FREE)) == 0:
                continue
            tx = ends[r, c, 0]
            ty = ends[r, c, 1]
            length = math.hypot(tx - sx, ty - sy)
            if (f & HIT) != 0:
                t_cut = 1.0 - ends[r, c, 2] / length if length > 0.0 else 1.0
                gap = ends[r, c, 2] + occlusion_gap_cells
            else:
                t_cut = 2.0
                gap = occlusion_gap_cells
            t_occ = 1.0 - gap / length if occlusion_gap_cells >= 0.0 and length > 0.0 else -1.0
            if _trace(sx, sy, sz, tx, ty, ends[r, c, 3], t_cut, t_occ, flags, z_range, z_tol, shadow, z_clear, unused,
                      0.0, miss):
                occluded[r, c] = 1
                n += 1
    return n


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
def finite_bounds(points, bounds):
    """``bounds`` (4,) = ``(x_min, y_min, x_max, y_max)`` of the points with finite (x, y), in one pass; returns
    their number (0: ``bounds`` untouched)."""
    n = 0
    for i in range(points.shape[0]):
        x = np.float64(points[i, 0])
        y = np.float64(points[i, 1])
        if not (math.isfinite(x) and math.isfinite(y)):
            continue
        if n == 0:
            bounds[0] = x
            bounds[1] = y
            bounds[2] = x
            bounds[3] = y
        else:
            bounds[0] = min(bounds[0], x)
            bounds[1] = min(bounds[1], y)
            bounds[2] = max(bounds[2], x)
            bounds[3] = max(bounds[3], y)
        n += 1
    return n


@njit(nogil=True, cache=True)
def segment_free(blocked, r0, c0, r1, c1):
    """True when no cell the straight segment between the centres of cells (r0, c0) and (r1, c1) passes
    through is blocked (Amanatides-Woo traversal; where it crosses a cell corner exactly, both cells
    beside the corner must be free, as A*'s no-corner-cutting rule)."""
    nr = abs(r1 - r0)
    nc = abs(c1 - c0)
    sr = 1 if r1 > r0 else -1
    sc = 1 if c1 > c0 else -1
    r = r0
    c = c0
    ir = 0
    ic = 0
    if blocked[r, c]:
        return False
    while ir < nr or ic < nc:
        a = (1 + 2 * ir) * nc          # compare the next row and column crossings, (ir + 1/2)/nr vs (ic + 1/2)/nc
        b = (1 + 2 * ic) * nr
        if a == b:
            if blocked[r + sr, c] or blocked[r, c + sc]:
                return False
            r += sr
            c += sc
            ir += 1
            ic += 1
        elif a < b:
            r += sr
            ir += 1
        else:
            c += sc
            ic += 1
        if blocked[r, c]:
            return False
    return True


@njit(nogil=True, cache=True)
def shortcut_path(blocked, rows, cols, keep):
    """Line-of-sight shortcuts of a cell path (``rows``, ``cols``, int64): from each kept cell, the farthest
    cell of the path reached by a free straight segment before the first blocked one is kept next
    (``keep``, uint8, zeroed, filled with 1 for the kept cells; the first and last are always kept)."""
    n = len(rows)
    keep[0] = 1
    keep[n - 1] = 1
    i = 0
    while i < n - 1:
        j = i + 1
        while j + 1 < n and segment_free(blocked, rows[i], cols[i], rows[j + 1], cols[j + 1]):
            j += 1
        keep[j] = 1
        i = j


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
        col = np.floor((np.float64(points[i, 0]) - origin_x) / resolution)
        row = np.floor((np.float64(points[i, 1]) - origin_y) / resolution)
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


@njit(nogil=True, cache=True, inline="always")
def _cell_at(x, y, origin_x, origin_y, resolution, rows, cols):
    """Flat cell of the point ``(x, y)`` (``floor((x - origin) / resolution)`` as ``GridSpec.cells_from_xy``), -1
    outside the grid."""
    c = math.floor((x - origin_x) / resolution)
    r = math.floor((y - origin_y) / resolution)
    if 0 <= r < rows and 0 <= c < cols:
        return int(r) * cols + int(c)
    return -1


@njit(nogil=True, cache=True, inline="always")
def _flat_cell(points, i, origin_x, origin_y, resolution, rows, cols):
    """Flat cell of point i (``floor((x - origin) / resolution)`` as ``GridSpec.cells_from_xy``), -1 when a
    coordinate is not finite or the cell lies outside the grid."""
    x = np.float64(points[i, 0])
    y = np.float64(points[i, 1])
    z = np.float64(points[i, 2])
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        return -1
    return _cell_at(x, y, origin_x, origin_y, resolution, rows, cols)


@njit(nogil=True, cache=True)
def layer_points(points, slot, origin_x, origin_y, resolution, rows, cols, heights, counts, stamp, view, votes,
                 clear_points, floor_views=False):
    """One view's points (N, 3) into the height and drop layers, in one pass: each finite point inside the grid
    widens its cell's lowest and highest height (``heights`` (rows*cols, 2) float32, NaN: none yet); with ``slot``
    0 (floor points), 1 (drop points) or 2 (weak drop points: they count, but widen no height) it counts in
    ``counts[cell, slot]`` (int32 scratch: a cell whose ``stamp`` is not ``view`` starts from zero, so no pass
    clears it). A cell reaching ``clear_points`` floor points loses a vote (``votes[cell, 0]``, down to 0) when
    this view gave it none (``counts[cell, 1]`` >= 0; the drop points come first), and a weak vote
    (``votes[cell, 1]``) when this view gave it no weak vote (``counts[cell, 2]`` >= 0). With ``floor_views``,
    a cell's first floor point of a view that gave it no vote of either kind counts the view in
    ``votes[cell, 3]`` (:func:`drop_votes` counts the weak ones in ``votes[cell, 2]``). Returns the points
    inside."""
    n = 0
    for i in range(points.shape[0]):
        k = _flat_cell(points, i, origin_x, origin_y, resolution, rows, cols)
        if k < 0:
            continue
        n += 1
        if slot < 2:
            z = np.float32(points[i, 2])
            if not heights[k, 0] <= z:          # (NaN: the first point)
                heights[k, 0] = z
            if not heights[k, 1] >= z:
                heights[k, 1] = z
        if slot < 0:
            continue
        if stamp[k] != view:
            stamp[k] = view
            counts[k, 0] = 0
            counts[k, 1] = 0
            counts[k, 2] = 0
        counts[k, slot] += 1
        if slot == 0 and floor_views and counts[k, 0] == 1 and counts[k, 1] >= 0 and counts[k, 2] >= 0:
            _count_view(votes, k, 3)
        if slot == 0 and counts[k, 0] == clear_points:
            for v in range(2):
                if counts[k, v + 1] >= 0 and votes[k, v] > 0:
                    votes[k, v] -= 1
    return n


@njit(nogil=True, cache=True)
def drop_votes(drops, slot, origin_x, origin_y, resolution, rows, cols, counts, votes, min_points, max_votes):
    """The votes for drops of one view, after :func:`layer_points` counted its drop points (``slot`` 1) or weak
    drop points (2): a cell with at least ``min_points`` of them gains a vote (``votes[cell, slot - 1]``, up to
    ``max_votes``; a weak one is counted in ``votes[cell, 2]`` too, without that cap) and its count becomes -1
    (voted: once per view, and the view's floor points do not vote against it). Returns the number of cells
    that got a vote."""
    n = 0
    for i in range(drops.shape[0]):
        k = _flat_cell(drops, i, origin_x, origin_y, resolution, rows, cols)
        if k >= 0 and counts[k, slot] >= min_points:
            votes[k, slot - 1] = min(votes[k, slot - 1] + 1, max_votes)
            if slot == 2:
                _count_view(votes, k, 2)
            counts[k, slot] = -1
            n += 1
    return n


@njit(nogil=True, cache=True, inline="always")
def _count_view(votes, k, column):
    """One more view in ``votes[k, column]`` (2: weak votes, 3: floor views); at int16's top both counts halve,
    keeping their ratio (:func:`mrstereo.mapping.occupancy._voted`)."""
    if votes[k, column] >= 32767:
        votes[k, 2] //= 2
        votes[k, 3] //= 2
    votes[k, column] += 1


@njit(nogil=True, cache=True)
def confirm_drops(candidates, origin_x, origin_y, resolution, rows, cols, heights, votes, floor_tol, max_walk_m, out):
    """The drop test's candidates (K, 11) (``mrstereo.geometry.drops.CANDIDATE_COLUMNS``) that the height layer
    ``heights`` (rows*cols, 2: lowest, highest; the views before this one) confirms, as drop points in ``out``.

    A candidate's sight line passes floor level at ``E``. It is confirmed when, walking back from ``E``
    toward the camera (half a cell a step, at most ``max_walk_m``), a cell whose lowest point lies at floor
    level (within ``floor_tol``) lies above ``c0 + tan_slope d`` (``d``: from the run's point ``q``): the
    floor was measured there and no drivable slope from it reaches ``q``. It is not when a floor-level cell
    that is no drop cell (``votes[:, 0]``; a drop edge lies at floor level too) lies between ``hide_from_m`` (at
    least a cell) and ``hide_to_m`` (less a cell) beyond ``E``: its sight line would pass under measured
    floor (a mismatch). A confirmed candidate puts its edge ``S -> E`` at floor level (a point every fifth
    of a cell) and ``q`` at its height into ``out``. Returns the number of points written."""
    n = 0
    step = 0.5 * resolution
    spacing = 0.2 * resolution
    for i in range(candidates.shape[0]):
        sx, sy, ex, ey = candidates[i, 0], candidates[i, 1], candidates[i, 2], candidates[i, 3]
        qx, qy, qz, c0, tan = candidates[i, 4], candidates[i, 5], candidates[i, 6], candidates[i, 7], candidates[i, 8]
        dq = math.sqrt((qx - ex) ** 2 + (qy - ey) ** 2)
        if not dq > 0.0:
            continue
        vx, vy = (qx - ex) / dq, (qy - ey) / dq           # along the sight line, away from the camera
        seen = False
        s = max(resolution, candidates[i, 9])
        while s < candidates[i, 10] - resolution and not seen:
            k = _cell_at(ex + vx * s, ey + vy * s, origin_x, origin_y, resolution, rows, cols)
            seen = k >= 0 and abs(heights[k, 0]) <= floor_tol and votes[k, 0] == 0
            s += step
        if seen:
            continue
        confirmed = False
        s = 0.0
        while s <= max_walk_m:
            x, y = ex - vx * s, ey - vy * s
            level = c0 + tan * (dq + s)
            if level >= floor_tol:
                break
            k = _cell_at(x, y, origin_x, origin_y, resolution, rows, cols)
            if k >= 0 and abs(heights[k, 0]) <= floor_tol and heights[k, 0] > level:
                confirmed = True
                break
            s += step
        if not confirmed:
            continue
        length = math.sqrt((ex - sx) ** 2 + (ey - sy) ** 2)
        m = int(length / spacing) + 1
        for t in range(m + 1):
            f = 1.0 if length <= 0.0 else min(1.0, t * spacing / length)
            if n < out.shape[0]:
                out[n, 0] = sx + f * (ex - sx)
                out[n, 1] = sy + f * (ey - sy)
                out[n, 2] = 0.0
                n += 1
        if n < out.shape[0]:
            out[n, 0] = qx
            out[n, 1] = qy
            out[n, 2] = qz
            n += 1
    return n
