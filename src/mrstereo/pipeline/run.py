"""The whole chain for a sequence: rectify -> match -> reject -> 3D -> occupancy grid.

:func:`observe_frame` takes one frame through matching (eq. 9-12), rejection (eq. 13) and
triangulation (eq. 14-16) into world-frame points; :func:`map_from_observations` fuses them in
order into the occupancy grid (paper section 5.2); :func:`build_map` runs both over a manifest,
:func:`write_map_outputs` writes the results, :func:`floor_for_run` finds the mount when there is
none. User guide: docs/mapping.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import json
import math
import os
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..camera import CameraMount, StereoCamera, mount_entry
from ..geometry.freespace import FreeSpaceConfig
from ..geometry.ground import GroundPlane, T_robot_from_cam_ground, ground_from_mount
from ..geometry.obstacles import MAPPING_MAX_RANGE_M, ObstacleConfig, mapping_range_m
from ..io import atomic_write
from ..mapping import GridSpec, read_ros_map, write_ros_map
from ..mapping.rosmap import ros_map_on_grid
from ..mapping.figures import plot_map
from ..mapping.fusion import FrameObservation, fuse
from ..mapping.tiles import TiledOccupancyGrid
from ..mapping.metrics import MapMetrics, map_metrics
from ..mapping.occupancy import MappingConfig, OccupancyGrid, view_cells
from ..matching.config import MatchingConfig
from ..profiling import stage
from ..recordings.layouts import read_recording
from ..recordings.manifest import FrameRecord, Manifest, frame_pair, pose_3d_of, rebased
from ..rejection import RejectionConfig
from ..transforms import T_from_planar, transform_points
from .frame import PairObstacles, obstacles_from_pair

__all__ = ["PipelineConfig", "MapRun", "observe_frame", "build_map", "map_from_observations", "floor_for_run",
           "write_map_outputs", "views_of_frames", "check_map", "RunFloor"]


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
        Height band, range limit and floor estimation. None: the defaults with the rig's mapping
        range (:func:`~mrstereo.geometry.obstacles.mapping_range_m`), filled in by :meth:`for_rig`.
    mapping : MappingConfig
        Sensor model and fusion (log-odds or the paper's union).
    grid : GridSpec or None
        A fixed map window (extent and resolution); points outside it are counted
        (``MapRun.points_outside``). None: the window of the recording's ground-truth map when it
        has one (maps compared cell by cell), else a map that grows with the path
        (:class:`~mrstereo.mapping.tiles.TiledOccupancyGrid`), written over the cells seen.
    resolution_m : float
        Cell size of a map that grows (``grid`` None).
    free_space : FreeSpaceConfig or None
        The free-space boundary (:mod:`mrstereo.geometry.freespace`), whose points join the
        frame's obstacle points. None: off.
    """

    preset: str = "mapping"
    max_disparity_px: float | None = None
    matching: MatchingConfig | None = None
    rejection: RejectionConfig = field(default_factory=RejectionConfig)
    obstacles: ObstacleConfig | None = None
    mapping: MappingConfig = field(default_factory=MappingConfig)
    grid: GridSpec | None = None
    resolution_m: float = GridSpec.resolution_m
    free_space: FreeSpaceConfig | None = field(default_factory=FreeSpaceConfig)

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
        return replace(self, obstacles=ObstacleConfig(max_range_m=mapping_range_m(stereo)))

    @property
    def obstacle_config(self) -> ObstacleConfig:
        """``obstacles``, or the defaults with the shortest mapping range when not filled in (:meth:`for_rig`)."""
        return self.obstacles if self.obstacles is not None else ObstacleConfig(max_range_m=MAPPING_MAX_RANGE_M)

    def with_fusion(self, fusion: str) -> PipelineConfig:
        """The same configuration with another grid fusion (``"log_odds"`` or ``"union"``)."""
        return replace(self, mapping=replace(self.mapping, fusion=fusion))


