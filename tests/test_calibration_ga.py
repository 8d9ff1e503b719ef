"""GA (paper eq. 4-8), LM refinement and single-camera calibration on synthetic geometry."""
import math

import numpy as np
import pytest

from mrstereo.calibration import (CalibrationView, GABounds, GAConfig, calibrate_camera, default_bounds,
                                  ga_calibrate_intrinsics, ga_calibrate_single, paper_bounds, planar_grid,
                                  pose_looking_at, synthetic_view)
from mrstereo.calibration.ga import homography_poses
from mrstereo.calibration.refine import refine_views
from mrstereo.camera import Camera, PaperCamera

# non-square image, off-centre principal point, fx != fy: axis swaps fail
TRUE = Camera(width=640, height=400, fx=520.0, fy=523.0, cx=331.0, cy=192.0, k1=-0.21, k2=0.05)
GRID = planar_grid(9, 6, 0.03)
CENTRE = GRID.mean(axis=0)


def board_views(camera=TRUE, noise_px=0.1, seed=0):
    # tilted boards, some reaching into every image corner (distortion is largest there)
    specs = [(0.0, 0.0, 0.0, (0, 0)), (0.45, 0.0, 0.1, (60, 30)), (-0.4, 0.1, -0.2, (-70, -20)),
             (0.1, 0.45, 0.3, (40, -50)), (0.0, -0.5, -0.1, (-50, 40)), (0.35, 0.35, 1.2, (0, 0)),
             (0.3, -0.2, 0.1, (135, 80)), (-0.2, 0.3, -0.1, (-135, -80)), (0.25, 0.25, 0.0, (135, -80)),
             (-0.25, -0.3, 0.05, (-135, 80))]
    rng = np.random.default_rng(seed)
    views = []
    specs = specs + [(-ax, ay, roll + 0.3, (-u, v)) for ax, ay, roll, (u, v) in specs]
    for i, (ax, ay, roll, off) in enumerate(specs):
        T = pose_looking_at(CENTRE, distance_m=0.36, tilt_x_rad=ax, tilt_y_rad=ay, roll_rad=roll, offset_px=off,
                            focal_px=camera.fx)
        views.append(synthetic_view(camera, GRID, T, noise_px=noise_px, rng=rng, name=f"v{i}"))
    return views


def distortion_difference_px(a: Camera, b: Camera) -> np.ndarray:
    """Difference of the distortion correction fields on a grid over the whole image."""
    u, v = np.meshgrid(np.linspace(0, a.width - 1, 33), np.linspace(0, a.height - 1, 25))
    uv = np.stack([u.ravel(), v.ravel()], 1)
    da = a.undistort_pixels(uv) - uv
    db = b.undistort_pixels(uv) - uv
    return np.linalg.norm(da - db, axis=1)


def test_ga_single_view_known_answer_and_paper_conversion():
    view = board_views(noise_px=0.0)[1]
    config = GAConfig(generations=400, stall_generations=400)
    res = ga_calibrate_single(view, width=TRUE.width, height=TRUE.height, config=config, rng=3)
    assert res.generations == 400 and len(res.history) == 400
    assert np.all(np.diff(res.history) <= 0)                    # elitism: best never gets worse
    assert res.rms_px < 5.0                                      # start: hundreds of px
    assert res.history[0] > 20 * res.history[-1]
    # the GA genes are the paper's parameterization, converted exactly
    f, u0, v0, k1, k2 = res.genes[:5]
    assert res.paper_camera.f_mm == f and res.camera.fx == pytest.approx(f * res.paper_camera.alpha_x)
    assert res.camera.k1 == pytest.approx(k1 * f**2) and res.camera.k2 == pytest.approx(k2 * f**4)
    lo, hi = default_bounds(view, width=TRUE.width, height=TRUE.height).array()
    assert np.all(res.genes >= lo) and np.all(res.genes <= hi)


def test_ga_is_deterministic_for_a_seed():
    view = board_views()[2]
    cfg = GAConfig(generations=30)
    a = ga_calibrate_single(view, width=640, height=400, config=cfg, rng=7)
    b = ga_calibrate_single(view, width=640, height=400, config=cfg, rng=7)
    c = ga_calibrate_single(view, width=640, height=400, config=cfg, rng=8)
    assert np.array_equal(a.genes, b.genes) and not np.array_equal(a.genes, c.genes)


def test_paper_bounds_match_table_1():
    b = paper_bounds()
    assert b.f_mm == (6.0, 9.0) and b.u0_px == (220.0, 360.0) and b.k1_mm == (-1e-3, 1e-3)
    assert b.alpha_rad == (-math.pi / 4, math.pi / 4) and b.Z_m[0] > 0
    assert b.array().shape == (2, 11)


def test_homography_pose_is_exact_without_noise():
    cam = Camera(width=640, height=400, fx=TRUE.fx, fy=TRUE.fy, cx=TRUE.cx, cy=TRUE.cy)   # no distortion
    for i, T_true in enumerate([pose_looking_at(CENTRE, distance_m=0.6, tilt_x_rad=0.3, tilt_y_rad=-0.2,
                                                roll_rad=0.7)]):
        v = synthetic_view(cam, GRID, T_true)
        xy = (v.uv - [cam.cx, cam.cy]) / [cam.fx, cam.fy]
        R, t = homography_poses(GRID, xy)
        assert np.allclose(R, T_true[:3, :3], atol=1e-9) and np.allclose(t, T_true[:3, 3], atol=1e-9)


