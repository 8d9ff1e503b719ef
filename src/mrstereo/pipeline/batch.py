"""Many datasets at once: per-frame products and a map per dataset, resumable, on Dask.

For every frame of every dataset (docs/dataset.md) :func:`run_batch` runs the
chain of :func:`mrstereo.pipeline.frame.scan_from_pair` (rectify -> match ->
reject (eq. 13) -> 3D (eq. 14-16) -> scan) once and writes::

    OUT/<dataset>/frames/NNNNNN.pfm        disparity after rejection (PFM, NaN -> inf)
    OUT/<dataset>/frames/NNNNNN.ply        robot-frame point cloud with intensity
    OUT/<dataset>/frames/NNNNNN.scan.json  virtual laser scan (ROS LaserScan fields)
    OUT/<dataset>/frames/NNNNNN.obs.npz    the frame's world-frame obstacle / floor points
    OUT/<dataset>/map/                     map.pgm, map.yaml, map.png, log_odds.npy, batch.json
    OUT/summary.json                       per dataset counts, and every failed frame

then fuses each dataset's frames in order into its map (the same map as
``mrstereo map``, bit for bit). Frames of all datasets are spread over the
workers of :func:`mrstereo.pipeline.parallel.map_ordered`.

Resumable: every file is written to a temporary name and renamed, so an
interrupted run leaves complete files only; a re-run skips frames whose four
files exist (their points are read back from ``.obs.npz``) and datasets whose
map was completed without failures. A frame that raises is listed in
``summary.json`` (and the map's ``batch.json``), the others go on, and the map
is built from the frames that succeeded; the next run retries it.

Conventions: docs/conventions.md.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..camera import CameraMount, StereoCamera
from ..geometry.ply import read_ply, write_ply
from ..geometry.scan import write_scan_json
from ..io import (atomic_write, check_output_dir, check_outputs, read_pfm, remove_stale_temporaries, temporary_dir,
                  write_disparity)
from ..mapping.fusion import FrameObservation
from ..mapping.rosmap import ros_map_files
from ..recordings.layouts import read_recording
from ..recordings.manifest import FrameRecord, Manifest, frame_pair, rebased
from .frame import scan_from_pair
from .parallel import ItemFailure, map_ordered
from .run import (MapRun, PipelineConfig, floor_for_run, map_from_observations, observation_from_pair, pair_options,
                  with_visual_odometry, write_map_outputs)

__all__ = ["FrameTask", "DatasetSummary", "BatchSummary", "frame_outputs", "process_frame", "run_batch",
           "dataset_files", "SUMMARY_NAME"]

SUMMARY_NAME = "summary.json"
_MAP_RECORD = "batch.json"


def dataset_files(manifest: Manifest) -> list[Path]:
    """Every file a run over ``manifest`` reads: the manifest, calibration, ground-truth map, images."""
    files = [p for p in (manifest.root / "manifest.yaml", manifest.calibration_path) if p.is_file()]
    if manifest.ground_truth_map is not None:
        files += ros_map_files(manifest.ground_truth_map)
    for r in manifest.frames:
        files += [p for p in (r.left, r.right, r.left_rect, r.right_rect, r.gt_disparity, r.gt_labels)
                  if p is not None]
    return files


def frame_outputs(frames_dir: str | os.PathLike, index: int) -> dict[str, Path]:
    """The four files of frame ``index``: disparity, cloud, scan, observation."""
    base = Path(frames_dir) / f"{index:06d}"
    return {"disparity": base.with_suffix(".pfm"), "cloud": base.with_suffix(".ply"),
            "scan": Path(f"{base}.scan.json"), "observation": Path(f"{base}.obs.npz")}


@dataclass(frozen=True)
class FrameTask:
    """One frame to process (small and picklable: paths, not images)."""

    record: FrameRecord
    index: int
    stereo: StereoCamera
    mount: CameraMount | None
    config: PipelineConfig
    frames_dir: Path
    dataset: str
    prefer_raw: bool = False


def _gray(image: np.ndarray) -> np.ndarray:
    import cv2

    return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image


def _read_task(task: FrameTask) -> tuple[FrameTask, tuple]:
    """``task`` -> ``(task, pair)``: the frame's images decoded (by the run's reader thread)."""
    return task, frame_pair(task.record, prefer_raw=task.prefer_raw)


def process_frame(task: FrameTask | tuple[FrameTask, tuple]) -> FrameObservation:
    """Run the chain on one frame, write its four files, return what it adds to the map.

    ``task`` may come with its images read ahead (:func:`_read_task`). The observation equals
    :func:`mrstereo.pipeline.observe_frame`'s for the same record and options.
    """
    task, pair = task if isinstance(task, tuple) else (task, None)
    left, right, rectified = frame_pair(task.record, prefer_raw=task.prefer_raw) if pair is None else pair
    result = scan_from_pair(left, right, task.stereo, rectified=rectified, mount=task.mount,
                            pan_rad=task.record.pan_rad, **pair_options(task.config))
    frame = result.frame
    obs = frame.obstacles
    observation = observation_from_pair(frame, task.record, index=task.index, config=task.config, stereo=task.stereo)
    files = frame_outputs(task.frames_dir, task.index)
    write_disparity(files["disparity"], frame.disparity_px)
    write_ply(files["cloud"], obs.points_robot_image.reshape(-1, 3), intensity=_gray(frame.left_rect).ravel(),
              comment=f"mrstereo {task.dataset} frame {task.index} (frame: robot, metres)")
    write_scan_json(files["scan"], result.scan)
    _save_observation(files["observation"], observation)
    return observation


def _save_observation(path: Path, obs: FrameObservation) -> None:
    with atomic_write(path) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, index=obs.index, pose=np.array(obs.pose), pan_rad=obs.pan_rad,
                 obstacle_points_world=obs.obstacle_points_world, floor_points_world=obs.floor_points_world,
                 n_valid_disparity=obs.n_valid_disparity, ground_message=np.array(obs.ground_message),
                 baseline_focal_m_px=np.nan if obs.baseline_focal_m_px is None else obs.baseline_focal_m_px,
                 sensor_height_m=np.nan if obs.sensor_height_m is None else obs.sensor_height_m,
                 boundary_points=obs.boundary_points)


def _resume(files: dict[str, Path]) -> FrameObservation | None:
    """The observation of a finished frame, or None when one of its four files is missing or unreadable
    (then the frame is computed again)."""
    if not all(p.is_file() for p in files.values()):
        return None
    try:
        read_pfm(files["disparity"])
        json.loads(files["scan"].read_text(encoding="utf-8"))
        read_ply(files["cloud"])
        return _load_observation(files["observation"])
    except Exception:                  # any damage: recompute (the files are rewritten atomically)
        return None


def _load_observation(path: Path) -> FrameObservation:
    with np.load(path) as z:
        return FrameObservation(index=int(z["index"]), pose=tuple(float(v) for v in z["pose"]),
                                pan_rad=float(z["pan_rad"]), obstacle_points_world=z["obstacle_points_world"],
                                floor_points_world=z["floor_points_world"],
                                n_valid_disparity=int(z["n_valid_disparity"]),
                                ground_message=str(z["ground_message"]),
                                baseline_focal_m_px=_optional_float(z["baseline_focal_m_px"]),
                                sensor_height_m=_optional_float(z["sensor_height_m"]),
                                boundary_points=int(z["boundary_points"]))


def _optional_float(value) -> float | None:
    """A scalar saved by :func:`_save_observation` (NaN: None)."""
    value = float(value)
    return None if np.isnan(value) else value


@dataclass(frozen=True)
class DatasetSummary:
    """What :func:`run_batch` did with one dataset."""

    name: str
    manifest: Path
    out_dir: Path
    n_frames: int
    n_computed: int
    n_skipped: int
    n_failed: int
    map_status: str = ""
    floor: object | None = None
    """The floor the frames used (:class:`mrstereo.geometry.GroundPlane`); None when all was kept."""
    mount_warning: str | None = None
    """Why the dataset's mount was not used (:func:`mrstereo.pipeline.floor_for_run`)."""

    def to_dict(self) -> dict:
        out = {"name": self.name, "manifest": str(self.manifest), "out_dir": str(self.out_dir),
               "frames": self.n_frames, "computed": self.n_computed, "skipped": self.n_skipped,
               "failed": self.n_failed, "map": self.map_status}
        if self.floor is not None:
            out["floor"] = self.floor.summary()
        if self.mount_warning is not None:
            out["mount_warning"] = self.mount_warning
        return out


