"""Visual odometry on real frames: four T265 fisheye pairs of OpenLORIS-Scene (shared/data).

The calibration is mrstereo's import of the recording's own files (sensors.yaml with its
Kannala-Brandt cameras, trans_matrix.yaml; :func:`mrstereo.camera.formats.import_calibration`),
the pairs are rectified with it (Fusiello, the equidistant model); the camera mount on the
robot base is trans_matrix.yaml's. The odometry's relative motion of the robot base is
compared with the ground truth (groundtruth.txt, interpolated at the image stamps).
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from mrstereo.camera.formats import import_calibration
from mrstereo.camera.mount import CameraMount
from mrstereo.odometry import visual_odometry
from mrstereo.transforms import T_from_position_quaternion, rotation_angle_rad

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
    from mrstereo.recordings.samples import local_path

    DATA = local_path("openloris-sample")
    stereo = import_calibration(DATA / "sensors.yaml").stereo           # trans_matrix.yaml found beside it
    assert stereo.left.camera.is_fisheye
    trans = {(e["parent_frame"], e["child_frame"]): e["matrix"]
             for e in _opencv_yaml(DATA / "trans_matrix.yaml")["trans_matrix"]}
    mount = CameraMount(trans[("base_link", "t265_fisheye1_optical_frame")])
    T_base_from_cam = mount.T_base_from_rectified(stereo.left.R)           # of the rectified left camera
    stamps, pairs = [], []
    for l1, l2 in zip((DATA / "fisheye1.txt").read_text().split("\n"), (DATA / "fisheye2.txt").read_text().split("\n")):
        if not l1.strip():
            continue
        stamps.append(float(l1.split()[0]))
        images = [cv2.imread(str(DATA / line.split()[1]), cv2.IMREAD_GRAYSCALE) for line in (l1, l2)]
        pairs.append(stereo.rectify(*images))
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
