"""Fusiello rectification over every camera model, raw <-> rectified pixels, swapped and zero baselines."""
import numpy as np
import pytest

from mrstereo.camera import (Camera, check_baseline, check_not_swapped, raw_px_from_rectified_px,
                             rectified_px_from_raw_px, rectify_fusiello)
from mrstereo.geometry import points_cam_from_raw_px
from mrstereo.transforms import rotation_from_rpy

R_LR = rotation_from_rpy(0.01, -0.02, 0.005)
T_LR = np.array([-0.12, 0.003, 0.002])          # right camera 12 cm on the +x side of the left one


def pair(model):
    """Two slightly different cameras of one model (640x400; fisheye: 848x800 T265-like)."""
    if model == "equidistant":
        K1 = [[285.7, 0, 418.2], [0, 286.6, 399.1], [0, 0, 1]]
        K2 = [[284.9, 0, 425.0], [0, 285.3, 395.2], [0, 0, 1]]
        return (Camera.from_ros(848, 800, K1, model, [-0.0089, 0.0472, -0.0448, 0.0086]),
                Camera.from_ros(848, 800, K2, model, [-0.0061, 0.0431, -0.0412, 0.0077]))
    K1 = [[452.0, 0, 331.7], [0, 447.5, 188.2], [0, 0, 1]]
    K2 = [[449.0, 0, 318.2], [0, 448.1, 203.5], [0, 0, 1]]
    D = {"k1k2": ([-0.21, 0.06], [-0.19, 0.04]),
         "plumb_bob": ([-0.28, 0.09, 1e-3, -5e-4, -0.01], [-0.26, 0.08, -7e-4, 3e-4, -0.008]),
         "rational_polynomial": ([7.9, 3.1, -4e-4, 2e-4, 0.08, 8.3, 5.4, 0.6],
                                 [7.2, 2.9, 3e-4, -1e-4, 0.07, 7.6, 5.1, 0.5])}[model]
    name = "plumb_bob" if model == "k1k2" else model
    return Camera.from_ros(640, 400, K1, name, D[0]), Camera.from_ros(640, 400, K2, name, D[1])


def scene_points(n=400, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform([-1.2, -0.7, 1.5], [1.4, 0.8, 5.0], size=(n, 3))


ANY_MODEL = pytest.mark.parametrize("model", ["k1k2", "plumb_bob", "rational_polynomial", "equidistant"])


@ANY_MODEL
def test_every_model_rectifies_rows_and_triangulates(model):
    left, right = pair(model)
    st = rectify_fusiello(left, right, R_LR, T_LR).stereo
    assert st.left.camera == left and st.right.camera.distortion_model == right.distortion_model
    pts = scene_points()
    uv_l, uv_r = left.project(pts), right.project(pts @ R_LR.T + T_LR)
    a, b = rectified_px_from_raw_px(st.left, uv_l), rectified_px_from_raw_px(st.right, uv_r)
    seen = np.isfinite(a).all(1) & np.isfinite(b).all(1)
    assert seen.mean() > 0.9
    assert np.abs(a[seen, 1] - b[seen, 1]).max() < 1e-6                     # same rectified row
    assert (a[seen, 0] - b[seen, 0] > 0).all()                              # positive disparity
    # rectified -> raw inverts raw -> rectified
    assert np.abs(raw_px_from_rectified_px(st.left, a[seen]) - uv_l[seen]).max() < 1e-6
    # triangulation from raw pixels recovers the points (raw left frame and rectified frame)
    p_raw = points_cam_from_raw_px(st, uv_l[seen], uv_r[seen], frame="raw_left")
    np.testing.assert_allclose(p_raw, pts[seen], atol=1e-6)
    p_rect = points_cam_from_raw_px(st, uv_l[seen], uv_r[seen])
    np.testing.assert_allclose(p_rect, pts[seen] @ st.left.R.T, atol=1e-6)
    # the remap maps send each rectified pixel to the raw pixel of the same ray
    (lx, ly), _ = st.rectification_maps()
    v, u = np.mgrid[5:left.height - 5:23, 7:left.width - 7:19]
    raw = raw_px_from_rectified_px(st.left, np.stack([u.ravel(), v.ravel()], 1).astype(float))
    np.testing.assert_allclose(np.stack([lx[v, u].ravel(), ly[v, u].ravel()], 1), raw, atol=0.01)


def test_fisheye_rectified_view_keeps_the_centre_resolution():
    left, right = pair("equidistant")
    rect = rectify_fusiello(left, right, R_LR, T_LR)
    f = rect.stereo.focal_px
    assert f == pytest.approx(min(left.fx, left.fy, right.fx, right.fy))
    fov_deg = np.degrees(2 * np.arctan(left.width / 2 / f))
    assert 100 < fov_deg < 125
    # the raw optical axes land near the rectified image centre
    centre = rectified_px_from_raw_px(rect.stereo.left, np.array([[left.cx, left.cy]]))[0]
    assert np.abs(centre - [left.width / 2, left.height / 2]).max() < 40


def test_swapped_cameras_are_refused_with_a_fix():
    left, right = pair("plumb_bob")
    # the right camera given as left: the "right" one then sits 12 cm to the LEFT
    R_sw, T_sw = R_LR.T, -R_LR.T @ T_LR
    with pytest.raises(ValueError, match=r"look swapped: the camera given as right sits 0\.12 m to the LEFT.*"
                                         r"exchange --left and --right"):
        rectify_fusiello(right, left, R_sw, T_sw)
    with pytest.raises(ValueError, match="^bag: the left and right views look swapped"):
        check_not_swapped(np.eye(3), [0.1, 0.0, 0.0], where="bag")      # OpenCV T[0] > 0
    check_not_swapped(np.eye(3), [-0.1, 0.0, 0.0])                        # the usual rig
    check_not_swapped(np.eye(3), [0.01, -0.1, 0.0])                       # a vertical rig is not "swapped"


def test_zero_baseline_says_so():
    left, right = pair("k1k2")
    with pytest.raises(ValueError, match="the baseline is zero"):
        rectify_fusiello(left, left, np.eye(3), [1e-6, 0.0, 0.0])
    assert check_baseline(R_LR, T_LR) == pytest.approx(np.linalg.norm(T_LR))
    with pytest.raises(TypeError, match="Camera instances"):
        rectify_fusiello(left, "right.yaml", R_LR, T_LR)


def test_points_cam_from_raw_px_bad_input():
    left, right = pair("k1k2")
    st = rectify_fusiello(left, right, R_LR, T_LR).stereo
    with pytest.raises(ValueError, match="same number of points"):
        points_cam_from_raw_px(st, np.zeros((3, 2)), np.zeros((4, 2)))
    with pytest.raises(ValueError, match="frame must be"):
        points_cam_from_raw_px(st, np.zeros((3, 2)), np.zeros((3, 2)), frame="world")
