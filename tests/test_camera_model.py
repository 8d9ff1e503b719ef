"""Camera model eq. (1)-(3): round trips, both parameterizations, OpenCV agreement."""
import cv2
import numpy as np
import pytest

from mrstereo.camera import Camera, PaperCamera, distort_normalized, project_points, undistort_normalized
from mrstereo.transforms import rotation_from_rpy, rpy_from_rotation

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
    R = rotation_from_rpy(a, b, g)
    Rx = cv2.Rodrigues(np.array([a, 0, 0.0]))[0]
    Ry = cv2.Rodrigues(np.array([0, b, 0.0]))[0]
    Rz = cv2.Rodrigues(np.array([0, 0, g]))[0]
    np.testing.assert_allclose(R, Rz @ Ry @ Rx, atol=1e-12)
    np.testing.assert_allclose(np.array(rpy_from_rotation(R)), [a, b, g], atol=1e-12)


def test_project_points_batches_over_population():
    rng = np.random.default_rng(3)
    pts = rng.uniform(-0.2, 0.2, size=(30, 3)) * [1, 1, 0]
    P = 7
    fx = rng.uniform(300, 500, P)
    R = rotation_from_rpy(rng.uniform(-0.2, 0.2, P), rng.uniform(-0.2, 0.2, P), rng.uniform(-0.2, 0.2, P))
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


# -- every ROS distortion model through the one Camera interface, against OpenCV ------------------

K_PIN = [452.0, 0.0, 331.7, 0.0, 447.5, 188.2, 0.0, 0.0, 1.0]
MODELS = {
    "k1k2": Camera(width=640, height=400, fx=452.0, fy=447.5, cx=331.7, cy=188.2, k1=-0.21, k2=0.06),
    "plumb_bob": Camera.from_ros(640, 400, K_PIN, "plumb_bob", [-0.28, 0.09, 1e-3, -5e-4, -0.01]),
    # OAK-D-like: large numerator and denominator that almost cancel
    "rational8": Camera.from_ros(640, 400, K_PIN, "rational_polynomial",
                                 [7.9, 3.1, -4e-4, 2e-4, 0.08, 8.3, 5.4, 0.6]),
    "rational12": Camera.from_ros(640, 400, K_PIN, "rational_polynomial",
                                  [-0.3, 0.1, 1e-3, -2e-4, 0.02, 0.05, 0.01, 0.002, 1e-3, -2e-3, 5e-4, 1e-3]),
    "rational14": Camera.from_ros(640, 400, K_PIN, "rational_polynomial",
                                  [-0.3, 0.1, 1e-3, -2e-4, 0.02, 0.05, 0.01, 0.002, 1e-3, -2e-3, 5e-4, 1e-3,
                                   0.01, -0.02]),
    # RealSense T265-like Kannala-Brandt fisheye, 848x800
    "equidistant": Camera.from_ros(848, 800, [285.7, 0, 418.2, 0, 286.6, 399.1, 0, 0, 1], "equidistant",
                                   [-0.0089, 0.0472, -0.0448, 0.0086]),
}
ANY_MODEL = pytest.mark.parametrize("name", list(MODELS))


def _cv_project(cam, pts):
    if cam.is_fisheye:
        return cv2.fisheye.projectPoints(pts.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K,
                                         cam.dist_coeffs)[0][:, 0]
    return cv2.projectPoints(pts, np.zeros(3), np.zeros(3), cam.K, cam.dist_coeffs)[0][:, 0]


@ANY_MODEL
def test_every_model_projects_like_opencv(name):
    cam = MODELS[name]
    pts = np.random.default_rng(4).uniform([-1.5, -0.8, 1.0], [2.0, 1.1, 4.0], size=(300, 3))
    np.testing.assert_allclose(cam.project(pts), _cv_project(cam, pts), atol=1e-8)
    assert np.isnan(cam.project(np.array([[0.1, 0.2, -1.0]]))).all()       # behind the camera


@ANY_MODEL
def test_every_model_rays_invert_projection_over_the_image(name):
    cam = MODELS[name]
    uv = grid_pixels(cam, step=9)
    rays = cam.rays(uv)
    ok = np.isfinite(rays).all(axis=1)
    # a fisheye's image corners lie beyond 90 degrees: no (x, y, 1) ray; everything else must invert
    assert ok.mean() > (0.7 if cam.is_fisheye else 0.999)
    assert np.abs(cam.project(rays[ok]) - uv[ok]).max() < 1e-6
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)
    inner = uv[np.hypot(uv[:, 0] - cam.cx, uv[:, 1] - cam.cy) < 0.4 * cam.width]
    if cam.is_fisheye:
        ref = cv2.fisheye.undistortPoints(inner[:, None, :], cam.K, cam.dist_coeffs, P=cam.K,
                                          criteria=crit)[:, 0]
    else:
        ref = cv2.undistortPoints(inner[:, None, :], cam.K, cam.dist_coeffs, P=cam.K, criteria=crit)[:, 0]
    np.testing.assert_allclose(cam.undistort_pixels(inner), ref, atol=1e-3)


