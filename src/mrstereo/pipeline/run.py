"""A recording to a map: its frames through a :class:`~mrstereo.pipeline.mapper.StereoMapper`.

:func:`build_map` drives the mapper over a recording's frames (on workers when asked),
:func:`finish_map` compares the map with the recording's ground-truth map, :func:`write_map_outputs`
writes the results. User guide: docs/mapping.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import itertools
import json
import os
import warnings
from contextlib import nullcontext
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..camera import CameraMount, StereoCamera, mount_entry
from ..geometry.ground import GroundPlane
from ..geometry.obstacles import MAPPING_MAX_RANGE_M
from ..io import atomic_write
from ..mapping import read_ros_map, write_ros_map
from ..mapping.figures import plot_map
from ..mapping.fusion import FrameObservation
from ..mapping.heights import HeightLayer
from ..mapping.metrics import MapMetrics, map_metrics
from ..mapping.occupancy import OccupancyGrid
from ..mapping.rosmap import ros_map_on_grid
from ..mapping.tiles import TiledOccupancyGrid
from ..recordings.frames import FrameSource
from ..recordings.layouts import read_recording
from ..recordings.manifest import Manifest, pose_3d_of, rebased
from ..rejection.streams import StreamCheck
from ..transforms import T_from_planar
from .._executor import read_ahead
from .mapper import PipelineConfig, StereoMapper, observe, views_of_poses
from .odometry import manifest_of

__all__ = ["PipelineConfig", "MapRun", "build_map", "map_frames", "finish_map", "map_from_observations",
           "write_map_outputs", "check_map", "recording_source", "check_pair_streams"]


@dataclass
class MapRun:
    """Result of :func:`build_map`."""

    grid: OccupancyGrid
    observations: list[FrameObservation]
    manifest: Manifest
    metrics: MapMetrics | None
    ground_truth_map: object | None
    floor: GroundPlane | None = None
    """The floor of the run: the given mount's, or the estimate from the first frames."""
    mount: CameraMount | None = None
    """The camera mount every frame used."""
    odometry: dict | None = None
    """Visual odometry figures (``{"visual_odometry": {...}}``) when the poses came from it."""
    fusion: object | None = None
    """The :class:`mrstereo.odometry.fusion.FusedOdometry` when the given poses were fused with visual odometry."""
    range_m: float = MAPPING_MAX_RANGE_M
    """The mapping range of the run (its obstacle configuration's ``max_range_m``)."""
    mount_warning: str | None = None
    """Why the given mount was not used (:class:`~mrstereo.geometry.floor.FloorVote`), None when it was (or none was given)."""
    trajectory: tuple[np.ndarray, np.ndarray] | None = None
    """``(stamps_s (N,), T_world_from_base (N, 4, 4))`` of the mapped frames (trajectory.txt)."""
    tiles: TiledOccupancyGrid | None = None
    """The whole map when it grew (``config.grid`` None); ``grid`` is then its dense window
    (:meth:`~mrstereo.mapping.tiles.TiledOccupancyGrid.map_window`: all of it unless it is too large)."""
    n_points: int | None = None
    """The floor and obstacle points the frames put into the map (None: count ``observations``' points)."""

    def pose_metrics(self) -> dict:
        """Odometry and alignment figures for metrics.json (empty when the given poses were used)."""
        out = {}
        out.update(self.odometry or {})
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


def recording_source(recording, *, prefer_raw: bool = False):
    """The :class:`~mrstereo.recordings.sources.FrameSource` of a recording (a Manifest or a path): the one
    place a map run turns a recording into frames."""
    from ..recordings.sources import RecordingSource

    manifest = recording if isinstance(recording, Manifest) else read_recording(recording)
    return RecordingSource(manifest, prefer_raw=prefer_raw)