@dataclass
class MapRun:
    """Result of :func:`build_map`."""

    grid: OccupancyGrid
    observations: list[FrameObservation]
    manifest: Manifest
    metrics: MapMetrics | None
    ground_truth_map: object | None
    floor: GroundPlane | None = None
    """The floor of the run: the given mount's, or the estimate :func:`floor_for_run` made."""
    mount: CameraMount | None = None
    """The camera mount every frame used."""
    odometry: object | None = None
    """The :class:`mrstereo.odometry.OdometryResult` when the poses came from visual odometry."""
    fusion: object | None = None
    """The :class:`mrstereo.odometry.fusion.FusedOdometry` when the given poses were fused with visual odometry."""
    range_m: float = MAPPING_MAX_RANGE_M
    """The mapping range of the run (its obstacle configuration's ``max_range_m``)."""
    mount_warning: str | None = None
    """Why the given mount was not used (:func:`floor_for_run`), None when it was (or none was given)."""
    tiles: TiledOccupancyGrid | None = None
    """The whole map when it grew (``config.grid`` None); ``grid`` is then its dense window
    (:meth:`~mrstereo.mapping.tiles.TiledOccupancyGrid.map_window`: all of it unless it is too large)."""

    def pose_metrics(self) -> dict:
        """Odometry and alignment figures for metrics.json (empty when the given poses were used)."""
        out = {}
        if self.odometry is not None:
            vo = self.odometry
            out["visual_odometry"] = {"frames": len(vo.status), "lost": vo.n_lost,
                                      "keyframes": vo.status.count("keyframe"),
                                      "median_inliers": float(np.median(vo.n_inliers)),
                                      "median_time_s": float(np.median(vo.time_s))}
        if self.fusion is not None:
            moved, turned = self.fusion.corrections([f.pose for f in self.manifest.frames])
            out["alignment"] = {"frames": len(moved), "visual_steps": int(self.fusion.visual_used.sum()),
                                "rejected_visual_steps": int(self.fusion.visual_rejected.sum()),
                                "mean_correction_m": float(np.mean(moved)), "max_correction_m": float(np.max(moved)),
                                "mean_correction_deg": float(np.degrees(np.mean(turned))),
                                "max_correction_deg": float(np.degrees(np.max(turned)))}
        frames = self.manifest.frames
        if self.observations and all(f.true_pose is not None for f in frames):
            from ..odometry.trajectory import trajectory_metrics

            by_index = {o.index: o.pose for o in self.observations}
            used = sorted(by_index)
            est = np.stack([T_from_planar(*by_index[k]) for k in used])
            true = np.stack([T_from_planar(*frames[k].true_pose) for k in used])
            given = np.stack([T_from_planar(*frames[k].pose) for k in used])
            out["poses_vs_truth"] = trajectory_metrics(est, true).to_dict()
            out["given_poses_vs_truth"] = trajectory_metrics(given, true).to_dict()
        return out


def pair_options(config: PipelineConfig) -> dict:
    """Keyword options of :func:`mrstereo.pipeline.frame.obstacles_from_pair` for a config."""
    return {"preset": config.preset, "max_disparity_px": config.max_disparity_px, "matching": config.matching,
            "rejection": config.rejection, "config": config.obstacle_config, "free_space": config.free_space}


def observation_from_pair(frame: PairObstacles, record: FrameRecord, *, index: int,
                          config: PipelineConfig = PipelineConfig(),
                          stereo: StereoCamera | None = None) -> FrameObservation:
    """Move a frame's obstacle and floor points into the world frame; find their grid cells.

    Parameters
    ----------
    frame : PairObstacles
        The frame's points (:func:`mrstereo.pipeline.frame.obstacles_from_pair`).
    record : FrameRecord
        Its manifest entry: the pose and head pan.
    index : int
        Its position in the sequence.
    config : PipelineConfig
        The grid and sensor model of the cells.
    stereo : StereoCamera, optional
        The calibration the frame was matched with: gives the mapping's range uncertainty its
        ``b f``; without it rays clear up to each point.
    """
    with stage("grid"):
        T = T_from_planar(*record.pose)
        obs = frame.obstacles
        boundary = frame.boundary.points_robot if frame.boundary is not None else np.empty((0, 3))
        obstacles = transform_points(T, np.concatenate([obs.obstacle_points_robot, boundary])).astype(np.float32)
        floor = transform_points(T, obs.floor_points_robot).astype(np.float32)
        bf = None if stereo is None else float(stereo.baseline_m * stereo.focal_px)
        height = float(obs.ground.height_m) if obs.success else None
        origin = tuple(record.pose[:2]) + (() if height is None else (height,))
        # (a map that occludes traces every view against the map so far, in order: add_observation)
        cells = None if config.mapping.map_occlusion_p is not None or config.grid is None else \
            view_cells(obstacles, floor, origin, grid=config.grid, config=config.mapping, baseline_focal_m_px=bf)
    return FrameObservation(index=index, pose=tuple(float(v) for v in record.pose), pan_rad=float(record.pan_rad),
                            obstacle_points_world=obstacles, floor_points_world=floor,
                            n_valid_disparity=int(np.isfinite(frame.disparity_px).sum()),
                            ground_message=obs.message, cells=cells, baseline_focal_m_px=bf,
                            sensor_height_m=height, boundary_points=len(boundary))


