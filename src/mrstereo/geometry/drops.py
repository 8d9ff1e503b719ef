"""Negative obstacles: where the floor ends (a ledge, a stairwell, a hole) and what lies below it.

Beyond the paper, which marks only points above the floor. Up each column of the disparity image the
floor's points are followed until the next measured point lies below the floor by more than the robot
climbs (``max_step_m`` plus twice the point's height uncertainty, for the matcher's disparity error measured on
the frame's floor) and no drivable slope
(``max_slope_deg``) joins the two: the floor visibly ends there -- unless the sight line to the lower
point passes under floor measured in the same column (a mismatch: floor matched too far lies below the
floor); at the image's left border, where the floor on a point's sight line would match outside the right
image, a point below the floor counts as unmeasured. The edge (between the last floor point
and where the sight line to the lower point passes floor level) and the lower points become obstacle
points at floor level (z = 0, below any sight line, so the grid's occlusion tests never see through them), so
the scan and the grid mark them like any obstacle; the far rim of a hole (a rise from below the floor back to
it) too, and along each image row the floor-level points beside a drop's run within the matcher's fattening (a
hole's side seen along it, which no column crosses). A drivable ramp, a kerb or a sunken step within the limits
is no drop. Points below the floor that one frame cannot tell from a ramp starting out of view (the floor
measured too far before them in their column, or none: ``DropConfig.robot_floor`` judges those against the
floor under the robot) are *candidates* that the map confirms with the floor it measured there before
(:meth:`mrstereo.mapping.OccupancyGrid.add_layers`). Where a drop's sight lines pass floor level on their way
to its lower points no floor lies (a hole's inside): weak points, which the map counts over views.
User guide: docs/obstacles.md, "Drops". Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .. import _checks
from . import _drops_kernels

__all__ = ["DropConfig", "DropResult", "find_drops", "floor_disparity_sigma_px", "transform_candidates",
           "CANDIDATE_COLUMNS"]

CANDIDATE_COLUMNS = ("sx", "sy", "ex", "ey", "qx", "qy", "qz", "c0", "tan_slope", "hide_from_m", "hide_to_m")
"""The columns of a drop candidate (:attr:`DropResult.candidates_robot`): the edge's start ``S`` and end ``E``
(where the sight line to the run passes floor level), the run's point ``q`` deepest below a drivable slope
from ``E``, and the confirming rule: floor measured ``d`` (horizontally) from ``q`` at a height above
``c0 + tan_slope d`` makes it a drop (``c0 = z_q + n_sigma sigma_h(q) + max_step_m``); floor measured between
``hide_from_m`` and ``hide_to_m`` beyond ``E`` (toward the run's first point, less its depth noise) would hide
the run: a mismatch."""


@dataclass(frozen=True)
class DropConfig:
    """Options of :func:`find_drops` (docs/obstacles.md, "Drops").

    The robot's limits: the highest step it climbs up or down (``max_step_m``) and the steepest slope it
    drives (``max_slope_deg``). The noise margin: ``n_sigma`` times a point's height uncertainty for the
    matcher's disparity error. ``noise_from_floor``: that error is measured in each frame on its floor
    (:func:`floor_disparity_sigma_px`), the matcher's noise on this camera and this floor, and
    ``disparity_sigma_px`` serves a frame with too little floor; False: ``disparity_sigma_px`` always. A drop
    needs ``support`` measured points below the floor after it in its column; its edge is marked over the last
    ``edge_reach_m`` before where the sight line passes floor level, a point every ``spacing_m``.
    ``robot_floor``: a run with no floor measured before it in its column is judged against the floor under the
    robot (one frame finds a ledge whose near floor is not matched); False: only the map's memory of the floor
    confirms it, so a floor that gives no disparity stays unknown (docs/obstacles.md, "Drops"). ``weak_n_sigma``:
    the same test with this looser margin too, in the same pass; its drops are *weak* points
    (:attr:`DropResult.weak_points_robot`) that mark nothing alone: the map makes a cell lethal where
    ``MappingConfig.drop_weak_views`` views put them (None: off). Where the sight
    lines to the drops' lower points pass floor level (no floor there; points below any drivable slope from
    there) are weak points too. ``fattening_px``: how far (pixels along an image row) the matcher's window
    carries the floor's disparity past an edge (about half a window, more on a decimated level); along each row
    the floor-level points within it beside a drop's run are edge points too (the sides of a hole seen along
    them; 0: off). ``min_row_texture``: the points of pixels whose window has less texture along the rows than
    this many times the image noise's (:func:`mrstereo.rejection.row_texture`: plain floor, planks running
    along the rows, where a match slides along the row by a pixel or two) are never below the floor for the test
    (at floor level they are floor) and do not count in its noise margin; the chain
    (:func:`mrstereo.geometry.obstacles_from_pair`) passes them as ``find_drops``' ``untextured`` (None: off).
    """

    max_step_m: float = 0.05
    max_slope_deg: float = 10.0
    disparity_sigma_px: float = 0.25
    noise_from_floor: bool = True
    n_sigma: float = 2.0
    support: int = 3
    edge_reach_m: float = 0.1
    spacing_m: float = 0.01
    robot_floor: bool = True
    weak_n_sigma: float | None = 0.75
    fattening_px: int = 8
    min_row_texture: float | None = 1.2

    def __post_init__(self) -> None:
        _checks.finite_number("max_step_m", self.max_step_m, nonnegative=True)
        slope = _checks.finite_number("max_slope_deg", self.max_slope_deg, nonnegative=True)
        if slope >= 90.0:
            raise ValueError(f"max_slope_deg must be below 90, got {slope}")
        _checks.finite_number("disparity_sigma_px", self.disparity_sigma_px, nonnegative=True)
        _checks.finite_number("n_sigma", self.n_sigma, nonnegative=True)
        _checks.positive_int("support", self.support)
        for name in ("robot_floor", "noise_from_floor"):
            if not isinstance(getattr(self, name), bool):
                raise TypeError(f"{name} must be a bool, got {type(getattr(self, name)).__name__}")
        _checks.finite_number("edge_reach_m", self.edge_reach_m, nonnegative=True)
        _checks.finite_number("spacing_m", self.spacing_m, positive=True)
        _checks.positive_int("fattening_px", self.fattening_px, minimum=0)
        if self.weak_n_sigma is not None:
            _checks.finite_number("weak_n_sigma", self.weak_n_sigma, nonnegative=True)
        if self.min_row_texture is not None:
            _checks.finite_number("min_row_texture", self.min_row_texture, nonnegative=True)


@dataclass(frozen=True)
class DropResult:
    """Output of :func:`find_drops`: ``edge_points_robot`` (N, 3) the points on the drop edges (at floor
    level, z = 0), ``below_points_robot`` (M, 3) the measured points below the floor past an edge (their own
    height), ``edge_columns`` (W,) the number of edges found in each image column, ``candidates_robot`` (K, 11)
    the runs below the floor that one frame cannot tell from a ramp starting out of view (no floor measured
    near enough before them in their column), for the map to confirm with the floor it measured before
    (:data:`CANDIDATE_COLUMNS`; :meth:`mrstereo.mapping.OccupancyGrid.add_layers`), ``weak_points_robot``
    (P, 3) the points of the drops of the test with ``DropConfig.weak_n_sigma`` (edges at floor level, then the
    lower points; those of the drops above among them), then where the sight lines to the lower points of the
    drops above pass floor level (no floor there: a hole's inside, the space past a ledge), for the map's weak
    votes (empty: off), and ``disparity_sigma_px`` the disparity error of the noise margins."""

    edge_points_robot: np.ndarray
    below_points_robot: np.ndarray
    edge_columns: np.ndarray
    candidates_robot: np.ndarray = field(default_factory=lambda: np.empty((0, len(CANDIDATE_COLUMNS))))
    weak_points_robot: np.ndarray = field(default_factory=lambda: np.empty((0, 3)))
    disparity_sigma_px: float = DropConfig.disparity_sigma_px
    """The disparity error (pixels) the noise margins used: the frame's floor's (``DropConfig.noise_from_floor``)
    or the configured one."""

    @property
    def points_robot(self) -> np.ndarray:
        """All the drop's points, the edges' then the lower ones, at their measured height."""
        return np.concatenate([self.edge_points_robot, self.below_points_robot])

    @property
    def obstacle_points_robot(self) -> np.ndarray:
        """:attr:`points_robot` at floor level (z = 0): obstacle points below every sight line, so the grid's
        occlusion tests never see through them."""
        out = self.points_robot
        out[:, 2] = 0.0
        return out


def find_drops(points_robot_image, T_robot_from_cam, baseline_focal_m_px: float, *,
               config: DropConfig = DropConfig(), floor_top_m: float = 0.08, max_range_m: float = 8.0,
               doffs_px: float = 0.0, untextured=None) -> DropResult:
    """Drop edges and negative obstacles of one frame's robot-frame points.

    Parameters
    ----------
    points_robot_image : ndarray of shape (H, W, 3)
        Robot-frame point of every pixel (z: height above the floor), NaN where none
        (``ObstacleResult.points_robot_image``; :func:`mrstereo.geometry.detect_obstacles` leaves out its
        too-near pixels: placed at the near limit, a floor nearer than that would lie below the floor).
    T_robot_from_cam : ndarray of shape (4, 4)
        Places the camera (the sight lines' origin).
    baseline_focal_m_px : float
        ``b f`` of the rig: the points' depth uncertainty ``Z^2 sigma_d / (b f)`` (eq. 14 differentiated).
    config : DropConfig
    floor_top_m : float
        A drop's upper side lies below this height (an obstacle config's ``min_obstacle_height_m``).
    max_range_m : float
        Returned points lie within this horizontal range of the camera.
    doffs_px : float
        The rig's disparity offset (``Z = b f / (d + doffs)``; 0 for a rig rectified to zero disparity at
        infinity). The point image's column ``x`` is the pixel's in the rectified left image: a point below the
        floor counts as unmeasured where the floor on its sight line would match outside the right image
        (``x - d_floor < 0``, the image's left border: no matcher finds the floor there, so a floor pixel
        matched wrongly, too far, is likely).
    untextured : ndarray of shape (H, W), bool, optional
        Pixels without texture along the rows (``DropConfig.min_row_texture``), where the matcher's errors run to a
        pixel or two in streaks: their points are never below the floor for the test (no evidence of a drop; at
        floor level they are floor, before a run or after it) and do not count in the floor's measured error.

    Returns
    -------
    DropResult
    """
    _checks.instance("config", config, DropConfig)
    pts, T, bf, top, reach = _checked_frame(points_robot_image, T_robot_from_cam, baseline_focal_m_px,
                                            floor_top_m, max_range_m)
    doffs = _checks.finite_number("doffs_px", doffs_px)
    mask = _NONE_LEFT_OUT if untextured is None else np.ascontiguousarray(untextured)
    if untextured is not None and (mask.dtype != np.bool_ or mask.shape != pts.shape[:2]):
        raise ValueError(f"untextured must be a bool array of shape {pts.shape[:2]}, got {mask.dtype} {mask.shape}")
    t = np.ascontiguousarray(T[:3, 3], dtype=np.float64)
    h, w = pts.shape[:2]
    per_edge = int(config.edge_reach_m / config.spacing_m) + 2
    out_edge = np.empty((4 * w * per_edge + 8 * h * (config.fattening_px + 1), 3))
    out_below = np.empty((h * w // 2 + 1, 3))
    out_candidates = np.empty((4 * w, len(CANDIDATE_COLUMNS)))
    columns = np.zeros(w, np.int64)
    weak = config.weak_n_sigma is not None
    weak_edge, weak_below = (np.empty_like(out_edge), np.empty_like(out_below)) if weak else (out_edge[:0],
                                                                                              out_below[:0])
    axis = np.ascontiguousarray(T[:3, 2], dtype=np.float64)         # the optical axis in the robot frame
    sigma = float(config.disparity_sigma_px)
    if config.noise_from_floor:
        sigma = _floor_sigma(pts, T, bf, top, reach, sigma, mask)
    n_edge, n_below, n_cand, n_weak_edge, n_weak_below = _drops_kernels.column_drops(
        pts, mask, t, axis, bf, doffs, float(config.max_step_m), math.tan(math.radians(config.max_slope_deg)),
        sigma / bf, float(config.n_sigma),
        float(config.weak_n_sigma) if weak else -1.0, top, int(config.support), float(config.edge_reach_m),
        float(config.spacing_m), bool(config.robot_floor), int(config.fattening_px), out_edge, out_below,
        out_candidates, columns, weak_edge, weak_below, np.zeros(w, np.int64))
    def near(a, x=0):               # the rows whose point (columns x, x + 1) lies within max_range_m
        return a[np.hypot(a[:, x] - t[0], a[:, x + 1] - t[1]) <= reach]

    below = out_below[:n_below]
    crossings = _floor_crossings(below, t, config, sigma / bf) if weak else below[:0]
    return DropResult(edge_points_robot=near(out_edge[:n_edge]), below_points_robot=near(below),
                      edge_columns=columns, candidates_robot=near(out_candidates[:n_cand], 2),
                      weak_points_robot=np.concatenate([near(weak_edge[:n_weak_edge]),
                                                        near(weak_below[:n_weak_below]), near(crossings)]),
                      disparity_sigma_px=sigma)


def _floor_crossings(points_below, t, config: DropConfig, sigma_per_m2: float) -> np.ndarray:
    """Where the sight lines from the camera ``t`` (3,) to the points below the floor ``points_below`` (N, 3)
    pass floor level (M, 3; z = 0): the floor point each pixel would have seen were the floor there (it
    depends on the pixel's direction only, not on its measured depth). The sight line goes on below floor
    level, so no floor lies there (a hole's inside, the space past a ledge) -- for the points deeper than a
    step, their height noise and a ``max_slope_deg`` slope from there (no drivable ramp starting there
    reaches them: a ramp's own points are no evidence against the floor before them; ``sigma_per_m2``: the
    disparity error over ``b f``; ``_drops_kernels.floor_crossings``)."""
    out = np.empty_like(points_below)
    n = _drops_kernels.floor_crossings(points_below, *(float(v) for v in t), float(config.max_step_m),
                                       math.tan(math.radians(config.max_slope_deg)),
                                       sigma_per_m2, float(config.n_sigma), out)
    return out[:n]


FLOOR_RESIDUAL_MAX_PX = 2.0
""":func:`floor_disparity_sigma_px` counts the floor-level points whose disparity lies within this of the floor's."""

_NONE_LEFT_OUT = np.zeros((0, 0), np.bool_)
"""The kernels' ``untextured`` when no pixel is left out."""

FLOOR_MIN_POINTS = 100
"""... and needs this many of them (at every other row and column), else the frame has too little floor."""


def floor_disparity_sigma_px(points_robot_image, T_robot_from_cam, baseline_focal_m_px: float, *,
                             floor_top_m: float = 0.08, max_range_m: float = 8.0,
                             default_px: float = DropConfig.disparity_sigma_px) -> float:
    """The matcher's disparity error (pixels) on one frame's floor: 1.4826 times the median absolute deviation
    of the disparity residuals of its floor-level points (within ``floor_top_m`` of floor level and
    ``max_range_m`` of the camera; ``r = b f z / (t_z Z)``, the measured disparity less the floor's on the same
    sight line, ``_drops_kernels.floor_residuals``) within :data:`FLOOR_RESIDUAL_MAX_PX` of the floor's.

    The error differs by camera, floor and light, and the drop test's noise margin scales with it: on the
    randomized worlds the matcher's error on true floor runs from 0.11 to 0.77 px (docs/obstacles.md, "The
    noise margin"). Obstacles above ``floor_top_m`` and drops below it do not count (their bases and the
    shallowest drops within it widen it somewhat). Returns ``default_px`` when fewer than
    :data:`FLOOR_MIN_POINTS` points are at floor level.
    """
    frame = _checked_frame(points_robot_image, T_robot_from_cam, baseline_focal_m_px, floor_top_m, max_range_m)
    return _floor_sigma(*frame, _checks.finite_number("default_px", default_px, nonnegative=True))


def _checked_frame(points_robot_image, T_robot_from_cam, baseline_focal_m_px, floor_top_m, max_range_m):
    """A frame's inputs to the drop test, checked: ``(points (H, W, 3) float64, T (4, 4), b f, floor_top_m,
    max_range_m)``; the camera must be above the floor."""
    pts = np.ascontiguousarray(points_robot_image, dtype=np.float64)
    if pts.ndim != 3 or pts.shape[2] != 3:
        raise ValueError(f"points_robot_image must have shape (H, W, 3), got {pts.shape}")
    T = _checks.matrix("T_robot_from_cam", T_robot_from_cam, (4, 4))
    if T[2, 3] <= 0.0:
        raise ValueError(f"T_robot_from_cam puts the camera {T[2, 3]:.3f} m above the floor; it must be above it")
    return (pts, T, _checks.finite_number("baseline_focal_m_px", baseline_focal_m_px, positive=True),
            _checks.finite_number("floor_top_m", floor_top_m, positive=True),
            _checks.finite_number("max_range_m", max_range_m, positive=True))


def _floor_sigma(pts, T, bf: float, top: float, reach: float, default: float, untextured=None) -> float:
    """:func:`floor_disparity_sigma_px` of checked inputs (the pixels set in ``untextured`` left out)."""
    t = T[:3, 3]
    out = np.empty(((pts.shape[0] + 1) // 2) * ((pts.shape[1] + 1) // 2))
    left_out = _NONE_LEFT_OUT if untextured is None else untextured
    n = _drops_kernels.floor_residuals(pts, left_out, float(t[0]), float(t[1]), float(t[2]),
                                       np.ascontiguousarray(T[:3, 2], dtype=np.float64), bf, top, reach,
                                       FLOOR_RESIDUAL_MAX_PX, out)
    if n < FLOOR_MIN_POINTS:
        return default
    r = out[:n]
    return float(1.4826 * np.median(np.abs(r - np.median(r))))


def transform_candidates(T, candidates) -> np.ndarray:
    """Drop candidates (K, 11) (:data:`CANDIDATE_COLUMNS`) moved by the rigid ``T`` (4, 4) that keeps the floor
    (a planar pose: a rotation about z and a shift; heights change by its z shift), float32."""
    T = _checks.matrix("T", T, (4, 4))
    rows = np.asarray(candidates, dtype=np.float64)
    if rows.ndim != 2 or rows.shape[1] != len(CANDIDATE_COLUMNS):
        raise ValueError(f"candidates must have shape (K, {len(CANDIDATE_COLUMNS)}), got {rows.shape}")
    out = rows.copy()
    R, t = T[:2, :2], T[:2, 3]
    for a in (0, 2, 4):
        out[:, a:a + 2] = rows[:, a:a + 2] @ R.T + t
    out[:, 6:8] += T[2, 3]
    return out.astype(np.float32)
