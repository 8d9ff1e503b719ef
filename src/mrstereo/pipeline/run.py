"""The whole chain for a sequence: rectify -> match -> reject -> 3D -> occupancy grid.

Per frame (independent, so it can run anywhere): :func:`observe_frame` reads a stereo pair of a
dataset manifest, rectifies it with the calibration, matches it with the multi-range approach
(paper eq. 9-12), rejects uniform patches (eq. 13), triangulates (eq. 14-16), splits obstacle
from floor points in the robot frame and moves them into the world frame with the frame's pose.
Then an ordered reduction, :func:`map_from_observations`, fuses them into a log-odds (or union)
occupancy grid (paper section 5.2) and compares it with the ground-truth map.
:func:`build_map` runs both over a manifest; :func:`write_map_outputs` writes the ROS map,
figures and metrics. Without a camera mount, :func:`floor_for_run` estimates the floor once from
the first frames that show enough of it and the run uses that mount (reported, with its
confidence, in ``MapRun.floor`` and metrics.json). Conventions: docs/conventions.md.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..camera import CameraMount, StereoCamera, mount_entry
from ..geometry.freespace import FreeSpaceConfig
from ..geometry.ground import GroundPlane, T_robot_from_cam_ground, ground_from_mount
from ..geometry.obstacles import MAPPING_MAX_RANGE_M, ObstacleConfig
from ..io import atomic_write
from ..mapping import GridSpec, read_ros_map, write_ros_map
from ..mapping.figures import plot_map
from ..mapping.fusion import FrameObservation, fuse
from ..mapping.metrics import MapMetrics, map_metrics
from ..mapping.occupancy import MappingConfig, OccupancyGrid, view_cells
from ..matching.config import MatchingConfig
from ..profiling import stage
from ..recordings.layouts import read_recording
from ..recordings.manifest import FrameRecord, Manifest, frame_pair, pose_3d_of
from ..rejection import RejectionConfig
from ..transforms import T_from_planar, transform_points
from .frame import PairObstacles, obstacles_from_pair

__all__ = ["PipelineConfig", "MapRun", "observe_frame", "build_map", "map_from_observations", "floor_for_run",
           "write_map_outputs", "views_of_frames"]


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
    obstacles : ObstacleConfig
        Height band, range limit and floor estimation; a map keeps points within
        :data:`~mrstereo.geometry.obstacles.MAPPING_MAX_RANGE_M`.
    mapping : MappingConfig
        Sensor model and fusion (log-odds or the paper's union).
    grid : GridSpec
        Map extent and resolution.
    free_space : FreeSpaceConfig or None
        The free-space boundary (:mod:`mrstereo.geometry.freespace`): where the floor ends in
        each image column, an obstacle base that the matcher cannot measure (a wall without
        texture); its points join the frame's obstacle points. None: off.
    """

    preset: str = "mapping"
    max_disparity_px: float | None = None
    matching: MatchingConfig | None = None
    rejection: RejectionConfig = field(default_factory=RejectionConfig)
    obstacles: ObstacleConfig = field(default_factory=lambda: ObstacleConfig(max_range_m=MAPPING_MAX_RANGE_M))
    mapping: MappingConfig = field(default_factory=MappingConfig)
    grid: GridSpec = field(default_factory=GridSpec)
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
            "rejection": config.rejection, "config": config.obstacles, "free_space": config.free_space}


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
        cells = None if config.mapping.map_occlusion_p is not None else \
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


def floor_for_run(manifest: Manifest, stereo: StereoCamera | None = None, *,
                  config: PipelineConfig = PipelineConfig(), prefer_raw: bool = False, max_frames: int = 10,
                  n_frames: int = 3) -> tuple[CameraMount, GroundPlane]:
    """The camera mount of a run and the floor it implies: given, or estimated from the first frames.

    With a mount in the manifest (``mount:`` or ``rig:``) that mount. Without,
    the floor is fitted (``config.obstacles.ground_method``, RANSAC) in the
    first ``max_frames`` frames until ``n_frames`` fits are confident
    (:attr:`GroundPlane.confident`); the median height, tilt and roll of those
    is the mount of the whole run (the camera is assumed to look along the
    robot's x axis, on its vertical axis: a floor says nothing about yaw or
    the horizontal offset). With no confident fit, the fit with the largest
    inlier share is used and reported as not confident.

    Returns
    -------
    (CameraMount, GroundPlane)
        The mount, and the floor with its confidence (``inlier_share``,
        ``residual_m``) and in ``message`` which frames it came from.

    Raises
    ------
    ValueError
        No floor in any of the first ``max_frames`` frames.
    """
    if not isinstance(manifest, Manifest):
        raise TypeError(f"manifest must be a Manifest, got {type(manifest).__name__}")
    stereo = manifest.calibration if stereo is None else stereo
    if manifest.mount is not None:
        return manifest.mount, ground_from_mount(manifest.mount, R_rect_from_cam=stereo.left.R)
    stereo = replace(stereo, mount=None)
    fits, best = [], None
    for k, record in enumerate(manifest.frames[:max(1, int(max_frames))]):
        left, right, rectified = frame_pair(record, prefer_raw=prefer_raw)
        ground = obstacles_from_pair(left, right, stereo, rectified=rectified, mount=None,
                                     **pair_options(replace(config, free_space=None))).obstacles.ground
        if ground.success and (best is None or ground.inlier_share > best[1].inlier_share):
            best = (k, ground)
        if ground.confident:
            fits.append((k, ground))
            if len(fits) >= n_frames:
                break
    if best is None:
        raise ValueError(f"no floor found in the first {min(len(manifest.frames), max_frames)} frames of "
                         f"{manifest.root}; give the camera mount (--mount x,y,z,roll,pitch,yaw or --height/--tilt, "
                         "or mount:/rig: in the manifest or stereo YAML)")
    used = fits or [best]
    med = {name: float(np.median([getattr(g, name) for _, g in used]))
           for name in ("height_m", "tilt_rad", "roll_rad", "inlier_share", "residual_m")}
    frames = ", ".join(str(k) for k, _ in used)
    ground = GroundPlane(**med, success=True, method=used[0][1].method,
                         n_inliers=int(np.median([g.n_inliers for _, g in used])),
                         message=f"estimated: median of {len(used)} floor fit(s), frame(s) {frames}"
                                 + ("" if fits else " (none confident)"))
    # the estimate is of the rectified left frame; the mount is of the raw camera (p_rect = R p_raw)
    return CameraMount.from_rectified(T_robot_from_cam_ground(ground), stereo.left.R), ground