def observe_frame(record: FrameRecord, stereo: StereoCamera, *, index: int = 0, mount: CameraMount | None = None,
                  config: PipelineConfig = PipelineConfig(), prefer_raw: bool = False,
                  pair: tuple[np.ndarray, np.ndarray, bool] | None = None) -> FrameObservation:
    """Run rectify -> match -> reject -> 3D on one manifest frame; points in the world frame.

    Parameters
    ----------
    record : FrameRecord
        The manifest frame.
    stereo : StereoCamera
        The calibration.
    index : int
        The frame's position in the sequence.
    mount : CameraMount, optional
        The camera mount (default: the calibration's; with neither the floor is estimated).
    config : PipelineConfig
        Options of every stage.
    prefer_raw : bool
        Rectify the raw images even where the dataset has rectified ones.
    pair : (ndarray, ndarray, bool), optional
        The frame's images as :func:`frame_pair` reads them (read ahead by a reader thread);
        default read here.
    """
    left, right, rectified = frame_pair(record, prefer_raw=prefer_raw) if pair is None else pair
    frame = obstacles_from_pair(left, right, stereo, rectified=rectified, mount=mount, pan_rad=record.pan_rad,
                                **pair_options(config))
    return observation_from_pair(frame, record, index=index, config=config, stereo=stereo)


def _observe_indexed(indexed: tuple, *, stereo: StereoCamera, mount: CameraMount | None, config: PipelineConfig,
                     prefer_raw: bool) -> FrameObservation:
    """:func:`observe_frame` of ``(index, record)`` or ``(index, record, pair)``: the picklable unit of work
    of :func:`build_map` (``pair`` read ahead by :func:`_read_indexed`)."""
    k, record, *pair = indexed
    return observe_frame(record, stereo, index=k, mount=mount, config=config, prefer_raw=prefer_raw,
                         pair=pair[0] if pair else None)


def _read_indexed(indexed: tuple[int, FrameRecord], *, prefer_raw: bool) -> tuple:
    """``(index, record)`` -> ``(index, record, pair)``: the images decoded (a sequence run's reader thread)."""
    k, record = indexed
    return k, record, frame_pair(record, prefer_raw=prefer_raw)


MOUNT_HEIGHT_TOLERANCE_M = 0.10
"""A given mount whose camera height differs more than this from the floor seen in the images is not used."""
MOUNT_TILT_TOLERANCE_RAD = math.radians(5.0)
"""A given mount whose tilt differs more than this from the floor seen in the images is not used."""
MIN_CAMERA_HEIGHT_M = 0.05
"""A given mount with the camera lower than this above the floor is taken for a base frame that is not on the floor."""


class RunFloor(NamedTuple):
    """The camera mount of a run and the floor it implies (:func:`floor_for_run`)."""

    mount: CameraMount
    floor: GroundPlane
    warning: str | None = None
    """Why the given mount was not used, or looks wrong: one line for the user (None: nothing to say)."""


