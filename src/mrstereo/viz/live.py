"""Live views in standard robotics viewers: Rerun and Foxglove (the optional extra ``mrstereo[viz]``).

:class:`RerunLogger` (``rerun-sdk``) and :class:`FoxgloveLogger` (``foxglove-sdk``) take plain
arrays -- the rectified left image, its disparity, obstacle points and scan returns in the robot
base frame, the robot's and the camera's poses, the occupancy grid in ``nav_msgs/OccupancyGrid``
values, the path -- and show them on one time line (the frames' stamps). Frames follow ROS
REP 105: ``map`` (the world, REP 103 axes, z up), ``base_link`` (the robot), the camera's optical
frame (x right, y down, z forward). Rerun: ``world`` is the map frame, ``world/robot`` the base,
``world/robot/camera`` the rectified left camera (pinhole, image, disparity). Foxglove: the
topics ``/tf``, ``/camera/image``, ``/camera/disparity``, ``/camera/calibration``, ``/points``,
``/scan``, ``/map``, ``/path``, ``/odom`` in Foxglove's own schemas, on a websocket server on
localhost and in an MCAP file. Conventions: docs/conventions.md; user guide: docs/live.md.
"""
from __future__ import annotations

import os
import warnings
from pathlib import Path

import cv2
import numpy as np

from .._executor import quiet_stderr
from ..transforms import quaternion_from_rotation

__all__ = ["require_viewers", "check_port", "RerunLogger", "FoxgloveLogger", "disparity_colours", "scan_points", "MAP_FRAME", "BASE_FRAME",
           "CAMERA_FRAME"]

MAP_FRAME, BASE_FRAME, CAMERA_FRAME = "map", "base_link", "camera_left_optical_frame"
_PACKAGES = {"rerun": ("rerun", "rerun-sdk"), "foxglove": ("foxglove", "foxglove-sdk")}


def require_viewers(viewers) -> None:
    """Raise RuntimeError naming the package when a viewer's SDK is not installed (the ``viz`` extra)."""
    import importlib.util

    for viewer in viewers:
        module, package = _PACKAGES[viewer]
        if importlib.util.find_spec(module) is None:
            raise RuntimeError(f"--viewer {viewer} needs {package}: pip install \"mrstereo[viz]\"")


def _listening(port: int) -> bool:
    """Whether something accepts connections on 127.0.0.1:``port``."""
    import socket

    try:
        socket.create_connection(("127.0.0.1", int(port)), timeout=1.0).close()
    except OSError:
        return False
    return True


def check_port(port: int, option: str) -> int:
    """``port`` when no socket of this machine holds it (any address), else ``ValueError`` naming ``option``.

    Checked before a viewer server starts, so that a busy port is one line before any work instead of a
    server's own log lines and a half-started run. Port 0 (the system picks one) is always free.
    """
    import socket

    port = int(port)
    if not 0 <= port <= 65535:
        raise ValueError(f"{option}: {port} is not a port number (0 to 65535)")
    if port == 0:
        return port
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)     # a closed connection's TIME_WAIT is free
        try:
            probe.bind(("0.0.0.0", port))
        except OSError:
            raise ValueError(f"{option}: port {port} is in use (another viewer or run?); give a free one with "
                             f"{option}") from None
    return port


def disparity_colours(disparity_px: np.ndarray, max_disparity_px: float | None = None) -> np.ndarray:
    """An RGB uint8 picture of a disparity map (turbo, near = red; invalid = black)."""
    d = np.asarray(disparity_px, dtype=np.float32)
    valid = np.isfinite(d)
    top = max_disparity_px or (float(np.percentile(d[valid], 99)) if valid.any() else 1.0)
    level = np.clip(np.nan_to_num(d, nan=0.0) / max(top, 1e-6) * 255.0, 0, 255).astype(np.uint8)
    rgb = cv2.cvtColor(cv2.applyColorMap(level, cv2.COLORMAP_TURBO), cv2.COLOR_BGR2RGB)
    rgb[~valid] = 0
    return rgb


