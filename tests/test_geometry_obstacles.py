"""Ground plane (V-disparity, 3D RANSAC) and obstacle detection on hand-made geometry.

The scene is ray-cast analytically: a flat floor seen by a camera at height H tilted
down by TILT, and a box standing on the floor. Off-centre principal point and a
non-square image so that swapped axes fail.
"""
import math

import numpy as np
import pytest

from mrstereo.camera import Camera, CameraInfo, CameraMount, StereoCamera
from mrstereo.geometry import (GroundPlane, ObstacleConfig, T_robot_from_cam_ground, detect_obstacles, estimate_ground,
                               fit_ground_plane, fit_ground_v_disparity, ground_from_mount, height_above_ground_m,
                               points_cam_from_disparity, v_disparity)
from mrstereo.transforms import T_robot_from_cam

W, H, F, CX, CY, B = 200, 150, 180.0, 96.3, 71.8, 0.12
HEIGHT, TILT = 0.62, 0.21
BOX = ((1.6, 2.0), (-0.35, 0.15), (0.0, 0.45))      # x, y, z ranges in the robot frame


def _stereo(mount=None):
    return StereoCamera.ideal(Camera(width=W, height=H, fx=F, fy=F, cx=CX, cy=CY), B, mount=mount)


def _render(height=HEIGHT, tilt=TILT, pan=0.0, box=BOX):
    """Exact disparity and labels (0 none, 1 floor, 2 box) by ray casting in the robot frame."""
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    rays = np.stack([(u - CX) / F, (v - CY) / F, np.ones_like(u)], axis=-1)     # camera z = 1
    T = T_robot_from_cam(height_m=height, tilt_rad=tilt, pan_rad=pan)
    dirs = rays @ T[:3, :3].T
    origin = T[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        t_floor = np.where(dirs[..., 2] < 0, -origin[2] / dirs[..., 2], np.inf)
        t_near = np.full(u.shape, -np.inf)
        t_far = np.full(u.shape, np.inf)
        for k, (lo, hi) in enumerate(box):
            t1, t2 = (lo - origin[k]) / dirs[..., k], (hi - origin[k]) / dirs[..., k]
            t_near = np.maximum(t_near, np.minimum(t1, t2))
            t_far = np.minimum(t_far, np.maximum(t1, t2))
    hit_box = (t_near <= t_far) & (t_near > 0)
    t = np.where(hit_box, np.minimum(t_near, t_floor), t_floor)
    labels = np.where(hit_box & (t_near <= t_floor), 2, np.where(np.isfinite(t_floor), 1, 0))
    with np.errstate(divide="ignore"):
        d = np.where(np.isfinite(t), B * F / t, np.nan).astype(np.float32)   # t = camera Z since ray z = 1
    return d, labels


def test_floor_disparity_is_the_v_disparity_line():
    d, labels = _render(box=((50, 51), (0, 1), (0, 1)))        # box out of view: floor only
    a = B * math.cos(TILT) / HEIGHT
    c = B * F * math.sin(TILT) / HEIGHT
    rows = np.arange(H)
    floor_rows = rows[(labels == 1).all(axis=1)]
    np.testing.assert_allclose(d[floor_rows, 17], a * (floor_rows - CY) + c, rtol=1e-5)
    hist = v_disparity(d, bin_px=1.0)
    peak = hist[floor_rows].argmax(axis=1)
    np.testing.assert_array_equal(peak, np.floor(a * (floor_rows - CY) + c).astype(int))
    assert hist[floor_rows].sum(axis=1).tolist() == [W] * floor_rows.size


def test_v_disparity_fit_recovers_height_and_tilt_with_box_and_ghosts():
    d, _ = _render()
    rng = np.random.default_rng(5)
    ghosts = rng.random(d.shape) < 0.15
    d[ghosts] = rng.uniform(0, 40, ghosts.sum())
    g = fit_ground_v_disparity(d, _stereo(), tolerance_px=0.5, rng=1)
    assert g.success, g.message
    assert g.height_m == pytest.approx(HEIGHT, abs=0.005)
    assert g.tilt_rad == pytest.approx(TILT, abs=0.002)
    assert g.method == "v_disparity" and g.roll_rad == 0.0
    again = fit_ground_v_disparity(d, _stereo(), tolerance_px=0.5, rng=1)
    assert again == g                                         # same seed, same answer


def test_plane_fit_recovers_roll_and_matches_the_transform():
    roll = 0.07
    n = np.array([math.sin(roll) * math.cos(TILT), math.cos(roll) * math.cos(TILT), math.sin(TILT)])
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    rays = np.stack([(u - CX) / F, (v - CY) / F, np.ones_like(u)], axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(rays @ n > 0, HEIGHT / (rays @ n), np.nan)      # floor n.P = h
        d = B * F / z
    pts = points_cam_from_disparity(d, focal_px=F, baseline_m=B, cx_px=CX, cy_px=CY)
    g = fit_ground_plane(pts, rng=0)
    assert g.success, g.message
    assert (g.height_m, g.tilt_rad, g.roll_rad) == pytest.approx((HEIGHT, TILT, roll), abs=1e-6)
    floor = pts[np.isfinite(pts).all(axis=-1)]
    T = T_robot_from_cam_ground(g)
    np.testing.assert_allclose(floor @ T[2, :3] + T[2, 3], 0.0, atol=1e-9)    # floor maps to z = 0
    np.testing.assert_allclose(height_above_ground_m(floor, g), 0.0, atol=1e-9)


def test_plane_fit_kernels_equal_the_numpy_expressions():
    # the RANSAC score of each hypothesis (inliers less the points below the floor) and the points kept for the
    # fit, as numpy computes them, on points that hold NaN, points behind the camera and points too far
    from mrstereo.geometry import _kernels

    rng = np.random.default_rng(3)
    pts = rng.normal(0.0, 2.0, (5000, 3)) + [0.0, 1.0, 4.0]
    pts[rng.random(len(pts)) < 0.1, rng.integers(0, 3)] = np.nan
    normals = rng.normal(size=(300, 3)) + [0.0, 3.0, 1.0]
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    dists = rng.uniform(0.2, 2.0, 300)
    ahead = np.empty_like(pts)
    kept = ahead[:_kernels.points_ahead(pts, 8.0, ahead)]
    np.testing.assert_array_equal(kept, pts[np.isfinite(pts).all(axis=1) & (pts[:, 2] > 0) & (pts[:, 2] <= 8.0)])
    assert 0 < len(kept) < 0.9 * len(pts)
    res = kept @ normals.T - dists
    scores = np.empty(len(dists))
    _kernels.plane_scores(*np.ascontiguousarray(kept.T), normals, dists, 0.03, 1.0, scores)
    np.testing.assert_array_equal(scores, (np.abs(res) <= 0.03).sum(axis=0) - 1.0 * (res > 0.03).sum(axis=0))
    assert len(np.unique(scores)) > 100


def test_scatter_points_equals_numpy_in_any_order():
    # in raster order (as detect_obstacles lists them: one pass), shuffled, and with a pixel listed twice (last wins)
    from mrstereo.geometry import _kernels

    rng = np.random.default_rng(4)
    pixels = np.sort(rng.choice(1000, 300, replace=False))
    points = rng.normal(size=(300, 3))
    for order in (np.arange(300), rng.permutation(300), np.r_[np.arange(300), 7]):
        out = np.zeros((1000, 3))
        _kernels.scatter_points(points[order % 300], pixels[order % 300], out)
        ref = np.full((1000, 3), np.nan)
        ref[pixels[order % 300]] = points[order % 300]
        np.testing.assert_array_equal(out, ref)


def test_ground_fits_fail_cleanly_without_a_floor():
    d = np.full((H, W), np.nan, np.float32)
    assert not fit_ground_v_disparity(d, _stereo()).success
    wall = np.full((H, W), 12.0, np.float32)                          # a fronto-parallel wall: vertical line
    g = fit_ground_v_disparity(wall, _stereo())
    assert not g.success and "positive" in g.message
    pts = points_cam_from_disparity(wall, focal_px=F, baseline_m=B, cx_px=CX, cy_px=CY)
    assert not fit_ground_plane(pts).success


def _box_truth(labels, d, config):
    T = T_robot_from_cam(height_m=HEIGHT, tilt_rad=TILT)
    pts = points_cam_from_disparity(d, focal_px=F, baseline_m=B, cx_px=CX, cy_px=CY) @ T[:3, :3].T + T[:3, 3]
    return (labels == 2) & (pts[..., 2] > config.min_obstacle_height_m), pts


def test_detect_obstacles_with_known_mount():
    d, labels = _render()
    cfg = ObstacleConfig()
    res = detect_obstacles(d, _stereo(), mount=CameraMount.from_rig(HEIGHT, TILT), config=cfg)
    assert res.success and res.ground.method == "mount"
    expected, _ = _box_truth(labels, d, cfg)
    np.testing.assert_array_equal(res.obstacle_mask, expected)
    floor_in_range = (labels == 1) & (np.hypot(*res.points_robot_image[..., :2].transpose(2, 0, 1)) <= cfg.max_range_m)
    np.testing.assert_array_equal(res.floor_mask, floor_in_range | ((labels == 2) & res.floor_mask))
    obs = res.obstacle_points_robot
    assert obs.shape == (expected.sum(), 3)
    assert obs[:, 0].min() == pytest.approx(BOX[0][0], abs=1e-6)       # front face of the box
    assert BOX[1][0] - 1e-6 <= obs[:, 1].min() and obs[:, 1].max() <= BOX[1][1] + 1e-6
    assert obs[:, 2].max() == pytest.approx(BOX[2][1], abs=0.02)
    np.testing.assert_allclose(res.points_robot_image[res.floor_mask & (labels == 1), 2], 0.0, atol=1e-6)
    assert (res.floor_points_robot[:, 2] <= cfg.floor_tolerance_m).all()   # box foot (z <= 4 cm) counts as floor
    assert res.points_robot.shape[0] == np.isfinite(d).sum()


@pytest.mark.parametrize("method", ["plane", "v_disparity"])
def test_detect_obstacles_estimates_the_floor_when_no_mount_is_known(method):
    d, labels = _render()
    noisy = d + np.random.default_rng(0).normal(0, 0.05, d.shape).astype(np.float32)
    res = detect_obstacles(noisy, _stereo(), config=ObstacleConfig(ground_method=method))
    assert res.success and res.ground.method == method, res.message
    assert res.ground.height_m == pytest.approx(HEIGHT, abs=0.02)
    assert res.ground.tilt_rad == pytest.approx(TILT, abs=0.01)
    expected, _ = _box_truth(labels, d, ObstacleConfig())
    recall = (res.obstacle_mask & expected).sum() / expected.sum()
    false_floor = (res.obstacle_mask & (labels == 1)).sum() / (labels == 1).sum()
    assert recall > 0.97 and false_floor < 0.001
    # The stereo YAML's mount is used when no mount argument is given.
    from_yaml = detect_obstacles(d, _stereo(mount=CameraMount.from_rig(HEIGHT, TILT)))
    assert from_yaml.ground.method == "mount"


def test_rough_mount_is_refined_and_kept_when_the_estimate_fails():
    d, _ = _render()
    rough = CameraMount.from_rig(HEIGHT + 0.1, TILT - 0.06)
    res = detect_obstacles(d, _stereo(), mount=rough, config=ObstacleConfig(estimate_ground=True))
    assert res.ground.method == "plane"
    assert (res.ground.height_m, res.ground.tilt_rad) == pytest.approx((HEIGHT, TILT), abs=1e-3)
    # Searched only near the mount: a floor 0.3 m away from it is not accepted, the mount is used.
    far = CameraMount.from_rig(HEIGHT + 0.4, TILT)
    res = detect_obstacles(d, _stereo(), mount=far, config=ObstacleConfig(estimate_ground=True))
    assert res.ground.method == "mount" and "mount used" in res.ground.message
    assert res.ground.height_m == HEIGHT + 0.4
    # the prior of estimate_ground: a mount or the floor it implies, the same search either way
    for prior in (rough, ground_from_mount(rough)):
        g = estimate_ground(d, _stereo(), method="plane", prior=prior)
        assert g.success and g.height_m == pytest.approx(HEIGHT, abs=1e-3)
    assert not estimate_ground(d, _stereo(), method="plane", prior=far).success
    with pytest.raises(TypeError, match="prior"):
        estimate_ground(d, _stereo(), prior=(HEIGHT, TILT))


def test_pan_rotates_the_obstacles_to_the_left():
    pan = 0.3
    # The box placed along the panned view direction appears where the pan says.
    c, s = math.cos(pan), math.sin(pan)
    d, labels = _render(pan=pan, box=((1.6, 2.0), (-0.35, 0.15), (0.0, 0.45)))
    res = detect_obstacles(d, _stereo(), mount=CameraMount.from_rig(HEIGHT, TILT), pan_rad=pan)
    obs = res.obstacle_points_robot
    assert obs.shape[0] > 0
    assert obs[:, 0].min() == pytest.approx(1.6, abs=1e-6)
    unpanned = detect_obstacles(d, _stereo(), mount=CameraMount.from_rig(HEIGHT, TILT))
    rotated = unpanned.obstacle_points_robot[:, :2] @ np.array([[c, -s], [s, c]]).T
    np.testing.assert_allclose(rotated, obs[:, :2], atol=1e-9)


def test_failed_ground_gives_empty_result_and_bad_input_raises():
    res = detect_obstacles(np.full((H, W), np.nan, np.float32), _stereo())
    assert not res.success and not res.obstacle_mask.any() and res.points_robot.shape == (0, 3)
    with pytest.raises(ValueError, match="calibration is 200x150"):
        detect_obstacles(np.zeros((10, 10)), _stereo())
    with pytest.raises(TypeError, match="stereo must be a StereoCamera"):
        detect_obstacles(np.zeros((H, W)), None)
    with pytest.raises(ValueError, match="max_obstacle_height_m"):
        ObstacleConfig(min_obstacle_height_m=2.0, max_obstacle_height_m=1.0)
    with pytest.raises(ValueError, match="ground_method"):
        ObstacleConfig(ground_method="hough")
    with pytest.raises(ValueError, match="ground plane was not found"):
        T_robot_from_cam_ground(GroundPlane(height_m=math.nan, tilt_rad=math.nan, success=False, message="x"))


def test_one_pass_points_and_band_equal_the_per_pixel_reference():
    """The fused kernel (eq. 14-16, robot transform, height band, range limit over the valid pixels only)
    against numpy on the whole image: the triangulation cross-checked with cv2.reprojectImageTo3D, the
    transform a matmul, the band with np.hypot. Too-near pixels, NaN, zero and negative disparities,
    a doffs, a roll and a pan; masks equal, points within 1e-12 m (summation order)."""
    import cv2

    stereo = _stereo()
    rng = np.random.default_rng(11)
    d, _ = _render()
    d = d + rng.normal(0, 0.3, d.shape).astype(np.float32)
    d[rng.random(d.shape) < 0.1] = np.nan
    d[5, 7], d[9, 11], d[12, 13] = 0.0, -2.0, -0.5       # -0.5 + doffs > 0: a point
    too_near = np.zeros(d.shape, bool)
    too_near[20:40, 150:180] = True
    too_near[140:150, 0:10] = True                        # the floor nearer than the limit: below it
    P_right = stereo.right.P.copy()
    P_right[0, 2] += 0.75                                 # doffs = cx_right - cx_left
    stereo = StereoCamera(left=stereo.left, right=CameraInfo(stereo.right.camera, P=P_right, name="right"))
    ground = GroundPlane(height_m=HEIGHT, tilt_rad=TILT, roll_rad=0.03)
    cfg = ObstacleConfig(max_range_m=3.0)
    res = detect_obstacles(d, stereo, ground=ground, pan_rad=0.2, config=cfg, too_near=too_near, near_limit_px=40.0)
    d_ref = np.where(too_near, 40.0, d.astype(np.float64))
    cam = points_cam_from_disparity(d_ref, focal_px=F, baseline_m=B, cx_px=CX, cy_px=CY, doffs_px=0.75)
    Q = np.array([[1, 0, 0, -CX], [0, 1, 0, -CY], [0, 0, 0, F], [0, 0, 1 / B, 0.75 / B]])
    cv = cv2.reprojectImageTo3D(d_ref.astype(np.float32), Q)
    ok = d_ref + 0.75 > 0
    np.testing.assert_allclose(cam[ok], cv[ok], rtol=1e-5, atol=1e-5)
    assert np.isnan(cam[~ok]).all()
    T = T_robot_from_cam_ground(ground, pan_rad=0.2)
    ref = cam @ T[:3, :3].T + T[:3, 3]
    band = (ref[..., 2] > cfg.min_obstacle_height_m) & (ref[..., 2] <= cfg.max_obstacle_height_m)
    in_range = np.hypot(ref[..., 0], ref[..., 1]) <= cfg.max_range_m
    obstacle = ok & in_range & band
    floor = ok & in_range & (np.abs(ref[..., 2]) <= cfg.floor_tolerance_m) & ~obstacle & ~too_near
    assert obstacle.sum() > 500 and floor.sum() > 500 and (obstacle & too_near).sum() > 100
    np.testing.assert_array_equal(res.obstacle_mask, obstacle)
    np.testing.assert_array_equal(res.floor_mask, floor)
    np.testing.assert_array_equal(np.isnan(res.points_robot_image), np.isnan(ref))
    np.testing.assert_allclose(res.points_robot_image[ok], ref[ok], rtol=0, atol=1e-12)
    np.testing.assert_allclose(res.points_robot, ref[ok], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(res.pixels, np.flatnonzero(ok))
    np.testing.assert_allclose(res.obstacle_points_robot, ref[obstacle], rtol=0, atol=1e-12)
    np.testing.assert_allclose(res.floor_points_robot, ref[floor], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(res.too_near_obstacle_mask, obstacle & too_near)
    assert f"{obstacle.sum()} obstacle and" in res.message and f"({(obstacle & too_near).sum()} obstacle" in res.message
    # the public full-image function computes the same points, bit for bit
    from mrstereo.geometry import points_robot_from_disparity

    assert np.array_equal(points_robot_from_disparity(d_ref, stereo, T), res.points_robot_image, equal_nan=True)