def _seen_floor(manifest: Manifest, stereo: StereoCamera, config: PipelineConfig, prefer_raw: bool,
                max_frames: int, n_frames: int) -> tuple[GroundPlane | None, int]:
    """The floor fitted in the first ``max_frames`` frames: the median of the first ``n_frames`` confident
    fits, else the fit with the largest inlier share (not confident), else None; and the number of
    confident fits."""
    stereo = replace(stereo, mount=None)
    fits, best = [], None
    for k, record in enumerate(manifest.frames[:max(1, int(max_frames))]):
        try:
            left, right, rectified = frame_pair(record, prefer_raw=prefer_raw)
        except (OSError, ValueError):
            continue                       # an unreadable frame: the run reports it when it gets there
        ground = obstacles_from_pair(left, right, stereo, rectified=rectified, mount=None,
                                     **pair_options(replace(config, free_space=None))).obstacles.ground
        if ground.success and (best is None or ground.inlier_share > best[1].inlier_share):
            best = (k, ground)
        if ground.confident:
            fits.append((k, ground))
            if len(fits) >= n_frames:
                break
    if best is None:
        return None, 0
    return median_floor(fits or [best], confident=bool(fits)), len(fits)


def median_floor(fits: list[tuple[int, GroundPlane]], *, confident: bool) -> GroundPlane:
    """The median height, tilt and roll of floor fits ``(frame index, GroundPlane)``."""
    med = {name: float(np.median([getattr(g, name) for _, g in fits]))
           for name in ("height_m", "tilt_rad", "roll_rad", "inlier_share", "residual_m")}
    frames = ", ".join(str(k) for k, _ in fits)
    return GroundPlane(**med, success=True, method=fits[0][1].method,
                       n_inliers=int(np.median([g.n_inliers for _, g in fits])),
                       message=f"estimated: median of {len(fits)} floor fit(s), frame(s) {frames}"
                               + ("" if confident else " (none confident)"))


def _disagreement(given: GroundPlane, seen: GroundPlane | None) -> str | None:
    """Why a given mount's floor disagrees with the seen one (None: it agrees, or nothing to compare)."""
    if given.height_m < MIN_CAMERA_HEIGHT_M:
        return f"a camera {given.height_m:.3f} m above the floor is below {MIN_CAMERA_HEIGHT_M:.2f} m"
    if seen is None:
        return None
    dh, dt = abs(given.height_m - seen.height_m), abs(given.tilt_rad - seen.tilt_rad)
    if dh > MOUNT_HEIGHT_TOLERANCE_M:
        return f"the height is off by {dh:.3f} m (more than {MOUNT_HEIGHT_TOLERANCE_M:.2f} m)"
    if dt > MOUNT_TILT_TOLERANCE_RAD:
        return f"the tilt is off by {math.degrees(dt):.1f} deg (more than {math.degrees(MOUNT_TILT_TOLERANCE_RAD):.0f} deg)"
    return None


def _floor_text(floor: GroundPlane) -> str:
    return f"height {floor.height_m:.3f} m, tilt {math.degrees(floor.tilt_rad):.1f} deg"


