"""Obstacle and floor points in the robot frame from one disparity map.

Eq. (14)-(16) give camera-frame points; the mount (or the fitted floor, :mod:`.ground`) takes them
into the robot frame. A point is an **obstacle** when ``min_obstacle_height_m < z <=
max_obstacle_height_m`` (as costmap_2d), **floor** when ``|z| <= floor_tolerance_m``, else
ignored. A too-near pixel (``DisparityResult.too_near``) is placed at the near-limit depth and
classified by the same rules, never as floor (fail-safe). Where the floor ends (a ledge, a hole) the
drop test (:mod:`.drops`) adds obstacle points on the edge. User guide: docs/obstacles.md.
Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from .. import _checks
from ..camera import CameraMount, StereoCamera
from . import _kernels
from .drops import CANDIDATE_COLUMNS, DropConfig, find_drops
from .ground import FLOOR_FIT_RANGE_M, GroundPlane, T_robot_from_cam_ground, estimate_ground, ground_from_mount

__all__ = ["ObstacleConfig", "ObstacleResult", "detect_obstacles", "ground_for_frame", "points_robot_from_disparity",
           "first_floor_row", "MAPPING_MAX_RANGE_M", "MAPPING_RANGE_SIGMA_M", "mapping_range_m"]

MAPPING_MAX_RANGE_M = 4.0
"""The shortest mapping range (``ObstacleConfig.max_range_m`` of a map, :func:`mapping_range_m`): the paper tells floor
and objects apart up to about 4 m; beyond, one pixel of disparity error is more than half a metre at 320x240."""

MAPPING_RANGE_SIGMA_M = MAPPING_MAX_RANGE_M ** 2 * 0.25 / 24.0
"""Depth uncertainty [m] at the end of the mapping range: that of the paper's rig (``b f = 24 m px``) at 4 m for a
quarter-pixel disparity error (``sigma_Z = Z^2 sigma_d / (b f)``, eq. 14 differentiated)."""


def mapping_range_m(stereo: StereoCamera, *, disparity_sigma_px: float = 0.25) -> float:
    """The mapping range of a rig: where its depth uncertainty reaches :data:`MAPPING_RANGE_SIGMA_M`, at least 4 m.

    ``Z_max = sqrt(sigma_Z b f / sigma_d)``: 4 m for the paper's rig (``b f = 24 m px``), about 16 m for
    KITTI's (``b f = 380 m px``), whose cameras 1.65 m above the road see it from 6 m on.
    """
    if not isinstance(stereo, StereoCamera):
        raise TypeError(f"stereo must be a StereoCamera, got {type(stereo).__name__}")
    sigma = _checks.finite_number("disparity_sigma_px", disparity_sigma_px, positive=True)
    bf = float(stereo.baseline_m * stereo.focal_px)
    return max(MAPPING_MAX_RANGE_M, math.sqrt(MAPPING_RANGE_SIGMA_M * bf / sigma))


@dataclass(frozen=True)
class ObstacleConfig:
    """Options of :func:`detect_obstacles` (docs/obstacles.md).

    The obstacle height band (``min_obstacle_height_m``, ``max_obstacle_height_m``), the floor band
    (``floor_tolerance_m``) and the horizontal range (``max_range_m``: farther depth errors, ``dZ =
    Z^2 / (b f) dd``, are too large). Without a mount, or with ``estimate_ground`` around a roughly
    known one (within ``prior_height_tolerance_m`` / ``prior_tilt_tolerance_rad``, falling back to it),
    the floor is estimated by ``ground_method`` within ``ground_height_range_m``, RANSAC seeded by
    ``seed``. ``drops``: the drop test's options (the robot's ``max_step_m`` and ``max_slope_deg``), None: off.
    """

    min_obstacle_height_m: float = 0.08
    max_obstacle_height_m: float = 1.5
    floor_tolerance_m: float = 0.04
    max_range_m: float = 8.0
    ground_method: str = "plane"
    estimate_ground: bool = False
    ground_height_range_m: tuple[float, float] = (0.1, 2.0)
    prior_height_tolerance_m: float = 0.15
    prior_tilt_tolerance_rad: float = 0.1
    seed: int = 0
    drops: DropConfig | None = None

    def __post_init__(self) -> None:
        if self.drops is not None and not isinstance(self.drops, DropConfig):
            raise TypeError(f"drops must be a DropConfig or None, got {type(self.drops).__name__}")
        lo = _checks.finite_number("min_obstacle_height_m", self.min_obstacle_height_m, nonnegative=True)
        hi = _checks.finite_number("max_obstacle_height_m", self.max_obstacle_height_m, positive=True)
        if hi <= lo:
            raise ValueError(f"max_obstacle_height_m ({hi}) must exceed min_obstacle_height_m ({lo})")
        _checks.finite_number("floor_tolerance_m", self.floor_tolerance_m, nonnegative=True)
        _checks.finite_number("max_range_m", self.max_range_m, positive=True)
        _checks.finite_number("prior_height_tolerance_m", self.prior_height_tolerance_m, positive=True)
        _checks.finite_number("prior_tilt_tolerance_rad", self.prior_tilt_tolerance_rad, positive=True)
        lo, hi = self.ground_height_range_m
        if not (_checks.finite_number("ground_height_range_m", lo, positive=True)
                < _checks.finite_number("ground_height_range_m", hi)):
            raise ValueError("ground_height_range_m must be (low, high) with low < high, "
                             f"got {self.ground_height_range_m}")
        if self.ground_method not in ("v_disparity", "plane"):
            raise ValueError(f"ground_method must be 'v_disparity' or 'plane', got {self.ground_method!r}")


@dataclass(frozen=True)
class ObstacleResult:
    """Output of :func:`detect_obstacles`.

    ``points_robot`` (N, 3): the robot-frame points of the pixels with a disparity (and the too-near
    placements), raster order, with their flat pixel indices ``pixels``; ``obstacle_points_robot`` /
    ``floor_points_robot`` among them and the disjoint (H, W) ``obstacle_mask`` / ``floor_mask``;
    ``drop_points_robot`` the drop test's points (edges at floor level, then the lower points at their
    measured height; :mod:`.drops`), which ``obstacle_points_robot`` ends with at floor level (z = 0), and its
    weak points (``drop_weak_points_robot``, :attr:`.drops.DropResult.weak_points_robot`: for the map only);
    ``ground`` and ``T_robot_from_cam`` used; ``success`` False (empty masks) without a floor,
    ``message`` how it was obtained; ``too_near_mask`` the too-near pixels placed at the near limit.
    """

    points_robot: np.ndarray
    pixels: np.ndarray
    obstacle_points_robot: np.ndarray
    floor_points_robot: np.ndarray
    obstacle_mask: np.ndarray
    floor_mask: np.ndarray
    ground: GroundPlane
    T_robot_from_cam: np.ndarray
    success: bool
    message: str
    too_near_mask: np.ndarray | None = None
    drop_points_robot: np.ndarray = field(default_factory=lambda: np.empty((0, 3)))
    drop_candidates_robot: np.ndarray = field(default_factory=lambda: np.empty((0, len(CANDIDATE_COLUMNS))))
    """The drop test's candidates for the map to confirm (:attr:`.drops.DropResult.candidates_robot`)."""
    drop_weak_points_robot: np.ndarray = field(default_factory=lambda: np.empty((0, 3)))

    @property
    def too_near_obstacle_mask(self) -> np.ndarray:
        """Obstacle pixels that are fail-safe placements at the near limit (not measured)."""
        if self.too_near_mask is None:
            return np.zeros_like(self.obstacle_mask)
        return self.obstacle_mask & self.too_near_mask

    @cached_property
    def points_robot_image(self) -> np.ndarray:
        """Robot-frame point of every pixel, (H, W, 3) float64, NaN where there is none (built on first use)."""
        h, w = self.obstacle_mask.shape
        image = np.empty((h * w, 3))
        _kernels.scatter_points(self.points_robot, self.pixels, image)
        return image.reshape(h, w, 3)


