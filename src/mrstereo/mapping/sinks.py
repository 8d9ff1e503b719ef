"""Where a map's frames go besides its files: live viewers (Rerun, Foxglove) and a ROS 2 bag.

A sink has ``frame(LiveFrame)``, ``close()`` and ``discard()``: :class:`ViewerSink` sends each frame to a
viewer logger (:mod:`mrstereo.viz.live`), :class:`BagSink` to a bag writer
(:class:`mrstereo.recordings.bag_writer.BagWriter`); the map and path at most every ``map_every_s`` of
stream time. ``mrstereo.pipeline.sinks.open_sinks`` makes those a command asks for; :func:`replay_map_run`
and :func:`replay_odometry` send them a finished run.
Conventions: docs/conventions.md; user guide: docs/live.md.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..camera import StereoCamera
from ..geometry.scan import LaserScan, laser_scan_from_points, scan_angles_of_camera
from ..transforms import T_from_planar, transform_points
from .fusion import fuse_step
from .occupancy import OccupancyGrid
from .rosmap import occupancy_values

__all__ = ["LiveFrame", "ViewerSink", "BagSink", "MAX_VIEW_POINTS", "replay_map_run", "replay_odometry"]


@dataclass(frozen=True)
class LiveFrame:
    """What one mapped frame produced: what the sinks (viewers, bags) receive.

    ``grid`` is the live map itself: a sink reads it during its call and keeps no reference.
    Points and the scan are in the robot frame (REP 103), poses are ``T_world_from_base`` and
    the rectified left camera's mount ``T_base_from_cam`` (optical axes, docs/conventions.md).
    """

    index: int
    stamp_s: float
    T_world_from_base: np.ndarray
    T_base_from_cam: np.ndarray
    left_rect: np.ndarray
    disparity_px: np.ndarray
    obstacle_points_robot: np.ndarray
    scan: LaserScan
    grid: object
    """The map (:class:`OccupancyGrid`, or the growing :class:`~mrstereo.mapping.tiles.TiledOccupancyGrid`)."""
    status: str = "tracked"



MAX_VIEW_POINTS = 20000
"""Obstacle points sent to a viewer per frame at most (an even subsample beyond)."""


def _grid_message(grid, *, trinary: bool = True) -> tuple[np.ndarray, float, tuple[float, float]]:
    """The map as ``nav_msgs/OccupancyGrid`` data (trinary with map.yaml's thresholds, as map_server publishes
    it, or probabilities in percent), its cell size and origin."""
    if not isinstance(grid, OccupancyGrid):             # a map that grows: the cells seen
        grid = grid.to_grid()
    g = grid.grid
    values = occupancy_values(grid.to_ros_map().occupancy if trinary else grid.probability(), trinary=trinary)
    return values, g.resolution_m, (g.origin_x_m, g.origin_y_m)


class _Throttled:
    """Map and path at most every ``map_every_s`` of stream time; the path kept for them."""

    def __init__(self, map_every_s: float) -> None:
        self.map_every_s = map_every_s
        self._last = -math.inf
        self._path: list[np.ndarray] = []
        self.grid: OccupancyGrid | None = None
        self.last_stamp_s = 0.0
        self.last_index = 0
        self.seen = False

    def due(self, frame: LiveFrame) -> bool:
        self._path.append(np.asarray(frame.T_world_from_base, dtype=np.float64)[:3, 3].copy())
        self.grid, self.last_stamp_s, self.last_index = frame.grid, frame.stamp_s, frame.index
        self.seen = True
        if frame.stamp_s - self._last >= self.map_every_s:
            self._last = frame.stamp_s
            return True
        return False

    @property
    def path_xyz(self) -> np.ndarray:
        return np.array(self._path)


class ViewerSink:
    """A frame to a viewer logger (:class:`~mrstereo.viz.live.RerunLogger` or
    :class:`~mrstereo.viz.live.FoxgloveLogger`)."""

    def __init__(self, logger, stereo: StereoCamera, *, map_every_s: float = 1.0) -> None:
        self.logger = logger
        P = stereo.left.P
        logger.camera(np.array([[P[0, 0], 0.0, P[0, 2]], [0.0, P[1, 1], P[1, 2]], [0.0, 0.0, 1.0]]),
                      stereo.size[0], stereo.size[1])
        self._throttle = _Throttled(map_every_s)
        self._map_sent: float | None = None

    def frame(self, frame: LiveFrame) -> None:
        due = self._throttle.due(frame)
        points = frame.obstacle_points_robot
        if len(points) > MAX_VIEW_POINTS:
            points = points[np.linspace(0, len(points) - 1, MAX_VIEW_POINTS).astype(np.int64)]
        scan = frame.scan
        self.logger.frame(stamp_s=frame.stamp_s, index=frame.index, T_world_from_base=frame.T_world_from_base,
                          T_base_from_cam=frame.T_base_from_cam, image=frame.left_rect,
                          disparity_px=frame.disparity_px, points_base=points,
                          scan=None if scan is None else (scan.angle_min_rad, scan.angle_max_rad, scan.ranges_m))
        if due:
            self._map(frame.stamp_s, frame.index)

    def _map(self, stamp_s: float, index: int) -> None:
        t = self._throttle
        self._map_sent = stamp_s
        self.logger.map(stamp_s=stamp_s, index=index, grid=None if t.grid is None else _grid_message(t.grid, trinary=False),
                        path_xyz=t.path_xyz)

    def close(self) -> None:
        t = self._throttle
        if t.seen and self._map_sent != t.last_stamp_s:
            self._map(t.last_stamp_s, t.last_index)
        self.logger.close()

    def discard(self) -> None:
        """After an error: stop the viewer, keep no file."""
        self.logger.discard()


class BagSink:
    """Frames to a ROS 2 bag: /odom, /tf, /scan, /points every frame, /map throttled and at the end
    (trinary as map_server publishes it, or probabilities in percent with ``trinary=False``)."""

    def __init__(self, writer, *, map_every_s: float = 1.0, trinary: bool = True) -> None:
        self.writer = writer
        self.trinary = trinary
        self._throttle = _Throttled(map_every_s)
        self._map_written_at: float | None = None

    def frame(self, frame: LiveFrame) -> None:
        stamp_ns = int(round(frame.stamp_s * 1e9))
        w = self.writer
        if not self._throttle.seen:
            w.static(stamp_ns, frame.T_base_from_cam)
        w.pose(stamp_ns, frame.T_world_from_base)
        if frame.scan is not None:
            s: LaserScan = frame.scan
            w.scan(stamp_ns, angle_min_rad=s.angle_min_rad, angle_max_rad=s.angle_max_rad,
                   angle_increment_rad=s.angle_increment_rad, range_min_m=s.range_min_m, range_max_m=s.range_max_m,
                   ranges_m=s.ranges_m, intensities=s.intensities)
        if frame.grid is not None:
            w.points(stamp_ns, frame.obstacle_points_robot)
        if self._throttle.due(frame) and frame.grid is not None:
            self._write_map(stamp_ns, frame.grid)

    def _write_map(self, stamp_ns: int, grid: OccupancyGrid) -> None:
        values, resolution_m, origin = _grid_message(grid, trinary=self.trinary)
        self.writer.map(stamp_ns, values, resolution_m=resolution_m, origin_xy=origin)
        self._map_written_at = stamp_ns

    def close(self) -> None:
        t = self._throttle
        stamp_ns = int(round(t.last_stamp_s * 1e9))
        if t.grid is not None and self._map_written_at != stamp_ns:
            self._write_map(stamp_ns, t.grid)
        self.writer.close()

    def discard(self) -> None:
        """After an error: no bag."""
        self.writer.discard()


def replay_map_run(run, sinks: Sequence, *, config) -> None:
    """Send a finished map run (:class:`mrstereo.evaluation.outputs.MapRun`) to ``sinks`` frame by frame: the
    pose, the obstacle points back in the robot frame, the scan they make, the map as fused up to the
    frame (:func:`mrstereo.mapping.fuse`'s steps: the footprint swept, a robot standing still one view of weak
    drop points) and, with the last frame, the run's map as written (the frames' images are not kept by a map
    run)."""
    stereo = run.manifest.calibration
    frames = run.manifest.frames
    grid = OccupancyGrid(run.grid.grid, config=config.mapping)        # the map's final window
    range_max = config.for_rig(stereo).obstacles.max_range_m
    mount = run.mount
    last = len(run.observations) - 1
    previous = weak_view = None
    for k, obs in enumerate(run.observations):
        weak_view = fuse_step(grid, obs, previous, weak_view)       # as the map was fused (mapping.fuse)
        previous = obs.pose
        record = frames[obs.index]
        T = T_from_planar(*obs.pose)
        n = len(obs.obstacle_points_world) - obs.boundary_points
        points = transform_points(np.linalg.inv(T), obs.obstacle_points_world[:n].astype(np.float64))
        lo, hi = scan_angles_of_camera(stereo, pan_rad=obs.pan_rad)
        scan = laser_scan_from_points(points, angle_min_rad=lo, angle_max_rad=hi, range_max_m=range_max, min_points=3)
        stamp = record.stamp_s if record.stamp_s is not None else float(obs.index)
        T_base_from_cam = np.eye(4) if mount is None else mount.T_base_from_rectified(stereo.left.R, obs.pan_rad)
        frame = LiveFrame(index=obs.index, stamp_s=stamp, T_world_from_base=T, T_base_from_cam=T_base_from_cam,
                          left_rect=None, disparity_px=None, obstacle_points_robot=points.astype(np.float32),
                          scan=scan, grid=run.grid if k == last else grid)     # the end: the map as written
        for sink in sinks:
            sink.frame(frame)


def replay_odometry(stamps_s, T_world_from_base, sinks: Sequence, *, T_base_from_cam=None) -> None:
    """Send a trajectory (an ``odometry`` run) to ``sinks``: poses only."""
    mount = np.eye(4) if T_base_from_cam is None else np.asarray(T_base_from_cam, dtype=np.float64)
    for k, (stamp, T) in enumerate(zip(stamps_s, T_world_from_base)):
        frame = LiveFrame(index=k, stamp_s=float(stamp), T_world_from_base=np.asarray(T), T_base_from_cam=mount,
                          left_rect=None, disparity_px=None, obstacle_points_robot=np.empty((0, 3), np.float32),
                          scan=None, grid=None)
        for sink in sinks:
            sink.frame(frame)