def floor_for_run(manifest: Manifest, stereo: StereoCamera | None = None, *,
                  config: PipelineConfig = PipelineConfig(), prefer_raw: bool = False, max_frames: int = 10,
                  n_frames: int = 3, check_mount: bool = True) -> RunFloor:
    """The camera mount of a run and the floor it implies: given and checked, or estimated from the first frames.

    The seen floor is the median of the first ``n_frames`` confident RANSAC fits within
    ``max_frames`` frames (else the fit with the largest inlier share, reported as not confident).
    A given mount is kept (with ``check_mount``) when the camera is at least :data:`MIN_CAMERA_HEIGHT_M`
    above its floor and a floor seen in two frames agrees within :data:`MOUNT_HEIGHT_TOLERANCE_M` and
    :data:`MOUNT_TILT_TOLERANCE_RAD`; otherwise the seen floor is used and ``warning`` says why
    (docs/mapping.md).

    Returns
    -------
    RunFloor
        The mount, the floor with its confidence (``inlier_share``, ``residual_m``; in ``message``
        which frames it came from), and the warning (None when there is nothing to say).

    Raises
    ------
    ValueError
        No mount and no floor in any of the first ``max_frames`` frames.
    """
    if not isinstance(manifest, Manifest):
        raise TypeError(f"manifest must be a Manifest, got {type(manifest).__name__}")
    stereo = manifest.calibration if stereo is None else stereo
    given = None if manifest.mount is None else ground_from_mount(manifest.mount, R_rect_from_cam=stereo.left.R)
    if given is not None and not check_mount:
        return RunFloor(manifest.mount, given)
    seen, n_confident = _seen_floor(manifest, stereo, config, prefer_raw, max_frames, n_frames)
    if given is None:
        if seen is None:
            raise ValueError(f"no floor found in the first {min(len(manifest.frames), max_frames)} frames of "
                             f"{manifest.root}; give the camera mount (--mount x,y,z,roll,pitch,yaw or "
                             "--height/--tilt, or mount:/rig: in the manifest or stereo YAML)")
        return RunFloor(_mount_of_floor(seen, stereo), seen)
    # one confident fit can be a wall's base or a ramp: a plausible mount is replaced on repeated evidence only
    repeated = n_confident >= min(2, len(manifest.frames))
    reason = _disagreement(given, seen if seen is not None and seen.confident and repeated else None)
    if reason is None:
        return RunFloor(manifest.mount, given)
    advice = ("give the mount of a base frame on the floor (--base-frame of a bag, --mount x,y,z,roll,pitch,yaw, "
              "--height/--tilt), or no mount to have the floor estimated")
    if seen is None:
        return RunFloor(manifest.mount, given, f"the camera mount looks wrong ({reason}: {_floor_text(given)}) and no "
                                               f"floor was seen in the first frames to replace it; {advice}")
    used = replace(seen, message=f"{seen.message}; used instead of the given mount ({_floor_text(given)})")
    return RunFloor(_mount_of_floor(seen, stereo), used,
                    f"the camera mount disagrees with the floor seen in the images ({reason}): given "
                    f"{_floor_text(given)}, seen {_floor_text(seen)}; the seen floor is used; {advice}; "
                    "--no-mount-check keeps the given mount")


def _mount_of_floor(floor: GroundPlane, stereo: StereoCamera) -> CameraMount:
    # the estimate is of the rectified left frame; the mount is of the raw camera (p_rect = R p_raw)
    return CameraMount.from_rectified(T_robot_from_cam_ground(floor), stereo.left.R)


