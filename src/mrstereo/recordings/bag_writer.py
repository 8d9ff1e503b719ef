"""A ROS 2 bag (MCAP, through ``rosbags``) of what the pipeline made: ``/scan``, ``/points``, ``/map``, ``/odom``, ``/tf``, ``/tf_static``, ``/plan``.

Frame ids per REP 105; ``/map`` and ``/tf_static`` are latched; a topic is in the bag only when a message was
written to it (no empty topics). The bag is written into a hidden
folder beside its destination and renamed into place when closed. Topics and types: docs/live.md
("ROS 2 bag"). Conventions: docs/conventions.md.
"""
from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np

from ..io import new_temporary_dir, remove_stale_temporaries
from ..transforms import quaternion_from_rotation

__all__ = ["BagWriter", "check_bag_stamps", "BAG_TOPICS", "LATCHED_TOPICS", "MAP_FRAME", "ODOM_FRAME", "BASE_FRAME",
           "CAMERA_FRAME"]

MAP_FRAME, ODOM_FRAME, BASE_FRAME, CAMERA_FRAME = "map", "odom", "base_link", "camera_left_optical_frame"
BAG_TOPICS = {"/scan": "sensor_msgs/msg/LaserScan", "/points": "sensor_msgs/msg/PointCloud2",
              "/map": "nav_msgs/msg/OccupancyGrid", "/odom": "nav_msgs/msg/Odometry",
              "/tf": "tf2_msgs/msg/TFMessage", "/tf_static": "tf2_msgs/msg/TFMessage",
              "/plan": "nav_msgs/msg/Path"}
"""Every topic the writer can create and its message type (a topic is created with its first message)."""

MAX_STAMP_NS = 2**31 * 10**9
"""Stamps a ROS 2 bag holds: from 0 (the bag's log times are unsigned) to 2^31 s (``builtin_interfaces/Time.sec``
is an int32: 2038-01-19)."""

LATCHED_TOPICS = ("/tf_static", "/map")
"""Offered as transient local (latched), as robot_state_publisher and map_server offer them: a node that
subscribes after ``ros2 bag play`` sent them still gets the last message."""


def check_bag_stamps(stamps_s) -> None:
    """Raise ``ValueError`` naming the first stamp [s] a ROS 2 bag cannot hold (:data:`MAX_STAMP_NS`)."""
    for stamp in stamps_s:
        if not 0 <= stamp * 1e9 < MAX_STAMP_NS:
            raise ValueError(f"--record-bag: a time stamp of {stamp:.10g} s cannot be written to a ROS 2 bag (stamps "
                             "from 0 to 2^31 s, before 2038-01-19): the recording's stamps are wrong; fix them or "
                             "record no bag")


def _qos(latched: bool) -> list:
    """The QoS profile recorded for a topic: reliable, keep last 1 (latched) or 10."""
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    never = QosTime(sec=0, nsec=0)
    return [Qos(history=QosHistory.KEEP_LAST, depth=1 if latched else 10, reliability=QosReliability.RELIABLE,
                durability=QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE, deadline=never,
                lifespan=never, liveliness=QosLiveliness.AUTOMATIC, liveliness_lease_duration=never,
                avoid_ros_namespace_conventions=False)]