def _rigid(T) -> tuple[np.ndarray, np.ndarray]:
    """``(R, t)`` of a 4x4 transform as contiguous float64 arrays for the kernels."""
    return np.ascontiguousarray(T[:3, :3], dtype=np.float64), np.ascontiguousarray(T[:3, 3], dtype=np.float64)


def _rectified_intrinsics(stereo: StereoCamera) -> dict:
    """Keyword arguments of the eq. (14)-(16) kernels: ``b f``, ``f``, ``cx``, ``cy``, ``fy``."""
    return {"bf": float(stereo.baseline_m) * float(stereo.focal_px), "focal_px": float(stereo.focal_px),
            "cx_px": float(stereo.cx_px), "cy_px": float(stereo.cy_px), "fy_px": float(stereo.left.P[1, 1])}


def first_floor_row(stereo: StereoCamera, ground: GroundPlane, *, pan_rad: float = 0.0) -> int:
    """The first (top) row of the rectified left image where some pixel's sight line points below the horizon
    (for the floor ``ground`` and the head's pan): a sight line going up from the camera stays above floor level,
    so the rows above it show no floor and nothing below it. 0 when the floor was not found or the camera's
    rows run upward."""
    _checks.instance("stereo", stereo, StereoCamera)
    _checks.instance("ground", ground, GroundPlane)
    if not ground.success:
        return 0
    return _horizon_row(stereo, T_robot_from_cam_ground(ground, pan_rad=_checks.finite_number("pan_rad", pan_rad)))