def build_map(manifest: Manifest | str | os.PathLike, *, config: PipelineConfig = PipelineConfig(),
              calibration: StereoCamera | None = None, prefer_raw: bool = False,
              progress: bool = True, workers: int | None = None, scheduler=None,
              processes: bool = False, odometry: str = "auto", align=None, check_mount: bool = True) -> MapRun:
    """Map a whole dataset: observe every frame, fuse in order, compare with the GT map if any.

    Parameters
    ----------
    manifest : Manifest or path
        The dataset (docs/dataset.md).
    config : PipelineConfig
        Options of every stage.
    calibration : StereoCamera, optional
        Overrides the manifest's calibration (e.g. one estimated by ``mrstereo
        stereo-calibrate``); then the raw images are used.
    prefer_raw : bool
        Rectify the raw images even where the dataset has rectified ones.
    progress : bool
        A tqdm bar over the frames.
    workers : int, optional
        Observe the frames on this many single-threaded workers: threads of this
        process, or the processes of a local Dask cluster with ``processes=True``.
    scheduler : str or distributed.Client, optional
        Observe the frames on an existing Dask cluster (its workers must see
        the dataset's files). The map is the same, bit for bit, in every case.
    processes : bool
        With ``workers``: worker processes instead of threads.
    odometry : {"auto", "given", "visual"}
        ``"auto"``: the recording's poses when it has some (``Manifest.has_poses``), else visual
        odometry. ``"visual"``: the poses come from stereo visual odometry
        (:func:`mrstereo.pipeline.odometry_from_manifest`, run in order before the
        matching), starting at the first frame's given pose; frames where tracking is
        lost are left out of the map.
    align : FusionConfig or True, optional
        Correct the given poses with visual odometry (with ``odometry="given"``): each step of
        the given odometry fused with the visual odometry's (:func:`mrstereo.odometry.fusion.
        fuse_odometry`); every frame is mapped, those visual odometry lost on the given steps.
    check_mount : bool
        Check a given mount against the floor seen in the first frames and use the seen floor when they
        disagree (:func:`floor_for_run`; ``MapRun.mount_warning`` says so).
    """
    from functools import partial

    from .parallel import map_ordered
    from .sanity import check_pair_streams

    if not isinstance(manifest, Manifest):
        manifest = read_recording(manifest)
    if not isinstance(config, PipelineConfig):
        raise TypeError(f"config must be a PipelineConfig, got {type(config).__name__}")
    if odometry not in ("auto", "given", "visual"):
        raise ValueError(f"odometry must be 'auto', 'given' or 'visual', got {odometry!r}")
    if odometry == "auto":
        odometry = "given" if manifest.has_poses else "visual"
    align = None if align is False else align
    if align is not None and odometry != "given":
        raise ValueError("align corrects the given odometry with visual odometry: use it with odometry='given'")
    stereo = manifest.calibration if calibration is None else calibration
    prefer_raw = prefer_raw or calibration is not None
    check_pair_streams(manifest)
    config = _on_true_map(manifest, config.for_rig(stereo))
    if config.grid is None:         # a map that grows: its memory checked before any frame is matched
        TiledOccupancyGrid(config.resolution_m, config=config.mapping,
                           view_reach_m=config.obstacle_config.max_range_m + 2.0)
    mount, floor, warning = floor_for_run(manifest, stereo, config=config, prefer_raw=prefer_raw,
                                          check_mount=check_mount)
    manifest = rebased(manifest, mount)
    items = list(enumerate(manifest.frames))
    vo = fused = None
    if odometry == "visual" or align is not None:
        visual, vo = with_visual_odometry(manifest, calibration=calibration, progress=progress)
    if odometry == "visual":
        items = [(k, record) for k, record, ok in zip(range(len(items)), visual.frames, vo.tracked) if ok]
    elif align is not None:
        from ..odometry.fusion import FusionConfig, fuse_odometry

        fused = fuse_odometry([f.pose for f in manifest.frames], vo.poses, vo.tracked,
                              config=FusionConfig() if align is True else align)
        items = [(k, replace(record, pose=tuple(float(v) for v in pose), pose_3d=None))
                 for (k, record), pose in zip(items, fused.poses)]
    observe = partial(_observe_indexed, stereo=stereo, mount=mount, config=config, prefer_raw=prefer_raw)
    observations = map_ordered(observe, items, workers=workers, scheduler=scheduler,
                               processes=processes, progress=progress, desc="mapping", unit="frame",
                               prefetch=partial(_read_indexed, prefer_raw=prefer_raw),
                               label=lambda item: f"frame {item[0]} ({(item[1].left_rect or item[1].left).name})")
    run = map_from_observations(manifest, observations, config=config, stereo=stereo, floor=floor, mount=mount,
                                odometry=vo, fusion=fused)
    run.mount_warning = warning
    return run


def with_visual_odometry(manifest: Manifest, *, calibration: StereoCamera | None = None, progress: bool = False):
    """``(recording, run)``: the recording with every frame's pose from stereo visual odometry
    (:func:`mrstereo.pipeline.odometry.odometry_from_manifest`; a lost frame gets the motion model's
    prediction, ``run.tracked`` says which), for a recording without poses."""
    from .odometry import odometry_from_manifest

    vo = odometry_from_manifest(manifest, calibration=calibration, progress=progress)
    frames = tuple(replace(f, pose=None, pose_3d=pose_3d_of(T)) for f, T in zip(manifest.frames, vo.T_world_from_base))
    return replace(manifest, frames=frames, has_poses=True), vo


def _on_true_map(manifest: Manifest, config: PipelineConfig) -> PipelineConfig:
    """``config`` with the window of the recording's ground-truth map (at ``config.resolution_m``) when it has
    one and no window is given."""
    if config.grid is not None or manifest.ground_truth_map is None:
        return config
    return replace(config, grid=replace(read_ros_map(manifest.ground_truth_map).grid, resolution_m=config.resolution_m))


