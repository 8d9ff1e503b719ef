"""A real robot's recording as a bag: four OpenLORIS-Scene T265 fisheye stereo frames (Kannala-Brandt,
848x800) with their calibration, the camera pose in the robot frame (/tf_static) and wheel odometry,
written as a ROS 1 and a ROS 2 bag and mapped from camera_info + TF alone (no --height/--tilt)."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from mrstereo.cli import entry

from _bags import BagWriter

pytestmark = pytest.mark.sample_data("openloris-sample")

FRAMES = (0, 3)             # two of the four frames keep the test short; the odometry spans all four


def _load(root):
    """Intrinsics, distortion (k1..k4), T_base_from_fisheye1, T_fisheye1_from_fisheye2, images, odometry."""
    fs = cv2.FileStorage(str(root / "sensors.yaml"), cv2.FILE_STORAGE_READ)
    cams = {}
    for side, name in (("left", "t265_fisheye1_optical_frame"), ("right", "t265_fisheye2_optical_frame")):
        n = fs.getNode(name)
        fx, cx, fy, cy = n.getNode("intrinsics").mat().ravel()           # OpenLORIS order: fx, cx, fy, cy
        assert n.getNode("distortion_model").string() == "Kannala-Brandt"
        cams[side] = dict(width=int(n.getNode("width").real()), height=int(n.getNode("height").real()),
                          K=np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]]),
                          D=n.getNode("distortion_coefficients").mat().ravel()[:4])
    fs.release()
    fs = cv2.FileStorage(str(root / "trans_matrix.yaml"), cv2.FILE_STORAGE_READ)
    node, tf = fs.getNode("trans_matrix"), {}
    for i in range(node.size()):
        e = node.at(i)
        tf[(e.getNode("parent_frame").string(), e.getNode("child_frame").string())] = e.getNode("matrix").mat()
    fs.release()
    frames = []
    for side in ("fisheye1", "fisheye2"):
        rows = [line.split() for line in (root / f"{side}.txt").read_text().splitlines() if line.strip()
                and not line.startswith("#")]
        frames.append([(int(round(float(t) * 1e9)), root / rel) for t, rel in rows])
    frames = [[side[k] for k in FRAMES] for side in frames]
    odom = []
    for line in (root / "odom.txt").read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            v = [float(x) for x in line.split()]
            odom.append((int(round(v[0] * 1e9)), v[1:4], v[4:8]))
    return cams, tf, frames, odom


def _write_bag(path, ros1, stereo, T_base_cam, frames, odom):
    topics = {f"/t265/fisheye{side}/{name}": msgtype for side in "12" for name, msgtype in
              (("image_raw", "sensor_msgs/msg/Image"), ("camera_info", "sensor_msgs/msg/CameraInfo"))}
    topics.update({"/odom": "nav_msgs/msg/Odometry", "/tf_static": "tf2_msgs/msg/TFMessage"})
    with BagWriter(path, ros1, topics) as bag:
        m, G = bag.msgs, bag.msgs.T
        t0 = min(frames[0][0][0], odom[0][0])
        bag.put("/tf_static", m.tf_3d([("base_link", "t265_fisheye1_optical_frame", T_base_cam)], t0), t0)
        for t, pos, q in odom:
            point = G["geometry_msgs/msg/Point"](x=pos[0], y=pos[1], z=pos[2])
            quaternion = G["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3])
            bag.put("/odom", m.odometry(point, quaternion, t), t)
        for (tl, left), (tr, right) in zip(*frames):
            for side, t, img_path, info in (("1", tl, left, stereo.left), ("2", tr, right, stereo.right)):
                frame = f"t265_fisheye{side}_optical_frame"
                bag.put(f"/t265/fisheye{side}/camera_info", m.camera_info(info, t, frame), t)
                img = cv2.imread(str(img_path), cv2.IMREAD_UNCHANGED)
                bag.put(f"/t265/fisheye{side}/image_raw", m.image(img, t, frame), t)
    return path


def _stereo(cams, tf):
    from mrstereo.camera import Camera, rectify_fusiello

    left, right = (Camera.from_ros(c["width"], c["height"], c["K"], "equidistant", c["D"])
                   for c in (cams["left"], cams["right"]))
    T_f1_f2 = tf[("t265_fisheye1_optical_frame", "t265_fisheye2_optical_frame")]
    T_f2_f1 = np.linalg.inv(T_f1_f2)                       # x_right = R x_left + T (OpenCV)
    return rectify_fusiello(left, right, T_f2_f1[:3, :3], T_f2_f1[:3, 3]).stereo


@pytest.mark.slow
def test_openloris_fisheye_bags_map_from_camera_info_and_tf(sample_data, tmp_path, capsys):
    from mrstereo.geometry.ground import ground_from_mount
    from mrstereo.recordings.manifest import read_manifest

    root = sample_data("openloris-sample")
    cams, tf, frames, odom = _load(root)
    stereo = _stereo(cams, tf)
    T_base_cam = tf[("base_link", "t265_fisheye1_optical_frame")]
    outputs = []
    for ros1 in (True, False):
        bag = _write_bag(tmp_path / ("run.bag" if ros1 else "run2"), ros1, stereo, T_base_cam, frames, odom)
        out = tmp_path / f"map{int(ros1)}"
        topics = ["--bag", str(bag), "--left-topic", "/t265/fisheye1/image_raw", "--right-topic",
                  "/t265/fisheye2/image_raw", "--odom-topic", "/odom", "--camera-frame", "t265_fisheye1_optical_frame"]
        assert entry(["map", *topics, "--origin", "-6,-3", "--size", "6,6", "-o", str(out), "--quiet"]) == 0
        outputs.append(out)
        if ros1:                                  # the export: camera_info (equidistant) + TF mount + odometry
            assert entry(["export", *topics, "-o", str(tmp_path / "ds"), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "mount: height 0.895 m" in err and "tf base_link <- t265_fisheye1_optical_frame" in err
    for name in ("map.pgm", "map.yaml", "log_odds.npy", "metrics.json"):
        assert (outputs[0] / name).read_bytes() == (outputs[1] / name).read_bytes(), name
    metrics = json.loads((outputs[0] / "metrics.json").read_text())
    assert metrics["floor"]["method"] == "mount" and metrics["floor"]["height_m"] == pytest.approx(0.8951, abs=1e-4)
    log_odds = np.load(outputs[0] / "log_odds.npy")
    assert (log_odds > 0).sum() > 50 and (log_odds < 0).sum() > 200      # obstacles and free floor seen
    # the dataset: the fisheye calibration from camera_info, the 6-DoF mount from TF, poses from odometry
    m = read_manifest(tmp_path / "ds")
    assert m.calibration.left.camera.distortion_model == "equidistant"
    np.testing.assert_allclose(m.mount.T_base_from_cam, T_base_cam, atol=1e-9)
    g = ground_from_mount(m.mount, R_rect_from_cam=m.calibration.left.R)
    assert g.height_m == pytest.approx(0.8951, abs=1e-4) and abs(g.tilt_rad) < 0.02
    x, y, yaw = m.frames[0].pose                      # odom.txt between its first two samples (linear, slerp)
    assert (x, y) == pytest.approx((-3.3102, 0.1207), abs=1e-4) and yaw == pytest.approx(-0.5515, abs=1e-4)
