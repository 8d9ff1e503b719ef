"""Many datasets at once: per-frame products and a map per dataset, resumable, on Dask.

For every frame of every dataset :func:`run_batch` runs the chain of
:func:`mrstereo.geometry.pair.scan_from_pair` (rectify -> match -> reject (eq. 13) -> 3D
(eq. 14-16) -> scan) once, writes its products under ``OUT/<dataset>/frames/``, then fuses each
dataset's frames into ``OUT/<dataset>/map/`` (the same map as ``mrstereo map``, bit for bit).
Every result carries a fingerprint of what it was computed from, so a re-run keeps what is still
valid and computes the rest; a failed frame is listed in ``summary.json`` and retried next run.
The layout and the resume rules: docs/scale-out.md ("Batch"). Conventions: docs/conventions.md.
"""
from __future__ import annotations

import contextlib
import itertools
import json
import os
from dataclasses import dataclass
from pathlib import Path

from ..camera import StereoCamera
from ..evaluation.outputs import BatchSummary, DatasetSummary, map_dir_current, write_map_dir
from ..io import Inputs, atomic_write, check_output_dir, check_outputs, remove_stale_temporaries
from ..mapping.fusion import FrameObservation, world_observation
from ..mapping.observations import (bag_fingerprint, claim_folder, dataset_fingerprint, digest, frame_fingerprint,
                                    frame_outputs, map_fingerprint, output_names, remove_stale_frames, resume_frame,
                                    save_frame)
from ..recordings.bag import BagSource, bag_inputs
from ..recordings.layouts import is_bag, read_recording
from ..recordings.manifest import FrameRecord, Manifest, frame_pair, rebased
from ..recordings.sources import StereoFrame
from .._executor import ItemFailure, dask_client, map_ordered
from .mapper import StereoMapper
from .run import PipelineConfig, build_map, map_from_observations, with_visual_odometry

__all__ = ["FrameTask", "DatasetSummary", "BatchSummary", "process_frame", "run_batch", "SUMMARY_NAME"]

SUMMARY_NAME = "summary.json"


@dataclass(frozen=True)
class FrameTask:
    """One frame to process (small and picklable: paths, not images)."""

    record: FrameRecord
    index: int
    stereo: StereoCamera
    observe: object
    """The mapper's per-frame chain (:meth:`~mrstereo.pipeline.mapper.StereoMapper.observer`)."""
    frames_dir: Path
    dataset: str
    prefer_raw: bool = False
    fingerprint: str = ""
    """What the frame's results are computed from (kept in its ``.obs.npz``)."""


def _read_task(task: FrameTask) -> tuple[FrameTask, tuple]:
    """``task`` -> ``(task, pair)``: the frame's images decoded (by the run's reader thread)."""
    return task, frame_pair(task.record, prefer_raw=task.prefer_raw)


def process_frame(task: FrameTask | tuple[FrameTask, tuple]) -> FrameObservation:
    """Run the chain on one frame, write its four files, return what it adds to the map.

    ``task`` may come with its images read ahead (:func:`_read_task`). The observation is the one the
    :class:`~mrstereo.pipeline.mapper.StereoMapper` fuses for the same frame, pose and options.
    """
    task, pair = task if isinstance(task, tuple) else (task, None)
    left, right, rectified = frame_pair(task.record, prefer_raw=task.prefer_raw) if pair is None else pair
    frame = StereoFrame(index=task.index, stamp_s=0.0, left=left, right=right, rectified=rectified,
                        pan_rad=float(task.record.pan_rad))
    observed = task.observe(frame)
    observation = world_observation(observed, tuple(float(v) for v in task.record.pose), task.stereo)
    save_frame(frame_outputs(task.frames_dir, task.index), observation, fingerprint=task.fingerprint,
               disparity_px=observed.disparity_px, points_robot_image=observed.points_robot_image,
               left_rect=observed.left_rect, scan=observed.scan,
               comment=f"mrstereo {task.dataset} frame {task.index} (frame: robot, metres)")
    return observation


@dataclass
class _Dataset:
    """What :func:`run_batch` plans for one dataset."""

    name: str
    manifest: Manifest
    folder: Path
    fingerprints: list[str]
    map_fingerprint: str
    loaded: dict[int, FrameObservation | None]
    map_kept: bool = False


def _plan(m: Manifest, name: str, out: Path, config: PipelineConfig, maps: bool, check_mount: bool) -> _Dataset:
    """Claim the dataset's output folder, clean a killed run's temporaries and the files of frames no longer
    in the recording, read back what is still valid."""
    folder = out / name
    frames_dir = folder / "frames"
    frames_dir.mkdir(parents=True, exist_ok=True)
    claim_folder(folder, m.root, m.root / "manifest.yaml")
    for where in (frames_dir, folder):
        remove_stale_temporaries(where)
    remove_stale_frames(frames_dir, len(m.frames))
    base = dataset_fingerprint(m, config, floor_frames=10, check_mount=check_mount)
    fingerprints = [frame_fingerprint(base, r) for r in m.frames]
    loaded = {k: resume_frame(frame_outputs(frames_dir, k), fingerprints[k]) for k in range(len(m.frames))}
    plan = _Dataset(name=name, manifest=m, folder=folder, fingerprints=fingerprints,
                    map_fingerprint=map_fingerprint(m, fingerprints, config), loaded=loaded)
    plan.map_kept = maps and all(v is not None for v in loaded.values()) and \
        map_dir_current(folder / "map", plan.map_fingerprint)
    return plan