def map_frames(mapper: StereoMapper, frames, *, workers: int | None = None, scheduler=None,
               processes: bool = False, progress: bool = True, total: int | None = None) -> None:
    """Drive ``mapper`` over ``frames`` in order: the first frames until the floor is known one by one, the
    rest observed on ``workers`` (threads, or Dask processes / an existing ``scheduler``) in chunks and
    integrated in order -- the same map, bit for bit, in every case."""
    import contextlib
    from functools import partial

    from tqdm.auto import tqdm

    from .._executor import dask_client, map_ordered, numba_thread_safe
    from .._interrupt import reached

    frames = _counted(frames, reached)
    with tqdm(total=total, desc="mapping", unit="frame", disable=not progress) as bar:
        if workers is None and scheduler is None:
            for frame in frames:
                mapper.step_frame(frame)
                bar.update(1)
            mapper.finish()
            return
        use_dask = scheduler is not None or processes or not numba_thread_safe()
        client = dask_client(workers=workers if scheduler is None else None, scheduler=scheduler,
                             processes=processes) if use_dask else contextlib.nullcontext()
        with client as c:                               # (started first: a Ctrl-C meets it as it starts)
            first = mapper.settle(frames)
            bar.update(mapper.frames_held)
            if first is None:
                mapper.finish()
                return
            mapper.check_streams(first)
            pending = [first]
            observe_one = partial(observe, stereo=mapper.stereo, mount=mapper.mount, config=mapper.config,
                                  keep_images=mapper.odometry != "given")
            chunk = 8 * (workers or 2)
            where = {"scheduler": c} if use_dask else {"workers": workers}
            while pending:
                for frame in frames:
                    mapper.check_streams(frame)
                    pending.append(frame)
                    if len(pending) >= chunk:
                        break
                for item in map_ordered(observe_one, pending, progress=False, desc="mapping",
                                        label=lambda f: f"frame {f.index}", **where):
                    mapper.integrate(item)
                bar.update(len(pending))
                pending = []
        mapper.finish()


def _counted(frames, reached):
    """``frames``, the interrupt tests' point ``frame`` reached as each is taken (mrstereo._interrupt)."""
    for frame in frames:
        yield frame
        reached("frame")


def build_map(manifest: Manifest | FrameSource | str | os.PathLike, *, config: PipelineConfig = PipelineConfig(),
              calibration: StereoCamera | None = None, prefer_raw: bool = False,
              progress: bool = True, workers: int | None = None, scheduler=None,
              processes: bool = False, odometry: str = "auto", align=None, check_mount: bool = True,
              keep_points: bool = True) -> MapRun:
    """Map a whole recording with a :class:`~mrstereo.pipeline.mapper.StereoMapper`; compare with the GT map if any.

    Parameters
    ----------
    manifest : Manifest, FrameSource or path
        The recording (docs/dataset.md), or a source that knows its frames' poses up front (a
        :class:`~mrstereo.recordings.bag.BagSource`: the bag read message by message, nothing written).
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
        Observe the frames on an existing Dask cluster. The map is the same, bit for bit, in every case.
    processes : bool
        With ``workers``: worker processes instead of threads.
    odometry : {"auto", "given", "visual"}
        ``"auto"``: the recording's poses when it has some, else visual odometry. ``"visual"``: stereo
        visual odometry frame by frame (the pose each frame has when it is mapped, as a robot has it),
        starting at the first frame's given pose; frames where tracking is lost are left out of the map.
    align : FusionConfig or True, optional
        Correct the given poses with visual odometry (with ``odometry="given"``): each step of
        the given odometry fused with the visual odometry's (:func:`mrstereo.odometry.fusion.
        fuse_odometry`); every frame is mapped, those visual odometry lost on the given steps.
    check_mount : bool
        Check a given mount against the floor seen in the first frames and use the seen floor when they
        disagree (``MapRun.mount_warning`` says so).
    keep_points : bool
        Keep every frame's world points in ``MapRun.observations`` (to fuse again or replay them); False:
        only their poses and counts, so memory stays flat however long the recording.
    """
    source = manifest if isinstance(manifest, FrameSource) else None
    if source is not None:
        manifest = manifest_of(source)
    elif not isinstance(manifest, Manifest):
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
    config = _on_true_map(manifest, config.for_rig(stereo))
    mapper = StereoMapper(stereo, manifest.mount, config, check_mount=check_mount, odometry=odometry,
                          pose_frame_mount=manifest.pose_frame_mount, keep_observations=keep_points or "poses",
                          name=str(manifest.root))
    fused = None
    with recording_source(manifest, prefer_raw=prefer_raw) if source is None else nullcontext(source) as frames:
        frames = read_ahead(frames, depth=2 if workers is None else workers + 1)     # decoded while matching
        if align is not None:
            fused, frames = _aligned(mapper, manifest, frames, calibration, progress, align, source)
        map_frames(mapper, frames, workers=workers, scheduler=scheduler, processes=processes, progress=progress,
                   total=len(manifest.frames))
    return finish_map(mapper, rebased(manifest, mapper.mount), fusion=fused)


