"""Calibration import from other tools' files (known answers), bad calibrations, `calib convert`."""
import cv2
import numpy as np
import pytest
import yaml

from mrstereo.camera import (Camera, CameraInfo, StereoCamera, read_stereo, rectify_fusiello, write_camera_info,
                             write_stereo)
from mrstereo.camera.formats import import_calibration
from mrstereo.cli import entry
from mrstereo.recordings.samples import local_path
from mrstereo.transforms import rotation_from_rpy

CHESS = local_path("opencv-stereo-chessboard")
LORIS = local_path("openloris-sample")

# A raw pair with known geometry: non-square image, off-centre principal points, 5 plumb_bob coefficients.
D_LEFT = [-0.28, 0.074, 0.0002, 1.8e-05, -0.0011]
D_RIGHT = [-0.283, 0.0739, -0.0003, 1.2e-05, 0.0009]
LEFT = Camera.from_ros(752, 480, [[458.654, 0, 367.215], [0, 457.296, 248.375], [0, 0, 1]], "plumb_bob", D_LEFT)
RIGHT = Camera.from_ros(752, 480, [[457.587, 0, 379.999], [0, 456.134, 255.238], [0, 0, 1]], "plumb_bob", D_RIGHT)
R_LR = rotation_from_rpy(0.0021, -0.0105, 0.0043)      # x_right = R x_left + T
C2 = np.array([0.1101, -0.0009, 0.0007])                   # right optical centre in the left frame [m]
T_LR = -R_LR @ C2
BASELINE = float(np.linalg.norm(C2))


def pose(R, t) -> np.ndarray:
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = R, t
    return M


def assert_known_pair(stereo: StereoCamera, left=LEFT, right=RIGHT, R=R_LR, T=T_LR, *, baseline=BASELINE):
    """Raw K, D as given; rectification puts one 3-D point on one row at disparity f b / Z."""
    assert stereo.baseline_m == pytest.approx(baseline, rel=1e-9)
    for info, cam in ((stereo.left, left), (stereo.right, right)):
        np.testing.assert_allclose(info.camera.K, cam.K, rtol=1e-12)
        np.testing.assert_allclose(info.camera.D, cam.D, rtol=1e-12, atol=1e-15)
        assert info.camera.distortion_model == cam.distortion_model
    rng = np.random.default_rng(7)
    pts = rng.uniform([-0.8, -0.5, 1.5], [0.8, 0.5, 6.0], (200, 3))
    uv = [left.project(pts), right.project(pts @ np.asarray(R).T + T)]
    inside = np.all([(u[:, 0] > 0) & (u[:, 0] < 751) & (u[:, 1] > 0) & (u[:, 1] < 479) for u in uv], axis=0)
    assert inside.sum() > 100

    def rectified(info, uv_raw):
        h = (info.P[:, :3] @ info.R @ info.camera.rays(uv_raw[inside]).T).T
        return h[:, :2] / h[:, 2:]

    rl, rr = rectified(stereo.left, uv[0]), rectified(stereo.right, uv[1])
    assert np.abs(rl[:, 1] - rr[:, 1]).max() < 1e-6
    z_rect = (pts[inside] @ stereo.left.R.T)[:, 2]
    np.testing.assert_allclose(rl[:, 0] - rr[:, 0], stereo.focal_px * baseline / z_rect, rtol=1e-7)


def expected_fusiello():
    return rectify_fusiello(LEFT, RIGHT, R_LR, T_LR).stereo


def opencv_write(path, entries: dict):
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for key, value in entries.items():
        fs.write(key, value)
    fs.release()


# ------------------------------------------------------------------------------------------ formats

def test_stereo_yaml_is_read_as_before(tmp_path):
    expected = expected_fusiello()
    write_stereo(tmp_path / "stereo.yaml", expected)
    result = import_calibration(tmp_path / "stereo.yaml")
    assert result.format.startswith("mrstereo/ROS stereo") and not result.rectified_here
    np.testing.assert_allclose(result.stereo.right.P, expected.right.P, rtol=1e-12)
    assert_known_pair(result.stereo)


