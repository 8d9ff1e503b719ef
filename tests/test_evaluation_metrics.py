"""Disparity metrics: known answers on hand-made arrays."""
import math

import numpy as np
import pytest

from mrstereo.evaluation.metrics import disparity_metrics

# 100 pixels, GT = 10 px; per-pixel error of the estimate (NaN = no estimate):
# 10 x +0.3, 20 x +0.75, 30 x +1.5, 10 x -3, 10 x +5, 20 x NaN
OFFSETS = np.repeat([0.3, 0.75, 1.5, -3.0, 5.0, np.nan], [10, 20, 30, 10, 10, 20]).astype(np.float64)


def _case():
    gt = np.full((10, 10), 10.0, np.float32)
    est = (gt.ravel() + OFFSETS).astype(np.float32).reshape(10, 10)
    return est, gt


def test_known_bad_percentages_dense_and_estimated():
    est, gt = _case()
    m = disparity_metrics(est, gt)
    assert m.region == "all" and m.evaluated_pixels == 100 and m.estimated_pixels == 80
    assert m.density_pct == pytest.approx(80.0)
    assert (m.dense.bad_0_5_pct, m.dense.bad_1_pct, m.dense.bad_2_pct, m.dense.bad_4_pct) == \
        pytest.approx((90.0, 70.0, 40.0, 30.0))
    assert (m.estimated.bad_0_5_pct, m.estimated.bad_1_pct, m.estimated.bad_2_pct, m.estimated.bad_4_pct) == \
        pytest.approx((87.5, 62.5, 25.0, 12.5))
    assert m.estimated.avg_abs_error_px == pytest.approx(143.0 / 80, rel=1e-5)
    assert m.estimated.rms_error_px == pytest.approx(math.sqrt(419.65 / 80), rel=1e-5)
    # dense: a missing estimate reads as d = 0, i.e. an error equal to its GT (10 px)
    assert m.dense.avg_abs_error_px == pytest.approx((143.0 + 20 * 10.0) / 100, rel=1e-5)
    assert m.dense.rms_error_px == pytest.approx(math.sqrt((419.65 + 20 * 100.0) / 100), rel=1e-5)
    assert m.estimated.bad_pct(2.0) == m.estimated.bad_2_pct
    with pytest.raises(ValueError, match="threshold_px must be one of"):
        m.dense.bad_pct(3.0)


def test_error_equal_to_threshold_is_not_bad():
    gt = np.full((2, 3), 10.0, np.float32)
    m = disparity_metrics(gt + 2.0, gt)
    assert m.dense.bad_2_pct == 0.0 and m.dense.bad_1_pct == 100.0


def test_mask_and_unknown_ground_truth_restrict_the_region():
    est, gt = _case()
    gt = gt.copy()
    gt.ravel()[60:70] = np.nan  # the -3 px pixels lose their GT
    mask = np.ones(gt.shape, bool)
    mask.ravel()[80:] = False  # the NaN estimates are outside the mask
    m = disparity_metrics(est, gt, nonocc_mask=mask)
    assert m.region == "nonocc" and m.evaluated_pixels == 70 and m.estimated_pixels == 70
    assert m.density_pct == 100.0
    assert m.dense.bad_2_pct == pytest.approx(100.0 * 10 / 70)
    assert m.dense == m.estimated


def test_no_estimate_at_all():
    gt = np.full((4, 5), 3.0, np.float32)
    m = disparity_metrics(np.full(gt.shape, np.nan, np.float32), gt)
    assert m.density_pct == 0.0 and m.dense.bad_0_5_pct == 100.0 and m.dense.avg_abs_error_px == 3.0
    assert m.estimated.pixel_count == 0 and math.isnan(m.estimated.bad_2_pct)


def test_bad_input():
    gt = np.ones((4, 5), np.float32)
    with pytest.raises(ValueError, match="same shape"):
        disparity_metrics(np.ones((5, 4)), gt)
    with pytest.raises(ValueError, match=r"disparity_px must have shape \(H, W\)"):
        disparity_metrics(np.ones((4, 5, 3)), gt)
    with pytest.raises(ValueError, match="no ground-truth pixel"):
        disparity_metrics(gt, np.full((4, 5), np.nan))
    with pytest.raises(ValueError, match="no ground-truth pixel"):
        disparity_metrics(gt, gt, nonocc_mask=np.zeros((4, 5), bool))
    with pytest.raises(TypeError, match="nonocc_mask must be a bool array"):
        disparity_metrics(gt, gt, nonocc_mask=np.ones((4, 5), np.uint8))
    with pytest.raises(ValueError, match="nonocc_mask must have shape"):
        disparity_metrics(gt, gt, nonocc_mask=np.ones((5, 4), bool))
