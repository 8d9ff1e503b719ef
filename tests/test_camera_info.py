"""ROS camera_info / stereo YAML round trips, rectification maps, bad files."""
import numpy as np
import pytest
import yaml

from mrstereo.camera import (Camera, CameraInfo, CameraMount, StereoCamera, read_camera_info, read_stereo,
                             write_camera_info, write_stereo)
from mrstereo.transforms import rotation_from_rpy

CAM = Camera(width=320, height=240, fx=201.0, fy=199.5, cx=162.3, cy=117.9, k1=-0.08, k2=0.01)


def make_stereo():
    K_rect = np.array([[200.0, 0, 160.0], [0, 200.0, 120.0], [0, 0, 1]])
    P_left = np.hstack([K_rect, np.zeros((3, 1))])
    P_right = P_left.copy()
    P_right[0, 3] = -200.0 * 0.12
    R_left = rotation_from_rpy(0.01, -0.005, 0.002)
    return StereoCamera(left=CameraInfo(CAM, R=R_left, P=P_left, name="left"),
                        right=CameraInfo(CAM, R=rotation_from_rpy(-0.004, 0.008, -0.01), P=P_right, name="right"),
                        mount=CameraMount.from_rig(0.45, 0.15, R_rect_from_cam=R_left))


def test_camera_info_round_trip(tmp_path):
    info = CameraInfo(CAM, name="cam0")
    write_camera_info(tmp_path / "cam.yaml", info)
    data = yaml.safe_load((tmp_path / "cam.yaml").read_text())
    assert data["distortion_model"] == "plumb_bob"
    assert data["camera_matrix"]["data"][2] == pytest.approx(162.3)
    back = read_camera_info(tmp_path / "cam.yaml")
    assert back.camera == CAM and back.name == "cam0"
    np.testing.assert_array_equal(back.P, info.P)


def test_stereo_round_trip_and_baseline_sign(tmp_path):
    stereo = make_stereo()
    write_stereo(tmp_path / "stereo.yaml", stereo)
    data = yaml.safe_load((tmp_path / "stereo.yaml").read_text())
    assert data["right"]["projection_matrix"]["data"][3] == pytest.approx(-24.0)
    back = read_stereo(tmp_path / "stereo.yaml")
    assert back.baseline_m == pytest.approx(0.12)
    assert back.focal_px == 200.0
    np.testing.assert_allclose(back.mount.T_base_from_cam, stereo.mount.T_base_from_cam, atol=1e-15)
    np.testing.assert_allclose(back.right.R, stereo.right.R)
    assert not back.is_rectified
    assert StereoCamera.ideal(Camera(width=32, height=24, fx=20, fy=20, cx=16, cy=12), 0.1).is_rectified


def test_rectify_moves_points_to_same_row():
    stereo = make_stereo()
    (lx, ly), (rx, ry) = stereo.rectification_maps()
    # A world point seen by both raw cameras must land on one row after rectification.
    p_rect = np.array([0.3, -0.2, 2.5])
    for (mx, my), info, offset in (((lx, ly), stereo.left, 0.0), ((rx, ry), stereo.right, 0.12)):
        p_raw = info.R.T @ (p_rect - [offset, 0, 0])
        uv_raw = info.camera.project(p_raw[None])[0]
        u_rect = 200.0 * (p_rect[0] - offset) / p_rect[2] + 160.0
        v_rect = 200.0 * p_rect[1] / p_rect[2] + 120.0
        iu, iv = int(round(u_rect)), int(round(v_rect))
        # The map near the rectified pixel points back at the raw pixel (within interpolation).
        assert abs(mx[iv, iu] - uv_raw[0]) < 1.5 and abs(my[iv, iu] - uv_raw[1]) < 1.5