def _horizon_row(stereo: StereoCamera, T_robot_from_cam) -> int:
    """:func:`first_floor_row` of the camera placed by ``T_robot_from_cam``."""
    R = T_robot_from_cam[:3, :3]
    k = _rectified_intrinsics(stereo)
    if R[2, 1] >= 0.0:
        return 0
    width, height = stereo.size
    # a pixel's sight line in the robot frame has height R[2] . ((u - cx) / f, (v - cy) / fy, 1): 0 at the horizon
    rows = [k["cy_px"] - k["fy_px"] * (R[2, 2] + R[2, 0] * (u - k["cx_px"]) / k["focal_px"]) / R[2, 1]
            for u in (0.0, width - 1.0)]
    return int(np.clip(np.floor(min(rows)), 0, height))


def _disparity_image(disparity_px) -> np.ndarray:
    """``disparity_px`` as a float32 or float64 (H, W) array."""
    d = np.asarray(disparity_px)
    if d.dtype not in (np.float32, np.float64):
        d = d.astype(np.float64)
    if d.ndim != 2:
        raise ValueError(f"disparity_px must have shape (H, W), got {d.shape}")
    return d


def points_robot_from_disparity(disparity_px, stereo: StereoCamera, T_robot_from_cam) -> np.ndarray:
    """Eq. (14)-(16) then a rigid transform: robot-frame points (H, W, 3), NaN invalid.

    The camera-frame points are :func:`~mrstereo.geometry.points_cam_from_disparity`'s;
    the transform is computed per point as :func:`detect_obstacles` does, so its points equal
    these bit for bit.
    """
    _checks.instance("stereo", stereo, StereoCamera)
    T = _checks.matrix("T_robot_from_cam", T_robot_from_cam, (4, 4))
    d = _disparity_image(disparity_px)
    R, t = _rigid(T)
    out = np.empty(d.shape + (3,), dtype=np.float64)
    _kernels.points_robot_image(d, float(stereo.doffs_px), **_rectified_intrinsics(stereo), R=R, t=t, out=out)
    return out


def ground_for_frame(disparity_px, stereo: StereoCamera, *, mount: CameraMount | None,
                     config: ObstacleConfig = ObstacleConfig()) -> GroundPlane:
    """The floor to use for a frame: the mount's, or an estimate (around the mount's if given).

    No mount: estimated with ``config.ground_method`` within
    ``config.ground_height_range_m``. A mount and ``config.estimate_ground``:
    estimated near the mount's floor (its height and tilt), falling back to it.
    Otherwise the mount's floor (:func:`~mrstereo.geometry.ground.ground_from_mount`).
    """
    if mount is None:
        reach = {"max_range_m": max(FLOOR_FIT_RANGE_M, config.max_range_m)} if config.ground_method == "plane" else {}
        return estimate_ground(disparity_px, stereo, method=config.ground_method, rng=config.seed,
                               height_range_m=config.ground_height_range_m, **reach)
    _checks.instance("mount", mount, CameraMount)
    given = ground_from_mount(mount, R_rect_from_cam=stereo.left.R)
    if not config.estimate_ground:
        return given
    ground = estimate_ground(disparity_px, stereo, method=config.ground_method, rng=config.seed, prior=given,
                             prior_height_tolerance_m=config.prior_height_tolerance_m,
                             prior_tilt_tolerance_rad=config.prior_tilt_tolerance_rad)
    if ground.success:
        return ground
    return replace(given, message=f"floor estimate failed ({ground.message}); mount used")


