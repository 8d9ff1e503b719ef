"""OpenCV's stereo chessboard set: compare with cv2.calibrateCamera / stereoCalibrate on the same corners."""

import cv2
import numpy as np
import pytest

from mrstereo.calibration import calibrate_camera, calibrate_stereo, chessboard_pairs, expand_glob
from mrstereo.recordings.samples import local_path

DATA = local_path("opencv-stereo-chessboard")
pytestmark = pytest.mark.sample_data("opencv-stereo-chessboard")
FLAGS = cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST


@pytest.fixture(scope="module")
def pairs():
    found = chessboard_pairs(expand_glob(str(DATA / "left*.jpg")), expand_glob(str(DATA / "right*.jpg")),
                             (9, 6), 0.025)
    assert found.skipped == []
    return found.left, found.right, found.size


def _cv(views, size):
    obj = [v.points_target.astype(np.float32) for v in views]
    img = [v.uv.astype(np.float32) for v in views]
    return cv2.calibrateCamera(obj, img, size, None, None, flags=FLAGS)


def test_single_camera_matches_opencv(pairs):
    left, right, size = pairs
    assert len(left) == 13
    for views in (left, right):
        res = calibrate_camera(views, width=size[0], height=size[1], method="lm")
        rms, K, D, *_ = _cv(views, size)
        assert res.success
        assert abs(res.rms_px / rms - 1) < 0.02
        assert abs(res.camera.fx / K[0, 0] - 1) < 0.01 and abs(res.camera.fy / K[1, 1] - 1) < 0.01
        assert abs(res.camera.cx - K[0, 2]) < 1.0 and abs(res.camera.cy - K[1, 2]) < 1.0
        assert all(0 < s < 5 for s in (res.sigmas["fx"], res.sigmas["cx"]))


def test_stereo_matches_opencv_and_rows_align(pairs):
    left, right, size = pairs
    res = calibrate_stereo(left, right, width=size[0], height=size[1], method="lm")
    obj = [v.points_target.astype(np.float32) for v in left]
    il = [v.uv.astype(np.float32) for v in left]
    ir = [v.uv.astype(np.float32) for v in right]
    _, K1, D1, *_ = _cv(left, size)
    _, K2, D2, *_ = _cv(right, size)
    rms, K1, D1, K2, D2, R, T, *_ = cv2.stereoCalibrate(obj, il, ir, K1, D1, K2, D2, size,
                                                       flags=FLAGS | cv2.CALIB_USE_INTRINSIC_GUESS)
    assert res.success, res.message
    assert abs(res.rms_px / rms - 1) < 0.02
    assert np.allclose(res.T, T.ravel(), atol=5e-4)
    assert res.vertical_error_px < 0.5
    # rectified |dy| of the same corners: cv2.stereoRectify on OpenCV's calibration vs ours (Fusiello)
    R1, R2, P1, P2, *_ = cv2.stereoRectify(K1, D1, K2, D2, size, R, T, alpha=0)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    dy_cv = np.mean([np.mean(np.abs(cv2.undistortPoints(a.reshape(-1, 1, 2), K1, D1, R=R1, P=P1, criteria=crit)[:, 0, 1]
                                    - cv2.undistortPoints(b.reshape(-1, 1, 2), K2, D2, R=R2, P=P2, criteria=crit)[:, 0, 1]))
                     for a, b in zip(il, ir)])
    assert abs(res.vertical_error_px / dy_cv - 1) < 0.02
    assert res.stereo.right.P[0, 3] < 0 and res.baseline_m == pytest.approx(np.linalg.norm(T), rel=0.01)
