"""From one stereo pair to obstacle points, a point cloud and a virtual laser scan.

rectify -> multi-range matching (eq. 9-12) -> rejection (eq. 13) -> floor -> triangulation into
the robot frame (eq. 14-16) -> obstacle / floor split -> laser scan: the functions behind
``mrstereo points`` and ``mrstereo scan``, and the pair half of :class:`mrstereo.StereoMapper`'s chain;
too-near pixels are fail-safe (docs/obstacles.md).
Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from .. import _checks
from ..camera import CameraMount, StereoCamera
from .ground import GroundPlane
from .freespace import FreeSpaceBoundary, FreeSpaceConfig, free_space_boundary
from .obstacles import ObstacleConfig, ObstacleResult, detect_obstacles, first_floor_row, ground_for_frame
from .scan import LaserScan, laser_scan_from_points, near_limit_range_m, scan_angles_of_camera
from ..matching import DisparityResult, compute_disparity
from ..profiling import stage
from ..rejection import FloorModel, RejectionConfig, RejectionResult, reject_uniform, row_texture

__all__ = ["PairObstacles", "PairScan", "obstacles_from_pair", "scan_from_pair", "Observed", "observe_pair"]


@dataclass(frozen=True)
class PairObstacles:
    """Everything :func:`obstacles_from_pair` computed for one frame.

    Attributes
    ----------
    left_rect : ndarray of shape (H, W) or (H, W, 3)
        The rectified left image.
    matching : DisparityResult
        The matcher's result (eq. 9-12): the disparity before rejection, each range's map, the plan.
    rejection : RejectionResult
        Eq. (13) applied to it (``rejection.disparity_px`` is what was triangulated).
    obstacles : ObstacleResult
        Robot-frame points, obstacle and floor masks, the floor used; the matcher's
        too-near pixels as fail-safe obstacle points at the near limit
        (``obstacles.too_near_mask``).
    boundary : FreeSpaceBoundary, optional
        Where the floor ends in each column and the obstacle points standing there
        (:mod:`mrstereo.geometry.freespace`), when asked for (``free_space``).
    """

    left_rect: np.ndarray
    matching: DisparityResult
    rejection: RejectionResult
    obstacles: ObstacleResult
    boundary: FreeSpaceBoundary | None = None

    @property
    def raw_disparity_px(self) -> np.ndarray:
        """The matcher's disparity before rejection, float32 (H, W)."""
        return self.matching.disparity_px

    @property
    def max_disparity_px(self) -> float:
        """The largest disparity the matcher searched (its near limit)."""
        return self.matching.near_limit_px

    @property
    def disparity_px(self) -> np.ndarray:
        """The disparity after rejection: what was triangulated."""
        return self.rejection.disparity_px


@dataclass(frozen=True)
class PairScan:
    """A virtual laser scan and the frame it was computed from."""

    scan: LaserScan
    frame: PairObstacles