def test_multiview_ga_plus_lm_recovers_the_camera():
    views = board_views()
    res = calibrate_camera(views, width=TRUE.width, height=TRUE.height, method="ga+lm",
                           ga_config=GAConfig(generations=40, stall_generations=40), rng=0)
    c = res.camera
    assert res.success, res.message
    assert abs(c.fx / TRUE.fx - 1) < 0.005 and abs(c.fy / TRUE.fy - 1) < 0.005
    assert abs(c.cx - TRUE.cx) < 1.0 and abs(c.cy - TRUE.cy) < 1.0
    err = distortion_difference_px(c, TRUE)
    # RMS over the image within 0.05 px; the far corners extrapolate k2 (r^5 at the corner)
    assert np.sqrt(np.mean(err**2)) < 0.05 and err.max() < 0.25
    assert res.lm_rms_px <= res.ga_rms_px and res.rms_px == pytest.approx(0.1 * math.sqrt(2), rel=0.15)
    assert res.generations == 40 and res.outlier_views == ()
    # sigmas: the true values are within ~4 sigma, and sigmas are not absurdly small or large
    for name in ("fx", "fy", "cx", "cy", "k1", "k2"):
        s = res.sigmas[name]
        assert 0 < s and abs(getattr(c, name) - getattr(TRUE, name)) < 5 * s + 1e-12, name


def test_lm_from_zhang_init_and_outlier_view():
    views = board_views()
    bad = views[3]
    views[3] = CalibrationView(bad.points_target, bad.uv + np.random.default_rng(1).normal(0, 2.0, bad.uv.shape),
                               name="bad")
    res = calibrate_camera(views, width=640, height=400, method="lm")
    assert res.success and res.generations == 0 and math.isnan(res.ga_rms_px)
    assert res.outlier_views == (3,)
    assert res.per_view_rms_px.shape == (20,)
    assert abs(res.camera.fx / TRUE.fx - 1) < 0.01
    assert res.summary()["outlier_views"] == ["bad"]


def test_ga_intrinsics_needs_planar_views_and_bad_inputs():
    v = board_views()[0]
    lifted = CalibrationView(v.points_target + [0, 0, 0.1], v.uv)
    with pytest.raises(ValueError, match="planar"):
        ga_calibrate_intrinsics([lifted, v], width=640, height=400)
    with pytest.raises(ValueError, match="method"):
        calibrate_camera([v], width=640, height=400, method="simplex")
    with pytest.raises(ValueError, match="empty"):
        calibrate_camera([], width=640, height=400)
    with pytest.raises(ValueError, match="crossover_probability"):
        GAConfig(crossover_probability=1.5)
    with pytest.raises(ValueError, match="elite"):
        GAConfig(population=10, elite=10)
    with pytest.raises(ValueError, match="mixing_weight"):
        GAConfig(mixing_weight="blend")
    with pytest.raises(ValueError, match="f_mm"):
        GABounds(f_mm=(9.0, 6.0), u0_px=(0, 1), v0_px=(0, 1), k1_mm=(0, 0), k2_mm=(0, 0))
    with pytest.raises(TypeError, match="rng"):
        ga_calibrate_single(v, width=640, height=400, config=GAConfig(generations=2), rng="seed")
    with pytest.raises(ValueError, match="at least 6"):
        CalibrationView(np.zeros((3, 3)), np.zeros((3, 2)))
    with pytest.raises(ValueError, match="NaN"):
        CalibrationView(GRID, np.full((len(GRID), 2), np.nan))


def test_paper_camera_roundtrip_used_by_ga():
    p = TRUE.to_paper(f_mm=4.0)
    back = p.to_camera()
    assert isinstance(p, PaperCamera)
    for k in ("fx", "fy", "cx", "cy", "k1", "k2"):
        assert getattr(back, k) == pytest.approx(getattr(TRUE, k))


@pytest.mark.slow
def test_paper_ga_on_the_rendered_paper_dot_target():
    import mrstereo.world as world
    cam = world.default_stereo(320, 240).left.camera
    dots = world.render_paper_dot_target(cam, supersample=1)
    uv = dots.points_px + np.random.default_rng(0).normal(0, 0.1, dots.points_px.shape)
    view = CalibrationView(dots.points_target, uv)
    res = calibrate_camera(view, width=320, height=240, method="ga", rng=0)    # Table 2 settings
    assert res.ga_rms_px < 1.0 and res.generations > 100
    polished = refine_views([view], res.camera, res.poses, fix_aspect=1.0)       # what "ga+lm" does next
    rms = float(np.sqrt(np.mean(np.sum(polished.residuals_px[0] ** 2, axis=1))))
    assert polished.success and rms < min(0.2, res.ga_rms_px)


def test_multiview_ga_searches_a_subset_of_points_and_reports_all():
    views = board_views()                                   # 54 corners per view
    cfg = GAConfig(generations=15, stall_generations=15)
    kw = dict(width=TRUE.width, height=TRUE.height, rng=3)
    full = ga_calibrate_intrinsics(views, config=cfg, **kw)
    # a cap at or above the view size changes nothing, bit for bit
    same = ga_calibrate_intrinsics(views, config=GAConfig(generations=15, stall_generations=15,
                                                          max_points_per_view=54), **kw)
    np.testing.assert_array_equal(full.genes, same.genes)
    assert full.fitness == same.fitness
    sub = ga_calibrate_intrinsics(views, config=GAConfig(generations=15, stall_generations=15,
                                                         max_points_per_view=12), **kw)
    n_points = sum(len(v.uv) for v in views)
    # fitness, RMS and poses over every point, not the 12 searched per view
    assert sub.rms_px == pytest.approx(math.sqrt(sub.fitness / n_points))
    assert sub.fitness > sub.history[-1] * 3               # history sums the 12 points per view only
    assert sub.rms_px < 1.0 and abs(sub.camera.fx / TRUE.fx - 1) < 0.02
    with pytest.raises(ValueError, match="max_points_per_view"):
        GAConfig(max_points_per_view=3)
