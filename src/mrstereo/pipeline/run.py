"""A recording to a map: its frames through a :class:`~mrstereo.pipeline.mapper.StereoMapper`.

:func:`build_map` drives the mapper over a recording's frames (on workers when asked),
:func:`finish_map` makes its :class:`~mrstereo.evaluation.outputs.MapRun` (compared with the recording's
ground-truth map), which :func:`~mrstereo.evaluation.outputs.write_map_outputs` writes.
User guide: docs/mapping.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import itertools
import os
import warnings
from contextlib import nullcontext
from dataclasses import replace

import numpy as np

from ..camera import StereoCamera
from ..evaluation.outputs import MapRun, map_vs_truth
from ..geometry.ground import GroundPlane
from ..mapping import read_ros_map
from ..mapping.fusion import FrameObservation
from ..mapping.tiles import TiledOccupancyGrid
from ..recordings.frames import FrameSource
from ..recordings.layouts import read_recording
from ..recordings.manifest import Manifest, pose_3d_of, rebased
from ..recordings.sources import recording_source
from ..transforms import T_from_planar
from .._executor import read_ahead
from .mapper import PipelineConfig, StereoMapper
from .odometry import manifest_of

__all__ = ["build_map", "map_frames", "finish_map", "map_from_observations", "with_visual_odometry",
           "config_for_recording"]


def map_frames(mapper: StereoMapper, frames, *, workers: int | None = None, scheduler=None,
               processes: bool = False, progress: bool = True, total: int | None = None) -> None:
    """Drive ``mapper`` over ``frames`` in order: the first frames until the floor is known one by one, the
    rest observed on ``workers`` (threads, or Dask processes / an existing ``scheduler``) in chunks and
    integrated in order -- the same map, bit for bit, in every case."""
    import contextlib

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
            observe_one = mapper.observer(keep_images=mapper.odometry != "given")
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
              keep_points: bool = True, prior=None) -> MapRun:
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
    prior : path, RosMap or OccupancyGrid, optional
        A saved map to continue on (:class:`~mrstereo.pipeline.mapper.StereoMapper`'s ``prior``).
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
    config = config_for_recording(config.for_rig(stereo), manifest.ground_truth_map)
    mapper = StereoMapper(stereo, manifest.mount, config, check_mount=check_mount, odometry=odometry,
                          pose_frame_mount=manifest.pose_frame_mount, keep_observations=keep_points or "poses",
                          name=str(manifest.root), prior=prior)
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
    metrics, gt = map_vs_truth(mapper, occupancy, manifest)
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
    mapper = StereoMapper(stereo, mount, config_for_recording(config, manifest.ground_truth_map), check_mount=False,
                          keep_observations=True,
                          name=str(manifest.root))
    for obs in observations:
        mapper.add(obs)
    run = finish_map(mapper, manifest, fusion=fusion)
    run.floor = floor
    return run