def test_two_camera_info_files_with_rectified_P(tmp_path):
    expected = expected_fusiello()
    write_camera_info(tmp_path / "left.yaml", expected.left)
    write_camera_info(tmp_path / "right.yaml", expected.right)
    for arg in (f"{tmp_path / 'left.yaml'},{tmp_path / 'right.yaml'}", [tmp_path / "left.yaml", tmp_path / "right.yaml"]):
        stereo = read_stereo(arg)
        assert stereo.baseline_m == pytest.approx(-expected.right.P[0, 3] / expected.right.P[0, 0])
        np.testing.assert_allclose(stereo.right.R, expected.right.R)
        assert_known_pair(stereo)


def test_two_camera_info_message_dumps(tmp_path):
    """``ros2 topic echo --once /cam0/camera_info > left.yaml`` (ROS 2 ``k d r p``; ROS 1 ``K D R P``)."""
    expected = expected_fusiello()
    for (name, info), upper in zip((("left", expected.left), ("right", expected.right)), (False, True)):
        k, d, r, p = ("K", "D", "R", "P") if upper else ("k", "d", "r", "p")
        msg = {"header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": f"cam_{name}"}, "height": 480,
               "width": 752, "distortion_model": "plumb_bob", d: [float(v) for v in info.camera.D],
               k: [float(v) for v in info.camera.K.ravel()], r: [float(v) for v in info.R.ravel()],
               p: [float(v) for v in info.P.ravel()], "binning_x": 0, "binning_y": 0}
        (tmp_path / f"{name}.yaml").write_text(yaml.safe_dump(msg))
    result = import_calibration(f"{tmp_path / 'left.yaml'},{tmp_path / 'right.yaml'}")
    assert result.format.startswith("two ROS camera_info") and result.stereo.left.name == "cam_left"
    assert_known_pair(result.stereo)


def test_two_camera_info_files_without_extrinsics(tmp_path):
    write_camera_info(tmp_path / "left.yaml", CameraInfo(LEFT))
    write_camera_info(tmp_path / "right.yaml", CameraInfo(RIGHT))
    with pytest.raises(ValueError, match="without stereo extrinsics"):
        read_stereo(f"{tmp_path / 'left.yaml'},{tmp_path / 'right.yaml'}")
    with pytest.raises(ValueError, match="left.yaml holds one camera"):
        read_stereo(tmp_path / "left.yaml")


def kalibr_camchain(model="radtan", left=LEFT, right=RIGHT, R=R_LR, T=T_LR) -> dict:
    def cam(c):
        d = {"camera_model": "pinhole", "intrinsics": [c.fx, c.fy, c.cx, c.cy], "distortion_model": model,
             "distortion_coeffs": [float(v) for v in (c.D[:4])], "resolution": [c.width, c.height],
             "rostopic": "/cam/image_raw"}
        return d
    return {"cam0": {**cam(left), "T_cam_imu": np.eye(4).tolist()},
            "cam1": {**cam(right), "T_cn_cnm1": pose(R, T).tolist()}}


def test_kalibr_camchain_radtan(tmp_path):
    # Kalibr's radtan has 4 coefficients: take the cameras without k3.
    left = Camera.from_ros(752, 480, LEFT.K, "plumb_bob", D_LEFT[:4])
    right = Camera.from_ros(752, 480, RIGHT.K, "plumb_bob", D_RIGHT[:4])
    (tmp_path / "camchain.yaml").write_text(yaml.safe_dump(kalibr_camchain(left=left, right=right)))
    result = import_calibration(tmp_path / "camchain.yaml")
    assert result.format.startswith("Kalibr") and result.rectified_here
    assert result.stereo.left.camera.distortion_model == "plumb_bob"
    assert_known_pair(result.stereo, left, right)


