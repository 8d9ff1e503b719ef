"""Visual odometry on real frames: four T265 fisheye pairs of OpenLORIS-Scene (shared/data).

The fisheye pair is rectified to a 640x480 pinhole pair with OpenCV's own fisheye functions
(the calibration of sensors.yaml, the extrinsics of trans_matrix.yaml); the odometry's relative
motion of the robot base is compared with the ground truth (groundtruth.txt, interpolated at the
image stamps).
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from mrstereo.camera import Camera, CameraInfo, StereoCamera
from mrstereo.odometry import visual_odometry
from mrstereo.odometry.se3 import T_from_position_quaternion, rotation_angle_rad

pytestmark = pytest.mark.sample_data("openloris-sample")


def _opencv_yaml(path: Path) -> dict:
    class Loader(yaml.SafeLoader):
        pass

    def matrix(loader, node):
        m = loader.construct_mapping(node, deep=True)
        return np.array(m["data"], dtype=np.float64).reshape(m["rows"], m["cols"])

    Loader.add_constructor("tag:yaml.org,2002:opencv-matrix", matrix)
    text = path.read_text().split("\n", 1)[1]          # drop the "%YAML:1.0" line
    return yaml.load(text, Loader=Loader)


@pytest.fixture(scope="module")
def loris():
    from mrstereo.data import local_path

    DATA = local_path("openloris-sample")
    sensors = _opencv_yaml(DATA / "sensors.yaml")
    trans = {(e["parent_frame"], e["child_frame"]): e["matrix"]
             for e in _opencv_yaml(DATA / "trans_matrix.yaml")["trans_matrix"]}

    def intrinsics(name):
        s = sensors[name]
        fx, cx, fy, cy = s["intrinsics"].ravel()                  # note the order
        return np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]]), s["distortion_coefficients"].ravel()[:4]

    (K1, D1), (K2, D2) = intrinsics("t265_fisheye1_optical_frame"), intrinsics("t265_fisheye2_optical_frame")
    T_c1_from_c2 = trans[("t265_fisheye1_optical_frame", "t265_fisheye2_optical_frame")]
    T_c2_from_c1 = np.linalg.inv(T_c1_from_c2)
    R1, R2, _, _, _ = cv2.fisheye.stereoRectify(K1, D1, K2, D2, (848, 800), T_c2_from_c1[:3, :3],
                                                T_c2_from_c1[:3, 3], flags=cv2.CALIB_ZERO_DISPARITY)
    f, size = 250.0, (640, 480)
    P1 = np.array([[f, 0, 320, 0], [0, f, 240, 0], [0, 0, 1, 0.0]])
    P2 = P1.copy()
    P2[0, 3] = -f * np.linalg.norm(T_c2_from_c1[:3, 3])
    maps = [cv2.fisheye.initUndistortRectifyMap(K, D, R, P, size, cv2.CV_32FC1)
            for K, D, R, P in ((K1, D1, R1, P1), (K2, D2, R2, P2))]
    camera = Camera(width=size[0], height=size[1], fx=f, fy=f, cx=320, cy=240)
    stereo = StereoCamera(left=CameraInfo(camera, P=P1, name="left"), right=CameraInfo(camera, P=P2, name="right"))
    T_c1_from_rect = np.eye(4)
    T_c1_from_rect[:3, :3] = R1.T
    T_base_from_cam = trans[("base_link", "t265_fisheye1_optical_frame")] @ T_c1_from_rect
    stamps, pairs = [], []
    for l1, l2 in zip((DATA / "fisheye1.txt").read_text().split("\n"), (DATA / "fisheye2.txt").read_text().split("\n")):
        if not l1.strip():
            continue
        stamps.append(float(l1.split()[0]))
        images = [cv2.imread(str(DATA / line.split()[1]), cv2.IMREAD_GRAYSCALE) for line in (l1, l2)]
        pairs.append(tuple(cv2.remap(img, mx, my, cv2.INTER_LINEAR) for img, (mx, my) in zip(images, maps)))
    gt = np.loadtxt(DATA / "groundtruth.txt")

    def truth(t):
        i = int(np.searchsorted(gt[:, 0], t))
        a = (t - gt[i - 1, 0]) / (gt[i, 0] - gt[i - 1, 0])
        return T_from_position_quaternion((1 - a) * gt[i - 1, 1:4] + a * gt[i, 1:4], (1 - a) * gt[i - 1, 4:] + a * gt[i, 4:])

    return stereo, T_base_from_cam, pairs, [truth(t) for t in stamps], stamps


def test_relative_motion_matches_ground_truth(loris):
    stereo, mount, pairs, truth, stamps = loris
    result = visual_odometry(pairs, stereo, T_base_from_cam=mount, stamps_s=stamps)
    assert result.success, result.message
    for k in range(1, len(pairs)):
        est = np.linalg.inv(result.T_world_from_base[0]) @ result.T_world_from_base[k]
        true = np.linalg.inv(truth[0]) @ truth[k]
        assert np.linalg.norm(est[:3, 3] - true[:3, 3]) < 0.01, k                           # 1 cm
        assert np.degrees(rotation_angle_rad(est[:3, :3].T @ true[:3, :3])) < 0.5, k         # 0.5 degree
    assert result.n_inliers[1:].min() >= 50


def test_repeated_real_pair_gives_no_motion(loris):
    stereo, mount, pairs, _, _ = loris
    result = visual_odometry([pairs[1]] * 20, stereo, T_base_from_cam=mount)
    assert result.success and result.status.count("keyframe") == 1
    moved = np.linalg.norm(result.T_world_from_base[:, :3, 3] - result.T_world_from_base[0, :3, 3], axis=1)
    assert moved.max() <= 0.001