def _readable(manifest: Manifest):
    """The recording's frames, None for one that cannot be read (the run reports it when it gets there)."""
    for k, record in enumerate(manifest.frames):
        try:
            left, right, rectified = frame_pair(record)
        except (OSError, ValueError):
            yield None
            continue
        yield StereoFrame(index=k, stamp_s=0.0, left=left, right=right, rectified=rectified,
                          T_world_from_base=record.T_world_from_base, pan_rad=float(record.pan_rad))


def _mounted(manifest: Manifest, config: PipelineConfig, check_mount: bool) -> tuple:
    """``(mapper, recording)``: a mapper with the mount (checked) or the floor estimated once, the poses on
    that base, and the poses of visual odometry for a recording without any (as ``mrstereo map`` takes them)."""
    mapper = StereoMapper(manifest.calibration, manifest.mount, config, check_mount=check_mount, name=str(manifest.root))
    for frame in itertools.islice(_readable(manifest), mapper.streams.n_frames):
        if frame is not None:
            mapper.check_streams(frame)                 # duplicated or swapped streams named
    mapper.streams.warn()
    mapper.settle(_readable(manifest))
    mapper.take_held()                                  # (their images: not kept for the run)
    manifest = rebased(manifest, mapper.mount)
    if not manifest.has_poses:
        manifest, _ = with_visual_odometry(manifest)
    return mapper, manifest


def run_batch(manifests, out_dir: str | os.PathLike, *, config: PipelineConfig = PipelineConfig(),
              maps: bool = True, workers: int | None = None, scheduler=None, processes: bool = False,
              progress: bool = True, check_mount: bool = True) -> BatchSummary:
    """Process many datasets: per-frame files and one map per dataset (see the module docstring).

    Parameters
    ----------
    manifests : sequence of path, Manifest or BagSource
        The recordings (:func:`mrstereo.recordings.read_recording`: dataset, KITTI, EuRoC/ASL folders, and
        ROS bags, read as :class:`~mrstereo.recordings.bag.BagSource` streams); all are read (and validated)
        before any work starts. A bag gives its map only (no per-frame files), made as :func:`build_map`
        makes it, and is kept whole on a re-run while the bag and the options are unchanged.
    out_dir : path
        Output root; created if needed, reused by a re-run.
    config : PipelineConfig
        Options of every stage (as for :func:`mrstereo.pipeline.build_map`).
    maps : bool
        Also fuse a map per dataset.
    workers, scheduler, processes
        Where the frames run (:func:`mrstereo._executor.map_ordered`).
    progress : bool
        A tqdm bar over all frames to compute.
    check_mount : bool
        Check each dataset's mount against the floor seen in its first frames
        (:func:`mrstereo.pipeline.floor_for_run`; ``DatasetSummary.mount_warning``).

    Returns
    -------
    BatchSummary
    """
    if not isinstance(config, PipelineConfig):
        raise TypeError(f"config must be a PipelineConfig, got {type(config).__name__}")
    if isinstance(manifests, (str, os.PathLike, Manifest, BagSource)):
        manifests = [manifests]
    datasets = [m if isinstance(m, (Manifest, BagSource)) else BagSource(m) if is_bag(m) else read_recording(m)
                for m in manifests]
    if not datasets:
        raise ValueError("no datasets given")
    sources = datasets
    datasets = [m.manifest if isinstance(m, BagSource) else m for m in sources]      # (a bag's: stamps, poses)
    bags = {id(m): source for m, source in zip(datasets, sources) if isinstance(source, BagSource)}
    out = Path(out_dir)
    inputs = Inputs()
    for m in datasets:
        inputs.update(bag_inputs(m.root) if id(m) in bags else m.inputs())
    check_output_dir("out_dir", out, inputs=inputs, input_kind="dataset")
    check_outputs({"summary": out / SUMMARY_NAME}, inputs)
    names = output_names(datasets, out)
    for name in names:
        check_output_dir(f"out_dir {out}: the dataset's output folder", out / name, inputs=inputs)

    with contextlib.ExitStack() as stack:
        if isinstance(scheduler, str):         # connected (a worker there) before any output is made
            scheduler = stack.enter_context(dask_client(scheduler=scheduler))
        remove_stale_temporaries(out)
        configs = {name: config.for_rig(m.calibration) for name, m in zip(names, datasets)}
        plans = [_plan(m, name, out, configs[name], maps, check_mount)
                 for m, name in zip(datasets, names) if id(m) not in bags]
        tasks, floors = [], {}
        for p in plans:
            complete = [p.loaded[k] is not None for k in range(len(p.manifest.frames))]
            if not all(complete) or (maps and not p.map_kept):
                floors[p.name], p.manifest = _mounted(p.manifest, configs[p.name], check_mount)
            tasks += [FrameTask(record=record, index=k, stereo=p.manifest.calibration, observe=floors[p.name].observer(),
                                frames_dir=p.folder / "frames", dataset=p.name, fingerprint=p.fingerprints[k])
                      for k, record in enumerate(p.manifest.frames) if not complete[k]]

        results = map_ordered(process_frame, tasks, workers=workers, scheduler=scheduler, processes=processes,
                              progress=progress,
                              desc="frames", unit="frame", return_exceptions=True, prefetch=_read_task,
                              label=lambda t: f"{t.dataset} frame {t.index}")
        failures = []
        for task, result in zip(tasks, results):
            if isinstance(result, ItemFailure):
                failures.append({"dataset": task.dataset, "frame": task.index, "error": result.error})
            else:
                next(p for p in plans if p.name == task.dataset).loaded[task.index] = result

        summaries = [_finish(p, tasks, failures, configs[p.name], maps, floors) for p in plans]
        summaries += [_bag_map(bags[id(m)], out / name, config, maps, workers=workers, scheduler=scheduler,
                               processes=processes, progress=progress, check_mount=check_mount)
                      for m, name in zip(datasets, names) if id(m) in bags]
        summaries.sort(key=lambda d: names.index(d.name))
        path = out / SUMMARY_NAME
        with atomic_write(path) as tmp:
            tmp.write_text(json.dumps({"datasets": [s.to_dict() for s in summaries], "failures": failures,
                                       "config": {"preset": config.preset, "fusion": config.mapping.fusion,
                                                  "fingerprint": digest(repr(config))}},
                                      indent=1) + "\n")
        return BatchSummary(path=path, datasets=tuple(summaries), failures=tuple(failures))


