"""Free-space boundary: where the floor ends in each image column (beyond the paper).

A wall without texture has no disparity, nor has its face-on edge with the floor; the floor can
be followed instead, up each column of the rectified left image to where something that is not
floor begins (the free space of the stixel world, Badino et al. 2009). That base becomes
obstacle points on the vertical line over it, which the occupancy grid treats like a measured
surface. The rules (one :class:`FreeSpaceConfig` field each, applied by the numba kernel
``_freespace_kernels.column_boundaries``): docs/mapping.md, "Free-space boundary". Sizes are for
a 320x240 image; a larger one is first reduced by an integer factor (:func:`_reduced`).
Conventions: docs/conventions.md.

References
----------
H. Badino, U. Franke, D. Pfeiffer, "The Stixel World -- A Compact Medium Level Representation
of the 3D-World", DAGM 2009.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np

from .. import _checks
from ..camera import StereoCamera
from . import _freespace_kernels as _kernels
from .obstacles import (MAPPING_MAX_RANGE_M, ObstacleConfig, ObstacleResult, _disparity_image, _rectified_intrinsics,
                        _rigid)

__all__ = ["FreeSpaceConfig", "FreeSpaceBoundary", "free_space_boundary"]


@dataclass(frozen=True)
class FreeSpaceConfig:
    """Options of :func:`free_space_boundary`; each rule: docs/mapping.md, "Free-space boundary".

    Gray levels on the 0-255 scale, rows and columns at 320x240: the boundary's gray step
    (``edge_threshold``) and change of floor appearance (``appearance_threshold``) over
    ``edge_rows`` / ``persist_rows``, the check for floor or farther points above it
    (``check_rows``, ``far_margin_m``, ``gap_rows``), runs of ``min_run_columns`` columns with steps
    of at most ``max_row_step``, the floor's appearance model (``adapt``, ``min_floor_pixels``,
    ``pattern_threshold``), unmeasured texture (``texture_threshold``), smoothing
    (``smooth_sigma_px``), the floor ranges of a boundary (``min_range_m``, ``max_range_m``; None:
    the obstacle config's) and the spacing of the returned points (``point_spacing_m``).
    """

    edge_threshold: float = 6.0
    appearance_threshold: float = 6.0
    edge_rows: int = 2
    persist_rows: int = 6
    check_rows: int = 12
    min_run_columns: int = 5
    max_row_step: int = 2
    adapt: float = 0.1
    smooth_sigma_px: float = 1.0
    far_margin_m: float = 0.3
    min_range_m: float = 0.0
    max_range_m: float | None = None
    point_spacing_m: float = 0.1
    gap_rows: int = 3
    texture_threshold: float = 4.0
    min_floor_pixels: int = 50
    pattern_threshold: float = 12.0

    def __post_init__(self) -> None:
        _checks.finite_number("edge_threshold", self.edge_threshold, positive=True)
        _checks.finite_number("appearance_threshold", self.appearance_threshold, positive=True)
        _checks.positive_int("edge_rows", self.edge_rows)
        _checks.positive_int("persist_rows", self.persist_rows, minimum=2)
        _checks.positive_int("check_rows", self.check_rows)
        if self.check_rows < self.persist_rows:
            raise ValueError(f"check_rows ({self.check_rows}) must be at least persist_rows ({self.persist_rows})")
        _checks.positive_int("min_run_columns", self.min_run_columns)
        _checks.positive_int("max_row_step", self.max_row_step)
        a = _checks.finite_number("adapt", self.adapt, positive=True)
        if a > 1.0:
            raise ValueError(f"adapt must be in (0, 1], got {a}")
        _checks.finite_number("smooth_sigma_px", self.smooth_sigma_px, nonnegative=True)
        _checks.finite_number("far_margin_m", self.far_margin_m, nonnegative=True)
        _checks.finite_number("min_range_m", self.min_range_m, nonnegative=True)
        if self.max_range_m is not None:
            _checks.finite_number("max_range_m", self.max_range_m, positive=True)
        _checks.finite_number("point_spacing_m", self.point_spacing_m, positive=True)
        _checks.positive_int("gap_rows", self.gap_rows)
        _checks.finite_number("texture_threshold", self.texture_threshold, positive=True)
        _checks.positive_int("min_floor_pixels", self.min_floor_pixels)
        _checks.finite_number("pattern_threshold", self.pattern_threshold, positive=True)


@dataclass(frozen=True)
class FreeSpaceBoundary:
    """Output of :func:`free_space_boundary`.

    ``base_row`` (W,): per column the row of the obstacle base (the edge between two rows, ``v -
    0.5``), NaN without a kept boundary; ``top_row`` the highest row of its evidence;
    ``base_points_robot`` (K, 3) the floor point of each kept column's base and ``columns`` (K,) its
    column; ``points_robot`` (N, 3) the obstacle points over the bases (robot frame).
    """

    base_row: np.ndarray
    top_row: np.ndarray
    base_points_robot: np.ndarray
    points_robot: np.ndarray
    columns: np.ndarray


def _runs(rows: np.ndarray, min_run: int, max_step: float) -> np.ndarray:
    """Columns that belong to a run of at least ``min_run`` neighbours with row steps <= ``max_step``."""
    valid = rows >= 0
    if not valid.any():
        return valid
    link = valid[1:] & valid[:-1] & (np.abs(np.diff(rows)) <= max_step)
    start = valid & ~np.concatenate([[False], link])
    run = np.cumsum(start) - 1
    length = np.bincount(run[valid], minlength=int(start.sum()))
    return valid & (length[np.maximum(run, 0)] >= min_run)


def free_space_boundary(left_rect, obstacles: ObstacleResult, disparity_px, stereo: StereoCamera, *,
                        config: FreeSpaceConfig = FreeSpaceConfig(), max_range_m: float = MAPPING_MAX_RANGE_M,
                        min_height_m: float = ObstacleConfig.min_obstacle_height_m,
                        max_height_m: float = ObstacleConfig.max_obstacle_height_m) -> FreeSpaceBoundary:
    """Where the floor ends in each column of the rectified left image, and the obstacle standing there.

    Parameters
    ----------
    left_rect : ndarray of shape (H, W) or (H, W, 3)
    obstacles : ObstacleResult
        The frame's floor / obstacle split (its masks, floor and transform).
    disparity_px : ndarray of shape (H, W)
        The disparity the obstacles were computed from (NaN invalid).
    stereo : StereoCamera
    config : FreeSpaceConfig
    max_range_m : float
        Farthest floor range of a boundary when ``config.max_range_m`` is None.
    min_height_m, max_height_m : float
        Height band of the returned obstacle points (the obstacle config's).

    Returns
    -------
    FreeSpaceBoundary
    """
    _checks.instance("stereo", stereo, StereoCamera)
    _checks.instance("obstacles", obstacles, ObstacleResult)
    _checks.instance("config", config, FreeSpaceConfig)
    _checks.image("left_rect", left_rect)
    d = _disparity_image(disparity_px)
    h, w = obstacles.obstacle_mask.shape
    if left_rect.shape[:2] != (h, w) or d.shape != (h, w):
        raise ValueError(f"left_rect {left_rect.shape[:2]} and disparity_px {d.shape} must have the masks' "
                         f"shape {(h, w)}")
    none = np.full(w, np.nan)
    empty = FreeSpaceBoundary(base_row=none, top_row=none.copy(), base_points_robot=np.empty((0, 3)),
                              points_robot=np.empty((0, 3)), columns=np.empty(0, np.int64))
    if not obstacles.success:
        return empty
    if np.count_nonzero(obstacles.floor_mask) < config.min_floor_pixels:
        return empty                # no floor measured: nothing says the image's bottom is floor
    n, gray, floor, obstacle, d, intr, doffs = _reduced(left_rect, obstacles, d, stereo)
    hh, ww = gray.shape
    sy = hh / 240.0
    sigma = config.smooth_sigma_px * sy
    smooth = cv2.GaussianBlur(gray, (0, 0), sigma) if sigma > 0 else np.ascontiguousarray(gray)
    rows = functools.partial(_rows, rows_per_240=sy)
    # texture the matcher did not measure: the smoothed image's local standard deviation
    win = (2 * rows(2) + 1,) * 2
    mean = cv2.boxFilter(smooth, cv2.CV_32F, win)
    var = cv2.boxFilter(smooth * smooth, cv2.CV_32F, win) - mean * mean
    uniform = var <= np.float32(config.texture_threshold) ** 2
    edge, persist, check = rows(config.edge_rows), rows(config.persist_rows), rows(config.check_rows)
    if hh <= persist + check + edge + 2:
        return empty
    # the floor's look in this frame: the gray levels of the image's bottom rows
    band = slice(hh - 2 * persist, hh)
    seen = smooth[band][~obstacle[band]]
    if seen.size < config.min_floor_pixels:
        return empty
    lo, q1, q3, hi = np.percentile(seen, [5.0, 25.0, 75.0, 95.0])
    start_lo, start_hi = lo - config.appearance_threshold, hi + config.appearance_threshold
    measured_only = bool(q3 - q1 > config.pattern_threshold)
    R, t = _rigid(obstacles.T_robot_from_cam)
    base = np.full(ww, -1, np.int64)
    base_xy = np.zeros((ww, 2))
    top = np.full(ww, -1, np.int64)
    _kernels.column_boundaries(
        *(np.ascontiguousarray(a.T) for a in (smooth, floor, obstacle, uniform, d)),
        doffs, intr["bf"], intr["focal_px"], intr["cx_px"], intr["cy_px"], intr["fy_px"], R, t,
        float(max_range_m if config.max_range_m is None else config.max_range_m), float(config.min_range_m),
        edge, persist, check, float(config.edge_threshold), float(config.appearance_threshold), float(config.adapt),
        float(config.far_margin_m), rows(config.gap_rows), float(start_lo), float(start_hi), measured_only,
        base, top, base_xy)
    small = np.flatnonzero(_runs(base, max(1, int(round(config.min_run_columns * ww / 320.0))),
                                 config.max_row_step * sy))
    if small.size == 0:
        return empty
    return _boundary(small, base, top, base_xy, n=n, width=w, stereo=stereo,
                     T_robot_from_cam=obstacles.T_robot_from_cam, point_spacing_m=config.point_spacing_m,
                     min_height_m=min_height_m, max_height_m=max_height_m)


def _rows(k: int, *, rows_per_240: float) -> int:
    """A size of ``k`` rows at 240 rows, at the image's height."""
    return max(1, int(round(k * rows_per_240)))


def _reduced(left_rect, obstacles: ObstacleResult, d: np.ndarray, stereo: StereoCamera) -> tuple:
    """``(n, gray, floor, obstacle, disparity, intrinsics, doffs)`` of the image reduced by the integer factor
    ``n`` that brings it to about 320x240, where the rules' sizes hold (``n = 1``: as it is): gray levels
    averaged, a block measured when any of its pixels is, disparities sampled."""
    gray = np.asarray(left_rect, dtype=np.float32)
    if gray.ndim == 3:
        gray = gray.mean(axis=2, dtype=np.float32)
    floor, obstacle = obstacles.floor_mask, obstacles.obstacle_mask
    intr = _rectified_intrinsics(stereo)
    doffs = float(stereo.doffs_px)
    h, w = floor.shape
    n = max(1, int(min(w / 320.0, h / 240.0) + 0.25))
    if n > 1:
        hs, ws = h // n, w // n
        gray = cv2.resize(gray[:hs * n, :ws * n], (ws, hs), interpolation=cv2.INTER_AREA)
        # any pixel of a block: its mean (INTER_AREA) of 0 / 255 is at least 255 / n^2 > 0
        floor, obstacle = (cv2.resize(m[:hs * n, :ws * n].view(np.uint8) * np.uint8(255), (ws, hs),
                                      interpolation=cv2.INTER_AREA) > 0 for m in (floor, obstacle))
        d = d[n // 2::n, n // 2::n][:hs, :ws] / np.float32(n)
        off = (n - 1) / 2.0                          # a reduced pixel's centre in the full image
        intr = {"bf": intr["bf"] / n, "focal_px": intr["focal_px"] / n, "cx_px": (intr["cx_px"] - off) / n,
                "cy_px": (intr["cy_px"] - off) / n, "fy_px": intr["fy_px"] / n}
        doffs /= n
    return n, gray, floor, obstacle, d, intr, doffs


def _boundary(small: np.ndarray, base: np.ndarray, top: np.ndarray, base_xy: np.ndarray, *, n: int, width: int,
              stereo: StereoCamera, T_robot_from_cam: np.ndarray, point_spacing_m: float, min_height_m: float,
              max_height_m: float) -> FreeSpaceBoundary:
    """The boundary of the kept columns ``small`` of the reduced image (factor ``n``) in the full image, and
    the obstacle points on the vertical lines over its bases."""
    R, t = _rigid(T_robot_from_cam)
    w = width
    # back to the full image: a reduced pixel's centre
    cols = small * n + n // 2
    base_row = np.full(w, np.nan)
    top_row = np.full(w, np.nan)
    base_row[cols] = (base[small] - 0.5) * n + (n - 1) / 2.0
    top_row[cols] = top[small] * n + (n - 1) / 2.0
    # the obstacle: the vertical line over the base, up to the top row's sight line
    full = _rectified_intrinsics(stereo)
    ray_top = np.stack([(cols - full["cx_px"]) / full["focal_px"], (top_row[cols] - full["cy_px"]) / full["fy_px"],
                        np.ones(cols.size)], axis=1) @ R.T
    base_xy = base_xy[small]
    base_points = np.column_stack([base_xy, np.zeros(cols.size)])
    reach = np.hypot(*(base_xy - t[:2]).T) / np.maximum(np.hypot(ray_top[:, 0], ray_top[:, 1]), 1e-12)
    z_top = np.minimum(t[2] + ray_top[:, 2] * reach, max_height_m)
    heights = np.arange(min_height_m + 0.5 * point_spacing_m, max_height_m, point_spacing_m)
    k, j = np.nonzero(heights[None, :] <= z_top[:, None])
    points = np.column_stack([base_xy[k], heights[j]])
    return FreeSpaceBoundary(base_row=base_row, top_row=top_row, base_points_robot=base_points,
                             points_robot=points, columns=cols.astype(np.int64))
