"""--model plumb_bob | rational | fisheye: LM fits checked against OpenCV and a known synthetic fisheye."""
import cv2
import numpy as np
import pytest

from mrstereo.calibration import (CALIBRATION_MODELS, calibrate_camera, chessboard_views, expand_glob, planar_grid,
                                  pose_looking_at, synthetic_view)
from mrstereo.camera import Camera
from mrstereo.recordings.samples import local_path

DATA = local_path("opencv-stereo-chessboard")
needs_data = pytest.mark.sample_data("opencv-stereo-chessboard")


@pytest.fixture(scope="module")
def left_views():
    views, size = chessboard_views(expand_glob(str(DATA / "left0[1-7].jpg")), (9, 6), 0.025)
    assert all(v is not None for v in views)
    return views, size


def _opencv(model, views, size):
    if model == "fisheye":
        obj = [v.points_target.reshape(1, -1, 3) for v in views]
        img = [v.uv.reshape(1, -1, 2) for v in views]
        crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-12)
        rms, K, D, *_ = cv2.fisheye.calibrate(obj, img, size, np.eye(3), np.zeros(4),
                                              flags=cv2.CALIB_RECOMPUTE_EXTRINSIC | cv2.CALIB_FIX_SKEW,
                                              criteria=crit)
        return rms, Camera.from_ros(size[0], size[1], K, "equidistant", np.ravel(D))
    flags = {"plumb_bob": 0, "rational": cv2.CALIB_RATIONAL_MODEL}[model]
    obj = [v.points_target.astype(np.float32) for v in views]
    img = [v.uv.astype(np.float32) for v in views]
    rms, K, D, *_ = cv2.calibrateCamera(obj, img, size, None, None, flags=flags)
    ros = CALIBRATION_MODELS[model].distortion_model
    return rms, Camera.from_ros(size[0], size[1], K, ros, np.ravel(D)[:8 if model == "rational" else 5])


def _field_difference_px(a: Camera, b: Camera, uv: np.ndarray) -> float:
    """Largest pixel distance between ``uv`` and the projection through ``a`` of ``b``'s rays of ``uv``:
    how far apart the two lens models put the same raw pixels."""
    return float(np.nanmax(np.abs(a.project(b.rays(uv)) - uv)))


@needs_data
@pytest.mark.parametrize("model", ["plumb_bob", "rational", "fisheye"])
def test_models_equal_opencv_on_real_chessboards(left_views, model):
    views, size = left_views
    if model == "rational":
        views = views[:4]          # 8 coefficients converge slowly; 4 views keep the test short
    res = calibrate_camera(views, width=size[0], height=size[1], method="lm", model=model)
    rms_cv, cam_cv = _opencv(model, views, size)
    assert res.success, res.message
    assert res.model == model and res.camera.distortion_model == CALIBRATION_MODELS[model].distortion_model
    assert abs(res.rms_px / rms_cv - 1) < 0.01
    assert abs(res.camera.fx / cam_cv.fx - 1) < 0.005 and abs(res.camera.cx - cam_cv.cx) < 1.0
    # the same lens: undistortion of every detected corner agrees with OpenCV's model (the rational
    # model's 8 coefficients are not identifiable from a few views: equal RMS, different parameters)
    corners = np.concatenate([v.uv for v in views])
    if model != "rational":
        assert _field_difference_px(res.camera, cam_cv, corners) < 0.05
    # the richer model fits better than the paper's k1k2 (its own LM stage, from the same start)
    assert res.rms_px < res.lm_rms_px
    assert set(res.sigmas) >= {"fx", "cx"} | set(CALIBRATION_MODELS[model].coefficient_names)
    s = res.summary()
    assert s["model"] == model and len(s["camera"]["D"]) == res.camera.D.size


def test_fisheye_known_answer_from_a_pinhole_start():
    """A T265-like Kannala-Brandt lens (848x800), exact corners: the k1k2 start, then the fisheye LM
    recovers the lens exactly (the pinhole k1k2 fit alone cannot: its RMS stays far above zero)."""
    true = Camera.from_ros(848, 800, [[285.7, 0, 418.2], [0, 286.6, 399.1], [0, 0, 1]], "equidistant",
                           [-0.0089, 0.0472, -0.0448, 0.0086])
    grid = planar_grid(9, 6, 0.05)
    rng = np.random.default_rng(0)
    specs = [(0, 0, 0, (0, 0)), (0.4, 0, 0.1, (150, 80)), (-0.4, 0.1, -0.2, (-160, -60)),
             (0.1, 0.4, 0.3, (120, -150)), (0, -0.45, -0.1, (-150, 140)), (0.25, -0.2, 0.1, (250, 170)),
             (-0.2, 0.3, -0.1, (-250, -170))]
    views = [synthetic_view(true, grid, pose_looking_at(grid.mean(0), distance_m=0.6, tilt_x_rad=ax, tilt_y_rad=ay,
                                                        roll_rad=roll, offset_px=off, focal_px=285.0),
                            rng=rng) for ax, ay, roll, off in specs]
    res = calibrate_camera(views, width=848, height=800, method="lm", model="fisheye")
    assert res.success and res.camera.is_fisheye
    assert res.lm_rms_px > 0.05                    # the k1k2 stage: a pinhole does not fit this lens
    assert res.rms_px < 1e-4                       # exact corners: the fisheye model fits exactly
    assert abs(res.camera.fx / true.fx - 1) < 1e-5 and abs(res.camera.cx - true.cx) < 1e-3
    np.testing.assert_allclose(res.camera.D, true.D, atol=1e-4)
    corners = np.concatenate([v.uv for v in views])
    assert _field_difference_px(res.camera, true, corners) < 1e-3


def test_ga_with_a_richer_model_is_refused():
    grid = planar_grid(9, 6, 0.03)
    cam = Camera(width=640, height=480, fx=500.0, fy=500.0, cx=320.0, cy=240.0)
    view = synthetic_view(cam, grid, pose_looking_at(grid.mean(0), distance_m=0.5, tilt_x_rad=0.3, focal_px=500.0))
    with pytest.raises(ValueError, match="GA fits the paper's k1k2 model only"):
        calibrate_camera([view], width=640, height=480, method="ga", model="rational")
    with pytest.raises(ValueError, match="model must be one of k1k2, plumb_bob, rational, fisheye"):
        calibrate_camera([view], width=640, height=480, method="lm", model="kb8")