def _finish(p: _Dataset, tasks: list, failures: list, config: PipelineConfig, maps: bool,
            floors: dict) -> DatasetSummary:
    """Fuse (or keep) one dataset's map; its summary."""
    m = p.manifest
    failed = sorted(f["frame"] for f in failures if f["dataset"] == p.name)
    n_tasks = sum(1 for t in tasks if t.dataset == p.name)
    status = ""
    if maps:
        if p.map_kept:
            status = "kept"
        else:
            obs = [p.loaded[k] for k in range(len(m.frames)) if p.loaded[k] is not None]
            run = map_from_observations(m, obs, config=config, floor=floors[p.name].floor,
                                        mount=floors[p.name].mount)
            write_map_dir(run, p.folder / "map", {"frames": len(m.frames), "fused": len(obs), "failed": failed,
                                               "fingerprint": p.map_fingerprint})
            status = "written" if not failed else f"written from {len(obs)} of {len(m.frames)} frames"
    floor = floors.get(p.name)
    return DatasetSummary(name=p.name, manifest=m.root / "manifest.yaml" if m.layout == "dataset" else m.root,
                          out_dir=p.folder, n_frames=len(m.frames), n_computed=n_tasks - len(failed),
                          n_skipped=len(m.frames) - n_tasks, n_failed=len(failed), map_status=status,
                          floor=floor.floor if floor else None, mount_warning=floor.mount_warning if floor else None,
                          fingerprint=p.map_fingerprint)


def _bag_map(source: BagSource, folder: Path, config: PipelineConfig, maps: bool, **run) -> DatasetSummary:
    """A bag's map: its frames read as a stream and mapped in order (:func:`build_map`, the map of
    ``mrstereo map BAG``), kept when the bag, its topics and the options are those of the map already there."""
    folder.mkdir(parents=True, exist_ok=True)
    claim_folder(folder, source.root, source.root)
    remove_stale_temporaries(folder)
    fingerprint = bag_fingerprint(source, config, run["check_mount"])
    n, status, floor, warning = source.n_frames, "", None, None
    if maps and map_dir_current(folder / "map", fingerprint):
        status = "kept"
    elif maps:
        result = build_map(source, config=config, keep_points=False, **run)
        write_map_dir(result, folder / "map", {"frames": n, "fused": len(result.observations), "failed": [],
                                            "fingerprint": fingerprint})
        status, floor, warning = "written", result.floor, result.mount_warning
    return DatasetSummary(name=folder.name, manifest=source.root, out_dir=folder, n_frames=n,
                          n_computed=n if status == "written" else 0, n_skipped=0 if status == "written" else n,
                          n_failed=0, map_status=status, floor=floor, fingerprint=fingerprint,
                          mount_warning=warning)