def test_bad_stereo_files(tmp_path):
    with pytest.raises(FileNotFoundError, match="stereo calibration not found"):
        read_stereo(tmp_path / "missing.yaml")
    (tmp_path / "bad.yaml").write_text("left: [1, 2\n")
    with pytest.raises(ValueError, match="not valid YAML"):
        read_stereo(tmp_path / "bad.yaml")
    (tmp_path / "half.yaml").write_text("left: {}\n")
    with pytest.raises(ValueError, match="expected 'left:' and 'right:'"):
        read_stereo(tmp_path / "half.yaml")
    data = make_stereo().to_dict()
    data["left"]["camera_matrix"]["data"][0] = float("nan")
    (tmp_path / "nan.yaml").write_text(yaml.safe_dump(data))
    with pytest.raises(ValueError, match="camera_matrix.*NaN"):
        read_stereo(tmp_path / "nan.yaml")
    data = make_stereo().to_dict()
    data["right"]["projection_matrix"]["data"][3] = 24.0
    (tmp_path / "sign.yaml").write_text(yaml.safe_dump(data))
    with pytest.raises(ValueError, match="baseline"):
        read_stereo(tmp_path / "sign.yaml")


def test_rectify_rejects_mismatched_sizes():
    stereo = make_stereo()
    with pytest.raises(ValueError, match="same size"):
        stereo.rectify(np.zeros((240, 320), np.uint8), np.zeros((240, 321), np.uint8))
    with pytest.raises(ValueError, match="calibration is 320x240"):
        stereo.rectify(np.zeros((100, 100), np.uint8), np.zeros((100, 100), np.uint8))


@pytest.mark.parametrize("model, D", [
    ("plumb_bob", [-0.28, 0.09, 1e-3, -5e-4, -0.01]),
    ("rational_polynomial", [7.9, 3.1, -4e-4, 2e-4, 0.08, 8.3, 5.4, 0.6]),
    ("rational_polynomial", [-0.3, 0.1, 1e-3, -2e-4, 0.02, 0.05, 0.01, 0.002, 1e-3, -2e-3, 5e-4, 1e-3]),
    ("rational_polynomial", [-0.3, 0.1, 1e-3, -2e-4, 0.02, 0.05, 0.01, 0.002, 1e-3, -2e-3, 5e-4, 1e-3, 0.01, -0.02]),
    ("equidistant", [-0.0089, 0.0472, -0.0448, 0.0086]),
])
def test_every_model_round_trips_through_camera_info(tmp_path, model, D):
    cam = Camera.from_ros(320, 240, CAM.K, model, D)
    info = CameraInfo(cam, R=rotation_from_rpy(0.01, -0.005, 0.002), name="cam0")
    write_camera_info(tmp_path / "cam.yaml", info)
    data = yaml.safe_load((tmp_path / "cam.yaml").read_text())
    assert data["distortion_model"] == model and data["distortion_coefficients"]["data"] == D
    assert data["distortion_coefficients"]["cols"] == len(D)
    back = read_camera_info(tmp_path / "cam.yaml")
    assert back.camera == cam and back.camera.distortion_model == model
    np.testing.assert_array_equal(back.R, info.R)
    assert CameraInfo.from_dict(info.to_dict()).to_dict() == info.to_dict()


def test_unknown_model_in_camera_info_is_named():
    data = CameraInfo(CAM).to_dict()
    data["distortion_model"] = "double_sphere"
    with pytest.raises(ValueError, match="cam.yaml: distortion_model 'double_sphere' is not supported"):
        CameraInfo.from_dict(data, where="cam.yaml")
    data = CameraInfo(CAM).to_dict()
    data["distortion_coefficients"]["data"] = ["a", 0, 0, 0, 0]
    with pytest.raises(ValueError, match="cam.yaml: field 'distortion_coefficients' is not numeric"):
        CameraInfo.from_dict(data, where="cam.yaml")


def test_is_rectified_sees_every_coefficient():
    ideal = StereoCamera.ideal(Camera(width=320, height=240, fx=200.0, fy=200.0, cx=160.0, cy=120.0), 0.1)
    assert ideal.is_rectified
    tangential = Camera.from_ros(320, 240, ideal.left.camera.K, "plumb_bob", [0, 0, 1e-3, 0, 0])
    assert not StereoCamera.ideal(tangential, 0.1).is_rectified
    fisheye = Camera.from_ros(320, 240, ideal.left.camera.K, "equidistant", [0, 0, 0, 0])
    assert not StereoCamera.ideal(fisheye, 0.1).is_rectified       # equidistant is not a pinhole
