"""What a run leaves behind: the results of a map run (:class:`MapRun`) and a live run (:class:`LiveRun`), their
comparison with the recording's truth, and their output files (:func:`write_map_outputs`,
:func:`write_live_outputs`). The runs themselves are :mod:`mrstereo.pipeline`'s. User guide: docs/mapping.md,
docs/live.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import gc
import json
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..camera import CameraMount, mount_entry
from ..geometry.ground import GroundPlane
from ..geometry.obstacles import MAPPING_MAX_RANGE_M
from ..io import atomic_write, replace_dir, temporary_dir
from ..mapping import RosMap, read_ros_map, write_ros_map
from ..mapping.figures import plot_map
from ..mapping.fusion import FrameObservation
from ..mapping.metrics import MapMetrics, map_metrics, views_of_poses
from ..mapping.observations import content_digest
from ..mapping.occupancy import OccupancyGrid
from ..mapping.rosmap import ros_map_on_grid
from ..mapping.tiles import TiledOccupancyGrid
from ..odometry.trajectory import trajectory_metrics, write_tum
from ..recordings.manifest import Manifest
from ..transforms import T_from_planar, planar_from_T

__all__ = ["MapRun", "map_vs_truth", "check_map", "write_map_outputs", "LiveRun", "write_live_outputs",
           "LIVE_FILES", "MAP_FILES", "MAP_RECORD", "write_map_dir", "map_dir_current", "DatasetSummary",
           "BatchSummary"]

MAP_RECORD = "batch.json"
"""What a map folder written by :func:`write_map_dir` was computed from (its fingerprint) and holds."""
MAP_FILES = ("map.yaml", "map.pgm", "map.png", "log_odds.npy")
"""The files of every finished map (metrics.json too when the map has metrics)."""


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
            by_index = {o.index: o.pose for o in self.observations}
            used = sorted(by_index)
            est = np.stack([T_from_planar(*by_index[k]) for k in used])
            true = np.stack([T_from_planar(*frames[k].true_pose) for k in used])
            given = np.stack([T_from_planar(*frames[k].pose) for k in used])
            out["poses_vs_truth"] = trajectory_metrics(est, true).to_dict()
            out["given_poses_vs_truth"] = trajectory_metrics(given, true).to_dict()
        return out


def map_vs_truth(mapper, occupancy: OccupancyGrid, manifest: Manifest):
    """``(metrics, ground truth)`` of a :class:`~mrstereo.pipeline.mapper.StereoMapper`'s map against the
    recording's ground-truth map (None, None without one),
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


def _floor_and_window(run, *, range_m: float | None = None) -> dict:
    """metrics.json's ``floor``, ``mount``, ``mount_warning`` (when known) and ``map_window`` of a run."""
    out = {}
    if run.floor is not None:
        out["floor"] = run.floor.summary()
    if run.mount is not None:
        out["mount"] = mount_entry(run.mount)
    if run.mount_warning:
        out["mount_warning"] = run.mount_warning
    g = run.grid.grid
    out["map_window"] = {"origin_m": [g.origin_x_m, g.origin_y_m], "size_m": [g.width_m, g.height_m],
                         "resolution_m": g.resolution_m, **({} if range_m is None else {"range_m": range_m}),
                         "points_outside": int(run.grid.points_outside)}
    return out