def map_from_observations(manifest: Manifest, observations: list[FrameObservation], *,
                          config: PipelineConfig = PipelineConfig(), stereo: StereoCamera | None = None,
                          floor: GroundPlane | None = None, mount=None, odometry=None, fusion=None) -> MapRun:
    """Fuse a run's frame observations in order and compare the map with the dataset's ground-truth map.

    The metrics are taken along the dataset's true path (``true_pose`` where the frames have one)
    with the true fields of view, whatever poses the frames were fused at.

    Parameters
    ----------
    manifest : Manifest
        The dataset the observations come from.
    observations : list of FrameObservation
        The frames in order (:func:`observe_frame`).
    config : PipelineConfig
        Its ``grid`` and ``mapping`` fuse; its obstacle range is the range of the views.
    stereo : StereoCamera, optional
        The calibration the frames were matched with (default: the manifest's).
    floor, mount, odometry, fusion
        Carried into the :class:`MapRun` (see there).
    """
    stereo = manifest.calibration if stereo is None else stereo
    config = _on_true_map(manifest, config)
    range_m = config.obstacle_config.max_range_m
    fused = fuse(observations, grid=config.grid, config=config.mapping, resolution_m=config.resolution_m,
                 view_reach_m=range_m + 2.0)
    tiles = fused if isinstance(fused, TiledOccupancyGrid) else None
    last_pose = observations[-1].pose if observations else None
    occupancy = fused if tiles is None else tiles.to_grid(tiles.map_window(last_pose))
    _warn_outside(observations if tiles is None else [], occupancy)     # (a map that grows holds every frame)
    metrics, gt = None, None
    if manifest.ground_truth_map is not None:
        gt = read_ros_map(manifest.ground_truth_map)
        if isinstance(fused, TiledOccupancyGrid):
            try:
                compared = fused.to_grid(gt.grid)           # the map on the ground truth's window
            except ValueError:
                compared = None                             # not on the map's lattice: no metrics
        else:
            aligned = ros_map_on_grid(gt, occupancy.grid)   # a fixed window: compared where the two overlap
            compared, gt = (occupancy, aligned) if aligned is not None else (None, gt)
        if compared is None:
            warnings.warn(f"no metrics: the ground-truth map {manifest.ground_truth_map} has cells of "
                          f"{gt.grid.resolution_m:g} m at origin ({gt.grid.origin_x_m:g}, {gt.grid.origin_y_m:g}), "
                          f"which do not fall on the map's cells of {occupancy.grid.resolution_m:g} m", stacklevel=2)
        elif gt.grid.shape == compared.grid.shape:
            true_frames = [replace(f, pose=f.true_pose, pose_3d=f.true_pose_3d) if f.true_pose is not None else f
                           for f in manifest.frames]
            views = views_of_frames(true_frames, stereo, range_m=config.obstacle_config.max_range_m, mount=mount)
            metrics = map_metrics(compared, gt, path_xy=np.array([f.pose for f in true_frames]), views=views)
    return MapRun(grid=occupancy, observations=observations, manifest=manifest, metrics=metrics,
                  ground_truth_map=gt, floor=floor, mount=mount, odometry=odometry, fusion=fusion,
                  range_m=range_m, tiles=tiles)


def _warn_outside(observations: list[FrameObservation], occupancy: OccupancyGrid) -> None:
    """A warning when frames were taken outside the map, or when the map observed no cell at all."""
    grid = occupancy.grid
    if observations:
        rows, cols = grid.cells_from_xy(np.array([o.pose[:2] for o in observations], dtype=np.float64))
        outside = [o.index for o, inside in zip(observations, grid.inside(rows, cols)) if not inside]
        if outside:
            x0, y0 = grid.origin_x_m, grid.origin_y_m
            warnings.warn(f"{len(outside)} of {len(observations)} frames were taken outside the map "
                          f"[{x0:g}, {x0 + grid.width_m:g}] x [{y0:g}, {y0 + grid.height_m:g}] m (frame(s) "
                          f"{', '.join(str(k) for k in outside[:5])}{', ...' if len(outside) > 5 else ''}); "
                          "give a --size and --origin that cover the path", stacklevel=3)
    if observations and not (~occupancy.unknown).any():
        warnings.warn("the map observed no cell: every frame's points fell outside it or none were found; "
                      "check the poses, --size and --origin", stacklevel=3)


