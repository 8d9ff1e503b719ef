"""Window cost + winner-take-all kernel vs a plain numpy reference of eq. (9)-(10)."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from mrstereo.matching import match_band, prefilter


def _textured(rng, height, width, sigma=1.0):
    img = rng.uniform(0, 255, (height, width)).astype(np.float32)
    return np.clip(cv2.GaussianBlur(img, (0, 0), sigma), 0, 255).round()


def _reference_costs(left, right, d_lo, d_hi, window, kind):
    """Cost volume of eq. (9) (or ZNCC) with the paper's formula, x_right = x_left - d."""
    r = window // 2
    lp = np.pad(left.astype(np.float64), r, mode="edge")
    rp = np.pad(right.astype(np.float64), r, mode="edge")
    h, w = left.shape
    costs = np.full((d_hi - d_lo + 1, h, w), np.inf)
    for k, d in enumerate(range(d_lo, d_hi + 1)):
        for y in range(h):
            for x in range(d, w):
                a = lp[y:y + window, x:x + window]
                b = rp[y:y + window, x - d:x - d + window]
                if kind == "nssd":   # eq. (9)
                    costs[k, y, x] = ((a - b) ** 2).sum() / np.sqrt((a * a).sum() * (b * b).sum())
                else:
                    za, zb = a - a.mean(), b - b.mean()
                    costs[k, y, x] = 1 - (za * zb).sum() / np.sqrt((za * za).sum() * (zb * zb).sum())
    return costs


@pytest.mark.parametrize("kind", ["nssd", "zncc"])
def test_kernel_matches_numpy_reference(kind):
    rng = np.random.default_rng(3)
    left = _textured(rng, 14, 23)
    right = _textured(rng, 14, 23)     # unrelated images: the WTA must still agree
    d_lo, d_hi, window = 2, 7, 5
    m = match_band(left.astype(np.int32), right.astype(np.int32), d_lo=d_lo, d_hi=d_hi,
                   window=window, cost=kind)
    ref = _reference_costs(left, right, d_lo, d_hi, window, kind)
    h, w = left.shape
    for y in range(h):
        for x in range(w):
            if x < d_lo:
                assert m.disparity_int[y, x] == -1
                continue
            column = ref[:, y, x]
            best = int(np.argmin(column))
            assert m.best_cost[y, x] == pytest.approx(column[best], rel=1e-4, abs=1e-5)
            # ties within float32 noise may pick another index with the same cost
            assert column[m.disparity_int[y, x] - d_lo] == pytest.approx(column[best], rel=1e-4, abs=1e-5)


def test_float_images_use_the_same_formula():
    rng = np.random.default_rng(4)
    left = _textured(rng, 12, 20) / 255.0 + 0.01 * rng.random((12, 20))
    right = np.roll(left, -3, axis=1)
    m = match_band(left, right, d_lo=0, d_hi=6, window=5)
    ref = _reference_costs(left, right, 0, 6, 5, "nssd")
    got = np.take_along_axis(ref, np.maximum(m.disparity_int, 0)[None], 0)[0]
    np.testing.assert_allclose(got[:, 6:], ref.min(axis=0)[:, 6:], rtol=1e-4)
    assert (m.disparity_int[2:-2, 8:-4] == 3).mean() > 0.95


def test_prefilter_xsobel_matches_opencv_sobel_and_is_integer():
    rng = np.random.default_rng(5)
    img = _textured(rng, 10, 16)
    out = prefilter(img, "xsobel", cap=31)
    assert out.dtype == np.int32
    sob = cv2.Sobel(img, cv2.CV_32F, 1, 0, ksize=3, borderType=cv2.BORDER_REPLICATE) / 4.0
    np.testing.assert_array_equal(out, np.clip(np.rint(sob), -31, 31))
    with pytest.raises(ValueError, match="prefilter must be one of"):
        prefilter(img, "laplace")


def test_gain_and_offset_change_leaves_the_normalized_winner_unchanged():
    kind = "zncc"
    rng = np.random.default_rng(6)
    left = _textured(rng, 16, 40)
    right = np.roll(left, -4, axis=1)
    brighter = np.clip(right * 1.3 + 20, 0, 400)
    a = match_band(left, right, d_lo=0, d_hi=8, window=7, cost=kind)
    b = match_band(left, brighter, d_lo=0, d_hi=8, window=7, cost=kind)
    np.testing.assert_array_equal(a.disparity_int[:, 10:-6], b.disparity_int[:, 10:-6])
    assert (b.disparity_int[:, 10:-6] == 4).all()