def obstacles_from_pair(left, right, stereo: StereoCamera, *, rectified: bool = False,
                        mount: CameraMount | None = None,
                        pan_rad: float = 0.0, preset: str = "mapping", max_disparity_px: float | None = None,
                        matching=None,
                        rejection: RejectionConfig = RejectionConfig(), floor_model: FloorModel | None = None,
                        config: ObstacleConfig = ObstacleConfig(),
                        free_space: FreeSpaceConfig | None = None) -> PairObstacles:
    """Obstacle and floor points (robot frame) of one stereo pair.

    Parameters
    ----------
    left, right : ndarray of shape (H, W) or (H, W, 3)
        The pair; raw images are rectified with ``stereo`` first unless ``rectified``.
    stereo : StereoCamera
        Calibration (and optionally the camera ``mount``).
    rectified : bool
        The images are already rectified.
    mount : CameraMount, optional
        The camera mount; default ``stereo.mount``; with neither the floor
        is estimated (on the disparity before rejection, which has the most
        floor pixels; RANSAC ignores the ghosts).
    pan_rad : float
        Head pan (positive left).
    preset, max_disparity_px
        Passed to :func:`mrstereo.matching.compute_disparity`.
    matching : MatchingConfig, optional
        Full matcher configuration (overrides ``preset``), e.g. a single-range search.
    rejection : RejectionConfig
        Eq. (13) options (``texture_threshold`` is T).
    floor_model : FloorModel, optional
        A learned floor model (paper section 3.5) used in addition to the texture test.
    config : ObstacleConfig
        Height band, range limit, ground method.
    free_space : FreeSpaceConfig, optional
        Also find where the floor ends in each column (:func:`~mrstereo.geometry.freespace.free_space_boundary`):
        ``PairObstacles.boundary``. None: not computed.

    Examples
    --------
    A textured wall 1.8 m in front of a level camera 0.5 m above the floor:

    >>> import numpy as np
    >>> from mrstereo import CameraMount, StereoCamera, obstacles_from_pair
    >>> from mrstereo.camera import Camera
    >>> stereo = StereoCamera.ideal(Camera(width=160, height=120, fx=120.0, fy=120.0, cx=80.0, cy=60.0), 0.12)
    >>> left = np.random.default_rng(0).integers(0, 255, (120, 160)).astype(np.uint8)
    >>> right = np.roll(left, -8, axis=1)            # 8 px of disparity: b f / d = 0.12 * 120 / 8 = 1.8 m
    >>> mount = CameraMount.from_xyz_rpy((0.0, 0.0, 0.5), (0.0, 0.0, 0.0))
    >>> frame = obstacles_from_pair(left, right, stereo, rectified=True, mount=mount)
    >>> points = frame.obstacles.obstacle_points_robot            # (N, 3) robot frame: x forward, z up
    >>> bool(np.median(points[:, 0]).round(1) == 1.8)
    True
    """

    if not isinstance(stereo, StereoCamera):
        raise TypeError(f"stereo must be a StereoCamera, got {type(stereo).__name__}")
    _checks.image("left", left)
    _checks.image("right", right)
    _checks.same_shape("left", left, "right", right)
    if (left.shape[1], left.shape[0]) != tuple(stereo.size):
        raise ValueError(f"images are {left.shape[1]}x{left.shape[0]} but the calibration is "
                         f"{stereo.size[0]}x{stereo.size[1]}")
    if not rectified and not stereo.is_rectified:
        with stage("rectify"):
            left, right = stereo.rectify(left, right)
    kwargs = {"preset": preset, "calibration": stereo, "config": matching}
    if max_disparity_px is not None:
        kwargs["max_disparity_px"] = max_disparity_px
    with stage("match"):
        result = compute_disparity(left, right, **kwargs)
    with stage("reject"):
        rej = reject_uniform(result.disparity_px, left, config=rejection, floor_model=floor_model)
    with stage("3-D"):
        ground = ground_for_frame(result.disparity_px, stereo, mount=stereo.mount if mount is None else mount,
                                  config=config)
        drops = config.drops
        untextured = (None if drops is None or drops.min_row_texture is None or not ground.success
                      else row_texture(left, window_px=rejection.window_px,
                                       first_row=first_floor_row(stereo, ground, pan_rad=pan_rad))
                      < drops.min_row_texture)
        obstacles = detect_obstacles(rej.disparity_px, stereo, ground=ground, pan_rad=pan_rad,
                                     config=config, too_near=result.too_near, near_limit_px=result.near_limit_px,
                                     untextured=untextured)
    boundary = None
    if free_space is not None:
        with stage("free space"):
            boundary = free_space_boundary(left, obstacles, rej.disparity_px, stereo, config=free_space,
                                           max_range_m=config.max_range_m, min_height_m=config.min_obstacle_height_m,
                                           max_height_m=config.max_obstacle_height_m)
    return PairObstacles(left_rect=left, matching=result, rejection=rej, obstacles=obstacles, boundary=boundary)


