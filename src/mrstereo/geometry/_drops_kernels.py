"""Numba kernel of the drop test (:mod:`mrstereo.geometry.drops`): one pass up each image column, one along
the rows beside the drops found.

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
def _untextured(untextured, i, j):
    """Is pixel ``(i, j)`` without texture along the rows (``untextured[i, j]``; an empty ``untextured``: none is)?
    Its point is floor where it lies at floor level, and never below the floor: no evidence of a drop."""
    return untextured.shape[0] > 0 and untextured[i, j]


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


@njit(nogil=True, cache=True, inline="always")
def _depth(points, i, j, tx, ty, tz, axis):
    """Depth of point ``(i, j)`` along the optical axis ``axis`` (robot frame) from the camera ``(tx, ty, tz)``."""
    return (points[i, j, 0] - tx) * axis[0] + (points[i, j, 1] - ty) * axis[1] + (points[i, j, 2] - tz) * axis[2]


@njit(nogil=True, cache=True, inline="always")
def _unmatchable(points, p, j, tx, ty, tz, axis, bf, doffs_px):
    """Would the floor on the sight line of point ``(p, j)`` (below floor level) have its match outside the right
    image (``j - d_floor < 0``, ``d_floor = b f / Z_floor - doffs``; ``axis``: the optical axis in the robot
    frame; a point behind the camera, which no pixel sees, is not)? Then no matcher could have found the floor
    there, and the point may be a floor pixel matched wrongly, too far: the image's left border, which the
    matcher searches anyway (OpenCV leaves it invalid)."""
    z = points[p, j, 2]
    depth = _depth(points, p, j, tx, ty, tz, axis)
    return depth > 0.0 and (j + doffs_px) * tz * depth < bf * (tz - z)


@njit(nogil=True, cache=True)
def _steep(points, rows, j, k0, k1, max_step_m, tan_slope, noise_m):
    """Does the run ``rows[k0:k1]`` of column ``j`` start with a face steeper than the slope limit over a
    step (the far wall of a pit, a stair riser; later in the run a wall rising from the lower floor that the
    rim before the run hid)?"""
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


@njit(nogil=True, cache=True, inline="always")
def _range(points, p, j, tx, ty):
    """Horizontal distance of point ``(p, j)`` from the camera."""
    return math.sqrt((points[p, j, 0] - tx) ** 2 + (points[p, j, 1] - ty) ** 2)


@njit(nogil=True, cache=True, inline="always")
def _floor_level(points, p, j, tx, ty, tz, max_step_m, sigma_per_m2, n_sigma, low_m):
    """Is point ``(p, j)`` at floor level (within a step and its noise below, under ``low_m`` above)?"""
    z = points[p, j, 2]
    return -(max_step_m + n_sigma * _sigma_h(points[p, j, 0], points[p, j, 1], z, tx, ty, tz, sigma_per_m2)) < z < low_m


@njit(nogil=True, cache=True)
def _flat_after(points, rows, j, k, m, tx, ty, tz, max_step_m, sigma_per_m2, n_sigma, low_m, reach_m):
    """Does floor follow from ``rows[k]`` on: floor-level points spreading over more than ``reach_m`` plus
    their depth noise horizontally (a far rim; not a wall rising through floor level)?"""
    if k >= m:
        return False
    r0 = _range(points, rows[k], j, tx, ty)
    noise = n_sigma * sigma_per_m2 * r0 * r0
    q = k
    while q < m and _floor_level(points, rows[q], j, tx, ty, tz, max_step_m, sigma_per_m2, n_sigma, low_m):
        if abs(_range(points, rows[q], j, tx, ty) - r0) > reach_m + noise:
            return True
        q += 1
    return False


@njit(nogil=True, cache=True)
def _seen_through(points, rows, j, k0, k1, m, r_cross, r_low, tx, ty, tz, max_step_m, sigma_per_m2, n_sigma,
                  low_m, support):
    """Is the sight line of a run below the floor contradicted: do at least ``support`` floor-level points
    of the column (other than the run ``rows[k0:k1]``) lie beyond where it passes floor level (``r_cross``)
    and before its point (``r_low``), by more than their depth noise? Its ray would pass under that floor:
    the run is a mismatch (a floor seen too far; the true floor follows it near where the sight line of its
    last point passes floor level), not a drop. The points right after the run nearer its last point than
    half way to that crossing are a face rising from it (a far wall through floor level, at the run's
    range), no floor in between."""
    pl = rows[k1 - 1]
    r_last = _range(points, pl, j, tx, ty)
    r_face = 0.5 * r_last * (1.0 + tz / (tz - points[pl, j, 2]))
    face = True
    n = 0
    for q in range(m):
        if k0 <= q < k1:
            continue
        p = rows[q]
        if face and q >= k1:
            if _range(points, p, j, tx, ty) > r_face:
                continue
            face = False
        if not _floor_level(points, p, j, tx, ty, tz, max_step_m, sigma_per_m2, n_sigma, low_m):
            continue
        r = _range(points, p, j, tx, ty)
        margin = n_sigma * sigma_per_m2 * r * r
        if r_cross + margin < r < r_low - margin:
            n += 1
            if n >= support:
                return True
    return False


@njit(nogil=True, cache=True)
def _column(points, untextured, rows, m, j, tx, ty, tz, max_step_m, tan_slope, sigma_per_m2, n_sigma, low_m,
            support, edge_reach_m, spacing_m, robot_floor, out_edge, n_edge, out_below, n_below, out_candidates, n_cand,
            edge_columns, dropped, dropped_rows):
    """The drop test of column ``j`` (its measured rows ``rows[:m]``, from the image's bottom up) with the margin
    ``n_sigma`` (:func:`column_drops`); appends to the outputs from the counts given, returns the new counts;
    ``dropped[i, j]`` set for the pixels of its drops' runs, ``dropped_rows[i]`` for their rows."""
    xa, ya, za, sa = tx, ty, 0.0, 0.0
    seen_floor = False
    in_drop = False
    k = 0
    while k < m:
        p = rows[k]
        xp, yp, zp = points[p, j, 0], points[p, j, 1], points[p, j, 2]
        sp = n_sigma * _sigma_h(xp, yp, zp, tx, ty, tz, sigma_per_m2)
        if -(max_step_m + sp) < zp < low_m:
            if in_drop and _flat_after(points, rows, j, k, m, tx, ty, tz, max_step_m, sigma_per_m2, n_sigma,
                                       low_m, edge_reach_m):       # back on the floor after a drop: its far rim
                n_edge = _emit(out_edge, n_edge, xp, yp)
                in_drop = False
            xa, ya, za, sa = xp, yp, zp, sp
            seen_floor = True
            k += 1
            continue
        if zp >= low_m or _untextured(untextured, p, j) or not _below(points, p, j, tx, ty, tz, max_step_m,
                                                                         sigma_per_m2, n_sigma):
            k += 1
            continue
        s = tz / (tz - zp)                       # the sight line to the run's first point at floor level
        ex, ey = tx + s * (xp - tx), ty + s * (yp - ty)
        r_low = math.sqrt((xp - tx) ** 2 + (yp - ty) ** 2)
        end = k                                  # the run of points below the floor
        deepest = 0.0                            # below a drivable slope from A
        deepest_e = 0.0                          # below a drivable slope from E
        q_best = p
        while end < m and not _untextured(untextured, rows[end], j) and _below(points, rows[end], j, tx, ty, tz,
                                                                                max_step_m, sigma_per_m2, n_sigma):
            q = rows[end]
            xq, yq, zq = points[q, j, 0], points[q, j, 1], points[q, j, 2]
            sq = n_sigma * _sigma_h(xq, yq, zq, tx, ty, tz, sigma_per_m2)
            d = math.sqrt((xq - xa) ** 2 + (yq - ya) ** 2)
            deepest = max(deepest, za - zq - math.sqrt(sa * sa + sq * sq) - tan_slope * d)
            below_e = -zq - sq - tan_slope * math.sqrt((xq - ex) ** 2 + (yq - ey) ** 2)
            if below_e > deepest_e:
                deepest_e = below_e
                q_best = q
            end += 1
        # a steep face counts when floor follows it, spreading on (a hole's far wall up to its far rim, a
        # stair riser); in a column without floor before it, a face reaching floor level (a wall rising
        # from a lower floor) whose foot no drivable slope from E reaches; in both only when the run starts
        # more than a step below A (the rim hid what lies between: a run entered within a step went down
        # a drivable slope, a face rising from it is a step up). Without floor measured in the column
        # before the run and without ``robot_floor``, the map decides (a candidate)
        judged = seen_floor or robot_floor
        drop = judged and deepest > max_step_m
        if judged and not drop and end - k >= support and za - zp > max_step_m:
            drop = ((not seen_floor and deepest_e > max_step_m and end < m and points[rows[end], j, 2] < low_m)
                    or _flat_after(points, rows, j, end, m, tx, ty, tz, max_step_m, sigma_per_m2, n_sigma,
                                   low_m, edge_reach_m)) and _steep(points, rows, j, k, end, max_step_m,
                                                                    tan_slope, sp)
        # and its sight line does not pass under floor measured in the column (a mismatch: floor matched
        # too far lies below the floor, and the floor goes on right after it)
        if end - k < support or _seen_through(points, rows, j, k, end, m, s * r_low, r_low, tx, ty, tz,
                                              max_step_m, sigma_per_m2, n_sigma, low_m, support):
            k = max(end, k + 1)
            continue
        length = math.sqrt((ex - xa) ** 2 + (ey - ya) ** 2)
        if not drop:                             # a candidate for the map: floor it saw before E may confirm it
            if deepest_e > max_step_m and n_cand < out_candidates.shape[0]:
                f = 0.0 if length <= 0.0 else max(0.0, 1.0 - edge_reach_m / length)
                xb, yb, zb = points[q_best, j, 0], points[q_best, j, 1], points[q_best, j, 2]
                row = out_candidates[n_cand]
                row[0], row[1], row[2], row[3] = xa + f * (ex - xa), ya + f * (ey - ya), ex, ey
                row[4], row[5], row[6] = xb, yb, zb
                row[7] = zb + n_sigma * _sigma_h(xb, yb, zb, tx, ty, tz, sigma_per_m2) + max_step_m
                row[8] = tan_slope
                margin = n_sigma * sigma_per_m2 * r_low * r_low       # the first point's depth noise
                row[9] = margin
                row[10] = math.sqrt((xp - ex) ** 2 + (yp - ey) ** 2) - margin
                n_cand += 1
        else:
            start = max(0.0, length - edge_reach_m)
            n_steps = int((length - start) / spacing_m) + 1
            for q in range(n_steps + 1):
                f = 1.0 if length <= 0.0 else min(1.0, (start + q * spacing_m) / length)
                n_edge = _emit(out_edge, n_edge, xa + f * (ex - xa), ya + f * (ey - ya))
            for q in range(k, end):
                r = rows[q]
                dropped[r, j] = True
                dropped_rows[r] = True
                if n_below < out_below.shape[0]:
                    out_below[n_below, 0] = points[r, j, 0]
                    out_below[n_below, 1] = points[r, j, 1]
                    out_below[n_below, 2] = points[r, j, 2]
                    n_below += 1
            edge_columns[j] += 1
            in_drop = True
        k = max(end, k + 1)
    return n_edge, n_below, n_cand


@njit(nogil=True, cache=True, inline="always")
def _disparity(points, i, j, tx, ty, tz, axis, bf, doffs_px):
    """The disparity of point ``(i, j)`` (``b f / Z - doffs``, ``Z`` its depth along the optical axis ``axis``)."""
    return bf / _depth(points, i, j, tx, ty, tz, axis) - doffs_px


@njit(nogil=True, cache=True)
def _sides(points, dropped, dropped_rows, tx, ty, tz, axis, bf, doffs_px, max_step_m, tan_slope, sigma_per_m2,
           n_sigma, low_m, fattening_px, edge_reach_m, out_edge, n_edge):
    """The side edges of the drops found up the columns (a hole's or a stairwell's side seen along it, which no
    column crosses). Along each image row, where a drop's run (``dropped``) meets a floor-level point ``A``
    within ``fattening_px`` pixels (unmeasured ones between; on the run's right, where the right camera does not
    see the run's pixels next to the floor, that many more as the disparities of ``A`` and the run's end differ)
    and lies deeper than a step, both points' noise and a drivable slope below ``A``, the floor-level points from
    ``A`` on into the floor, over ``fattening_px`` pixels and ``edge_reach_m``, are edge points: the matcher's
    window carries the floor's disparity past the true edge onto the drop's side, and the floor's disparity is
    the same along a row, so those pixels triangulate onto the floor; the true edge lies among them. Returns the
    new count of ``out_edge``."""
    H, W = dropped.shape
    for i in range(H):
        if not dropped_rows[i]:
            continue
        j = 0
        while j < W:
            if not dropped[i, j]:
                j += 1
                continue
            j1 = j
            while j1 + 1 < W and dropped[i, j1 + 1]:
                j1 += 1
            for side in (-1, 1):
                q = j if side < 0 else j1
                a = q + side
                while 0 <= a < W and math.isnan(points[i, a, 2]):
                    a += side
                if not (0 <= a < W and _floor_level(points, i, a, tx, ty, tz, max_step_m, sigma_per_m2, n_sigma,
                                                    low_m)):
                    continue
                occluded = 0.0 if side < 0 else max(0.0, _disparity(points, i, a, tx, ty, tz, axis, bf, doffs_px)
                                                    - _disparity(points, i, q, tx, ty, tz, axis, bf, doffs_px))
                if abs(a - q) > fattening_px + occluded:
                    continue
                xa, ya, za = points[i, a, 0], points[i, a, 1], points[i, a, 2]
                xq, yq, zq = points[i, q, 0], points[i, q, 1], points[i, q, 2]
                sa = n_sigma * _sigma_h(xa, ya, za, tx, ty, tz, sigma_per_m2)
                sq = n_sigma * _sigma_h(xq, yq, zq, tx, ty, tz, sigma_per_m2)
                if za - zq - math.sqrt(sa * sa + sq * sq) - tan_slope * math.sqrt((xq - xa) ** 2 + (yq - ya) ** 2) \
                        <= max_step_m:
                    continue
                b = a
                while 0 <= b < W and abs(b - a) <= fattening_px:
                    if not math.isnan(points[i, b, 2]):
                        if not (_floor_level(points, i, b, tx, ty, tz, max_step_m, sigma_per_m2, n_sigma, low_m)
                                and math.sqrt((points[i, b, 0] - xa) ** 2 + (points[i, b, 1] - ya) ** 2)
                                <= edge_reach_m):
                            break
                        n_edge = _emit(out_edge, n_edge, points[i, b, 0], points[i, b, 1])
                    b += side
            j = j1 + 1
    return n_edge


@njit(nogil=True, cache=True)
def column_drops(points, untextured, t, axis, bf, doffs_px, max_step_m, tan_slope, sigma_per_m2, n_sigma, weak_n_sigma,
                 low_m, support, edge_reach_m, spacing_m, robot_floor, fattening_px, out_edge, out_below,
                 out_candidates, edge_columns, weak_edge, weak_below, weak_columns):
    """Drop edges and negative obstacles of a robot-frame point image ``points`` (H, W, 3), NaN invalid; the
    points of the pixels set in ``untextured`` (H, W; or empty: none) are floor at floor level and never below it.

    Up each column (from the image's bottom) a run of at least ``support`` measured points below the floor
    (``z < -(max_step + n_sigma sigma_h)``) is a drop when no drivable surface reaches it: it lies deeper than
    a step plus a slope of ``tan_slope`` below the last floor-level point ``A`` before it (``-thr < z <
    low_m``; none measured and ``robot_floor``: the floor under the camera, where the robot stands), or it
    starts with a face steeper than that slope over a step and floor follows it, spreading on over
    ``edge_reach_m`` (a hole's far wall, a stair riser; in a column without floor before the run, with
    ``robot_floor``, a face reaching floor level whose foot lies deeper than a step plus that slope from
    ``E``; either face only when the run starts more than a step below ``A``). Its sight
    line passes floor level at ``E``: no ``support`` floor-level points of the column may lie between ``E``
    and the run's first point beyond their depth noise (that floor would hide it: a mismatch; a far wall
    rising from the run right after it, at its range, is no such floor). Points every
    ``spacing_m`` over the last ``edge_reach_m`` of ``A -> E`` go to ``out_edge``, the run's points to
    ``out_below``. Floor spreading on after a drop marks its first point (a far rim).

    A run that is no mismatch but no drop either (the floor measured too far before it, or none measured in
    its column -- the floor at the near end of the view unmatched, or a floor that gives no disparity: a
    ramp could start out of view) and lies more than a step below a drivable slope from ``E``
    is a *candidate* for the map to confirm with the floor it measured before
    (:func:`mrstereo.mapping._kernels.confirm_drops`): a row of ``out_candidates``
    ``(sx, sy, ex, ey, qx, qy, qz, c0, tan_slope, hide_from_m, hide_to_m)``, the edge's start ``S``
    (``edge_reach_m`` before ``E``), ``E``, the run's point ``q`` deepest below a drivable slope from ``E`` at
    its measured height, ``c0 = z_q + n_sigma sigma_h(q) + max_step`` (floor at height ``z_a`` a horizontal
    ``d`` from ``q`` with ``z_a > c0 + tan_slope d`` confirms the drop) and the stretch beyond ``E`` (to the
    run's first point, less its depth noise at both ends) where measured floor would hide the run (a
    mismatch). ``t``: the camera in the robot frame.

    A point more than a step below floor level counts as unmeasured where the floor on its sight line would
    have its match outside the right image (:func:`_unmatchable`; ``axis``: the optical axis in the robot
    frame, ``bf``: ``b f``, ``doffs_px``: the rig's disparity offset): no matcher can have found the floor there.

    ``fattening_px`` > 0: then along each image row the sides of the drops found (:func:`_sides`) into
    ``out_edge`` (and the weak drops' into ``weak_edge``).

    ``weak_n_sigma`` >= 0 (negative: off): each column (its measured rows gathered once) is also tested with that
    looser margin, the same rules (:func:`_column`), its drops' points into ``weak_edge`` / ``weak_below`` and
    their count into ``weak_columns`` (no candidates): the map's weak votes. A column with no point below the
    floor by the looser margin of the two is skipped (no run can start in it). Returns the counts of
    ``out_edge``, ``out_below``, ``out_candidates``, ``weak_edge`` and ``weak_below``; ``edge_columns[j]``
    counts column j's drops.
    """
    H, W = points.shape[0], points.shape[1]
    tx, ty, tz = t[0], t[1], t[2]
    # counts typed int64 from the start: a literal 0 would compile _column once more for it
    n_edge = n_below = n_cand = n_weak_edge = n_weak_below = none = np.int64(0)
    no_candidates = out_candidates[:0]
    weak = weak_n_sigma >= 0.0
    gate = min(n_sigma, weak_n_sigma) if weak else n_sigma
    # low[j]: column j has a point below the floor by the looser margin (else no run, no drop in it), found
    # in one pass along the image's rows (memory order; NaN compares false); only those columns are walked
    low = np.zeros(W, np.bool_)
    for i in range(H):
        for j in range(W):
            if points[i, j, 2] < -max_step_m and not low[j] and not _untextured(untextured, i, j):
                low[j] = (_below(points, i, j, tx, ty, tz, max_step_m, sigma_per_m2, gate)
                          and not _unmatchable(points, i, j, tx, ty, tz, axis, bf, doffs_px))
    rows = np.empty(H, np.int64)
    dropped, dropped_rows = np.zeros((H, W), np.bool_), np.zeros(H, np.bool_)
    weak_dropped, weak_rows = np.zeros((H, W), np.bool_), np.zeros(H, np.bool_)
    for j in range(W):
        if not low[j]:
            continue
        m = np.int64(0)
        for i in range(H - 1, -1, -1):          # the column's measured rows from the bottom up
            z = points[i, j, 2]
            if not math.isnan(z) and not (z < -max_step_m and _unmatchable(points, i, j, tx, ty, tz, axis, bf,
                                                                          doffs_px)):
                rows[m] = i
                m += 1
        n_edge, n_below, n_cand = _column(points, untextured, rows, m, j, tx, ty, tz, max_step_m, tan_slope,
                                          sigma_per_m2, n_sigma, low_m, support, edge_reach_m, spacing_m, robot_floor,
                                          out_edge, n_edge, out_below, n_below, out_candidates, n_cand, edge_columns,
                                          dropped, dropped_rows)
        if weak:
            n_weak_edge, n_weak_below, _ = _column(points, untextured, rows, m, j, tx, ty, tz, max_step_m, tan_slope,
                                                   sigma_per_m2, weak_n_sigma, low_m, support, edge_reach_m,
                                                   spacing_m, robot_floor, weak_edge, n_weak_edge, weak_below,
                                                   n_weak_below, no_candidates, none, weak_columns, weak_dropped,
                                                   weak_rows)
    if fattening_px > 0:
        n_edge = _sides(points, dropped, dropped_rows, tx, ty, tz, axis, bf, doffs_px, max_step_m, tan_slope,
                        sigma_per_m2, n_sigma, low_m, fattening_px, edge_reach_m, out_edge, n_edge)
        if weak:
            n_weak_edge = _sides(points, weak_dropped, weak_rows, tx, ty, tz, axis, bf, doffs_px, max_step_m,
                                 tan_slope, sigma_per_m2, weak_n_sigma, low_m, fattening_px, edge_reach_m, weak_edge,
                                 n_weak_edge)
    return n_edge, n_below, n_cand, n_weak_edge, n_weak_below


@njit(nogil=True, cache=True)
def floor_crossings(points, tx, ty, tz, max_step_m, tan_slope, sigma_per_m2, n_sigma, out):
    """Where the sight lines from the camera ``(tx, ty, tz)`` to points below the floor (N, 3) pass floor level,
    into ``out`` (N, 3; z = 0), for the points deeper than a step, their noise (``n_sigma`` sigma_h) and a
    drivable slope (``tan_slope``) from there. Returns the number written."""
    n = 0
    for i in range(points.shape[0]):
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        s = tz / (tz - z)
        ex, ey = tx + s * (x - tx), ty + s * (y - ty)
        run = math.sqrt((x - ex) ** 2 + (y - ey) ** 2)
        if -z - n_sigma * _sigma_h(x, y, z, tx, ty, tz, sigma_per_m2) - tan_slope * run > max_step_m:
            n = _emit(out, n, ex, ey)
    return n


@njit(nogil=True, cache=True)
def floor_residuals(points, untextured, tx, ty, tz, axis, bf, top_m, reach_m, max_px, out):
    """The floor's disparity residuals (pixels) at every other row and column: a point at height ``z`` and depth
    ``Z`` was measured at ``d + doffs = b f / Z`` (eq. 14), and the floor on its sight line, which passes floor
    level ``t_z / (t_z - z)`` times as far, at ``(d + doffs)(t_z - z) / t_z``; their difference is
    ``r = b f z / (t_z Z)``. Into ``out`` for the points within ``top_m`` of floor level and ``reach_m`` of the
    camera (horizontally) whose ``|r| < max_px``, but the pixels set in ``untextured`` (or empty: none). Returns the
    number written."""
    n = 0
    for i in range(0, points.shape[0], 2):
        for j in range(0, points.shape[1], 2):
            z = points[i, j, 2]
            if (not abs(z) < top_m or _untextured(untextured, i, j) or _range(points, i, j, tx, ty) > reach_m
                    or n >= out.shape[0]):
                continue
            depth = _depth(points, i, j, tx, ty, tz, axis)
            if depth > 0.0:
                r = bf * z / (tz * depth)
                if abs(r) < max_px:
                    out[n] = r
                    n += 1
    return n