@pytest.mark.parametrize("share", [0.01, 0.3])
def test_refinement_of_scattered_pixels_equals_the_running_sums(share):
    """refine_pixels (direct window sums) and refine_strips (running sums) re-score the same
    scattered pixels of a piecewise-constant coarse field to the same disparities and costs
    (float32 rounding of the cost formula aside), including windows clamped at the left edge."""
    from mrstereo.matching import cost as C

    rng = np.random.default_rng(3)
    truth = 12
    right = _textured(rng, 60, 90)
    left = np.roll(right, truth, axis=1)
    left[:, :truth] = right[:, :truth]
    pair = [C.prepare_gray(im, kind="xsobel", cap=31, window=9, cost="zncc") for im in (left, right)]
    coarse = np.full((60, 90), truth, np.float32)
    coarse[:, ::7] += rng.integers(-2, 3, coarse[:, ::7].shape)      # runs of other shifts
    want = rng.random((60, 90)) < share
    want[:, :3] = True                                                 # clamped windows
    results = []
    for sparse in (True, False):
        old = C.SPARSE_REFINE_SHARE
        C.SPARSE_REFINE_SHARE = 0 if sparse else 1e9       # 0: always direct sums
        try:
            results.append([a.copy() for a in C.refine_candidates(*pair, coarse, want, half_px=3)])
        finally:
            C.SPARSE_REFINE_SHARE = old
    (d_sparse, c_sparse), (d_dense, c_dense) = results
    assert np.array_equal(np.isnan(d_sparse), np.isnan(d_dense))
    np.testing.assert_allclose(d_sparse[want], d_dense[want], atol=1e-4)
    np.testing.assert_allclose(c_sparse[want], c_dense[want], atol=1e-5)
    inside = want & (np.arange(90) >= truth + 4)
    assert np.isfinite(d_dense[inside]).mean() > 0.8
    assert np.nanmedian(np.abs(d_dense[inside] - truth)) < 0.1     # known shift
    assert np.isnan(d_dense[~want]).all()


@pytest.mark.parametrize("kind", ["zncc", "nssd"])
def test_refinement_in_boxes_equals_the_running_sums_bit_for_bit(kind):
    """refine_candidates(boxes=...) (running sums per box, products gathered pixel by pixel)
    gives the disparities and costs of the dense path (running sums over row strips, products
    gathered along runs of constant shift) exactly, on a coarse field that changes at almost every pixel (with NaNs, negative and too large shifts at the borders) and on
    overlapping boxes that hold the wanted pixels; pixels outside them stay untouched (NaN)."""
    from mrstereo.matching import cost as C

    rng = np.random.default_rng(5)
    truth = 9
    right = _textured(rng, 50, 80)
    left = np.roll(right, truth, axis=1)
    pair = [C.prepare_gray(im, kind="xsobel", cap=31, window=9, cost=kind) for im in (left, right)]
    coarse = (truth + rng.uniform(-2.5, 2.5, (50, 80))).astype(np.float32)
    coarse[rng.random((50, 80)) < 0.1] = np.nan
    coarse[:, :4] = rng.uniform(-3, 12, (50, 4))             # shifts past the left edge
    want = np.zeros((50, 80), bool)
    want[5:30, 0:40] = rng.random((25, 40)) < 0.7
    want[20:48, 30:80] |= rng.random((28, 50)) < 0.5
    boxes = [(5, 30, 0, 40), (20, 48, 30, 80)]              # overlapping
    max_cost = None if kind == "nssd" else 0.8
    old = C.SPARSE_REFINE_SHARE
    C.SPARSE_REFINE_SHARE = 1e9                              # the running sums, not the direct ones
    try:
        dense = [a.copy() for a in C.refine_candidates(*pair, coarse, want, half_px=3, max_cost=max_cost)]
    finally:
        C.SPARSE_REFINE_SHARE = old
    boxed = C.refine_candidates(*pair, coarse, want, half_px=3, max_cost=max_cost, boxes=boxes)
    np.testing.assert_array_equal(boxed[0], dense[0])
    np.testing.assert_array_equal(boxed[1], dense[1])
    assert np.isfinite(boxed[0][want]).mean() > 0.3 and np.isnan(boxed[0][~want]).all()
    # one box for three strips: split into row strips, same result
    strips = C.refine_candidates(*pair, coarse, want, half_px=3, max_cost=max_cost, boxes=[(0, 50, 0, 80)],
                                 n_strips=3)
    np.testing.assert_array_equal(strips[0], dense[0])
    np.testing.assert_array_equal(strips[1], dense[1])


def test_checks_in_the_search_equal_the_checks_of_the_raw_winners():
    """match_checked (the checks fused into the search) = the raw winners of the same search
    through the left-right, uniqueness and maximum-cost checks, evaluated here in numpy."""
    from mrstereo.matching import cost as C

    rng = np.random.default_rng(9)
    right = _textured(rng, 30, 70)
    left = np.roll(right, 6, axis=1)
    pl, pr = (C.prepare_gray(im, kind="xsobel", cap=7, window=7, cost="zncc") for im in (left, right))
    d_int, sub, best, second, d_right = C.match_prepared(pl, pr, d_lo=0, d_hi=15, rows=(0, 30), cols=(0, 70),
                                                         right_check=True)
    checked = C.match_checked(pl, pr, d_lo=0, d_hi=15, rows=(0, 30), cols=(0, 70), lr_max_diff_px=1.0,
                              uniqueness_ratio=0.1, max_cost=0.6, subpixel=True)
    xs = np.arange(70)[None, :].repeat(30, 0)
    back = np.take_along_axis(d_right, np.clip(xs - d_int, 0, 69), 1)
    ok = (d_int >= 0) & (back >= 0) & (np.abs(d_int - back) <= 1) & (best <= 0.9 * second) & (best <= 0.6)
    np.testing.assert_array_equal(np.isfinite(checked.disparity_px), ok)
    np.testing.assert_allclose(checked.disparity_px[ok], (d_int + sub)[ok], atol=1e-6)
    assert np.nanmedian(np.abs(checked.disparity_px[:, 10:64] - 6)) < 0.2
