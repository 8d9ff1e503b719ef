"""Matcher on real data (Middlebury 2001 Tsukuba, 2003 Teddy) against OpenCV StereoBM in the same run."""
from __future__ import annotations

import cv2
import numpy as np

from mrstereo.matching import MatchingConfig, PostFilterConfig, SearchConfig, compute_disparity

def _bad2(d, truth):
    """bad-2 % dense (missing counts as bad), among estimated pixels, and density %."""
    known = np.isfinite(truth)
    bad = ~(np.abs(d - truth) <= 2.0)
    est = known & np.isfinite(d)
    return 100.0 * np.mean(bad[known]), 100.0 * np.mean(bad[est]), 100.0 * est.sum() / known.sum()


def _stereo_bm(left, right, max_d):
    """StereoBM as users run it (ROS stereo_image_proc-like settings, 9x9 below 640 px)."""
    bm = cv2.StereoBM.create(numDisparities=max_d, blockSize=9)
    bm.setTextureThreshold(10)
    bm.setUniquenessRatio(15)
    bm.setSpeckleWindowSize(100)
    bm.setSpeckleRange(4)
    bm.setDisp12MaxDiff(1)
    raw = bm.compute(left, right).astype(np.float32) / 16.0
    return np.where(raw >= 0, raw, np.nan)


def test_teddy_robust_is_denser_and_as_accurate_as_stereobm(middlebury_scene):
    left, right, truth, max_d = middlebury_scene("teddy")
    dense, est, density = _bad2(compute_disparity(left, right, max_disparity_px=max_d).disparity_px, truth)
    bm_dense, bm_est, _ = _bad2(_stereo_bm(left, right, max_d), truth)
    assert dense < bm_dense          # missing counts as bad: more right answers than StereoBM
    assert est < bm_est + 1.5        # and about as few wrong ones among those given
    assert density > 70.0


def test_tsukuba_robust_accurate_where_it_answers_and_paper_answers_everywhere(middlebury_scene):
    left, right, truth, max_d = middlebury_scene("tsukuba")
    dense, est, density = _bad2(compute_disparity(left, right, max_disparity_px=max_d).disparity_px, truth)
    assert density > 70.0
    assert est < 4.0                 # wrong in-band winners or lost coarse-level precision exceed this
    _, p_est, p_density = _bad2(compute_disparity(left, right, max_disparity_px=max_d,
                                                  preset="paper").disparity_px, truth)
    assert p_density > 95.0 and p_est < 20.0


def test_tsukuba_refinement_recovers_the_coarse_level_precision(middlebury_scene):
    left, right, truth, max_d = middlebury_scene("tsukuba")
    cfg = MatchingConfig(search=SearchConfig(decimations=(4, 2, 1)))      # D = 16 alone would plan no k = 4 level
    _, est_refined, _ = _bad2(compute_disparity(left, right, max_disparity_px=max_d, config=cfg).disparity_px, truth)
    _, est_coarse, _ = _bad2(compute_disparity(left, right, max_disparity_px=max_d,
                                               config=cfg.replace(subpixel={"refine": False})).disparity_px, truth)
    assert est_refined < 0.8 * est_coarse


def test_tsukuba_gap_filling_answers_more_than_stereobm_and_stays_accurate(middlebury_scene):
    left, right, truth, max_d = middlebury_scene("tsukuba")
    dense, est, density = _bad2(compute_disparity(left, right, max_disparity_px=max_d).disparity_px, truth)
    holes = MatchingConfig(postfilter=PostFilterConfig(gap_fill_px=0))
    dense0, est0, density0 = _bad2(compute_disparity(left, right, max_disparity_px=max_d,
                                                     config=holes).disparity_px, truth)
    bm_dense, bm_est, _ = _bad2(_stereo_bm(left, right, max_d), truth)
    assert dense0 > bm_dense > dense    # 15.3 without gap filling, StereoBM 13.5, 12.3 with it
    assert density > density0 + 2.5    # 86.1 % -> 89.5 %
    assert est < min(bm_est, 2.5)        # 1.6 % -> 2.0 % wrong among estimated (StereoBM 2.1 %)
