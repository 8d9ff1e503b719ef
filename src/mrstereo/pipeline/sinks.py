"""The sinks a command asks for (viewers, a ROS 2 bag: :mod:`mrstereo.mapping.sinks`), and finished runs
replayed into them: :func:`open_sinks` makes them, :func:`replay_map_run` and :func:`replay_odometry` replay.
Conventions: docs/conventions.md; user guide: docs/live.md.
"""
from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from ..camera import StereoCamera
from ..geometry.scan import laser_scan_from_points, scan_angles_of_camera
from ..mapping.fusion import add_observation
from ..mapping.occupancy import OccupancyGrid
from ..mapping.sinks import BagSink, LiveFrame, ViewerSink
from ..transforms import T_from_planar, transform_points

__all__ = ["ViewerSink", "BagSink", "open_sinks", "replay_map_run", "replay_odometry"]

def open_sinks(stereo: StereoCamera, view_stem: str | os.PathLike, *, viewers: Sequence[str] = (),
               record_bag: str | os.PathLike | None = None, foxglove_port: int | None = 8765,
               rerun_mode: str | None = None, echo: Callable[[str], None] | None = None, viewer_port: int = 9876,
               viewer_web_port: int | None = None) -> list:
    """The sinks a run's options ask for: ``viewers`` (``"rerun"``: ``view_stem``.rrd, and a viewer spawned
    with a display or its data served on 127.0.0.1:``viewer_port`` (and the web viewer on ``viewer_web_port``
    when given), or neither with ``rerun_mode="none"``; ``"foxglove"``:
    ``view_stem``.mcap and a websocket server on ``foxglove_port``, None: none), and a ROS 2 bag at
    ``record_bag``. ``echo`` is told where to look."""
    from ..viz.live import FoxgloveLogger, RerunLogger, require_viewers

    require_viewers(viewers)
    stem = Path(view_stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    sinks = []
    try:
        for viewer in viewers:
            if viewer == "rerun":
                mode = rerun_mode or ("spawn" if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
                                      else "serve" if viewer_web_port is None else "web")
                logger = RerunLogger(rrd_path=stem.with_suffix(".rrd"), mode=mode, grpc_port=viewer_port,
                                     web_port=viewer_web_port or 9090)
                if echo is not None and logger.url:
                    echo(f"rerun: open {logger.url} in a browser" if mode == "web" else
                         f"rerun: connect a viewer with `rerun {logger.url}`")
            else:
                logger = FoxgloveLogger(mcap_path=stem.with_suffix(".mcap"), port=foxglove_port)
                if echo is not None and logger.url:
                    echo(f"foxglove: connect the Foxglove app to {logger.url}")
            sinks.append(ViewerSink(logger, stereo))
        if record_bag is not None:
            from ..recordings.bag_writer import BagWriter

            sinks.append(BagSink(BagWriter(record_bag)))
    except BaseException:
        for sink in sinks:
            sink.discard()
        raise
    return sinks


def replay_map_run(run, sinks: Sequence, *, config) -> None:
    """Send a finished map run (:class:`mrstereo.evaluation.outputs.MapRun`) to ``sinks`` frame by frame: the
    pose, the obstacle points back in the robot frame, the scan they make, the map as fused up to the
    frame and, with the last frame, the run's map as written (the frames' images are not kept by a map run)."""
    stereo = run.manifest.calibration
    frames = run.manifest.frames
    grid = OccupancyGrid(run.grid.grid, config=config.mapping)        # the map's final window
    range_max = config.for_rig(stereo).obstacles.max_range_m
    mount = run.mount
    last = len(run.observations) - 1
    for k, obs in enumerate(run.observations):
        add_observation(grid, obs)
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