def _aligned(mapper: StereoMapper, manifest: Manifest, frames, calibration, progress: bool, align, source=None):
    """The floor settled on the first frames, the given poses (on its base) fused with visual odometry of the
    whole recording (read a second time: from ``source`` when given); the frames with the fused poses."""
    from ..odometry.fusion import FusionConfig, fuse_odometry

    first = mapper.settle(frames)
    base = rebased(manifest, mapper.mount)
    _, vo = with_visual_odometry(base, calibration=calibration, progress=progress, source=source)
    fused = fuse_odometry([f.pose for f in base.frames], vo.poses, vo.tracked,
                          config=FusionConfig() if align is True else align)
    poses = {k: T_from_planar(*p) for k, p in enumerate(fused.poses)}
    mapper.odometry, mapper.pose_frame_mount = "given", mapper.mount

    def with_fused(stream):
        for frame in stream:
            yield replace(frame, T_world_from_base=poses[frame.index])
    return fused, with_fused(itertools.chain(mapper.take_held(), [] if first is None else [first], frames))


def finish_map(mapper: StereoMapper, manifest: Manifest, *, fusion=None) -> MapRun:
    """The :class:`MapRun` of a mapper that has taken every frame of ``manifest``: its grid compared with
    the recording's ground-truth map (along the true path, with the true fields of view)."""
    occupancy = mapper.occupancy()
    if mapper.outside_warning():
        warnings.warn(mapper.outside_warning(), stacklevel=3)
    if mapper.trajectory_index and not (~occupancy.unknown).any():
        warnings.warn("the map observed no cell: every frame's points fell outside it or none were found; "
                      "check the poses, --size and --origin", stacklevel=3)
    metrics, gt = _compare(mapper, occupancy, manifest)
    return MapRun(grid=occupancy, observations=mapper.observations, manifest=manifest, metrics=metrics,
                  ground_truth_map=gt, floor=mapper.floor, mount=mapper.mount, fusion=fusion,
                  range_m=mapper.range_m, mount_warning=mapper.mount_warning, odometry=mapper.odometry_metrics(),
                  tiles=mapper.grid if isinstance(mapper.grid, TiledOccupancyGrid) else None, n_points=mapper.n_points,
                  trajectory=(np.array(mapper.trajectory_stamps_s), np.array(mapper.trajectory_T))
                  if mapper.trajectory_T else None)

def with_visual_odometry(manifest: Manifest, *, calibration: StereoCamera | None = None, progress: bool = False,
                         source=None):
    """``(recording, run)``: the recording with every frame's pose from stereo visual odometry
    (:func:`mrstereo.pipeline.odometry.odometry_from_manifest`, its images from ``source`` when given; a
    lost frame gets the motion model's prediction, ``run.tracked`` says which), for a recording without poses."""
    from .odometry import odometry_from_manifest

    vo = odometry_from_manifest(manifest, calibration=calibration, progress=progress, source=source)
    frames = tuple(replace(f, pose=None, pose_3d=pose_3d_of(T)) for f, T in zip(manifest.frames, vo.T_world_from_base))
    return replace(manifest, frames=frames, has_poses=True), vo


def _on_true_map(manifest: Manifest, config: PipelineConfig) -> PipelineConfig:
    return config_for_recording(config, manifest.ground_truth_map)


def config_for_recording(config: PipelineConfig, ground_truth_map=None) -> PipelineConfig:
    """``config`` with the window of the recording's ground-truth map (at ``config.resolution_m``) when it has
    one and no window is given: the map is compared with it cell by cell (``map`` and ``live`` alike)."""
    if config.grid is not None or ground_truth_map is None:
        return config
    return replace(config, grid=replace(read_ros_map(ground_truth_map).grid, resolution_m=config.resolution_m))


def map_from_observations(manifest: Manifest, observations: list[FrameObservation], *,
                          config: PipelineConfig = PipelineConfig(), stereo: StereoCamera | None = None,
                          floor: GroundPlane | None = None, mount=None, fusion=None) -> MapRun:
    """Fuse a run's frame observations in order (:meth:`StereoMapper.add`) and compare the map with the
    dataset's ground-truth map (:func:`finish_map`). ``floor`` and ``mount`` are those the frames used."""
    stereo = manifest.calibration if stereo is None else stereo
    mapper = StereoMapper(stereo, mount, _on_true_map(manifest, config), check_mount=False, keep_observations=True,
                          name=str(manifest.root))
    for obs in observations:
        mapper.add(obs)
    run = finish_map(mapper, manifest, fusion=fusion)
    run.floor = floor
    return run