def scan_points(angle_min_rad: float, angle_max_rad: float, ranges_m) -> np.ndarray:
    """The returns (finite ranges) of a laser scan as (N, 2) points ``(x, y)`` in its frame."""
    r = np.asarray(ranges_m, dtype=np.float64)
    angles = np.linspace(angle_min_rad, angle_max_rad, len(r)) if len(r) > 1 else np.full(len(r), angle_min_rad)
    ok = np.isfinite(r)
    return np.column_stack([r[ok] * np.cos(angles[ok]), r[ok] * np.sin(angles[ok])])


def _pose(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(translation (3,), quaternion xyzw (4,)) of a 4x4 pose."""
    T = np.asarray(T, dtype=np.float64)
    return T[:3, 3].copy(), np.asarray(quaternion_from_rotation(T[:3, :3]), dtype=np.float64)


def _hidden_temporary(path: Path) -> Path:
    return path.with_name(f".{path.name}.{os.getpid()}.tmp")


def _finish(tmp: Path | None, path: Path | None, keep: bool) -> None:
    """Move a finished temporary file into place, or remove it."""
    if tmp is None or not tmp.exists():
        return
    if keep:
        os.replace(tmp, path)
    else:
        tmp.unlink()


class RerunLogger:
    """A Rerun recording of the run: shown in a viewer while it runs and saved as ``.rrd``.

    Parameters
    ----------
    rrd_path : path, optional
        Save the stream here (written to a hidden temporary file, renamed when closed).
    mode : {"spawn", "serve", "web", "none"}
        ``spawn`` the native viewer (needs a display); ``serve`` the data stream on 127.0.0.1
        (``grpc_port``) for a viewer to connect to (``rerun URL``); ``web`` that and Rerun's web viewer
        on ``web_port`` (Rerun serves its web viewer on every interface of the machine, so it is only
        started when asked for); ``none`` only save.
    web_port, grpc_port : int
        Ports of the web viewer and of the data stream (checked free before anything starts).
    memory_limit : str
        Data the server keeps for viewers that connect late (older data is dropped).
    """

    def __init__(self, *, rrd_path=None, mode: str = "serve", web_port: int = 9090, grpc_port: int = 9876,
                 memory_limit: str = "256MiB", application_id: str = "mrstereo_live") -> None:
        import rerun as rr

        if mode not in ("spawn", "serve", "web", "none"):
            raise ValueError(f"mode must be 'spawn', 'serve', 'web' or 'none', got {mode!r}")
        if mode != "none":
            check_port(grpc_port, "--viewer-port")
        if mode == "web":
            check_port(web_port, "--viewer-web-port")
        self._rr = rr
        self.path = None if rrd_path is None else Path(rrd_path)
        self._tmp = None if self.path is None else _hidden_temporary(self.path)
        self.rec = rr.RecordingStream(application_id)
        sinks = [] if self._tmp is None else [rr.FileSink(str(self._tmp))]
        self.url = None
        if mode == "spawn":
            with quiet_stderr():            # the viewer's own log lines (and its errors without a display)
                self.rec.spawn(port=grpc_port, connect=False)
            if not _listening(grpc_port):
                display = os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
                raise OSError(f"--viewer rerun: the Rerun viewer did not start on display {display!r}: without "
                              "DISPLAY (and WAYLAND_DISPLAY) its stream is served on --viewer-port instead")
            sinks.append(rr.GrpcSink(f"rerun+http://127.0.0.1:{grpc_port}/proxy"))
        elif mode in ("serve", "web"):
            server = rr.GrpcServerSink("127.0.0.1", grpc_port, server_memory_limit=memory_limit)
            sinks.append(server)
            self.url = server.uri
        if sinks:
            self.rec.set_sinks(*sinks)
        if mode == "web":
            rr.serve_web_viewer(web_port=web_port, open_browser=False, connect_to=server.uri)
            self.url = f"http://127.0.0.1:{web_port}/?url={server.uri}"
        self.rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)

    def camera(self, K: np.ndarray, width: int, height: int) -> None:
        """The rectified left camera's pinhole (logged once)."""
        rr = self._rr
        self.rec.log("world/robot/camera", rr.Pinhole(image_from_camera=np.asarray(K, dtype=np.float64),
                                                      resolution=[int(width), int(height)],
                                                      camera_xyz=rr.ViewCoordinates.RDF, image_plane_distance=0.5),
                     static=True)

    def frame(self, *, stamp_s: float, index: int, T_world_from_base, T_base_from_cam, image=None,
              disparity_px=None, points_base=None, scan=None) -> None:
        """One frame on the time line: the robot's and the camera's poses (4x4), the rectified left image
        (uint8), its disparity, obstacle points (N, 3) in the base frame, and the laser scan as
        ``(angle_min_rad, angle_max_rad, ranges_m)`` in the base frame."""
        rr = self._rr
        rec = self.rec
        self._time(stamp_s, index)
        t, q = _pose(T_world_from_base)
        rec.log("world/robot", rr.Transform3D(translation=t, quaternion=q))
        t, q = _pose(T_base_from_cam)
        rec.log("world/robot/camera", rr.Transform3D(translation=t, quaternion=q))
        if image is not None:
            rec.log("world/robot/camera/image", rr.Image(np.ascontiguousarray(image)).compress(jpeg_quality=75))
        if disparity_px is not None:
            rec.log("world/robot/camera/disparity", rr.Image(disparity_colours(disparity_px)).compress(jpeg_quality=75))
        if points_base is not None:
            rec.log("world/robot/points", rr.Points3D(np.asarray(points_base, dtype=np.float32), radii=0.01,
                                                      colors=[230, 90, 40]))
        if scan is not None:
            xy = scan_points(*scan)
            rec.log("world/robot/scan", rr.Points3D(np.column_stack([xy, np.zeros(len(xy))]).astype(np.float32),
                                                    radii=0.03, colors=[40, 200, 60]))

    def map(self, *, stamp_s: float, index: int, grid, path_xyz=None) -> None:
        """The occupancy grid ``(values int8 (rows, cols) in nav_msgs/OccupancyGrid values, row 0 at the
        lowest y; resolution_m; (origin_x_m, origin_y_m))`` and the path so far (K, 3)."""
        rr = self._rr
        self._time(stamp_s, index)
        if grid is not None:
            values, resolution_m, origin = grid
            values = np.ascontiguousarray(values, dtype=np.int8)
            rows, cols = values.shape
            self.rec.log("world/map", rr.GridMap(data=values.view(np.uint8).tobytes(),
                                                 format=rr.components.ImageFormat(width=cols, height=rows,
                                                                                  color_model="L",
                                                                                  channel_datatype="U8"),
                                                 cell_size=float(resolution_m),
                                                 translation=[float(origin[0]), float(origin[1]), 0.0],
                                                 colormap=rr.components.Colormap.RvizMap))
        if path_xyz is not None and len(path_xyz) > 1:
            self.rec.log("world/path", rr.LineStrips3D([np.asarray(path_xyz, dtype=np.float32)],
                                                       colors=[40, 110, 230]))

    def _time(self, stamp_s: float, index: int) -> None:
        self.rec.set_time("stamp", timestamp=float(stamp_s))
        self.rec.set_time("frame", sequence=int(index))

    def close(self, *, keep: bool = True) -> None:
        """Flush, stop serving, and move the saved stream into place (``keep=False``: remove it). A viewer that
        went away during the run (closed by the user) makes rerun's flush fail: the stream, which may then be
        incomplete, is removed with one warning, and the run's other outputs stand."""
        try:
            self.rec.flush()
            self.rec.disconnect()
        except Exception as exc:        # (rerun's own error types, raised from its Rust core)
            keep = False
            first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
            warnings.warn(f"--viewer rerun: the viewer went away during the run ({first}); "
                          f"{self.path or 'the stream'} was not kept")
        _finish(self._tmp, self.path, keep)

    def discard(self) -> None:
        self.close(keep=False)


class FoxgloveLogger:
    """Foxglove's schemas on a websocket server on localhost and in an MCAP file.

    Parameters
    ----------
    mcap_path : path, optional
        Write the stream here (a hidden temporary file, renamed when closed).
    port : int, optional
        The websocket server's port on 127.0.0.1 (``ws://127.0.0.1:PORT``; checked free before anything
        starts); None: no server.
    """

    def __init__(self, *, mcap_path=None, port: int | None = 8765, name: str = "mrstereo live") -> None:
        import foxglove

        if port is not None:
            check_port(port, "--foxglove-port")
        self._fg = foxglove
        self.context = foxglove.Context()
        self.path = None if mcap_path is None else Path(mcap_path)
        self._tmp = None if self.path is None else _hidden_temporary(self.path)
        self._writer = None if self._tmp is None else foxglove.open_mcap(self._tmp, allow_overwrite=True,
                                                                         context=self.context)
        self.server = None if port is None else foxglove.start_server(name=name, host="127.0.0.1", port=port,
                                                                      context=self.context)
        self.url = None if self.server is None else f"ws://127.0.0.1:{self.server.port}"
        ch = foxglove.channels
        self._channels = {
            "/tf": ch.FrameTransformsChannel("/tf", context=self.context),
            "/camera/image": ch.RawImageChannel("/camera/image", context=self.context),
            "/camera/disparity": ch.RawImageChannel("/camera/disparity", context=self.context),
            "/camera/calibration": ch.CameraCalibrationChannel("/camera/calibration", context=self.context),
            "/points": ch.PointCloudChannel("/points", context=self.context),
            "/scan": ch.LaserScanChannel("/scan", context=self.context),
            "/map": ch.GridChannel("/map", context=self.context),
            "/path": ch.PosesInFrameChannel("/path", context=self.context),
            "/odom": ch.OdometryChannel("/odom", context=self.context),
        }
        self._calibration = None

    def camera(self, K: np.ndarray, width: int, height: int) -> None:
        """The rectified left camera (sent with every image, as ROS camera_info is)."""
        K = np.asarray(K, dtype=np.float64)
        self._calibration = (K, int(width), int(height))

    def _time(self, stamp_s: float):
        sec = int(np.floor(stamp_s))
        return self._fg.messages.Timestamp(sec=sec, nsec=int(round((stamp_s - sec) * 1e9)) % 1_000_000_000)

    def _transform(self, ts, parent: str, child: str, T):
        m = self._fg.messages
        t, q = _pose(T)
        return m.FrameTransform(timestamp=ts, parent_frame_id=parent, child_frame_id=child,
                                translation=m.Vector3(x=t[0], y=t[1], z=t[2]),
                                rotation=m.Quaternion(x=q[0], y=q[1], z=q[2], w=q[3]))

    def _raw(self, ts, image: np.ndarray, encoding: str):
        image = np.ascontiguousarray(image)
        return self._fg.messages.RawImage(timestamp=ts, frame_id=CAMERA_FRAME, width=image.shape[1],
                                          height=image.shape[0], encoding=encoding,
                                          step=image.strides[0], data=image.tobytes())

    def frame(self, *, stamp_s: float, index: int, T_world_from_base, T_base_from_cam, image=None,
              disparity_px=None, points_base=None, scan=None) -> None:
        """One frame; the arguments as :meth:`RerunLogger.frame`."""
        m = self._fg.messages
        ts = self._time(float(stamp_s))
        log_ns = int(round(float(stamp_s) * 1e9))
        c = self._channels
        c["/tf"].log(m.FrameTransforms(transforms=[self._transform(ts, MAP_FRAME, BASE_FRAME, T_world_from_base),
                                                   self._transform(ts, BASE_FRAME, CAMERA_FRAME, T_base_from_cam)]),
                     log_time=log_ns)
        t, q = _pose(T_world_from_base)
        c["/odom"].log(m.Odometry(timestamp=ts, frame_id=MAP_FRAME, body_frame_id=BASE_FRAME,
                                  pose=m.Pose(position=m.Vector3(x=t[0], y=t[1], z=t[2]),
                                              orientation=m.Quaternion(x=q[0], y=q[1], z=q[2], w=q[3]))),
                       log_time=log_ns)
        if image is not None:
            c["/camera/image"].log(self._raw(ts, np.asarray(image, dtype=np.uint8), "mono8"), log_time=log_ns)
            if self._calibration is not None:
                K, w, h = self._calibration
                P = np.hstack([K, np.zeros((3, 1))])
                c["/camera/calibration"].log(m.CameraCalibration(timestamp=ts, frame_id=CAMERA_FRAME, width=w,
                                                                 height=h, distortion_model="plumb_bob",
                                                                 D=[0.0] * 5, K=K.ravel().tolist(),
                                                                 R=np.eye(3).ravel().tolist(), P=P.ravel().tolist()),
                                             log_time=log_ns)
        if disparity_px is not None:
            c["/camera/disparity"].log(self._raw(ts, disparity_colours(disparity_px), "rgb8"), log_time=log_ns)
        if points_base is not None:
            pts = np.ascontiguousarray(points_base, dtype=np.float32).reshape(-1, 3)
            f32 = m.PackedElementFieldNumericType.Float32
            fields = [m.PackedElementField(name=n, offset=4 * k, type=f32) for k, n in enumerate("xyz")]
            c["/points"].log(m.PointCloud(timestamp=ts, frame_id=BASE_FRAME, point_stride=12, fields=fields,
                                          data=pts.tobytes()), log_time=log_ns)
        if scan is not None:
            angle_min, angle_max, ranges = scan
            c["/scan"].log(m.LaserScan(timestamp=ts, frame_id=BASE_FRAME, start_angle=float(angle_min),
                                       end_angle=float(angle_max),
                                       ranges=np.where(np.isfinite(ranges), ranges, np.nan).tolist()),
                           log_time=log_ns)

    def map(self, *, stamp_s: float, index: int, grid, path_xyz=None) -> None:
        """The occupancy grid and the path; the arguments as :meth:`RerunLogger.map`."""
        m = self._fg.messages
        ts = self._time(float(stamp_s))
        log_ns = int(round(float(stamp_s) * 1e9))
        c = self._channels
        if grid is not None:
            values, resolution_m, origin = grid
            values = np.ascontiguousarray(values, dtype=np.int8)
            rows, cols = values.shape
            c["/map"].log(m.Grid(timestamp=ts, frame_id=MAP_FRAME,
                                 pose=m.Pose(position=m.Vector3(x=float(origin[0]), y=float(origin[1]), z=0.0),
                                             orientation=m.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
                                 column_count=cols, cell_size=m.Vector2(x=float(resolution_m), y=float(resolution_m)),
                                 row_stride=cols, cell_stride=1,
                                 fields=[m.PackedElementField(name="occupancy", offset=0,
                                                              type=m.PackedElementFieldNumericType.Int8)],
                                 data=values.tobytes()), log_time=log_ns)
        if path_xyz is not None and len(path_xyz):
            poses = [m.Pose(position=m.Vector3(x=float(p[0]), y=float(p[1]), z=float(p[2])),
                            orientation=m.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)) for p in path_xyz]
            c["/path"].log(m.PosesInFrame(timestamp=ts, frame_id=MAP_FRAME, poses=poses), log_time=log_ns)

    def close(self, *, keep: bool = True) -> None:
        """Stop the server, finish the MCAP file and move it into place (``keep=False``: remove it)."""
        if self.server is not None:
            self.server.stop()
            self.server = None
        if self._writer is not None:
            self._writer.close()
            self._writer = None
            _finish(self._tmp, self.path, keep)

    def discard(self) -> None:
        self.close(keep=False)