@dataclass(frozen=True)
class BatchSummary:
    """Result of :func:`run_batch` (also written to ``OUT/summary.json``)."""

    path: Path
    datasets: tuple[DatasetSummary, ...]
    failures: tuple[dict, ...] = field(default_factory=tuple)


def _names(manifests: list[Manifest]) -> list[str]:
    names, seen = [], {}
    for m in manifests:
        base = (m.root.parent.name if m.root.name == "mav0" else m.root.name) or "dataset"   # EuRoC: the sequence
        seen[base] = seen.get(base, 0) + 1
        names.append(base if seen[base] == 1 else f"{base}_{seen[base]}")
    return names


def _map_done(map_dir: Path, n_frames: int) -> bool:
    try:
        record = json.loads((map_dir / _MAP_RECORD).read_text())
    except (OSError, ValueError):
        return False
    return record.get("frames") == n_frames and not record.get("failed") and (map_dir / "log_odds.npy").is_file()


def _write_map(run: MapRun, map_dir: Path, record: dict) -> None:
    """Write the map outputs into a temporary directory and swap it into place.

    The temporary directory (``.map.PID.XXXX.tmp`` beside ``map_dir``) is removed on failure;
    one left by a killed run is removed by the next :func:`run_batch` on the same output.
    """
    with temporary_dir(map_dir.parent, prefix="map") as staging:
        tmp = staging / "map"
        write_map_outputs(run, tmp)
        (tmp / _MAP_RECORD).write_text(json.dumps(record, indent=1) + "\n")
        if map_dir.exists():
            old = staging / "old"
            os.replace(map_dir, old)
        os.replace(tmp, map_dir)


