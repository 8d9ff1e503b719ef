"""Multi-range matcher: known answers on synthetic shifted random texture."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from mrstereo.camera import Camera, StereoCamera
from mrstereo.matching import (AcceptanceConfig, CostConfig, MatchingConfig, PostFilterConfig, SearchConfig,
                               compute_disparity, make_plan)

SINGLE = SearchConfig(multi_range=False)

H, W = 48, 160


def _texture(rng, height, width):
    img = cv2.GaussianBlur(rng.uniform(0, 1, (height, width)).astype(np.float32), (0, 0), 1.0)
    img = (img - img.min()) / (img.max() - img.min())
    return np.round(20 + 215 * img).astype(np.uint8)


def _two_plane_pair(d_far, d_near, seed=0):
    """Far plane (small d) on the left half, near plane (large d) on the right half."""
    rng = np.random.default_rng(seed)
    far = _texture(rng, H, W + 64)
    near = _texture(rng, H, W + 64)
    xs = np.arange(W)
    half = W // 2
    left = np.where(xs < half, far[:, xs], near[:, xs]).astype(np.uint8)
    # right image: x_right = x_left - d  ->  right(x) = texture(x + d)
    right_far = far[:, xs + d_far]
    right_near = near[:, xs + d_near]
    boundary = half - d_near                 # near plane starts at x_left = half
    right = np.where(xs < boundary, right_far, right_near).astype(np.uint8)
    truth = np.where(xs < half, d_far, d_near).astype(np.float32)[None].repeat(H, 0)
    return left, right, truth


def _good(result, truth, cols, tol=1.0):
    d = result.disparity_px[8:-8, cols]
    t = truth[8:-8, cols]
    return np.mean(np.abs(d - t) <= tol)        # NaN counts as not good


def test_multi_range_recovers_near_and_far_single_range_with_same_work_misses_near():
    left, right, truth = _two_plane_pair(5, 36)
    multi = compute_disparity(left, right, max_disparity_px=48)
    far_cols, near_cols = slice(16, 44), slice(90, 150)   # far x >= 44 is occluded
    assert _good(multi, truth, far_cols) > 0.9
    assert _good(multi, truth, near_cols, tol=2.0) > 0.9
    # a single full-resolution range doing about the same work searches only [0, ~16]
    work = multi.plan.work
    d_equal = int(work / (H * W)) - 1
    assert d_equal < 36
    single = compute_disparity(left, right, disparity_bands_px=[(0, d_equal)],
                               config=MatchingConfig(search=SINGLE, near_guard=None))
    assert single.plan.work <= work * 1.1
    assert _good(single, truth, far_cols) > 0.9
    assert _good(single, truth, near_cols, tol=2.0) < 0.05
    # with its near guard the single range reports the near plane as too near, not farther
    guarded = compute_disparity(left, right, disparity_bands_px=[(0, d_equal)],
                                config=MatchingConfig(search=SINGLE))
    assert guarded.too_near[8:-8, near_cols].mean() > 0.9
    assert not np.isfinite(guarded.disparity_px[8:-8, near_cols]).any()
    assert _good(guarded, truth, far_cols) > 0.9
    assert not multi.too_near[8:-8, 16:150].any()
    # the levels: the near plane comes from the coarsest level, the far one from the finest
    assert np.isfinite(multi.levels[0][8:-8, far_cols]).mean() > 0.8
    assert np.isfinite(multi.levels[-1][8:-8, near_cols]).mean() > 0.8


def test_paper_preset_recovers_both_planes():
    left, right, truth = _two_plane_pair(5, 36, seed=1)
    res = compute_disparity(left, right, max_disparity_px=48, preset="paper")
    assert _good(res, truth, slice(16, 44)) > 0.8
    assert _good(res, truth, slice(90, 150), tol=2.0) > 0.8


def test_left_right_check_removes_occlusion_errors():
    left, right, truth = _two_plane_pair(4, 14, seed=2)
    # left pixels just left of the near plane (x in [half - (14-4), half)) are occluded in right
    occluded = slice(W // 2 - 10, W // 2 - 1)
    base = MatchingConfig(search=SINGLE, acceptance=AcceptanceConfig(uniqueness_ratio=0.0, median_size=0, max_cost=None),
                          postfilter=PostFilterConfig(speckle_size_px=0, edge_guard_px=0), near_guard=None)
    without = compute_disparity(left, right, max_disparity_px=20, config=base.replace(acceptance={"lr_max_diff_px": None}))
    with_lr = compute_disparity(left, right, max_disparity_px=20, config=base.replace(acceptance={"lr_max_diff_px": 1.0}))
    wrong = lambda r: np.mean(np.isfinite(r.disparity_px[8:-8, occluded])
                              & (np.abs(r.disparity_px[8:-8, occluded] - 4) > 1))
    assert wrong(without) > 0.5
    assert wrong(with_lr) < 0.2 * wrong(without)
    assert _good(with_lr, truth, slice(20, 60)) > 0.9


def test_subpixel_refinement_reduces_error_on_fractional_shift():
    rng = np.random.default_rng(3)
    scene = _texture(rng, H, 4 * (W + 32)).astype(np.float32)
    wide_left = scene
    shift = 4 * 6 + 2                                   # 6.5 px after 4x decimation
    wide_right = np.roll(scene, -shift, axis=1)
    left = cv2.resize(wide_left, (W + 32, H), interpolation=cv2.INTER_AREA)[:, :W]
    right = cv2.resize(wide_right, (W + 32, H), interpolation=cv2.INTER_AREA)[:, :W]
    cfg = MatchingConfig(search=SINGLE)
    err = {}
    for sub in (False, True):
        d = compute_disparity(left, right, max_disparity_px=12, config=cfg.replace(subpixel={"parabola": sub})).disparity_px
        err[sub] = np.nanmean(np.abs(d[8:-8, 20:-8] - 6.5))
    assert err[True] < 0.2
    assert err[True] < 0.6 * err[False]


def test_aoi_leaves_nan_outside_and_matches_inside():
    left, right, truth = _two_plane_pair(5, 36, seed=4)
    aoi = (10, 30, 20, 140)
    full = compute_disparity(left, right, max_disparity_px=48)
    part = compute_disparity(left, right, max_disparity_px=48, aoi=aoi)
    d = part.disparity_px
    assert np.isnan(d[:10]).all() and np.isnan(d[30:]).all()
    assert np.isnan(d[:, :20]).all() and np.isnan(d[:, 140:]).all()
    inside = np.isfinite(d[10:30, 20:140])
    assert inside.mean() > 0.6
    assert part.plan.work < full.plan.work


def test_plan_from_calibration_depth_bands():
    cam = Camera(fx=451.0, fy=451.0, cx=320.0, cy=240.0, width=640, height=480)
    rig = StereoCamera.ideal(cam, 0.075)
    plan = make_plan((640, 480), calibration=rig)
    assert [lvl.decimation for lvl in plan.levels] == [1, 2, 4]
    near = plan.levels[-1]
    assert near.band_px[1] == pytest.approx(451 * 0.075 / 0.5)
    assert near.depth_band_m == pytest.approx((0.5, 1.0))
    assert plan.levels[0].depth_band_m == pytest.approx((2.5, 15.0))
    assert plan.work < 0.5 * plan.single_range_work
    text = plan.describe()
    assert "0.50-1.00" in text and "single-range" in text
    custom = make_plan((640, 480), calibration=rig, depth_bands_m=[0.4, 2.0, 20.0])
    assert len(custom.levels) == 2 and [lvl.decimation for lvl in custom.levels] == [1, 2]


def test_color_and_float_inputs_agree_with_gray():
    left, right, _ = _two_plane_pair(5, 36, seed=5)
    gray = compute_disparity(left, right, max_disparity_px=48).disparity_px
    bgr = compute_disparity(np.dstack([left] * 3), np.dstack([right] * 3), max_disparity_px=48).disparity_px
    # BT.601 weights reproduce the gray values up to float rounding: same answer almost everywhere
    assert np.mean(np.isfinite(gray) == np.isfinite(bgr)) > 0.995
    assert np.nanmedian(np.abs(gray - bgr)) < 0.01


@pytest.mark.parametrize("kwargs, match", [
    (dict(), "undetermined"),
    (dict(max_disparity_px=float("nan")), "finite"),
    (dict(max_disparity_px=-4), "> 0"),
    (dict(max_disparity_px=16, disparity_bands_px=[(0, 16)]), "only one"),
    (dict(depth_bands_m=[0.5, 1.0]), "needs calibration"),
    (dict(disparity_bands_px=[(10, 5)]), "high > low"),
    (dict(max_disparity_px=16, aoi=(0, 100, 0, 10)), "aoi"),
    (dict(max_disparity_px=16, preset="fast"), "preset"),
])
def test_bad_arguments(kwargs, match):
    img = np.zeros((20, 30), np.uint8)
    with pytest.raises(ValueError, match=match):
        compute_disparity(img, img, **kwargs)


def test_bad_images():
    img = np.zeros((20, 30), np.uint8)
    with pytest.raises(ValueError, match="same size"):
        compute_disparity(img, np.zeros((20, 31), np.uint8), max_disparity_px=8)
    with pytest.raises(TypeError, match="numpy array"):
        compute_disparity([[1]], img, max_disparity_px=8)
    with pytest.raises(ValueError, match="NaN"):
        compute_disparity(np.full((20, 30), np.nan, np.float32), img, max_disparity_px=8)
    with pytest.raises(ValueError, match="window_px must be odd"):
        CostConfig(window_px=8)


def test_refinement_only_where_the_union_can_take_it_changes_no_result(monkeypatch):
    """The coarsest level is re-scored only where no finer level holds a value at least as confident
    (eq. 12 keeps that one whatever the re-scoring gives): the same disparity and confidence as
    re-scoring every valid value, on the warm-up pair and a real-texture two-plane pair, with fewer
    pixels re-scored."""
    from mrstereo.matching import _union_kernels, cost
    from mrstereo.matching.warmup import warm_pair

    wanted = []
    original_refine = cost.refine_candidates

    def counting(*args, **kwargs):
        wanted.append(int(np.count_nonzero(args[3])))
        return original_refine(*args, **kwargs)

    def everywhere(d, c, kept_d, kept_c, first, out):
        out[...] = np.isfinite(d)

    left, right, _ = _two_plane_pair(5, 40)
    pairs = [(warm_pair(), 64.0), ((left, right), 48.0)]
    from mrstereo.matching import disparity as disparity_module
    monkeypatch.setattr(disparity_module, "refine_candidates", counting)
    totals = np.zeros(2, int)
    for (l, r), d_max in pairs:
        for preset in ("robust", "mapping"):
            wanted.clear()
            fast = compute_disparity(l, r, max_disparity_px=d_max, preset=preset)
            fewer = sum(wanted)
            wanted.clear()
            with monkeypatch.context() as m:
                m.setattr(_union_kernels, "can_win", everywhere)
                full = compute_disparity(l, r, max_disparity_px=d_max, preset=preset)
            assert np.array_equal(fast.disparity_px, full.disparity_px, equal_nan=True)
            assert np.array_equal(fast.confidence, full.confidence)
            assert np.array_equal(fast.too_near, full.too_near)
            totals += (fewer, sum(wanted))
    assert totals[0] < totals[1]
