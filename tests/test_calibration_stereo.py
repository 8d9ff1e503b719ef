"""Stereo calibration and Fusiello rectification: synthetic known answers, OpenCV, rendered images."""
import math

import cv2
import numpy as np
import pytest

from mrstereo.calibration import (CalibrationView, calibrate_stereo, detect_chessboard, planar_grid, pose_looking_at,
                                  rectified_vertical_error_px, synthetic_view)
from mrstereo.camera import Camera, StereoCamera, rectify_fusiello
from mrstereo.transforms import rotation_from_rpy

LEFT = Camera(width=640, height=400, fx=520.0, fy=523.0, cx=331.0, cy=192.0, k1=-0.21, k2=0.05)
RIGHT = Camera(width=640, height=400, fx=515.0, fy=516.0, cx=318.0, cy=205.0, k1=-0.19, k2=0.04)
R_LR = rotation_from_rpy(0.01, -0.02, 0.005)
T_LR = np.array([-0.12, 0.003, 0.002])            # right camera 12 cm to the right: c2 = -R^T T ~ (+0.12, ...)
GRID = planar_grid(9, 6, 0.03)


def stereo_views(noise_px=0.1, seed=0):
    rng = np.random.default_rng(seed)
    specs = [(0.0, 0.0, 0.0, (0, 0)), (0.4, 0.0, 0.1, (60, 30)), (-0.4, 0.1, -0.2, (-70, -20)),
             (0.1, 0.4, 0.3, (40, -50)), (0.0, -0.45, -0.1, (-50, 40)), (0.3, 0.3, 1.2, (0, 0)),
             (0.25, -0.2, 0.1, (120, 70)), (-0.2, 0.3, -0.1, (-120, -70))]
    Trel = np.eye(4)
    Trel[:3, :3], Trel[:3, 3] = R_LR, T_LR
    left, right = [], []
    for i, (ax, ay, roll, off) in enumerate(specs):
        T = pose_looking_at(GRID.mean(0), distance_m=0.45, tilt_x_rad=ax, tilt_y_rad=ay, roll_rad=roll,
                            offset_px=off, focal_px=520.0)
        left.append(synthetic_view(LEFT, GRID, T, noise_px=noise_px, rng=rng, name=f"l{i}"))
        right.append(synthetic_view(RIGHT, GRID, Trel @ T, noise_px=noise_px, rng=rng, name=f"r{i}"))
    return left, right


def test_fusiello_rectification_known_geometry():
    rect = rectify_fusiello(LEFT, RIGHT, R_LR, T_LR)
    st = rect.stereo
    assert isinstance(st, StereoCamera)
    b = float(np.linalg.norm(T_LR))
    assert st.baseline_m == pytest.approx(b) and st.right.P[0, 3] == pytest.approx(-st.focal_px * b)
    assert st.right.P[0, 3] < 0 and st.doffs_px == 0.0
    for R in (st.left.R, st.right.R):
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-12) and np.linalg.det(R) == pytest.approx(1.0)
    assert np.allclose(st.right.R, st.left.R @ R_LR.T)
    # the new x axis is the baseline direction and the frame stays close to the old one
    c2 = -R_LR.T @ T_LR
    assert np.allclose(rect.R_new[0], c2 / b) and rect.R_new[2, 2] > 0.99
    # noise-free corners land on the same row after undistortion + rectification
    left, right = stereo_views(noise_px=0.0)
    err = rectified_vertical_error_px(st, [v.uv for v in left], [v.uv for v in right])
    assert err.max() < 1e-6
    # alpha = 0: every rectified pixel maps inside both raw images
    for info in (st.left, st.right):
        mx, my = info.camera.undistort_rectify_maps(R=info.R, P=info.P)
        assert mx.min() >= -1 and mx.max() <= 640 and my.min() >= -1 and my.max() <= 400


def test_fusiello_identity_for_an_ideal_pair_and_agrees_with_opencv():
    cam = Camera(width=320, height=240, fx=200.0, fy=200.0, cx=159.5, cy=119.5)
    rect = rectify_fusiello(cam, cam, np.eye(3), [-0.1, 0.0, 0.0])
    assert np.allclose(rect.stereo.left.R, np.eye(3)) and np.allclose(rect.A, cam.K)
    # against cv2.stereoRectify on a general pair: same vertical alignment of the same points
    left, right = stereo_views(noise_px=0.0)
    R1, R2, P1, P2, *_ = cv2.stereoRectify(LEFT.K, LEFT.dist_coeffs, RIGHT.K, RIGHT.dist_coeffs, LEFT.size,
                                           R_LR, T_LR.reshape(3, 1), alpha=0)
    assert P2[0, 3] < 0                                       # OpenCV uses the same sign
    ours = rectify_fusiello(LEFT, RIGHT, R_LR, T_LR).stereo
    for v, w in zip(left, right):
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
        a = cv2.undistortPoints(v.uv.reshape(-1, 1, 2), LEFT.K, LEFT.dist_coeffs, R=R1, P=P1,
                                criteria=crit).reshape(-1, 2)
        b = cv2.undistortPoints(w.uv.reshape(-1, 1, 2), RIGHT.K, RIGHT.dist_coeffs, R=R2, P=P2,
                                criteria=crit).reshape(-1, 2)
        assert np.abs(a[:, 1] - b[:, 1]).max() < 1e-3           # OpenCV aligns rows too
        # same x axis (the baseline); the frames may differ by a rotation about it
        ours_l = (rectified_points_of(ours, v.uv) - ours.left.P[:2, 2]) / ours.focal_px
        cv_l = (a - P1[:2, 2]) / P1[0, 0]
        assert np.abs(ours_l[:, 0] - cv_l[:, 0]).max() < 2e-3
    assert ours.focal_px == pytest.approx(P1[0, 0], rel=0.05)