def detect_obstacles(disparity_px, stereo: StereoCamera, *, mount: CameraMount | None = None,
                     ground: GroundPlane | None = None, pan_rad: float = 0.0,
                     config: ObstacleConfig = ObstacleConfig(), too_near=None,
                     near_limit_px: float | None = None, untextured=None) -> ObstacleResult:
    """Split a disparity map into obstacle and floor points in the robot frame.

    Parameters
    ----------
    disparity_px : ndarray of shape (H, W)
        Disparity of the rectified left image (after rejection, eq. 13), NaN invalid.
    stereo : StereoCamera
        The calibration; its ``mount`` is used when ``mount`` is None.
    mount : CameraMount, optional
        Without ``mount``, ``ground`` or ``stereo.mount`` the floor is estimated from the disparity.
    ground : GroundPlane, optional
        A floor estimated beforehand; takes precedence over ``mount``.
    pan_rad : float
        Pan of the stereo head about the robot's z axis (positive left).
    config : ObstacleConfig
    too_near : ndarray of shape (H, W), bool, optional
        ``DisparityResult.too_near``: placed at ``near_limit_px`` along their rays, fail-safe.
    near_limit_px : float, optional
        ``DisparityResult.near_limit_px``; needed with ``too_near``.
    untextured : ndarray of shape (H, W), bool, optional
        Pixels without texture along the rows, whose points the drop test (``config.drops``;
        :func:`.drops.find_drops`) never takes for below the floor.

    Returns
    -------
    ObstacleResult
    """
    _checks.instance("stereo", stereo, StereoCamera)
    _checks.instance("config", config, ObstacleConfig)
    if ground is not None:
        _checks.instance("ground", ground, GroundPlane)
    d = _disparity_image(disparity_px)
    if (d.shape[1], d.shape[0]) != tuple(stereo.size):
        raise ValueError(f"disparity_px is {d.shape[1]}x{d.shape[0]} but the calibration is "
                         f"{stereo.size[0]}x{stereo.size[1]}")
    pan = _checks.finite_number("pan_rad", pan_rad)
    near, limit = None, 0.0
    if too_near is not None:
        near = np.asarray(too_near)
        if near.dtype != np.bool_ or near.shape != d.shape:
            raise ValueError(f"too_near must be a boolean mask of shape {d.shape}, got {near.dtype} {near.shape}")
        if near_limit_px is None:
            raise ValueError("too_near needs near_limit_px (the largest searched disparity)")
        limit = _checks.finite_number("near_limit_px", near_limit_px, positive=True)
        if not near.any():
            near = None
    if ground is None:
        # fail-safe: something at the near limit along the ray of a too-near pixel
        d64 = np.asarray(d, dtype=np.float64)
        ground = ground_for_frame(d64 if near is None else np.where(near, limit, d64), stereo,
                                  mount=stereo.mount if mount is None else mount, config=config)
    h, w = d.shape
    if not ground.success:
        empty = np.zeros((h, w), dtype=bool)
        none = np.empty((0, 3))
        return ObstacleResult(points_robot=none, pixels=np.empty(0, np.int64), obstacle_points_robot=none,
                              floor_points_robot=none, obstacle_mask=empty, floor_mask=empty.copy(), ground=ground,
                              T_robot_from_cam=np.full((4, 4), np.nan), success=False,
                              message=f"no floor: {ground.message}", too_near_mask=empty.copy())
    T = T_robot_from_cam_ground(ground, pan_rad=pan)
    R, t = _rigid(T)
    doffs = float(stereo.doffs_px)
    near_arg = np.zeros((0, 0), dtype=bool) if near is None else np.ascontiguousarray(near)
    n = _kernels.count_points(d, doffs, near_arg, limit)
    points, pixels = np.empty((n, 3)), np.empty(n, np.int64)
    obstacle_points, floor_points = np.empty((n, 3)), np.empty((n, 3))
    obstacle = np.empty((h, w), dtype=bool)
    floor = np.empty((h, w), dtype=bool)
    first = 0 if config.drops is None else _drop_first_row(stereo, T, config)
    image = np.empty((h - first if config.drops is not None else 0, w, 3))     # the drop test's point image
    # eq. (14)-(16), robot frame, height band and range limit, in one pass over the valid pixels
    n, n_obstacle, n_floor, n_floor_band, n_near = _kernels.obstacle_points(
        d, doffs, near_arg, limit, **_rectified_intrinsics(stereo), R=R, t=t,
        max_range_m=float(config.max_range_m), min_height_m=float(config.min_obstacle_height_m),
        max_height_m=float(config.max_obstacle_height_m), floor_tolerance_m=float(config.floor_tolerance_m),
        points=points, pixels=pixels, obstacle_points=obstacle_points, floor_points=floor_points, obstacle=obstacle,
        floor=floor, image=image, first_row=first)
    result = ObstacleResult(points_robot=points[:n], pixels=pixels[:n], obstacle_points_robot=obstacle_points[:n_obstacle],
                            floor_points_robot=floor_points[:n_floor], obstacle_mask=obstacle, floor_mask=floor,
                            ground=ground, T_robot_from_cam=T, success=True,
                            message=f"floor from {ground.method}: height {ground.height_m:.3f} m, "
                                    f"tilt {np.degrees(ground.tilt_rad):.2f} deg; "
                                    f"{int(n_obstacle)} obstacle and {int(n_floor_band)} floor points"
                                    + (f" ({n_near} obstacle points too near, placed at the near limit)"
                                       if n_near else ""),
                            too_near_mask=np.zeros((h, w), dtype=bool) if near is None else near)
    if config.drops is None:
        return result
    if first == 0 and near is None:
        result.__dict__["points_robot_image"] = image       # the whole point image: computed once
    return _with_drops(result, stereo, config, image, first, untextured)