def check_map(run: MapRun) -> None:
    """Raise when a run saw nothing: no frame put a single point into the map (an empty map is no result).

    Raises
    ------
    ValueError
        With the likely causes: the mapping range, the camera mount, the images.
    """
    seen = sum(len(o.obstacle_points_world) + len(o.floor_points_world) for o in run.observations)
    if seen:
        return
    height = f"{run.floor.height_m:.2f} m" if run.floor is not None and run.floor.success else "unknown"
    raise ValueError(f"the map of {len(run.observations)} frames is empty: no frame saw a floor or obstacle point "
                     f"within the mapping range of {run.range_m:.1f} m (camera height {height}). A camera high above "
                     "the floor sees it only farther away: raise --max-range; check the camera mount (mrstereo info) "
                     "or leave it out to have the floor estimated")


def views_of_frames(frames, stereo: StereoCamera, *, range_m: float = MAPPING_MAX_RANGE_M,
                    mount: CameraMount | None = None) -> list[tuple]:
    """Field-of-view wedges ``(x, y, heading, half_fov, range)`` of frames (anything with ``pose``, ``pan_rad``).

    The heading is the robot's plus the head pan plus the camera's heading on the robot (the optical axis of
    ``mount``'s rectified camera, projected on the floor; 0 without a mount).
    """
    half = math.atan2(stereo.size[0] / 2.0, stereo.focal_px)
    offset = 0.0
    if mount is not None:
        T = mount.T_base_from_rectified(stereo.left.R)
        offset = math.atan2(T[1, 2], T[0, 2]) if abs(T[1, 2]) > 1e-12 else 0.0
    return [(f.pose[0], f.pose[1], f.pose[2] + f.pan_rad + offset, half, range_m) for f in frames]


def write_map_outputs(run: MapRun, out_dir: str | os.PathLike, *, planned_path=None) -> dict[str, Path]:
    """Write map.pgm + map.yaml (ROS map_server), map.png, log_odds.npy and metrics.json; for a map that grew
    also tiles.npz and overview.png + overview.yaml (docs/mapping.md, "A long drive").

    metrics.json holds the comparison with the ground-truth map (when there is
    one) and ``floor``: the floor of the run with its confidence.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_ros_map(out / "map.yaml", run.grid.to_ros_map())
    run.grid.save_log_odds(out / "log_odds.npy")
    files = {"map_yaml": out / "map.yaml", "map_pgm": out / "map.pgm", "map_png": out / "map.png",
             "log_odds": out / "log_odds.npy"}
    report = run.metrics.to_dict() if run.metrics is not None else {}
    if run.floor is not None:
        report["floor"] = run.floor.summary()
    if run.mount is not None:
        report["mount"] = mount_entry(run.mount)
    if run.mount_warning:
        report["mount_warning"] = run.mount_warning
    g = run.grid.grid
    report["map_window"] = {"origin_m": [g.origin_x_m, g.origin_y_m], "size_m": [g.width_m, g.height_m],
                            "resolution_m": g.resolution_m, "range_m": run.range_m,
                            "points_outside": int(run.grid.points_outside)}
    report.update(run.pose_metrics())
    if report:
        with atomic_write(out / "metrics.json") as tmp:
            tmp.write_text(json.dumps(report, indent=2))
        files["metrics"] = out / "metrics.json"
    path = np.array([o.pose for o in run.observations]) if run.observations else None
    views = views_of_frames(run.observations, run.manifest.calibration, range_m=run.range_m, mount=run.mount)
    plot_map(run.grid, out / "map.png", robot_path=path, fov_views=views,
             planned_path=planned_path, ground_truth=run.ground_truth_map,
             title=f"occupancy grid ({run.grid.config.fusion})")
    if run.tiles is not None:           # the whole map that grew: its tiles and an overview image
        run.tiles.save(out / "tiles.npz")
        files.update(tiles=out / "tiles.npz", overview_yaml=out / "overview.yaml",
                     overview_png=run.tiles.write_overview(out / "overview.yaml"))
    return files
