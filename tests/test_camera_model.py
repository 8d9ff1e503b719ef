"""Camera model eq. (1)-(3): round trips, both parameterizations, OpenCV agreement."""
import cv2
import numpy as np
import pytest

from mrstereo.camera import (Camera, PaperCamera, distort_normalized, euler_from_rotation,
                             project_points, rotation_from_euler, undistort_normalized)

# Non-square image, off-centre principal point, non-square pixels: an axis swap must fail.
CAM = Camera(width=640, height=400, fx=452.0, fy=447.5, cx=331.7, cy=188.2, k1=-0.21, k2=0.06)


def grid_pixels(cam, step=37):
    v, u = np.mgrid[0:cam.height:step, 0:cam.width:step]
    return np.stack([u.ravel(), v.ravel()], 1).astype(float) + np.array([0.3, 0.7])


def test_project_matches_opencv():
    rng = np.random.default_rng(1)
    pts = rng.uniform([-1.5, -0.8, 1.0], [2.0, 1.1, 4.0], size=(200, 3))
    ours = CAM.project(pts)
    ref, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), CAM.K, CAM.dist_coeffs)
    np.testing.assert_allclose(ours, ref[:, 0, :], atol=1e-9)


def test_undistort_inverts_distort_over_whole_image():
    uv = grid_pixels(CAM, step=5)
    rays = CAM.rays(uv)
    back = CAM.project(rays)
    assert np.abs(back - uv).max() < 1e-3
    xy = rays[:, :2]
    np.testing.assert_allclose(undistort_normalized(distort_normalized(xy, CAM.k1, CAM.k2), CAM.k1, CAM.k2),
                               xy, atol=1e-12)


def test_undistort_pixels_matches_opencv():
    uv = grid_pixels(CAM)
    ours = CAM.undistort_pixels(uv)
    ref = cv2.undistortPoints(uv[:, None, :], CAM.K, CAM.dist_coeffs, P=CAM.K,
                              criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12))[:, 0]
    np.testing.assert_allclose(ours, ref, atol=1e-3)


def test_paper_parameterization_round_trip_exact():
    paper = CAM.to_paper(f_mm=6.5)
    back = paper.to_camera()
    for name in ("fx", "fy", "cx", "cy", "k1", "k2"):
        assert getattr(back, name) == pytest.approx(getattr(CAM, name), rel=1e-14, abs=1e-14)
    rng = np.random.default_rng(2)
    pts = rng.uniform([-1, -0.6, 1.0], [1.2, 0.7, 3.0], size=(50, 3))
    np.testing.assert_allclose(paper.project(pts), CAM.project(pts), atol=1e-9)
    assert paper.alpha_x == pytest.approx(452.0 / 6.5)
    assert paper.k1_mm == pytest.approx(-0.21 / 6.5**2)


def test_paper_bounds_example():
    paper = PaperCamera(width=320, height=240, f_mm=7.5, alpha_x=30.0, alpha_y=30.5, u0=250.0, v0=230.0,
                        k1_mm=0.001, k2_mm=-0.0005)
    cam = paper.to_camera()
    assert cam.fx == pytest.approx(225.0) and cam.fy == pytest.approx(228.75)
    assert cam.k1 == pytest.approx(0.001 * 56.25) and cam.k2 == pytest.approx(-0.0005 * 7.5**4)


def test_euler_round_trip_and_convention():
    a, b, g = 0.3, -0.2, 1.1
    R = rotation_from_euler(a, b, g)
    Rx = cv2.Rodrigues(np.array([a, 0, 0.0]))[0]
    Ry = cv2.Rodrigues(np.array([0, b, 0.0]))[0]
    Rz = cv2.Rodrigues(np.array([0, 0, g]))[0]
    np.testing.assert_allclose(R, Rz @ Ry @ Rx, atol=1e-12)
    np.testing.assert_allclose(np.array(euler_from_rotation(R)), [a, b, g], atol=1e-12)


def test_project_points_batches_over_population():
    rng = np.random.default_rng(3)
    pts = rng.uniform(-0.2, 0.2, size=(30, 3)) * [1, 1, 0]
    P = 7
    fx = rng.uniform(300, 500, P)
    R = rotation_from_euler(rng.uniform(-0.2, 0.2, P), rng.uniform(-0.2, 0.2, P), rng.uniform(-0.2, 0.2, P))
    t = np.stack([rng.uniform(-0.1, 0.1, P), rng.uniform(-0.1, 0.1, P), rng.uniform(1, 2, P)], 1)
    batch = project_points(pts, fx=fx, fy=fx * 1.01, cx=320.0, cy=200.0, k1=-0.1, k2=0.02, R=R, t=t)
    assert batch.shape == (P, 30, 2)
    for i in range(P):
        cam = Camera(width=640, height=400, fx=fx[i], fy=fx[i] * 1.01, cx=320.0, cy=200.0, k1=-0.1, k2=0.02)
        np.testing.assert_allclose(batch[i], cam.project(pts @ R[i].T + t[i]), atol=1e-9)


def test_undistort_map_matches_point_undistortion():
    map_x, map_y = CAM.undistort_rectify_maps()
    # The map at undistorted pixel (u, v) holds the distorted pixel that images the same ray.
    u, v = 101, 57
    distorted = np.array([[map_x[v, u], map_y[v, u]]], dtype=float)
    np.testing.assert_allclose(CAM.undistort_pixels(distorted)[0], [u, v], atol=1e-2)


@pytest.mark.parametrize("field,value,match", [("fx", np.nan, "fx must be finite"),
                                                ("fy", -1.0, "fy must be > 0"),
                                                ("width", 0, "width must be >= 1"),
                                                ("k1", "a", "k1 must be a real number")])
def test_bad_parameters(field, value, match):
    kwargs = dict(width=10, height=10, fx=1.0, fy=1.0, cx=5.0, cy=5.0)
    kwargs[field] = value
    with pytest.raises((ValueError, TypeError), match=match):
        Camera(**kwargs)


def test_points_shape_checked():
    with pytest.raises(ValueError, match="points_cam must have shape"):
        CAM.project(np.zeros((4, 2)))
