"""Test ROS bags: messages of a rosbags typestore and a writer of ROS 1 / ROS 2 bags (the bag tests share them)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from mrstereo.io import read_image

T0_NS = 1_700_000_000_000_000_000
DT_NS = 100_000_000                 # 10 Hz
RIGHT_LAG_NS = 3_000_000            # right images 3 ms after the left ones

TOPICS = dict(left_topic="/stereo/left/image_raw", right_topic="/stereo/right/image_raw",
              camera_info_topics=("/stereo/left/camera_info", "/stereo/right/camera_info"))
"""The topics :func:`write_bag` writes, as :func:`mrstereo.recordings.bag.export_bag` keywords."""


def typestore(ros1: bool):
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    if "tf2_msgs/msg/TFMessage" not in ts.types:
        ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    return ts


class Msgs:
    """Build messages for one typestore (ROS 1 headers have a seq, camera_info K/D/R/P upper case)."""

    def __init__(self, ts, ros1: bool):
        self.ts, self.ros1, self.T = ts, ros1, ts.types

    def header(self, stamp_ns: int, frame: str):
        t = self.T["builtin_interfaces/msg/Time"](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
        if self.ros1:
            return self.T["std_msgs/msg/Header"](seq=0, stamp=t, frame_id=frame)
        return self.T["std_msgs/msg/Header"](stamp=t, frame_id=frame)

    def image(self, img: np.ndarray, stamp_ns: int, frame: str, *, compressed: bool = False):
        if compressed:
            import cv2
            ok, buf = cv2.imencode(".png", img)
            return self.T["sensor_msgs/msg/CompressedImage"](header=self.header(stamp_ns, frame), format="png",
                                                             data=buf.ravel())
        enc = "mono8" if img.ndim == 2 else "bgr8"
        ch = 1 if img.ndim == 2 else 3
        return self.T["sensor_msgs/msg/Image"](header=self.header(stamp_ns, frame), height=img.shape[0],
                                               width=img.shape[1], encoding=enc, is_bigendian=0,
                                               step=img.shape[1] * ch, data=np.ascontiguousarray(img).ravel())

    def camera_info(self, info, stamp_ns: int, frame: str):
        cam = info.camera
        model = getattr(cam, "distortion_model", "plumb_bob")           # ROS name and D (equidistant: k1..k4)
        fields = dict(D=np.asarray(getattr(cam, "D", cam.dist_coeffs), float), K=cam.K.ravel().astype(float),
                      R=info.R.ravel().astype(float), P=info.P.ravel().astype(float))
        if not self.ros1:
            fields = {k.lower(): v for k, v in fields.items()}
        roi = self.T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
        return self.T["sensor_msgs/msg/CameraInfo"](header=self.header(stamp_ns, frame), height=cam.height,
                                                    width=cam.width, distortion_model=model, binning_x=0,
                                                    binning_y=0, roi=roi, **fields)

    def _planar(self, x, y, yaw):
        """Point and Quaternion of a planar pose, exactly (the bag tests compare maps bit for bit)."""
        G = self.T
        return (G["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                G["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)))

    def odometry(self, point, quaternion, stamp_ns: int):
        """nav_msgs/Odometry of base_link in odom from a geometry_msgs Point and Quaternion."""
        G = self.T
        cov = np.zeros(36)
        zero = G["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        return G["nav_msgs/msg/Odometry"](
            header=self.header(stamp_ns, "odom"), child_frame_id="base_link",
            pose=G["geometry_msgs/msg/PoseWithCovariance"](
                pose=G["geometry_msgs/msg/Pose"](position=point, orientation=quaternion), covariance=cov),
            twist=G["geometry_msgs/msg/TwistWithCovariance"](
                twist=G["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=cov))

    def planar_odometry(self, pose, stamp_ns: int):
        """nav_msgs/Odometry of a planar pose ``(x, y, yaw)``."""
        return self.odometry(*self._planar(*pose), stamp_ns)

    def tf(self, items, stamp_ns: int):
        """TFMessage of planar transforms ``(parent, child, (x, y, yaw))``."""
        G, out = self.T, []
        for parent, child, pose in items:
            p, q = self._planar(*pose)
            tr = G["geometry_msgs/msg/Transform"](translation=G["geometry_msgs/msg/Vector3"](x=p.x, y=p.y, z=0.0),
                                                  rotation=q)
            out.append(G["geometry_msgs/msg/TransformStamped"](header=self.header(stamp_ns, parent),
                                                               child_frame_id=child, transform=tr))
        return G["tf2_msgs/msg/TFMessage"](transforms=out)

    def tf_3d(self, items, stamp_ns: int):
        """TFMessage of full 3-D transforms ``(parent, child, T_parent_from_child)``."""
        from scipy.spatial.transform import Rotation

        G, out = self.T, []
        for parent, child, T in items:
            q = Rotation.from_matrix(T[:3, :3]).as_quat()
            tr = G["geometry_msgs/msg/Transform"](
                translation=G["geometry_msgs/msg/Vector3"](x=float(T[0, 3]), y=float(T[1, 3]), z=float(T[2, 3])),
                rotation=G["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]),
                                                           w=float(q[3])))
            out.append(G["geometry_msgs/msg/TransformStamped"](header=self.header(stamp_ns, parent),
                                                               child_frame_id=child, transform=tr))
        return G["tf2_msgs/msg/TFMessage"](transforms=out)


class BagWriter:
    """``with BagWriter(path, ros1, {topic: msgtype}) as bag: bag.put(topic, bag.msgs.image(...), t_ns)``.

    A ROS 1 ``.bag`` file, or a ROS 2 bag directory in ``storage`` ("sqlite3" or "mcap").
    """

    def __init__(self, path: Path, ros1: bool, topics: dict[str, str], *, storage: str = "sqlite3"):
        self.path, self.topics = path, topics
        self.ts = typestore(ros1)
        self.msgs = Msgs(self.ts, ros1)
        if ros1:
            from rosbags.rosbag1 import Writer
            self._writer, self._serialize = Writer(path), self.ts.serialize_ros1
        else:
            from rosbags.rosbag2 import StoragePlugin, Writer
            plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
            self._writer, self._serialize = Writer(path, version=9, storage_plugin=plugin), self.ts.serialize_cdr

    def __enter__(self) -> BagWriter:
        self._writer.__enter__()
        self._connections = {topic: self._writer.add_connection(topic, msgtype, typestore=self.ts)
                             for topic, msgtype in self.topics.items()}
        return self

    def __exit__(self, *exc) -> None:
        self._writer.__exit__(*exc)

    def put(self, topic: str, msg, stamp_ns: int) -> None:
        connection = self._connections[topic]
        self._writer.write(connection, stamp_ns, self._serialize(msg, connection.msgtype))


def write_bag(path: Path, manifest, *, ros1: bool, storage: str = "sqlite3", odom: bool = True, tf: bool = False,
              compressed: bool = False, frames=None, right_lag_ns: int = RIGHT_LAG_NS, recalibrated=None) -> Path:
    """Write the raw pairs of a manifest as a bag (:data:`TOPICS`): images, camera_info, odometry and/or TF;
    ``recalibrated=(k, stereo)``: the camera_info of frame k on is that of ``stereo``."""
    img_type = "sensor_msgs/msg/CompressedImage" if compressed else "sensor_msgs/msg/Image"
    topics = {"/stereo/left/image_raw": img_type, "/stereo/right/image_raw": img_type,
              "/stereo/left/camera_info": "sensor_msgs/msg/CameraInfo",
              "/stereo/right/camera_info": "sensor_msgs/msg/CameraInfo"}
    if odom:
        topics["/odom"] = "nav_msgs/msg/Odometry"
    if tf:
        topics.update({"/tf": "tf2_msgs/msg/TFMessage", "/tf_static": "tf2_msgs/msg/TFMessage"})
    records = manifest.frames if frames is None else [manifest.frames[k] for k in frames]
    cal = manifest.calibration
    with BagWriter(path, ros1, topics, storage=storage) as bag:
        m = bag.msgs
        if tf:
            bag.put("/tf_static", m.tf([("map", "odom", (0.0, 0.0, 0.0))], T0_NS - DT_NS), T0_NS - DT_NS)
        for k, rec in enumerate(records):
            t, t_right = T0_NS + k * DT_NS, T0_NS + k * DT_NS + right_lag_ns
            if recalibrated is not None and k == recalibrated[0]:
                cal = recalibrated[1]
            bag.put("/stereo/left/camera_info", m.camera_info(cal.left, t, "left"), t)
            bag.put("/stereo/right/camera_info", m.camera_info(cal.right, t_right, "right"), t_right)
            if odom:
                bag.put("/odom", m.planar_odometry(rec.pose, t), t)
            if tf:
                bag.put("/tf", m.tf([("odom", "base_link", rec.pose),
                                     ("base_link", "stereo_link", (0.0, 0.0, rec.pan_rad))], t), t)
            bag.put("/stereo/left/image_raw", m.image(read_image(rec.left), t, "left", compressed=compressed), t)
            bag.put("/stereo/right/image_raw", m.image(read_image(rec.right), t_right, "right",
                                                       compressed=compressed), t_right)
    return path
