"""Triangulation eq. (14)-(16) and the camera/robot/world frames."""
import numpy as np
import pytest

from mrstereo.camera import Camera
from mrstereo.geometry import depth_m_from_disparity_px, disparity_px_from_depth_m, points_cam_from_disparity
from mrstereo.transforms import T_from_planar, T_robot_from_cam, transform_points


def test_triangulation_recovers_projected_points():
    cam = Camera(width=64, height=40, fx=50.0, fy=50.0, cx=30.5, cy=17.25)
    b = 0.1
    rng = np.random.default_rng(0)
    u = rng.integers(0, 64, 20)
    v = rng.integers(0, 40, 20)
    z = rng.uniform(0.5, 5.0, 20)
    d = np.full((40, 64), np.nan)
    d[v, u] = b * cam.fx / z
    pts = points_cam_from_disparity(d, focal_px=cam.fx, baseline_m=b, cx_px=cam.cx, cy_px=cam.cy)
    got = pts[v, u]
    np.testing.assert_allclose(got[:, 2], z, rtol=1e-12)
    np.testing.assert_allclose(cam.project(got), np.stack([u, v], 1), atol=1e-9)
    assert np.isnan(pts[~np.isfinite(d)]).all()


def test_depth_disparity_inverse_and_invalid():
    d = np.array([48.0, 0.0, -1.0, np.nan])
    z = depth_m_from_disparity_px(d, focal_px=200.0, baseline_m=0.12)
    assert z[0] == pytest.approx(0.5) and np.isnan(z[1:]).all()
    assert disparity_px_from_depth_m(0.5, focal_px=200.0, baseline_m=0.12) == pytest.approx(48.0)
    with pytest.raises(ValueError, match="baseline_m must be > 0"):
        depth_m_from_disparity_px(d, focal_px=200.0, baseline_m=-0.1)
    with pytest.raises(ValueError, match="focal_px must be finite"):
        depth_m_from_disparity_px(d, focal_px=np.nan, baseline_m=0.1)


def test_frames_axes():
    # Level camera: optical axis (cam z) points along robot x, cam x (right) along robot -y.
    T = T_robot_from_cam(height_m=0.5)
    np.testing.assert_allclose(transform_points(T, [[0, 0, 2.0], [1.0, 0, 0], [0, 1.0, 0]]),
                               [[2, 0, 0.5], [0, -1, 0.5], [0, 0, -0.5]], atol=1e-12)
    # Tilted down: a point on the optical axis is below the camera; panned left: y > 0.
    p = transform_points(T_robot_from_cam(height_m=0.5, tilt_rad=0.3, pan_rad=np.pi / 2), [[0, 0, 1.0]])[0]
    np.testing.assert_allclose(p, [0, np.cos(0.3), 0.5 - np.sin(0.3)], atol=1e-12)
    w = transform_points(T_from_planar(1.0, 2.0, np.pi / 2), [[1.0, 0, 0]])[0]
    np.testing.assert_allclose(w, [1.0, 3.0, 0.0], atol=1e-12)