def _compare(mapper: StereoMapper, occupancy: OccupancyGrid, manifest: Manifest):
    """``(metrics, ground truth)`` of a map against the recording's ground-truth map (None, None without one),
    along the true path with the true fields of view, whatever poses the frames were fused at."""
    if manifest.ground_truth_map is None:
        return None, None
    gt = read_ros_map(manifest.ground_truth_map)
    if isinstance(mapper.grid, TiledOccupancyGrid):
        try:
            compared = mapper.grid.to_grid(gt.grid)         # the map on the ground truth's window
        except ValueError:
            compared = None                                 # not on the map's lattice: no metrics
    else:
        aligned = ros_map_on_grid(gt, occupancy.grid)       # a fixed window: compared where the two overlap
        compared, gt = (occupancy, aligned) if aligned is not None else (None, gt)
    if compared is None:
        warnings.warn(f"no metrics: the ground-truth map {manifest.ground_truth_map} has cells of "
                      f"{gt.grid.resolution_m:g} m at origin ({gt.grid.origin_x_m:g}, {gt.grid.origin_y_m:g}), "
                      f"which do not fall on the map's cells of {occupancy.grid.resolution_m:g} m", stacklevel=3)
        return None, gt
    if gt.grid.shape != compared.grid.shape:
        return None, gt
    path = np.array([f.true_pose if f.true_pose is not None else f.pose for f in manifest.frames])
    views = views_of_poses(path, [f.pan_rad for f in manifest.frames], mapper.stereo, range_m=mapper.range_m,
                           mount=mapper.mount)
    return map_metrics(compared, gt, path_xy=path, views=views), gt


def check_map(run: MapRun) -> None:
    """Raise when a run saw nothing: no frame put a single point into the map (an empty map is no result).

    Raises
    ------
    ValueError
        With the likely causes: the mapping range, the camera mount, the images.
    """
    seen = run.n_points if run.n_points is not None else \
        sum(len(o.obstacle_points_world) + len(o.floor_points_world) for o in run.observations)
    if seen:
        return
    height = f"{run.floor.height_m:.2f} m" if run.floor is not None and run.floor.success else "unknown"
    raise ValueError(f"the map of {len(run.observations)} frames is empty: no frame saw a floor or obstacle point "
                     f"within the mapping range of {run.range_m:.1f} m (camera height {height}). A camera high above "
                     "the floor sees it only farther away: raise --max-range; check the camera mount (mrstereo info) "
                     "or leave it out to have the floor estimated")


def write_map_outputs(run: MapRun, out_dir: str | os.PathLike, *, planned_path=None) -> dict[str, Path]:
    """Write map.pgm + map.yaml (ROS map_server), map.png, log_odds.npy, metrics.json, trajectory.txt (the
    mapped frames' poses, TUM: ``mrstereo plan --start robot`` starts from its last) and the height layer in
    heights/ (:class:`~mrstereo.mapping.heights.HeightLayer`); for a map that grew also
    tiles.npz and overview.png + overview.yaml (docs/mapping.md, "A long drive").

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
    if run.trajectory is not None:
        from ..odometry.trajectory import write_tum

        files["trajectory"] = write_tum(out / "trajectory.txt", *run.trajectory,
                                        comment="mrstereo map: the mapped frames' robot base in the map frame")
    path = np.array([o.pose for o in run.observations]) if run.observations else None
    views = views_of_poses(path if path is not None else [], [o.pan_rad for o in run.observations],
                           run.manifest.calibration, range_m=run.range_m, mount=run.mount)
    plot_map(run.grid, out / "map.png", robot_path=path, fov_views=views,
             planned_path=planned_path, ground_truth=run.ground_truth_map,
             title=f"occupancy grid ({run.grid.config.fusion})")
    files.update(HeightLayer.of(run.grid).save(out / "heights"))      # the height and drop layers
    if run.tiles is not None:           # the whole map that grew: its tiles and an overview image
        run.tiles.save(out / "tiles.npz")
        files.update(tiles=out / "tiles.npz", overview_yaml=out / "overview.yaml",
                     overview_png=run.tiles.write_overview(out / "overview.yaml"))
    return files


def check_pair_streams(manifest: Manifest | FrameSource) -> list[str]:
    """Warn (one ``mrstereo: warning:`` line on the command line) when the first frames of a recording (or a
    source that can be read twice, a bag) show identical or swapped left and right streams
    (:class:`~mrstereo.rejection.streams.StreamCheck`, as a :class:`StereoMapper` does); return the warnings."""
    check = StreamCheck(manifest.calibration, f"dataset {manifest.root}")
    try:
        with recording_source(manifest) if isinstance(manifest, Manifest) else nullcontext(manifest) as source:
            for frame in itertools.islice(source, check.n_frames):
                check.add(frame.index, frame.left, frame.right, rectified=frame.rectified)
    except (OSError, ValueError, TypeError):      # an unreadable frame: the run reports it itself
        pass
    return check.warn()