def scan_from_pair(left, right, stereo: StereoCamera, *, angle_increment_rad: float = math.radians(0.5),
                   range_min_m: float = 0.1, range_max_m: float | None = None, min_points: int = 3,
                   **options) -> PairScan:
    """Virtual laser scan (nearest obstacle per bearing, robot frame) of one stereo pair.

    Bearings over the left camera's field of view (turned by ``pan_rad``); each ray reports its
    ``min_points``-th nearest obstacle point, ``+inf`` seen clear, ``nan`` unseen, ``range_min``
    (at least the matcher's near limit) when too-near points fall on it (docs/obstacles.md).
    Other keyword options are those of :func:`obstacles_from_pair`.
    """
    frame = obstacles_from_pair(left, right, stereo, **options)
    config = options.get("config", ObstacleConfig())
    obstacles = frame.obstacles
    lo, hi = scan_angles_of_camera(stereo, pan_rad=options.get("pan_rad", 0.0))
    range_min = _checks.finite_number("range_min_m", range_min_m, nonnegative=True)
    if obstacles.success and math.isfinite(frame.max_disparity_px):
        range_min = max(range_min, near_limit_range_m(stereo, obstacles.T_robot_from_cam, frame.max_disparity_px))
    gray = frame.left_rect if frame.left_rect.ndim == 2 else frame.left_rect.mean(axis=2)
    range_max = config.max_range_m if range_max_m is None else range_max_m
    if range_max_m is None and range_max <= range_min:     # a mapping range inside the near limit: an empty scan
        range_max = range_min + 0.01
    with stage("scan"):
        # the obstacle points are those of obstacle_mask in raster order (no (H, W, 3) image needed), then the
        # drop test's (returns without an intensity)
        n = int(np.count_nonzero(obstacles.obstacle_mask))
        points, drops = obstacles.obstacle_points_robot[:n], obstacles.obstacle_points_robot[n:]
        keep = ~obstacles.too_near_obstacle_mask[obstacles.obstacle_mask]
        near = ~keep
        scan = laser_scan_from_points(np.concatenate([points[keep], drops]), angle_min_rad=lo, angle_max_rad=hi,
                                      angle_increment_rad=angle_increment_rad, range_min_m=range_min,
                                      range_max_m=range_max,
                                      min_points=min_points,
                                      intensities=np.concatenate([gray[obstacles.obstacle_mask][keep],
                                                                  np.full(len(drops), np.nan)]),
                                      observed_points_robot=obstacles.points_robot)
        if near.any():
            # the too-near bearings, whatever the placement's range (it is a bound, not a measurement)
            hits = laser_scan_from_points(points[near], angle_min_rad=lo, angle_max_rad=hi,
                                          angle_increment_rad=angle_increment_rad, range_min_m=0.0,
                                          range_max_m=1e9, min_points=min_points)
            scan.ranges_m[np.isfinite(hits.ranges_m)] = scan.range_min_m
    return PairScan(scan=scan, frame=frame)


@dataclass
class Observed:
    """One frame after the pair half of the chain (:func:`observe_pair`), before its pose and the map: what a
    worker returns. Points in the robot frame (REP 103)."""

    index: int
    stamp_s: float
    pan_rad: float
    mount: CameraMount | None
    """The mount the chain used; None: only the floor was fitted (the floor is not known yet)."""
    ground: GroundPlane | None
    """The floor of the frame (None: not looked for, the pair only rectified for visual odometry)."""
    T_world_from_base: np.ndarray | None = None
    T_world_from_base_true: np.ndarray | None = None
    obstacle_points_robot: np.ndarray | None = None
    """Obstacle points, then ``n_boundary`` free-space boundary points."""
    n_boundary: int = 0
    floor_points_robot: np.ndarray | None = None
    drop_points_robot: np.ndarray | None = None
    """The drop test's points at their measured height (None: the test is off)."""
    drop_candidates_robot: np.ndarray | None = None
    """The drop test's candidates for the map (:attr:`.drops.DropResult.candidates_robot`; None: the test is off)."""
    drop_weak_points_robot: np.ndarray | None = None
    """The drop test's weak points for the map (:attr:`.drops.DropResult.weak_points_robot`; None: the test is off)."""
    n_valid_disparity: int = 0
    scan: LaserScan | None = None
    disparity_px: np.ndarray | None = None
    left_rect: np.ndarray | None = None
    right_rect: np.ndarray | None = None
    _obstacles: ObstacleResult | None = field(default=None, repr=False)
    """The frame's 3-D result with ``keep_images``: its point image is built only when asked for."""
    floor_fit: GroundPlane | None = None
    """The floor fitted without the mount (``fit_floor``: a given mount being checked)."""
    frame: object | None = None
    """The :class:`~mrstereo.recordings.sources.StereoFrame` itself while the floor is not known (kept to be
    mapped once it is)."""
    time_s: float = 0.0

    @property
    def points_robot_image(self) -> np.ndarray | None:
        """(H, W, 3) robot-frame point of every pixel (NaN: none), with ``keep_images`` (built on first use: the
        live loop and the map never need it)."""
        return None if self._obstacles is None else self._obstacles.points_robot_image