class BagWriter:
    """Write the run's messages into a new ROS 2 bag folder (MCAP storage).

    Parameters
    ----------
    path : path
        The bag folder to create (must not exist).
    """

    def __init__(self, path: str | os.PathLike) -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.typesys import Stores, get_typestore

        self.path = Path(path)
        if self.path.exists():
            raise ValueError(f"--record-bag: {self.path} already exists; choose a new folder")
        # built in a temporary folder of mrstereo's beside it (only those are ever removed), under its own name
        # (the storage file is named after the bag)
        remove_stale_temporaries(self.path.parent)
        self._tmp = new_temporary_dir(self.path.parent, prefix=self.path.name)
        self.ts = get_typestore(Stores.ROS2_HUMBLE)
        self.T = self.ts.types
        self._writer = Writer(self._tmp / self.path.name, version=9, storage_plugin=StoragePlugin.MCAP)
        self._writer.open()
        self._conn: dict = {}
        self.counts: dict[str, int] = {}
        """Messages written per topic (only topics with messages)."""

    # -- message parts ------------------------------------------------------------------------
    def _header(self, stamp_ns: int, frame: str):
        t = self.T["builtin_interfaces/msg/Time"](sec=int(stamp_ns // 10**9), nanosec=int(stamp_ns % 10**9))
        return self.T["std_msgs/msg/Header"](stamp=t, frame_id=frame)

    def _pose(self, T: np.ndarray):
        G = self.T
        q = quaternion_from_rotation(T[:3, :3])
        return G["geometry_msgs/msg/Pose"](position=G["geometry_msgs/msg/Point"](x=float(T[0, 3]), y=float(T[1, 3]),
                                                                                 z=float(T[2, 3])),
                                           orientation=G["geometry_msgs/msg/Quaternion"](
                                               x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])))

    def _transform(self, stamp_ns: int, parent: str, child: str, T: np.ndarray):
        G = self.T
        q = quaternion_from_rotation(T[:3, :3])
        return G["geometry_msgs/msg/TransformStamped"](
            header=self._header(stamp_ns, parent), child_frame_id=child,
            transform=G["geometry_msgs/msg/Transform"](
                translation=G["geometry_msgs/msg/Vector3"](x=float(T[0, 3]), y=float(T[1, 3]), z=float(T[2, 3])),
                rotation=G["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]),
                                                           w=float(q[3]))))

    def _write(self, topic: str, msg, stamp_ns: int) -> None:
        check_bag_stamps([stamp_ns / 1e9])
        if topic not in self._conn:
            self._conn[topic] = self._writer.add_connection(topic, BAG_TOPICS[topic], typestore=self.ts,
                                                            offered_qos_profiles=_qos(topic in LATCHED_TOPICS))
            self.counts[topic] = 0
        self._writer.write(self._conn[topic], int(stamp_ns), self.ts.serialize_cdr(msg, BAG_TOPICS[topic]))
        self.counts[topic] += 1

    # -- public -------------------------------------------------------------------------------
    def static(self, stamp_ns: int, T_base_from_cam: np.ndarray) -> None:
        """``/tf_static``: map -> odom (identity) and base_link -> the left camera's optical frame."""
        self._write("/tf_static", self.T["tf2_msgs/msg/TFMessage"](transforms=[
            self._transform(stamp_ns, MAP_FRAME, ODOM_FRAME, np.eye(4)),
            self._transform(stamp_ns, BASE_FRAME, CAMERA_FRAME, np.asarray(T_base_from_cam, dtype=np.float64))]),
            stamp_ns)

    def pose(self, stamp_ns: int, T_world_from_base: np.ndarray) -> None:
        """``/odom`` and ``/tf``: the robot base in the odom frame."""
        G = self.T
        T = np.asarray(T_world_from_base, dtype=np.float64)
        cov = np.zeros(36)
        zero = G["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        self._write("/odom", G["nav_msgs/msg/Odometry"](
            header=self._header(stamp_ns, ODOM_FRAME), child_frame_id=BASE_FRAME,
            pose=G["geometry_msgs/msg/PoseWithCovariance"](pose=self._pose(T), covariance=cov),
            twist=G["geometry_msgs/msg/TwistWithCovariance"](
                twist=G["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=cov)), stamp_ns)
        self._write("/tf", G["tf2_msgs/msg/TFMessage"](transforms=[
            self._transform(stamp_ns, ODOM_FRAME, BASE_FRAME, T)]), stamp_ns)

    def scan(self, stamp_ns: int, *, angle_min_rad: float, angle_max_rad: float, angle_increment_rad: float,
             range_min_m: float, range_max_m: float, ranges_m, intensities=()) -> None:
        """``/scan``: a sensor_msgs/LaserScan in base_link (ranges with REP 117's inf / nan)."""
        self._write("/scan", self.T["sensor_msgs/msg/LaserScan"](
            header=self._header(stamp_ns, BASE_FRAME), angle_min=float(angle_min_rad), angle_max=float(angle_max_rad),
            angle_increment=float(angle_increment_rad), time_increment=0.0, scan_time=0.0,
            range_min=float(range_min_m), range_max=float(range_max_m),
            ranges=np.asarray(ranges_m, dtype=np.float32), intensities=np.asarray(intensities, dtype=np.float32)),
            stamp_ns)

    def points(self, stamp_ns: int, points_base) -> None:
        """``/points``: a sensor_msgs/PointCloud2 of (N, 3) points in base_link (x, y, z float32)."""
        G = self.T
        pts = np.ascontiguousarray(points_base, dtype=np.float32).reshape(-1, 3)
        fields = [G["sensor_msgs/msg/PointField"](name=n, offset=4 * k, datatype=7, count=1)   # 7: FLOAT32
                  for k, n in enumerate("xyz")]
        self._write("/points", G["sensor_msgs/msg/PointCloud2"](
            header=self._header(stamp_ns, BASE_FRAME), height=1, width=len(pts), fields=fields, is_bigendian=False,
            point_step=12, row_step=12 * len(pts), data=pts.view(np.uint8).ravel(), is_dense=True), stamp_ns)

    def map(self, stamp_ns: int, values, *, resolution_m: float, origin_xy) -> None:
        """``/map``: a nav_msgs/OccupancyGrid of int8 values (-1 unknown, 0..100), row 0 at the lowest y."""
        G = self.T
        values = np.ascontiguousarray(values, dtype=np.int8)
        rows, cols = values.shape
        origin = np.eye(4)
        origin[:2, 3] = origin_xy
        t = self._header(stamp_ns, MAP_FRAME).stamp
        info = G["nav_msgs/msg/MapMetaData"](map_load_time=t, resolution=float(resolution_m), width=cols, height=rows,
                                             origin=self._pose(origin))
        self._write("/map", G["nav_msgs/msg/OccupancyGrid"](header=self._header(stamp_ns, MAP_FRAME), info=info,
                                                            data=values.ravel()), stamp_ns)

    def plan(self, stamp_ns: int, poses_xy_yaw) -> None:
        """``/plan``: a nav_msgs/Path in the map frame of ``(x_m, y_m, yaw_rad)`` poses, as Nav2's planners publish."""
        G = self.T
        stamped = []
        for x, y, yaw in np.asarray(poses_xy_yaw, dtype=np.float64).reshape(-1, 3):
            T = np.eye(4)
            c, s_ = np.cos(yaw), np.sin(yaw)
            T[:2, :2] = [[c, -s_], [s_, c]]
            T[:2, 3] = x, y
            stamped.append(G["geometry_msgs/msg/PoseStamped"](header=self._header(stamp_ns, MAP_FRAME),
                                                              pose=self._pose(T)))
        self._write("/plan", G["nav_msgs/msg/Path"](header=self._header(stamp_ns, MAP_FRAME), poses=stamped),
                    stamp_ns)

    def close(self) -> None:
        """Finish the bag and move it into place."""
        if self._writer is None:
            return
        self._writer.close()
        self._writer = None
        os.replace(self._tmp / self.path.name, self.path)
        shutil.rmtree(self._tmp, ignore_errors=True)

    def discard(self) -> None:
        """Abandon the bag (an error): remove what was written."""
        if self._writer is not None:
            try:
                self._writer.close()
            except Exception:
                pass
            self._writer = None
        shutil.rmtree(self._tmp, ignore_errors=True)