def write_map_outputs(run: MapRun, out_dir: str | os.PathLike, *, planned_path=None) -> dict[str, Path]:
    """Write map.pgm + map.yaml (ROS map_server), map.png, log_odds.npy, metrics.json and trajectory.txt (the
    mapped frames' poses, TUM: ``mrstereo plan --start robot`` starts from its last); for a map that grew also
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
    report.update(_floor_and_window(run, range_m=run.range_m))
    report.update(run.pose_metrics())
    if report:
        with atomic_write(out / "metrics.json") as tmp:
            tmp.write_text(json.dumps(report, indent=2))
        files["metrics"] = out / "metrics.json"
    if run.trajectory is not None:
        files["trajectory"] = write_tum(out / "trajectory.txt", *run.trajectory,
                                        comment="mrstereo map: the mapped frames' robot base in the map frame")
    path = np.array([o.pose for o in run.observations]) if run.observations else None
    views = views_of_poses(path if path is not None else [], [o.pan_rad for o in run.observations],
                           run.manifest.calibration, range_m=run.range_m, mount=run.mount)
    plot_map(run.grid, out / "map.png", robot_path=path, fov_views=views,
             planned_path=planned_path, ground_truth=run.ground_truth_map,
             title=f"occupancy grid ({run.grid.config.fusion})")
    if run.tiles is not None:           # the whole map that grew: its tiles and an overview image
        run.tiles.save(out / "tiles.npz")
        files.update(tiles=out / "tiles.npz", overview_yaml=out / "overview.yaml",
                     overview_png=run.tiles.write_overview(out / "overview.yaml"))
    return files


LIVE_FILES = ("map.yaml", "map.pgm", "map.png", "trajectory.txt", "metrics.json")
"""What :func:`run_live` writes into its output folder."""


@dataclass
class LiveRun:
    """The counts, times and results of a live run (:func:`run_live`); ``metrics()`` is metrics.json."""

    grid: OccupancyGrid
    stamps_s: np.ndarray
    T_world_from_base: np.ndarray
    frames_in: int = 0
    frames_processed: int = 0
    frames_dropped: int = 0
    frames_mapped: int = 0
    frames_lost: int = 0
    frames_before_floor: int = 0
    latency_ms: np.ndarray = field(default_factory=lambda: np.empty(0))
    duration_s: float = 0.0
    odometry: str = "visual"
    floor: GroundPlane | None = None
    mount: CameraMount | None = None
    mount_warning: str | None = None
    source: str = ""
    stopped: str = "end of source"
    cpu_s: dict = field(default_factory=dict)
    stage_ms: dict = field(default_factory=dict)
    peak_memory_mb: float = 0.0
    memory_mb: float = 0.0
    files: dict = field(default_factory=dict)

    @property
    def rate_hz(self) -> float:
        """Frames processed per second of the run."""
        return self.frames_processed / self.duration_s if self.duration_s > 0 else 0.0

    def metrics(self) -> dict:
        lat = self.latency_ms
        q = (lambda p: float(np.percentile(lat, p))) if len(lat) else (lambda p: float("nan"))
        out = {"source": self.source, "stopped": self.stopped, "frames_in": self.frames_in,
               "frames_processed": self.frames_processed, "frames_dropped": self.frames_dropped,
               "frames_mapped": self.frames_mapped, "frames_lost": self.frames_lost,
               "frames_before_floor": self.frames_before_floor, "duration_s": round(self.duration_s, 3),
               "rate_hz": round(self.rate_hz, 3),
               "latency_ms": {"median": round(q(50), 2), "p95": round(q(95), 2), "max": round(q(100), 2)},
               "peak_memory_mb": round(self.peak_memory_mb, 1), "memory_mb": round(self.memory_mb, 1),
               "odometry": self.odometry,
               "cpu_s": {k: round(v, 3) for k, v in self.cpu_s.items()},
               "stage_ms_per_frame": {k: round(v, 2) for k, v in self.stage_ms.items()}}
        if self.duration_s > 0 and self.cpu_s:
            out["cores_used"] = round(self.cpu_s.get("process", 0.0) / self.duration_s, 2)
        out.update(_floor_and_window(self))
        return out


def write_live_outputs(out_dir: Path, snapshot: dict) -> dict[str, Path]:
    """Write one snapshot: map.pgm then map.yaml (a reader of the YAML finds its image), map.png,
    trajectory.txt, metrics.json -- each atomically."""
    out = Path(out_dir)
    files = {"map_yaml": out / "map.yaml", "map_pgm": out / "map.pgm", "map_png": out / "map.png",
             "trajectory": out / "trajectory.txt", "metrics": out / "metrics.json"}
    ros_map: RosMap = snapshot["ros_map"]
    write_ros_map(files["map_yaml"], ros_map)
    T = snapshot["T_world_from_base"]
    path = planar_from_T(T) if len(T) else None
    plot_map(ros_map, files["map_png"], robot_path=path,
             title=f"live map, {len(T)} frames ({snapshot['metrics']['rate_hz']:.1f} Hz)")
    if len(T):                  # (no pose yet: the floor is being estimated)
        write_tum(files["trajectory"], snapshot["stamps_s"], T, comment=snapshot["comment"])
    with atomic_write(files["metrics"]) as tmp:
        tmp.write_text(json.dumps(snapshot["metrics"], indent=2))
    # a matplotlib figure is a web of reference cycles: only the cycle collector frees it, and a long run
    # would otherwise hold every figure since the last full collection
    gc.collect()
    return files


def map_dir_current(map_dir: Path, fingerprint: str) -> bool:
    """The map in ``map_dir`` is complete, was computed from what ``fingerprint`` says and its files are
    those written then (their bytes' hash)."""
    try:
        record = json.loads((map_dir / MAP_RECORD).read_text(encoding="utf-8"))
        files = record.get("files") or MAP_FILES
        return (record.get("fingerprint") == fingerprint and not record.get("failed")
                and record.get("content") == content_digest(map_dir / name for name in files))
    except (OSError, ValueError, TypeError):
        return False


def write_map_dir(run: MapRun, map_dir: Path, record: dict) -> None:
    """Write the map outputs into a temporary folder and swap it into place in one step, with ``record``
    and the hash of the files (:func:`map_dir_current`) in its ``batch.json``.

    The temporary folder (``.mrstereo-tmp-PID-XXXXXXXX.map`` beside ``map_dir``) is removed on failure;
    one left by a killed run is removed by the next :func:`~mrstereo.pipeline.batch.run_batch` on the same output.
    """
    with temporary_dir(map_dir.parent, prefix="map") as staging:
        tmp = staging / "map"
        written = write_map_outputs(run, tmp)
        names = sorted(p.name for p in written.values())
        record = dict(record, files=names, content=content_digest(tmp / name for name in names))
        (tmp / MAP_RECORD).write_text(json.dumps(record, indent=1) + "\n")
        replace_dir(tmp, map_dir)


@dataclass(frozen=True)
class DatasetSummary:
    """What :func:`~mrstereo.pipeline.batch.run_batch` did with one dataset."""

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
    fingerprint: str = ""
    """The map's fingerprint (what it was computed from)."""
    mount_warning: str | None = None
    """Why the dataset's mount was not used (:class:`mrstereo.geometry.floor.FloorVote`)."""

    def to_dict(self) -> dict:
        out = {"name": self.name, "manifest": str(self.manifest), "out_dir": str(self.out_dir),
               "frames": self.n_frames, "computed": self.n_computed, "skipped": self.n_skipped,
               "failed": self.n_failed, "map": self.map_status, "fingerprint": self.fingerprint}
        if self.floor is not None:
            out["floor"] = self.floor.summary()
        if self.mount_warning is not None:
            out["mount_warning"] = self.mount_warning
        return out


@dataclass(frozen=True)
class BatchSummary:
    """Result of :func:`~mrstereo.pipeline.batch.run_batch` (also written to ``OUT/summary.json``)."""

    path: Path
    datasets: tuple[DatasetSummary, ...]
    failures: tuple[dict, ...] = field(default_factory=tuple)