def rectified_points_of(stereo, uv):
    from mrstereo.calibration import rectified_points
    return rectified_points(stereo, uv, side="left")


def test_rectification_bad_input():
    with pytest.raises(ValueError, match="baseline is zero"):
        rectify_fusiello(LEFT, RIGHT, np.eye(3), [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="sizes differ"):
        rectify_fusiello(LEFT, Camera(width=320, height=240, fx=1.0, fy=1.0, cx=0, cy=0), np.eye(3), [-0.1, 0, 0])
    with pytest.raises(ValueError, match="alpha"):
        rectify_fusiello(LEFT, RIGHT, R_LR, T_LR, alpha=2.0)
    with pytest.raises(ValueError, match="shape"):
        rectify_fusiello(LEFT, RIGHT, np.eye(2), T_LR)


def test_stereo_calibration_recovers_the_rig():
    left, right = stereo_views()
    res = calibrate_stereo(left, right, width=640, height=400, method="lm")
    assert res.success, res.message
    assert res.baseline_m == pytest.approx(0.1201, rel=0.01)
    assert np.allclose(res.T, T_LR, atol=2e-3)
    ang = math.degrees(np.arccos(np.clip((np.trace(res.R @ R_LR.T) - 1) / 2, -1, 1)))
    assert ang < 0.3          # statistical: 0.1 px noise, 8 small boards
    for est, true in ((res.stereo.left.camera, LEFT), (res.stereo.right.camera, RIGHT)):
        assert abs(est.fx / true.fx - 1) < 0.005 and abs(est.cx - true.cx) < 1.5
    assert res.vertical_error_px < 0.15 and res.rms_px < 0.2
    assert res.per_view_rms_px.shape == (8, 2) and set(res.sigmas) >= {"left_fx", "right_k2", "Tx"}
    s = res.summary()
    assert s["baseline_m"] == pytest.approx(res.baseline_m) and len(s["per_pair"]) == 8


def test_stereo_bad_input():
    left, right = stereo_views()
    with pytest.raises(ValueError, match="same number"):
        calibrate_stereo(left, right[:-1], width=640, height=400)
    with pytest.raises(ValueError, match="at least 2"):
        calibrate_stereo(left[:1], right[:1], width=640, height=400)
    # a right view numbered from the opposite corner of the board is put back in order
    flipped = [CalibrationView(v.points_target, v.uv[::-1].copy(), name=v.name) for v in right]
    a = calibrate_stereo(left, right, width=640, height=400, method="lm")
    b = calibrate_stereo(left, flipped, width=640, height=400, method="lm")
    assert np.allclose(a.T, b.T) and b.vertical_error_px < 0.15
    other = [CalibrationView(v.points_target * 2, v.uv) for v in right]
    with pytest.raises(ValueError, match="same target points"):
        calibrate_stereo(left, other, width=640, height=400)


def test_rendered_chessboards_end_to_end():
    import mrstereo.world as world
    truth = world.default_stereo(320, 240)
    rendered = world.render_calibration_views(truth, n_views=10, seed=3, supersample=2)
    pairs = []
    for v in rendered:
        a, b = detect_chessboard(v.image, v.board), detect_chessboard(v.image_right, v.board)
        if a is not None and b is not None:
            grid = planar_grid(v.board[0], v.board[1], v.spacing_m)
            pairs.append((CalibrationView(grid, a), CalibrationView(grid, b)))
    assert len(pairs) >= 6
    res = calibrate_stereo([p[0] for p in pairs], [p[1] for p in pairs], width=320, height=240, method="lm")
    assert res.success, res.message
    for est, true in ((res.stereo.left.camera, truth.left.camera), (res.stereo.right.camera, truth.right.camera)):
        assert abs(est.fx / true.fx - 1) < 0.02 and abs(est.cx - true.cx) < 3
    assert res.baseline_m == pytest.approx(truth.baseline_m, rel=0.03)
    assert res.vertical_error_px < 0.3