@ANY_MODEL
def test_every_model_maps_equal_opencv_within_0_01_px(name):
    """The remap maps (OpenCV's) and our numpy projection of the same rays agree over the image."""
    cam = MODELS[name]
    R = rotation_from_rpy(0.02, -0.03, 0.01)
    P = np.array([[0.9 * cam.fx, 0.0, 0.47 * cam.width], [0.0, 0.9 * cam.fx, 0.52 * cam.height], [0, 0, 1.0]])
    map_x, map_y = cam.undistort_rectify_maps(R=R, P=P)
    assert map_x.shape == (cam.height, cam.width) and map_x.dtype == np.float32
    v, u = np.mgrid[0:cam.height:2, 0:cam.width:2]
    rays = np.stack([u.ravel(), v.ravel(), np.ones(u.size)], 1) @ np.linalg.inv(P).T @ R    # R^T ray
    ours = cam.project(rays)
    ref = np.stack([map_x[v, u].ravel(), map_y[v, u].ravel()], 1)
    inside = ((ref > -1) & (ref < [cam.width, cam.height])).all(axis=1)
    assert inside.mean() > 0.8
    assert np.abs(ours[inside] - ref[inside]).max() < 0.01


def test_models_from_ros_names_and_coefficients():
    cam = Camera.from_ros(640, 480, np.diag([500.0, 501.0, 1.0]) + [[0, 0, 320], [0, 0, 240], [0, 0, 0]],
                          "plumb_bob", [0.1, -0.2])
    assert cam.distortion_model == "plumb_bob" and cam.D.tolist() == [0.1, -0.2, 0.0, 0.0, 0.0]
    assert cam.k1 == 0.1 and cam.k2 == -0.2 and not cam.is_fisheye
    kalibr = Camera.from_ros(640, 480, MODELS["k1k2"].K, "radtan", [0.1, -0.2, 1e-3, 2e-3])
    assert kalibr.distortion_model == "plumb_bob" and kalibr.D.tolist() == [0.1, -0.2, 1e-3, 2e-3, 0.0]
    fish = Camera.from_ros(640, 480, MODELS["k1k2"].K, "fisheye", [0.01, 0.02, 0.03, 0.04])
    assert fish.distortion_model == "equidistant" and fish.is_fisheye and fish.dist_coeffs.shape == (4,)
    rat = Camera.from_ros(640, 480, MODELS["k1k2"].K, "rational_polynomial", np.arange(1, 9) * 0.01)
    assert rat.D.size == 8 and rat.k2 == 0.02
    # the paper's constructor is plumb_bob with p1 = p2 = k3 = 0; equal cameras compare and hash equal
    a = Camera(width=640, height=480, fx=500.0, fy=500.0, cx=320.0, cy=240.0, k1=0.1)
    b = Camera.from_ros(640, 480, a.K, "plumb_bob", [0.1, 0, 0, 0, 0])
    assert a == b and hash(a) == hash(b)


@pytest.mark.parametrize("model, D, match", [
    ("plumb_bob", [0.1] * 8, "use distortion_model 'rational_polynomial'"),
    ("rational_polynomial", [0.1] * 9, "takes 8 or 12 or 14 coefficients"),
    ("equidistant", [0.1] * 5, "takes 4 coefficients"),
    ("double_sphere", [0.1] * 4, "not supported; supported: plumb_bob, rational_polynomial, equidistant"),
    ("plumb_bob", [0.1, np.nan], "NaN or inf"),
])
def test_bad_models_are_named(model, D, match):
    with pytest.raises(ValueError, match=match):
        Camera.from_ros(640, 480, MODELS["k1k2"].K, model, D)


def test_k1_conflicting_with_coefficients():
    with pytest.raises(ValueError, match="k1=0.5 disagrees with coefficients"):
        Camera(width=10, height=10, fx=1.0, fy=1.0, cx=5.0, cy=5.0, k1=0.5, coefficients=(0.1, 0, 0, 0, 0))
    with pytest.raises(ValueError, match="skew"):
        Camera.from_ros(10, 10, [[1.0, 0.2, 5], [0, 1, 5], [0, 0, 1]], "plumb_bob", [])
