"""The stereo mapper: one stereo pair at a time into a map that grows, with the robot's trajectory.

:class:`StereoMapper` is the one place where the per-frame chain is composed: rectify -> match
(eq. 9-12) -> reject (eq. 13) -> 3-D (eq. 14-16) -> scan (:func:`~mrstereo.geometry.pair.observe_pair`, pure, runs on
any thread or worker) -> pose (given or stereo visual odometry) -> occupancy grid (paper section 5.2,
:meth:`StereoMapper.integrate`, in order). ``mrstereo map``, ``batch``, ``live`` and the demo all
drive it. Without a camera mount the first frames are held until the floor is found
(:class:`~mrstereo.geometry.floor.FloorVote`), then mapped in order. User guide: docs/mapping.md.
Conventions: docs/conventions.md.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from functools import partial

import numpy as np

from ..camera import CameraMount, StereoCamera
from ..geometry.drops import DropConfig
from ..geometry.floor import FloorVote, RunFloor
from ..geometry.freespace import FreeSpaceConfig
from ..geometry.ground import GroundPlane
from ..geometry.obstacles import MAPPING_MAX_RANGE_M, ObstacleConfig, mapping_range_m
from ..geometry.pair import Observed, observe_pair
from ..geometry.scan import LaserScan
from ..mapping import GridSpec
from ..mapping.fusion import FrameObservation, fuse_step, world_observation
from ..mapping.occupancy import MappingConfig, OccupancyGrid
from ..mapping.prior import seeded
from ..mapping.tiles import TiledOccupancyGrid
from ..matching.config import MatchingConfig
from ..odometry import LOST, OdometryConfig, OdometryResult, StereoOdometry
from ..profiling import stage
from ..rejection import RejectionConfig
from ..rejection.streams import StreamCheck
from ..transforms import T_from_planar, planar_from_T

__all__ = ["PipelineConfig", "StereoMapper", "MappedFrame"]


@dataclass(frozen=True)
class PipelineConfig:
    """Options of every stage of a map, each stage's config with its own defaults.

    Attributes
    ----------
    preset : str
        Matching preset: ``"mapping"`` (the robust matcher with the stricter acceptance a map
        needs), ``"robust"`` or the paper's exact ``"paper"``.
    max_disparity_px : float, optional
        Overrides the disparity search derived from the calibration's depth bands.
    matching : MatchingConfig, optional
        Full matcher configuration (overrides ``preset``).
    rejection : RejectionConfig
        Eq. (13) texture / ground suppression.
    obstacles : ObstacleConfig or None
        Height band, range limit, floor estimation and drop test. None: the defaults with the rig's mapping
        range (:func:`~mrstereo.geometry.obstacles.mapping_range_m`) and ``drops``, filled in by :meth:`for_rig`.
    drops : DropConfig or None
        The drop test (the robot's ``max_step_m`` and ``max_slope_deg``; None: off) of the filled-in
        ``obstacles`` (``ObstacleConfig.drops`` when ``obstacles`` is given).
    mapping : MappingConfig
        Sensor model and fusion (log-odds or the paper's union).
    grid : GridSpec or None
        A fixed map window (extent and resolution); points outside it are counted and warned
        about. None: a map that grows with the path
        (:class:`~mrstereo.mapping.tiles.TiledOccupancyGrid`), written over the cells seen.
    resolution_m : float
        Cell size of a map that grows (``grid`` None).
    free_space : FreeSpaceConfig or None
        The free-space boundary (:mod:`mrstereo.geometry.freespace`), whose points join the
        frame's obstacle points. None: off.
    odometry : OdometryConfig
        Stereo visual odometry, for frames without a given pose.

    Examples
    --------
    >>> from mrstereo import PipelineConfig
    >>> PipelineConfig().with_fusion("union").mapping.fusion
    'union'
    """

    preset: str = "mapping"
    max_disparity_px: float | None = None
    matching: MatchingConfig | None = None
    rejection: RejectionConfig = field(default_factory=RejectionConfig)
    obstacles: ObstacleConfig | None = None
    drops: DropConfig | None = ObstacleConfig.drops
    mapping: MappingConfig = field(default_factory=MappingConfig)
    grid: GridSpec | None = None
    resolution_m: float = GridSpec.resolution_m
    free_space: FreeSpaceConfig | None = field(default_factory=FreeSpaceConfig)
    odometry: OdometryConfig = field(default_factory=OdometryConfig)

    def single_range_equal_work(self, stereo: StereoCamera) -> PipelineConfig:
        """A single full-resolution range doing the same work as the multi-range plan.

        The baseline the paper argues against: one disparity window ``[0, n]`` with ``n``
        chosen so that pixel x disparity evaluations equal the three ranges' (it cannot see
        closer than ``b f / n``: the near blind zone).
        """
        from ..matching import make_plan
        from ..matching.config import preset_config

        plan = make_plan(stereo.size, calibration=stereo)
        n = max(1, round(plan.work / (stereo.size[0] * stereo.size[1])))
        base = self.matching or preset_config(self.preset)
        return replace(self, matching=base.replace(search={"multi_range": False}), max_disparity_px=float(n))

    def for_rig(self, stereo: StereoCamera) -> PipelineConfig:
        """The configuration a run with the calibration ``stereo`` uses: ``obstacles`` filled in with the
        rig's mapping range when it is None."""
        if self.obstacles is not None:
            return self
        return replace(self, obstacles=ObstacleConfig(max_range_m=mapping_range_m(stereo), drops=self.drops))

    @property
    def obstacle_config(self) -> ObstacleConfig:
        """``obstacles``, or the defaults with the shortest mapping range when not filled in (:meth:`for_rig`)."""
        if self.obstacles is not None:
            return self.obstacles
        return ObstacleConfig(max_range_m=MAPPING_MAX_RANGE_M, drops=self.drops)

    def with_fusion(self, fusion: str) -> PipelineConfig:
        """The same configuration with another grid fusion (``"log_odds"`` or ``"union"``)."""
        return replace(self, mapping=replace(self.mapping, fusion=fusion))

    def pair_options(self) -> dict:
        """Keyword options of :func:`mrstereo.geometry.pair.obstacles_from_pair` for this config."""
        return {"preset": self.preset, "max_disparity_px": self.max_disparity_px, "matching": self.matching,
                "rejection": self.rejection, "config": self.obstacle_config, "free_space": self.free_space}


@dataclass(frozen=True)
class MappedFrame:
    """What :meth:`StereoMapper.step` produced for one frame.

    Points and the scan are in the robot frame (REP 103); ``T_world_from_base`` is the pose the frame was
    mapped at (``status`` ``"lost"``: visual odometry lost it and the map did not take it);
    ``T_base_from_cam`` the rectified left camera on the robot.
    """

    index: int
    stamp_s: float
    T_world_from_base: np.ndarray
    T_base_from_cam: np.ndarray
    status: str
    disparity_px: np.ndarray | None
    left_rect: np.ndarray | None
    obstacle_points_robot: np.ndarray
    scan: LaserScan | None
    times_s: dict
    """Seconds of ``chain`` (rectify to scan), ``odometry`` and ``grid`` for this frame."""


class StereoMapper:
    """Stereo pairs in, one at a time; a growing occupancy grid and the robot's trajectory out.

    Parameters
    ----------
    calibration : StereoCamera
        The rig.
    mount : CameraMount, optional
        The camera on the robot. None: the floor is estimated from the first frames (they are held
        until it is found, then mapped in order).
    config : PipelineConfig, optional
        Options of every stage (the defaults of ``mrstereo map``).
    check_mount : bool
        Check a given mount against the floor seen in the first frames; when they disagree the seen
        floor is used and ``mount_warning`` says why.
    odometry : {"auto", "given", "visual"}
        The robot's pose: each frame's given pose, or stereo visual odometry (starting at the first
        frame's given pose, else the origin). ``"auto"``: given when the first frame has a pose.
    pose_frame_mount : CameraMount, optional
        The camera in the frame the given poses are of, when that frame is not the base on the floor
        (the poses are moved to the base, the camera staying where it is).
    keep_observations : bool or "poses"
        Keep each mapped frame's world points (``observations``: to fuse again, replay or store);
        ``"poses"``: its observation without the points (pose, pan, counts: memory flat in the length).
    track_only : bool
        Visual odometry alone (``mrstereo odometry``): each pair rectified and tracked, no matching, floor,
        obstacles or map; every frame joins the trajectory (a lost one at the motion model's prediction) and
        :meth:`odometry_run` gives the refined poses. Without a mount the camera is level on the floor
        (the base is its REP 103 body frame). The streams are not checked (the caller does).
    name : str
        What is mapped, for messages.
    prior : path, RosMap or OccupancyGrid, optional
        A saved map to continue mapping on (``map.yaml`` of an earlier run; :func:`mrstereo.mapping.prior.
        prior_grid`: its occupied / free cells as log-odds ``l_max`` / ``l_min``, unknown ones unknown, the same
        resolution). The frames' poses must be in its frame; the map made covers it and what is seen.

    Examples
    --------
    >>> import numpy as np
    >>> from mrstereo import CameraMount, PipelineConfig, StereoCamera, StereoMapper
    >>> from mrstereo.camera import Camera
    >>> stereo = StereoCamera.ideal(Camera(width=160, height=120, fx=120.0, fy=120.0, cx=80.0, cy=60.0), 0.12)
    >>> mount = CameraMount.from_xyz_rpy((0.0, 0.0, 0.5), (0.0, 0.0, 0.0))
    >>> mapper = StereoMapper(stereo, mount, PipelineConfig(), check_mount=False)
    >>> left = np.random.default_rng(0).integers(0, 255, (120, 160)).astype(np.uint8)
    >>> right = np.roll(left, -8, axis=1)            # a textured wall 1.8 m ahead
    >>> [frame] = mapper.step(left, right, pose=np.eye(4))
    >>> frame.status, len(mapper.trajectory_T), int(mapper.occupancy().occupied.sum()) > 20
    ('given', 1, True)
    """

    def __init__(self, calibration: StereoCamera, mount: CameraMount | None = None,
                 config: PipelineConfig | None = None, *, check_mount: bool = True,
                 odometry: str = "auto", pose_frame_mount: CameraMount | None = None,
                 keep_observations: bool | str = False, name: str = "the source", track_only: bool = False,
                 prior=None) -> None:
        if not isinstance(calibration, StereoCamera):
            raise TypeError(f"calibration must be a StereoCamera, got {type(calibration).__name__}")
        if mount is not None and not isinstance(mount, CameraMount):
            raise TypeError(f"mount must be a CameraMount or None, got {type(mount).__name__}")
        config = PipelineConfig() if config is None else config
        if not isinstance(config, PipelineConfig):
            raise TypeError(f"config must be a PipelineConfig, got {type(config).__name__}")
        if track_only:
            if odometry == "given":
                raise ValueError("track_only estimates the poses: odometry must be 'visual' or 'auto'")
            odometry, check_mount = "visual", False
            mount = mount or CameraMount.from_xyz_rpy((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        self.track_only = bool(track_only)
        self.stereo = calibration
        self.config = config.for_rig(calibration)
        self.name = name
        self.pose_frame_mount = pose_frame_mount
        self.keep_observations = keep_observations
        self.range_m = self.config.obstacle_config.max_range_m
        if self.config.grid is None:
            self.grid = TiledOccupancyGrid(self.config.resolution_m, config=self.config.mapping,
                                           view_reach_m=self.range_m + 2.0)
        else:
            self.grid = OccupancyGrid(self.config.grid, config=self.config.mapping)
        if prior is not None:
            self.grid = seeded(self.grid, prior, config=self.config.mapping, resolution_m=self.config.resolution_m,
                               window=self.config.grid)
        self._vote = FloorVote(calibration, mount, check_mount=check_mount, name=name)
        self._held: list = []
        self.streams = StreamCheck(calibration, name)
        self.floor_decision: RunFloor | None = None
        if self._vote.done:
            self.floor_decision = self._vote.result()
        if odometry not in ("auto", "given", "visual"):
            raise ValueError(f"odometry must be 'auto', 'given' or 'visual', got {odometry!r}")
        self.odometry: str | None = None if odometry == "auto" else odometry
        self._vo: StereoOdometry | None = None
        self._previous_xy = self._weak_view = None    # the last frame's pose, the last weak drop votes' view
        self.observations: list[FrameObservation] = []
        self.trajectory_T: list[np.ndarray] = []
        self.trajectory_index: list[int] = []
        self.trajectory_stamps_s: list[float] = []
        self.true_T: list[np.ndarray | None] = []
        self.pan_rad: list[float] = []
        self.vo_status: list[str] = []
        self.vo_inliers: list[int] = []
        self.vo_time_s: list[float] = []
        self.vo_tracked: list[int] = []
        self.n_points = 0
        self.frames_lost = 0
        self.lost_index: list[int] = []
        self.frames_outside: list[int] = []

    # ------------------------------------------------------------------ the floor
    @property
    def mount(self) -> CameraMount | None:
        """The mount every frame is mapped with (None while the floor is being estimated)."""
        return None if self.floor_decision is None else self.floor_decision.mount

    @property
    def floor(self) -> GroundPlane | None:
        return None if self.floor_decision is None else self.floor_decision.floor

    @property
    def mount_warning(self) -> str | None:
        return None if self.floor_decision is None else self.floor_decision.warning

    @property
    def frames_held(self) -> int:
        """Frames waiting for the floor estimate."""
        return len(self._held)

    # ------------------------------------------------------------------ frames in
    def step(self, left: np.ndarray, right: np.ndarray, *, stamp_s: float | None = None,
             pose: np.ndarray | None = None, rectified: bool = False, pan_rad: float = 0.0) -> list[MappedFrame]:
        """Map one stereo pair; returns the frames mapped by this call, in order.

        Usually the pair itself; none while the first frames are held for the floor estimate; the held
        frames and this one when it is found. ``pose`` is ``T_world_from_base`` (4x4); None: stereo
        visual odometry (from the first pose given, else the origin). ``stamp_s`` None: 0.1 s after the
        previous frame.
        """
        from ..recordings.sources import StereoFrame

        index = len(self.trajectory_index) + len(self._held) + (0 if self.track_only else self.frames_lost)
        if stamp_s is None:
            stamp_s = self._last_stamp + 0.1 if self._last_stamp is not None else 0.0
        pose = None if pose is None else np.asarray(pose, dtype=np.float64)
        if pose is not None and (pose.shape != (4, 4) or not np.isfinite(pose).all()):
            raise ValueError(f"pose must be a finite 4x4 T_world_from_base, got shape {pose.shape}")
        return self.step_frame(StereoFrame(index=index, stamp_s=float(stamp_s), left=np.asarray(left),
                                           right=np.asarray(right), rectified=rectified, T_world_from_base=pose,
                                           pan_rad=float(pan_rad)))

    @property
    def _last_stamp(self) -> float | None:
        if self._held:
            return self._held[-1].stamp_s
        return self.trajectory_stamps_s[-1] if self.trajectory_stamps_s else None

    def step_frame(self, frame) -> list[MappedFrame]:
        """:meth:`step` of a :class:`~mrstereo.recordings.sources.StereoFrame` (its pose, stamp, pan)."""
        self.check_streams(frame)
        return self.integrate(self.observe(frame))

    def check_streams(self, frame) -> None:
        """Look for a duplicated or swapped camera stream in the first frames
        (:class:`~mrstereo.rejection.streams.StreamCheck`, one warning); :meth:`step_frame` calls it."""
        if not self.track_only:
            self.streams.add(frame.index, frame.left, frame.right, rectified=frame.rectified)

    def observe(self, frame, *, keep_images: bool = True) -> Observed:
        """The per-frame chain with the mount as known now (:meth:`observer`); thread-safe. While a given mount
        is being checked: with that mount, and the floor fitted without it."""
        if self.floor_decision is None and self._vote.mount is not None:
            return observe_pair(frame, self.stereo, self._vote.mount, self.config, keep_images=True,
                                fit_floor=True)
        return self.observer(keep_images=keep_images)(frame)

    def observer(self, *, keep_images: bool = True):
        """The per-frame chain (:func:`~mrstereo.geometry.pair.observe_pair`) with this mapper's rig, config and
        mount as known now: a picklable function of a frame, for workers (threads or processes)."""
        return partial(observe_pair, stereo=self.stereo, mount=self.mount,
                       config=None if self.track_only else self.config, keep_images=keep_images)

    def integrate(self, observed: Observed) -> list[MappedFrame]:
        """Take an observed frame into the map, in order (the ordered half of :meth:`step`)."""
        if self.floor_decision is None:
            self._vote_on(observed)
            return self._map_held() if self.floor_decision is not None else []
        done = self._map_held()
        if observed.mount is not self.mount:            # observed before the floor was known
            observed = self.observe(observed.frame)
        return done + [self._map(observed)]

    def settle(self, frames):
        """Take frames from the iterator ``frames`` until the floor is known, holding them unmapped (the
        next :meth:`integrate` maps them first); returns the next frame, not taken (None: the end).
        A None in ``frames`` is a frame that could not be read: it counts as seen, without a floor fit."""
        for frame in frames:
            if self.floor_decision is not None:
                return frame
            if frame is None:
                self._vote.skip()
                if self._vote.done:
                    self.floor_decision = self._vote.result()
                continue
            self.check_streams(frame)
            self._vote_on(self.observe(frame))
        if self.floor_decision is None and self._held:
            self.floor_decision = self._vote.result()
        self.streams.warn()
        return None

    def take_held(self) -> list:
        """The frames held unmapped (they leave the mapper)."""
        held, self._held = self._held, []
        return [o.frame for o in held]

    def _vote_on(self, observed: Observed) -> None:
        fit = observed.ground if observed.mount is None else observed.floor_fit
        if fit is not None:
            self._vote.add(observed.index, fit)
        else:
            self._vote.skip()
        self._held.append(observed)
        if self._vote.done:
            self.floor_decision = self._vote.result()

    def _map_held(self) -> list[MappedFrame]:
        """The held frames into the map: as observed when that was with the mount decided (a given mount
        kept), else observed again."""
        held, self._held = self._held, []
        return [self._map(o if o.mount is self.mount else self.observe(o.frame)) for o in held]

    def finish(self) -> list[MappedFrame]:
        """The end of the frames: decide the floor from the frames held (a run shorter than the floor
        estimate's frames) and map them. Raises ValueError when no floor was found and no mount given."""
        self.streams.warn()
        if self.floor_decision is None and self._held:
            self.floor_decision = self._vote.result()
        return self._map_held()

    # ------------------------------------------------------------------ pose and map
    def _pose(self, observed: Observed, T_base_from_cam: np.ndarray) -> tuple[np.ndarray, str]:
        if self.odometry is None:
            self.odometry = "given" if observed.T_world_from_base is not None else "visual"
        if self.odometry == "given":
            if observed.T_world_from_base is None:
                raise ValueError(f"frame {observed.index} has no pose but the frames before had: give every "
                                 "frame a pose, or none (visual odometry)")
            return np.asarray(observed.T_world_from_base, dtype=np.float64) @ self._pose_shift(), "given"
        if observed.left_rect is None:
            raise ValueError("visual odometry needs the rectified images (keep_images=True)")
        if self._vo is None:
            T0 = observed.T_world_from_base if observed.T_world_from_base is not None else np.eye(4)
            self._vo = StereoOdometry(self.stereo, T0, self.config.odometry, keep_history=self.track_only)
        with stage("odometry"):
            estimate = self._vo.step(observed.left_rect, observed.right_rect, T_base_from_cam=T_base_from_cam,
                                     stamp_s=observed.stamp_s)
        self.vo_status.append(estimate.status)
        self.vo_inliers.append(estimate.n_inliers)
        self.vo_time_s.append(estimate.time_s)
        self.vo_tracked.append(estimate.n_tracked)
        return estimate.T_world_from_base, estimate.status

    def _pose_shift(self) -> np.ndarray:
        """Given poses of the pose frame -> poses of the base of the mount used (the camera staying put)."""
        posed = self.pose_frame_mount if self.pose_frame_mount is not None else self._vote.mount
        if posed is None or posed == self.mount:
            return np.eye(4)
        return posed.T_base_from_cam @ np.linalg.inv(self.mount.T_base_from_cam)

    def _map(self, observed: Observed) -> MappedFrame:
        T_base_from_cam = self.mount.T_base_from_rectified(self.stereo.left.R, observed.pan_rad)
        start = time.perf_counter()
        T, status = self._pose(observed, T_base_from_cam)
        odometry_s = time.perf_counter() - start
        grid_s = 0.0
        if status == LOST:
            self.frames_lost += 1
            self.lost_index.append(observed.index)
        if self.track_only:             # every frame on the trajectory, nothing into the map
            self._on_trajectory(observed.index, T, observed.stamp_s, observed.T_world_from_base_true, observed.pan_rad)
        elif status != LOST:
            start = time.perf_counter()
            self.add(world_observation(observed, tuple(float(v) for v in planar_from_T(T)), self.stereo),
                     T_world_from_base=T,
                     stamp_s=observed.stamp_s, T_world_from_base_true=observed.T_world_from_base_true)
            grid_s = time.perf_counter() - start
        points = observed.obstacle_points_robot
        return MappedFrame(index=observed.index, stamp_s=observed.stamp_s, T_world_from_base=T,
                           T_base_from_cam=T_base_from_cam, status=status, disparity_px=observed.disparity_px,
                           left_rect=observed.left_rect,
                           obstacle_points_robot=np.empty((0, 3), np.float32) if points is None else
                           points[:len(points) - observed.n_boundary],
                           scan=observed.scan, times_s={"chain": observed.time_s, "odometry": odometry_s,
                                                        "grid": grid_s})

    def add(self, obs: FrameObservation, *, T_world_from_base: np.ndarray | None = None,
            stamp_s: float | None = None, T_world_from_base_true: np.ndarray | None = None) -> None:
        """Fuse a frame's world points (a :class:`~mrstereo.mapping.fusion.FrameObservation`, e.g. one stored
        by a batch run) into the map, after the frames before it; its pose joins the trajectory."""
        self._weak_view = fuse_step(self.grid, obs, self._previous_xy, self._weak_view)
        self._previous_xy = obs.pose
        self.n_points += len(obs.obstacle_points_world) + len(obs.floor_points_world)
        if self.keep_observations:
            self.observations.append(obs if self.keep_observations is True else replace(
                obs, obstacle_points_world=obs.obstacle_points_world[:0].copy(),      # (copies: a view keeps it all)
                floor_points_world=obs.floor_points_world[:0].copy(), cells=None,
                drop_points_world=None if obs.drop_points_world is None else obs.drop_points_world[:0].copy(),
                drop_candidates_world=None, drop_weak_points_world=(None if obs.drop_weak_points_world is None
                                                                    else obs.drop_weak_points_world[:0].copy())))
        self._on_trajectory(obs.index, T_from_planar(*obs.pose) if T_world_from_base is None else T_world_from_base,
                            float(obs.index) * 0.1 if stamp_s is None else stamp_s, T_world_from_base_true, obs.pan_rad)
        self._count_outside(obs)

    def _on_trajectory(self, index: int, T_world_from_base, stamp_s: float, T_world_from_base_true, pan_rad: float):
        self.trajectory_T.append(T_world_from_base)
        self.trajectory_index.append(index)
        self.trajectory_stamps_s.append(stamp_s)
        self.true_T.append(T_world_from_base_true)
        self.pan_rad.append(pan_rad)

    def _count_outside(self, obs: FrameObservation) -> None:
        """A frame taken outside a fixed map window is counted (:meth:`outside_warning`)."""
        if not isinstance(self.grid, OccupancyGrid):
            return
        g = self.grid.grid
        rows, cols = g.cells_from_xy(np.array([obs.pose[:2]], dtype=np.float64))
        if not g.inside(rows, cols)[0]:
            self.frames_outside.append(obs.index)

    def outside_warning(self) -> str | None:
        """What to tell the user when frames were taken outside a fixed map window (None: none were)."""
        outside = self.frames_outside
        if not outside:
            return None
        g = self.grid.grid
        x0, y0 = g.origin_x_m, g.origin_y_m
        return (f"{len(outside)} of {len(self.trajectory_index)} frames were taken outside the map [{x0:g}, "
                f"{x0 + g.width_m:g}] x [{y0:g}, {y0 + g.height_m:g}] m (frame(s) "
                f"{', '.join(str(k) for k in outside[:5])}{', ...' if len(outside) > 5 else ''}); "
                "give a --size and --origin that cover the path")

    # ------------------------------------------------------------------ outputs
    def occupancy(self) -> OccupancyGrid:
        """The map as a dense grid: the cells seen (a map that grows; beyond
        :data:`~mrstereo.mapping.tiles.DENSE_MAP_MAX_CELLS` the window around the last pose, with a warning) or
        the fixed window."""
        if not isinstance(self.grid, TiledOccupancyGrid):
            return self.grid
        last = self.planar_poses[-1][:2] if len(self.planar_poses) else None
        return self.grid.to_grid(self.grid.map_window(last))

    @property
    def planar_poses(self) -> np.ndarray:
        """``(N, 3)`` ``(x_m, y_m, yaw_rad)`` of the mapped frames."""
        return planar_from_T(np.array(self.trajectory_T)) if self.trajectory_T else np.empty((0, 3))

    def odometry_run(self) -> OdometryResult:
        """The visual odometry of a ``track_only`` mapper's frames: the poses refined over the window (a lost
        frame: the motion model's prediction), and as known at each frame; ``stamps_s`` those tracked with."""
        if not self.track_only or self._vo is None:
            raise ValueError("odometry_run needs a track_only mapper that has tracked at least one frame")
        T, online = self._vo.trajectory(), np.stack(self.trajectory_T)
        for a in (T, online):
            a.setflags(write=False)
        return OdometryResult(T_world_from_base=T, status=tuple(self.vo_status), n_tracked=np.array(self.vo_tracked),
                              n_inliers=np.array(self.vo_inliers), time_s=np.array(self.vo_time_s),
                              stamps_s=np.array(self.trajectory_stamps_s), T_world_from_base_online=online)

    def odometry_metrics(self) -> dict:
        """Visual odometry figures for metrics.json (empty with given poses)."""
        if not self.vo_status:
            return {}
        lost = self.lost_index
        message = f"tracked all {len(self.vo_status)} frames" if not lost else \
            (f"lost tracking on {len(lost)} of {len(self.vo_status)} frames ({', '.join(map(str, lost[:10]))}"
             f"{', ...' if len(lost) > 10 else ''}); they are not mapped")
        return {"visual_odometry": {"message": message, "frames": len(self.vo_status), "lost": len(lost),
                                    "keyframes": self.vo_status.count("keyframe"),
                                    "median_inliers": float(np.median(self.vo_inliers)),
                                    "median_time_s": float(np.median(self.vo_time_s))}}