def build_map(manifest: Manifest | str | os.PathLike, *, config: PipelineConfig = PipelineConfig(),
              calibration: StereoCamera | None = None, prefer_raw: bool = False,
              progress: bool = True, workers: int | None = None, scheduler=None,
              processes: bool = False, odometry: str = "given", align=None) -> MapRun:
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
        the dataset's files). With neither, everything runs in this process.
        The fused map is the same, bit for bit, in every case
        (:func:`mrstereo.pipeline.parallel.map_ordered` keeps the frame order).
    processes : bool
        With ``workers``: worker processes instead of threads.
    odometry : {"given", "visual"}
        ``"visual"``: the poses come from stereo visual odometry
        (:func:`mrstereo.pipeline.odometry_from_manifest`, run in order before the
        matching), starting at the first frame's given pose; frames where tracking is
        lost are left out of the map.
    align : FusionConfig or True, optional
        Correct the given poses with visual odometry (with ``odometry="given"``): each step of
        the given odometry fused with the visual odometry's (:func:`mrstereo.odometry.fusion.
        fuse_odometry`); every frame is mapped, those visual odometry lost on the given steps.
    """
    from functools import partial

    from .parallel import map_ordered

    if not isinstance(manifest, Manifest):
        manifest = read_recording(manifest)
    if not isinstance(config, PipelineConfig):
        raise TypeError(f"config must be a PipelineConfig, got {type(config).__name__}")
    if odometry not in ("given", "visual"):
        raise ValueError(f"odometry must be 'given' or 'visual', got {odometry!r}")
    align = None if align is False else align
    if align is not None and odometry != "given":
        raise ValueError("align corrects the given odometry with visual odometry: use it with odometry='given'")
    stereo = manifest.calibration if calibration is None else calibration
    prefer_raw = prefer_raw or calibration is not None
    mount, floor = floor_for_run(manifest, stereo, config=config, prefer_raw=prefer_raw)
    items = list(enumerate(manifest.frames))
    vo = fused = None
    if odometry == "visual" or align is not None:
        from .odometry import odometry_from_manifest

        run_mount = replace(manifest, mount=mount)     # the floor the map uses
        vo = odometry_from_manifest(run_mount, calibration=calibration, progress=progress)
    if odometry == "visual":
        items = [(k, replace(record, pose=None, pose_3d=pose_3d_of(T)))
                 for (k, record), T, ok in zip(items, vo.T_world_from_base, vo.tracked) if ok]
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
    return map_from_observations(manifest, observations, config=config, stereo=stereo, floor=floor, mount=mount,
                                 odometry=vo, fusion=fused)


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
    occupancy = fuse(observations, grid=config.grid, config=config.mapping)
    metrics, gt = None, None
    if manifest.ground_truth_map is not None:
        gt = read_ros_map(manifest.ground_truth_map)
        if gt.grid.shape == occupancy.grid.shape:
            true_frames = [replace(f, pose=f.true_pose, pose_3d=f.true_pose_3d) if f.true_pose is not None else f
                           for f in manifest.frames]
            views = views_of_frames(true_frames, stereo, range_m=config.obstacles.max_range_m)
            metrics = map_metrics(occupancy, gt, path_xy=np.array([f.pose for f in true_frames]), views=views)
    return MapRun(grid=occupancy, observations=observations, manifest=manifest, metrics=metrics,
                  ground_truth_map=gt, floor=floor, mount=mount, odometry=odometry, fusion=fusion)


def views_of_frames(frames, stereo: StereoCamera, *, range_m: float = MAPPING_MAX_RANGE_M) -> list[tuple]:
    """Field-of-view wedges ``(x, y, heading, half_fov, range)`` of frames (anything with ``pose``, ``pan_rad``)."""
    half = math.atan2(stereo.size[0] / 2.0, stereo.focal_px)
    return [(f.pose[0], f.pose[1], f.pose[2] + f.pan_rad, half, range_m) for f in frames]


def write_map_outputs(run: MapRun, out_dir: str | os.PathLike, *, planned_path=None) -> dict[str, Path]:
    """Write map.pgm + map.yaml (ROS map_server), map.png, log_odds.npy and metrics.json.

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
    report.update(run.pose_metrics())
    if report:
        with atomic_write(out / "metrics.json") as tmp:
            tmp.write_text(json.dumps(report, indent=2))
        files["metrics"] = out / "metrics.json"
    path = np.array([o.pose for o in run.observations]) if run.observations else None
    plot_map(run.grid, out / "map.png", robot_path=path, fov_views=views_of_frames(run.observations,
                                                                                   run.manifest.calibration),
             planned_path=planned_path, ground_truth=run.ground_truth_map,
             title=f"occupancy grid ({run.grid.config.fusion})")
    return files