def _drop_first_row(stereo: StereoCamera, T_robot_from_cam, config: ObstacleConfig) -> int:
    """The first row the drop test needs: the rows above the horizon hold nothing at floor level or below it when the
    camera is higher than ``min_obstacle_height_m``; an even row, where it samples the floor's residuals."""
    if T_robot_from_cam[2, 3] <= config.min_obstacle_height_m:
        return 0
    first = _horizon_row(stereo, T_robot_from_cam)
    return first - first % 2


def _with_drops(result: ObstacleResult, stereo: StereoCamera, config: ObstacleConfig, image: np.ndarray,
                first: int, untextured=None) -> ObstacleResult:
    """``result`` with the drop test's obstacle points (:func:`.drops.find_drops` on its point ``image`` of the
    rows from ``first`` on)."""
    T = result.T_robot_from_cam
    drops = find_drops(image, T,
                       float(stereo.baseline_m) * float(stereo.focal_px), config=config.drops,
                       floor_top_m=config.min_obstacle_height_m, max_range_m=config.max_range_m,
                       doffs_px=float(stereo.doffs_px), untextured=None if untextured is None else untextured[first:])
    found = drops.points_robot
    if not len(found) and not len(drops.candidates_robot) and not len(drops.weak_points_robot):
        return result
    # (weak points or candidates alone add no obstacle point: the frame's list is kept, not copied)
    out = replace(result, obstacle_points_robot=np.concatenate([result.obstacle_points_robot,
                                                                drops.obstacle_points_robot])
                  if len(found) else result.obstacle_points_robot,
                  drop_points_robot=found, drop_candidates_robot=drops.candidates_robot,
                  drop_weak_points_robot=drops.weak_points_robot,
                  message=result.message + f"; {int(np.count_nonzero(drops.edge_columns))} columns with a drop")
    if "points_robot_image" in result.__dict__:
        out.__dict__["points_robot_image"] = result.points_robot_image      # computed once
    return out