def _drop_data(obs, on: bool) -> dict:
    """The drop test's data of an :class:`~.obstacles.ObstacleResult` as :class:`Observed` fields (None: off)."""
    return {name: getattr(obs, name) if on else None
            for name in ("drop_points_robot", "drop_candidates_robot", "drop_weak_points_robot")}


def observe_pair(frame, stereo: StereoCamera, mount: CameraMount | None, config, *,
            keep_images: bool = True, fit_floor: bool = False) -> Observed:
    """The per-frame chain of one :class:`~mrstereo.recordings.sources.StereoFrame`: rectify, match, reject,
    3-D, scan with ``mount`` and ``config`` (a :class:`~mrstereo.pipeline.mapper.PipelineConfig`: its
    ``pair_options()`` and ``obstacle_config``); with ``mount`` None only the floor fit (without a mount,
    without free space); with ``config`` None only the rectified pair (what visual odometry alone needs).
    ``fit_floor``: with a mount, also the floor fitted without it (``floor_fit``: a given mount checked).
    Pure: runs on any thread or worker. ``keep_images`` False: no images in the result (a worker's reply
    when the poses are given)."""
    start = time.perf_counter()
    left, right = frame.left, frame.right
    if (left.shape[1], left.shape[0]) != tuple(stereo.size):
        raise ValueError(f"frame {frame.index} is {left.shape[1]}x{left.shape[0]} but the calibration is "
                         f"{stereo.size[0]}x{stereo.size[1]}")
    if not frame.rectified and not stereo.is_rectified:
        with stage("rectify"):
            left, right = stereo.rectify(left, right)
    base = {"index": frame.index, "stamp_s": float(frame.stamp_s), "pan_rad": float(frame.pan_rad),
            "T_world_from_base": frame.T_world_from_base, "T_world_from_base_true": frame.T_world_from_base_true}
    if config is None:
        return Observed(**base, mount=mount, ground=None, left_rect=left, right_rect=right,
                        time_s=time.perf_counter() - start)
    if mount is None:
        options = replace(config, free_space=None).pair_options()
        ground = obstacles_from_pair(left, right, replace(stereo, mount=None), rectified=True, mount=None,
                                     **options).obstacles.ground
        return Observed(**base, mount=None, ground=ground, frame=frame, time_s=time.perf_counter() - start)
    result = scan_from_pair(left, right, stereo, rectified=True, mount=mount, pan_rad=frame.pan_rad,
                            **config.pair_options())
    pair, obs = result.frame, result.frame.obstacles
    boundary = pair.boundary.points_robot if pair.boundary is not None else np.empty((0, 3))
    floor_fit = None
    if fit_floor:           # the fit of the matcher's disparity, as without a mount
        with stage("3-D"):
            floor_fit = ground_for_frame(pair.raw_disparity_px, replace(stereo, mount=None), mount=None,
                                         config=config.obstacle_config)
    return Observed(**base, mount=mount, ground=obs.ground, floor_fit=floor_fit, frame=frame if fit_floor else None,
                    obstacle_points_robot=np.concatenate([obs.obstacle_points_robot, boundary]),
                    n_boundary=len(boundary), floor_points_robot=obs.floor_points_robot,
                    **_drop_data(obs, config.obstacle_config.drops is not None),
                    n_valid_disparity=int(np.isfinite(pair.disparity_px).sum()),
                    scan=replace(result.scan, stamp_s=float(frame.stamp_s)),
                    disparity_px=pair.disparity_px if keep_images else None,
                    left_rect=pair.left_rect if keep_images else None, right_rect=right if keep_images else None,
                    _obstacles=obs if keep_images else None,
                    time_s=time.perf_counter() - start)