def test_kalibr_camchain_equidistant(tmp_path):
    left = Camera.from_ros(752, 480, LEFT.K, "equidistant", [-0.012, 0.043, -0.041, 0.0077])
    right = Camera.from_ros(752, 480, RIGHT.K, "equidistant", [-0.006, 0.041, -0.039, 0.0070])
    (tmp_path / "camchain.yaml").write_text(yaml.safe_dump(kalibr_camchain("equidistant", left, right)))
    stereo = read_stereo(tmp_path / "camchain.yaml")
    assert stereo.left.camera.is_fisheye
    assert_known_pair(stereo, left, right)


def test_kalibr_swapped_cameras_one_line(tmp_path, capsys):
    R_RL = R_LR.T
    (tmp_path / "camchain.yaml").write_text(yaml.safe_dump(kalibr_camchain(left=RIGHT, right=LEFT, R=R_RL,
                                                                           T=-R_RL @ T_LR)))
    with pytest.raises(ValueError, match="swapped"):
        read_stereo(tmp_path / "camchain.yaml")
    assert entry(["calib", "convert", str(tmp_path / "camchain.yaml"), "-o", str(tmp_path / "s.yaml")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "swapped" in err and "camchain.yaml" in err
    assert not (tmp_path / "s.yaml").exists()


EUROC = """%YAML:1.0
# General sensor definitions.
sensor_type: camera
comment: VI-Sensor {name} (MT9M034)

# Sensor extrinsics wrt. the body-frame.
T_BS:
  cols: 4
  rows: 4
  data: {T_BS}

# Camera specific definitions.
rate_hz: 20
resolution: [752, 480]
camera_model: pinhole
intrinsics: {intr} #fu, fv, cu, cv
distortion_model: radial-tangential
distortion_coefficients: {dist}
"""


def test_euroc_sensor_yaml_pair(tmp_path):
    left = Camera.from_ros(752, 480, LEFT.K, "plumb_bob", D_LEFT[:4])
    right = Camera.from_ros(752, 480, RIGHT.K, "plumb_bob", D_RIGHT[:4])
    T_B_cam0 = pose(rotation_from_rpy(-1.58, 0.01, -1.55), [-0.0216, -0.0647, 0.0098])
    T_B_cam1 = T_B_cam0 @ np.linalg.inv(pose(R_LR, T_LR))       # cam1's pose: T_B_cam0 @ T_cam0_cam1
    for name, cam, T_BS in (("cam0", left, T_B_cam0), ("cam1", right, T_B_cam1)):
        (tmp_path / name).mkdir()
        (tmp_path / name / "sensor.yaml").write_text(EUROC.format(
            name=name, T_BS=[float(v) for v in T_BS.ravel()], intr=[cam.fx, cam.fy, cam.cx, cam.cy],
            dist=[float(v) for v in cam.D[:4]]))
    result = import_calibration(f"{tmp_path / 'cam0' / 'sensor.yaml'},{tmp_path / 'cam1' / 'sensor.yaml'}")
    assert result.format.startswith("two ASL/EuRoC")
    assert_known_pair(result.stereo, left, right)
    with pytest.raises(ValueError, match="one camera's EuRoC sensor.yaml"):
        read_stereo(tmp_path / "cam0" / "sensor.yaml")


# The published calibration of the EuRoC MAV dataset (ASL, ETH Zurich), mav0/cam{0,1}/sensor.yaml.
EUROC_REAL = {
    "cam0": dict(T_BS=[0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975,
                       0.999557249008, 0.0149672133247, 0.025715529948, -0.064676986768,
                       -0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949,
                       0.0, 0.0, 0.0, 1.0],
                 intr=[458.654, 457.296, 367.215, 248.375],
                 dist=[-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]),
    "cam1": dict(T_BS=[0.0125552670891, -0.999755099723, 0.0182237714554, -0.0198435579556,
                       0.999598781151, 0.0130119051815, 0.0251588363115, 0.0453689425024,
                       -0.0253898008918, 0.0179005838253, 0.999517347078, 0.00786212447038,
                       0.0, 0.0, 0.0, 1.0],
                 intr=[457.587, 456.134, 379.999, 255.238],
                 dist=[-0.28368365, 0.07451284, -0.00010473, -3.55590700e-05]),
}


def test_euroc_published_calibration(tmp_path):
    cams, poses = [], []
    for name, c in EUROC_REAL.items():
        (tmp_path / name).mkdir()
        (tmp_path / name / "sensor.yaml").write_text(EUROC.format(name=name, **c))
        fu, fv, cu, cv_ = c["intr"]
        cams.append(Camera.from_ros(752, 480, [[fu, 0, cu], [0, fv, cv_], [0, 0, 1]], "plumb_bob", c["dist"]))
        poses.append(np.reshape(c["T_BS"], (4, 4)))
    T_cam0_cam1 = np.linalg.inv(poses[0]) @ poses[1]
    R = T_cam0_cam1[:3, :3].T
    stereo = read_stereo(f"{tmp_path / 'cam0' / 'sensor.yaml'},{tmp_path / 'cam1' / 'sensor.yaml'}")
    assert stereo.baseline_m == pytest.approx(0.1100778, abs=1e-6)         # cam1 sits 11.0 cm to the right
    assert T_cam0_cam1[0, 3] > 0.11
    assert_known_pair(stereo, cams[0], cams[1], R, -R @ T_cam0_cam1[:3, 3], baseline=0.11007784219)


@pytest.mark.parametrize("suffix", [".yml", ".xml"])
@pytest.mark.parametrize("names", [("M1", "D1", "M2", "D2"), ("K1", "D1", "K2", "D2"),
                                   ("cameraMatrix1", "distCoeffs1", "cameraMatrix2", "distCoeffs2")])
def test_opencv_filestorage_stereo(tmp_path, suffix, names):
    path = tmp_path / f"stereo{suffix}"
    opencv_write(path, {names[0]: LEFT.K, names[1]: np.array([D_LEFT]), names[2]: RIGHT.K,
                        names[3]: np.array([D_RIGHT]), "R": R_LR, "T": T_LR.reshape(3, 1)})
    head = path.read_text()[:40]
    assert head.startswith("%YAML" if suffix == ".yml" else "<?xml")      # %YAML:1.0 (OpenCV 4) or 1.2 (5)
    with pytest.raises(ValueError, match="without the image size"):
        read_stereo(path)
    result = import_calibration(path, image_size=(752, 480))
    assert result.format.startswith("OpenCV FileStorage") and result.rectified_here
    assert_known_pair(result.stereo)
    np.testing.assert_allclose(result.stereo.right.P, expected_fusiello().right.P, rtol=1e-12)


def test_opencv_with_stereo_rectify_output_uses_it(tmp_path):
    R1, R2, P1, P2, _, _, _ = cv2.stereoRectify(LEFT.K, np.array(D_LEFT), RIGHT.K, np.array(D_RIGHT),
                                                (752, 480), R_LR, T_LR.reshape(3, 1), alpha=0)
    opencv_write(tmp_path / "extrinsics.yml", {"R": R_LR, "T": T_LR, "R1": R1, "R2": R2, "P1": P1, "P2": P2})
    opencv_write(tmp_path / "intrinsics.yml", {"M1": LEFT.K, "D1": np.array(D_LEFT), "M2": RIGHT.K,
                                               "D2": np.array(D_RIGHT), "image_width": 752, "image_height": 480})
    with pytest.raises(ValueError, match="without stereo extrinsics"):
        read_stereo(tmp_path / "intrinsics.yml")
    result = import_calibration(f"{tmp_path / 'intrinsics.yml'},{tmp_path / 'extrinsics.yml'}")
    assert not result.rectified_here
    np.testing.assert_allclose(result.stereo.right.P, P2)
    np.testing.assert_allclose(result.stereo.left.R, R1)
    assert_known_pair(result.stereo)


def openloris_sensors(path, left, right):
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for name, cam in (("t265_fisheye1_optical_frame", left), ("t265_fisheye2_optical_frame", right),
                      ("d400_color_optical_frame", None)):
        fs.startWriteStruct(name, cv2.FileNode_MAP)
        fs.write("sensor_type", "camera")
        fs.write("width", 752 if cam else 848)
        fs.write("height", 480)
        fs.write("model", "fisheye" if cam else "pinhole")
        fs.write("intrinsics", np.array([[cam.fx, cam.cx, cam.fy, cam.cy]]) if cam else np.array([[611.0, 433.0, 611.0, 249.0]]))
        fs.write("distortion_model", "Kannala-Brandt" if cam else "radial-tangential")
        fs.write("distortion_coefficients", np.array([list(cam.D) + [0.0]]) if cam else np.zeros((1, 5)))
        fs.endWriteStruct()
    fs.release()


def test_openloris_sensors_and_trans_matrix(tmp_path):
    left = Camera.from_ros(752, 480, LEFT.K, "equidistant", [-0.0073, 0.0435, -0.0413, 0.0077])
    right = Camera.from_ros(752, 480, RIGHT.K, "equidistant", [-0.0064, 0.0415, -0.0395, 0.0070])
    openloris_sensors(tmp_path / "sensors.yaml", left, right)
    T_base_f1 = pose(rotation_from_rpy(-1.57, 0.0, -1.56), [0.2376, -0.0387, 0.895])
    T_f1_f2 = np.linalg.inv(pose(R_LR, T_LR))
    # Chain base -> f1 and base -> f2 only: the reader has to go through base_link.
    fs = cv2.FileStorage(str(tmp_path / "poses.yaml"), cv2.FILE_STORAGE_WRITE)
    fs.startWriteStruct("trans_matrix", cv2.FileNode_SEQ)
    for parent, child, M in (("base_link", "t265_fisheye1_optical_frame", T_base_f1),
                             ("base_link", "t265_fisheye2_optical_frame", T_base_f1 @ T_f1_f2)):
        fs.startWriteStruct("", cv2.FileNode_MAP)
        fs.write("parent_frame", parent)
        fs.write("child_frame", child)
        fs.write("matrix", M)
        fs.endWriteStruct()
    fs.endWriteStruct()
    fs.release()
    with pytest.raises(ValueError, match="trans_matrix.yaml"):
        read_stereo(tmp_path / "sensors.yaml")
    stereo = read_stereo(f"{tmp_path / 'poses.yaml'},{tmp_path / 'sensors.yaml'}")
    assert stereo.left.camera.is_fisheye
    assert_known_pair(stereo, left, right)


@pytest.mark.sample_data("openloris-sample")
def test_real_openloris_t265(tmp_path, capsys):
    result = import_calibration(LORIS / "sensors.yaml")          # trans_matrix.yaml found beside it
    stereo = result.stereo
    assert result.format.startswith("OpenLORIS") and stereo.size == (848, 800)
    assert stereo.left.camera.is_fisheye
    assert stereo.left.camera.fx == pytest.approx(284.98089599609375)      # intrinsics are fx, cx, fy, cy
    assert stereo.left.camera.cx == pytest.approx(425.244384765625)
    assert stereo.baseline_m == pytest.approx(0.06398, abs=2e-5)           # |t| of fisheye1 -> fisheye2
    assert entry(["calib", "convert", str(LORIS / "sensors.yaml"), str(LORIS / "trans_matrix.yaml"),
                  "-o", str(tmp_path / "t265.yaml")]) == 0
    assert "baseline 0.0640 m" in capsys.readouterr().out
    back = read_stereo(tmp_path / "t265.yaml")
    np.testing.assert_allclose(back.right.P, stereo.right.P)
    assert back.right.camera.distortion_model == "equidistant"
    # Epipolar alignment on the real frames: cross-checked SIFT matches lie on one rectified row.
    left_path = sorted((LORIS / "fisheye1").glob("*.png"))[0]
    left, right = stereo.rectify(cv2.imread(str(left_path), cv2.IMREAD_GRAYSCALE),
                                 cv2.imread(str(LORIS / "fisheye2" / left_path.name), cv2.IMREAD_GRAYSCALE))
    sift = cv2.SIFT_create()
    (kl, dl), (kr, dr) = sift.detectAndCompute(left, None), sift.detectAndCompute(right, None)
    matches = cv2.BFMatcher(cv2.NORM_L2, crossCheck=True).match(dl, dr)
    uv_l = np.array([kl[m.queryIdx].pt for m in matches])
    uv_r = np.array([kr[m.trainIdx].pt for m in matches])
    dy, d = np.abs(uv_l[:, 1] - uv_r[:, 1]), uv_l[:, 0] - uv_r[:, 0]
    inliers = (dy < 5) & (d > -1)
    assert inliers.sum() > 500
    assert np.median(dy[inliers]) <= 0.5                     # measured 0.23 px


# ----------------------------------------------------------------- OpenCV chessboard: |dy| vs OpenCV

@pytest.fixture(scope="module")
def chessboard_calibration():
    pattern, square = (9, 6), 0.025
    board = np.zeros((54, 3), np.float32)
    board[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2) * square
    obj, img_l, img_r = [], [], []
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-4)
    for left_path in sorted(CHESS.glob("left*.jpg")):
        found = []
        for path in (left_path, CHESS / left_path.name.replace("left", "right")):
            gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
            ok, corners = cv2.findChessboardCorners(gray, pattern)
            if ok:
                found.append(cv2.cornerSubPix(gray, corners, (11, 11), (-1, -1), crit))
        if len(found) == 2:
            obj.append(board)
            img_l.append(found[0])
            img_r.append(found[1])
    size = (640, 480)
    _, K1, D1, _, _ = cv2.calibrateCamera(obj, img_l, size, None, None)
    _, K2, D2, _, _ = cv2.calibrateCamera(obj, img_r, size, None, None)
    rms, K1, D1, K2, D2, R, T, _, _ = cv2.stereoCalibrate(obj, img_l, img_r, K1, D1, K2, D2, size,
                                                          flags=cv2.CALIB_FIX_INTRINSIC)
    return dict(K1=K1, D1=D1, K2=K2, D2=D2, R=R, T=T, size=size, img_l=img_l, img_r=img_r, rms=rms)


def corner_dy_opencv(c):
    R1, R2, P1, P2, _, _, _ = cv2.stereoRectify(c["K1"], c["D1"], c["K2"], c["D2"], c["size"], c["R"], c["T"],
                                                alpha=0)
    dy = [np.abs(cv2.undistortPoints(l, c["K1"], c["D1"], R=R1, P=P1)[:, 0, 1]
                 - cv2.undistortPoints(r, c["K2"], c["D2"], R=R2, P=P2)[:, 0, 1])
          for l, r in zip(c["img_l"], c["img_r"])]
    return float(np.mean(np.concatenate(dy)))


def corner_dy_mrstereo(stereo: StereoCamera, c):
    def rect(info, uv):
        h = (info.P[:, :3] @ info.R @ info.camera.rays(uv.reshape(-1, 2).astype(float)).T).T
        return h[:, :2] / h[:, 2:]
    dy = [np.abs(rect(stereo.left, l)[:, 1] - rect(stereo.right, r)[:, 1]) for l, r in zip(c["img_l"], c["img_r"])]
    return float(np.mean(np.concatenate(dy)))


@pytest.mark.sample_data("opencv-stereo-chessboard")
@pytest.mark.parametrize("suffix", [".yml", ".xml"])
def test_opencv_chessboard_calibration_imported_rectifies_like_opencv(tmp_path, chessboard_calibration, suffix):
    c = chessboard_calibration
    assert c["D1"].size == 5 and np.all(c["D1"][0, 2:] != 0)            # a real 5-coefficient calibration
    path = tmp_path / f"stereo_calib{suffix}"
    opencv_write(path, {"M1": c["K1"], "D1": c["D1"], "M2": c["K2"], "D2": c["D2"], "R": c["R"], "T": c["T"],
                        "imageSize": np.array(c["size"])})
    stereo = read_stereo(path)
    np.testing.assert_allclose(stereo.left.camera.D, c["D1"].ravel())
    assert stereo.baseline_m == pytest.approx(float(np.linalg.norm(c["T"])))
    dy_cv, dy_ms = corner_dy_opencv(c), corner_dy_mrstereo(stereo, c)
    assert dy_cv < 0.5
    assert abs(dy_ms - dy_cv) <= 0.02, (dy_ms, dy_cv)


@pytest.mark.sample_data("opencv-stereo-chessboard")
def test_opencv_sample_intrinsics_without_extrinsics(tmp_path, capsys):
    assert entry(["rectify", "--calib", str(CHESS / "intrinsics.yml"), str(CHESS / "left01.jpg"),
                  str(CHESS / "right01.jpg"), "-o", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "intrinsics.yml" in err and "without stereo extrinsics" in err


# ---------------------------------------------------------------------------- bad calibrations (#18)

def stereo_dict():
    return expected_fusiello().to_dict()


def write(tmp_path, data, name="bad.yaml"):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data) if isinstance(data, dict) else data)
    return path


def zero_R(d):
    d["left"]["rectification_matrix"]["data"] = [0.0] * 9


def tiny_baseline(d):
    d["right"]["projection_matrix"]["data"][3] = -d["right"]["projection_matrix"]["data"][0] * 1e-300


def huge_tx(d):
    d["right"]["projection_matrix"]["data"][3] = -1e300


def string_in_D(d):
    d["right"]["distortion_coefficients"]["data"][1] = "a"


def no_overlap(d):
    d["right"]["rectification_matrix"]["data"] = [float(v) for v in rotation_from_rpy(0, 2.5, 0).ravel()]


def swapped(d):
    d["right"]["projection_matrix"]["data"][3] *= -1


def scaled_R(d):
    d["left"]["rectification_matrix"]["data"] = [2 * v for v in d["left"]["rectification_matrix"]["data"]]


def reflection_R(d):
    d["left"]["rectification_matrix"]["data"] = [float(v) for v in np.diag([1.0, 1.0, -1.0]).ravel()]


def huge_focal(d):
    d["left"]["projection_matrix"]["data"][0] = 1e300


def vertical(d):
    d["right"]["projection_matrix"]["data"][7] = -20.0


BAD = [
    (zero_R, "left: field 'rectification_matrix' is not a rotation"),
    (scaled_R, "left: field 'rectification_matrix' is not a rotation"),
    (reflection_R, "not a rotation.*det is -1"),
    (tiny_baseline, "baseline of 1e-300 m, outside the plausible"),
    (huge_tx, "baseline of .* m, outside the plausible"),
    (string_in_D, "right: field 'distortion_coefficients' is not numeric \\(found 'a'\\)"),
    (no_overlap, "rectified views .* overlap on 0.0 %"),
    (swapped, "views look swapped, exchange left and right"),
    (huge_focal, "left projection_matrix P\\[0,0\\] \\(fx\\) = 1e\\+300 px is implausible"),
    (vertical, "only horizontal stereo"),
]


@pytest.mark.parametrize("break_it,message", BAD, ids=[b[0].__name__ for b in BAD])
def test_bad_calibration_named(tmp_path, break_it, message):
    data = stereo_dict()
    break_it(data)
    path = write(tmp_path, data)
    with pytest.raises(ValueError, match=message) as info:
        read_stereo(path)
    assert str(path) in str(info.value)


@pytest.mark.parametrize("break_it", [zero_R, tiny_baseline, huge_tx, string_in_D, no_overlap, swapped])
def test_bad_calibration_cli_one_line(tmp_path, capsys, break_it):
    data = stereo_dict()
    break_it(data)
    path = write(tmp_path, data)
    img = tmp_path / "img.png"
    cv2.imwrite(str(img), np.full((480, 752), 128, np.uint8))
    for args in (["rectify", "--calib", str(path), str(img), str(img), "-o", str(tmp_path / "out")],
                 ["disparity", str(img), str(img), "--calib", str(path), "-o", str(tmp_path / "d.pfm")],
                 ["points", str(img), str(img), "--calib", str(path), "-o", str(tmp_path / "p.ply")],
                 ["calib", "convert", str(path), "-o", str(tmp_path / "s.yaml")]):
        assert entry(args) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("mrstereo: error: ") and err.count("\n") == 0 and str(path) in err
    assert not any((tmp_path / name).exists() for name in ("out", "d.pfm", "p.ply", "s.yaml"))


@pytest.mark.parametrize("content,message", [
    ("foo: 1\nbar: [1, 2]\n", "not a calibration mrstereo can read; formats tried: mrstereo/ROS stereo YAML"),
    ("- 1\n- 2\n", "not a calibration mrstereo can read"),
    (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", "is not a text file"),
    (b"left: \xff\xfe\n", "is not a text file"),
    ("%YAML:1.0\nfoo: [1, 2\n", "OpenCV FileStorage cannot parse it"),
    ("<?xml version=\"1.0\"?>\n<opencv_storage>\n<a>1</a></opencv_storage>\n", "not a calibration mrstereo can read"),
    ("cam0: {intrinsics: [1, 2, 3, 4]}\n", "cam0: missing field 'camera_model'"),
])
def test_unknown_or_broken_file_one_line(tmp_path, capsys, content, message):
    path = tmp_path / "calib.yaml"
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    with pytest.raises(ValueError, match=message):
        read_stereo(path)
    assert entry(["calib", "convert", str(path), "-o", str(tmp_path / "out.yaml")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and str(path) in err
    assert not (tmp_path / "out.yaml").exists()


def test_string_in_opencv_matrix_named(tmp_path):
    path = tmp_path / "s.yml"
    opencv_write(path, {"M1": LEFT.K, "D1": np.array(D_LEFT), "M2": RIGHT.K, "D2": np.array(D_RIGHT),
                        "R": R_LR, "T": T_LR})
    path.write_text(path.read_text().replace("457.58699999999999", "x", 1))     # M2 fx
    with pytest.raises(ValueError, match=r"s.yml: field 'M2' is not numeric \(found 'x'\)"):
        read_stereo(path, image_size=(640, 480))


def test_calib_convert_writes_stereo_yaml(tmp_path, capsys):
    path = tmp_path / "stereo.xml"
    opencv_write(path, {"K1": LEFT.K, "D1": np.array(D_LEFT), "K2": RIGHT.K, "D2": np.array(D_RIGHT),
                        "R": R_LR, "T": T_LR})
    out = tmp_path / "stereo.yaml"
    assert entry(["calib", "convert", str(path), "--image-size", "752x480", "-o", str(out)]) == 0
    assert f"baseline {BASELINE:.4f} m" in capsys.readouterr().out
    assert_known_pair(read_stereo(out))
    assert entry(["calib", "convert", str(out), "-o", str(out)]) == 2          # never over its input
    assert "would overwrite the input" in capsys.readouterr().err
    assert entry(["calib", "convert", str(path), "--image-size", "752", "-o", str(tmp_path / "x.yaml")]) == 2
    assert "--image-size/--size must be WIDTHxHEIGHT" in capsys.readouterr().err