def _mounted(manifest: Manifest, config: PipelineConfig, check_mount: bool) -> tuple:
    """``(RunFloor, recording)``: the mount (checked) or the floor estimated once, the poses on that base,
    and the poses of visual odometry for a recording without any (as ``mrstereo map`` takes them)."""
    floor = floor_for_run(manifest, config=config, check_mount=check_mount)
    manifest = rebased(manifest, floor.mount)
    if not manifest.has_poses:
        manifest, _ = with_visual_odometry(manifest)
    return floor, manifest


def _check_outputs(out: Path, datasets: list[Manifest], names: list[str]) -> None:
    """Refuse an output root or dataset folder that would write over an input (before any work)."""
    inputs = [f for m in datasets for f in dataset_files(m)]
    check_output_dir("out_dir", out, input_dirs=[m.root for m in datasets if out.resolve().is_relative_to(m.root.resolve())],
                     input_kind="dataset")
    check_outputs({"summary": out / SUMMARY_NAME}, inputs)
    for name in names:
        check_output_dir(f"out_dir {out}: the dataset's output folder", out / name, input_kind="dataset",
                         input_dirs=[m.root for m in datasets], inputs=inputs)


def run_batch(manifests, out_dir: str | os.PathLike, *, config: PipelineConfig = PipelineConfig(),
              maps: bool = True, workers: int | None = None, scheduler=None, processes: bool = False,
              progress: bool = True, check_mount: bool = True) -> BatchSummary:
    """Process many datasets: per-frame files and one map per dataset (see the module docstring).

    Parameters
    ----------
    manifests : sequence of path or Manifest
        The recordings (:func:`mrstereo.recordings.read_recording`: dataset, KITTI, EuRoC/ASL folders);
        all are read (and validated) before any work starts.
    out_dir : path
        Output root; created if needed, reused by a re-run.
    config : PipelineConfig
        Options of every stage (as for :func:`mrstereo.pipeline.build_map`).
    maps : bool
        Also fuse a map per dataset.
    workers, scheduler, processes
        Where the frames run (:func:`mrstereo.pipeline.parallel.map_ordered`).
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
    if isinstance(manifests, (str, os.PathLike, Manifest)):
        manifests = [manifests]
    datasets = [m if isinstance(m, Manifest) else read_recording(m) for m in manifests]
    if not datasets:
        raise ValueError("no datasets given")
    out = Path(out_dir)
    names = _names(datasets)
    _check_outputs(out, datasets, names)

    tasks, observations, skipped, done_maps, floors = [], {}, {}, set(), {}
    configs = {name: config.for_rig(m.calibration) for name, m in zip(names, datasets)}
    for i, (name, m) in enumerate(zip(names, datasets)):
        frames_dir = out / name / "frames"
        frames_dir.mkdir(parents=True, exist_ok=True)
        remove_stale_temporaries(frames_dir)
        remove_stale_temporaries(out / name)
        loaded = {k: _resume(frame_outputs(frames_dir, k)) for k in range(len(m.frames))}
        complete = [loaded[k] is not None for k in range(len(m.frames))]
        if maps and all(complete) and _map_done(out / name / "map", len(m.frames)):
            done_maps.add(name)
        skipped[name] = sum(complete)
        if not all(complete) or (maps and name not in done_maps):
            floors[name], datasets[i] = _mounted(m, configs[name], check_mount)
            m = datasets[i]
        for k, record in enumerate(m.frames):
            if complete[k]:
                if maps and name not in done_maps:
                    observations[(name, k)] = loaded[k]
            else:
                tasks.append(FrameTask(record=record, index=k, stereo=m.calibration, mount=floors[name].mount,
                                       config=configs[name], frames_dir=frames_dir, dataset=name))

    results = map_ordered(process_frame, tasks, workers=workers, scheduler=scheduler, processes=processes,
                          progress=progress,
                          desc="frames", unit="frame", return_exceptions=True, prefetch=_read_task,
                          label=lambda t: f"{t.dataset} frame {t.index}")
    failures = []
    for task, result in zip(tasks, results):
        if isinstance(result, ItemFailure):
            failures.append({"dataset": task.dataset, "frame": task.index, "error": result.error})
        else:
            observations[(task.dataset, task.index)] = result

    summaries = []
    for name, m in zip(names, datasets):
        failed = sorted(f["frame"] for f in failures if f["dataset"] == name)
        computed = sum(1 for t in tasks if t.dataset == name) - len(failed)
        status = ""
        if maps:
            if name in done_maps:
                status = "kept"
            else:
                obs = [observations[(name, k)] for k in range(len(m.frames)) if (name, k) in observations]
                run = map_from_observations(m, obs, config=configs[name], floor=floors[name].floor,
                                            mount=floors[name].mount)
                _write_map(run, out / name / "map", {"frames": len(m.frames), "fused": len(obs), "failed": failed})
                status = "written" if not failed else f"written from {len(obs)} of {len(m.frames)} frames"
        summaries.append(DatasetSummary(name=name, manifest=m.root / "manifest.yaml" if m.layout == "dataset" else m.root,
                                        out_dir=out / name,
                                        n_frames=len(m.frames), n_computed=computed, n_skipped=skipped[name],
                                        n_failed=len(failed), map_status=status,
                                        floor=floors[name].floor if name in floors else None,
                                        mount_warning=floors[name].warning if name in floors else None))
    path = out / SUMMARY_NAME
    with atomic_write(path) as tmp:
        tmp.write_text(json.dumps({"datasets": [s.to_dict() for s in summaries], "failures": failures,
                                   "config": {"preset": config.preset, "fusion": config.mapping.fusion}},
                                  indent=1) + "\n")
    return BatchSummary(path=path, datasets=tuple(summaries), failures=tuple(failures))
