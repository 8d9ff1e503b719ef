"""Speckle removal: exactly OpenCV's cv2.filterSpeckles on the same 1/16-pixel code."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from mrstereo.matching.postfilter import remove_speckles


def opencv_speckles(d, max_size, max_diff):
    """cv2.filterSpeckles on the code clip(rint(16 d), 0, 2047 * 16), -16 invalid."""
    code = np.where(np.isfinite(d), np.clip(np.rint(np.nan_to_num(d) * 16), 0, 2047 * 16), -16).astype(np.int16)
    cv2.filterSpeckles(code, -16, max_size, int(round(max_diff * 16)))
    return np.where(code == -16, np.float32(np.nan), d).astype(np.float32)


@pytest.mark.parametrize("seed", range(6))
def test_speckles_equal_opencv_on_random_maps(seed):
    rng = np.random.default_rng(seed)
    for _ in range(40):
        h, w = rng.integers(1, 48, 2)
        d = (rng.integers(0, 6, (h, w)) * rng.choice([0.3, 1.0, 2.5])).astype(np.float32)
        d += rng.normal(0, rng.choice([0.0, 0.2]), (h, w)).astype(np.float32)
        d[rng.random((h, w)) < rng.uniform(0, 0.6)] = np.nan
        size, diff = int(rng.integers(1, 40)), float(rng.choice([0.5, 1.0, 2.0]))
        got = remove_speckles(d, max_size_px=size, max_diff_px=diff)
        np.testing.assert_array_equal(got, opencv_speckles(d, size, diff))


def test_speckles_known_answer():
    d = np.full((20, 30), 5.0, np.float32)
    d[2:4, 2:4] = 20.0                   # a 4-pixel island: dropped
    d[10:20, 10:20] = 9.0                # 100 pixels: kept
    d[0, 29] = np.nan
    got = remove_speckles(d, max_size_px=10, max_diff_px=1.0)
    assert np.isnan(got[2:4, 2:4]).all()
    assert np.isnan(got).sum() == 5
    np.testing.assert_array_equal(got[10:20, 10:20], 9.0)
    # a ramp of 0.9 px steps is one region (connected through its neighbours)
    ramp = np.tile(np.arange(30, dtype=np.float32) * 0.9, (3, 1))
    np.testing.assert_array_equal(remove_speckles(ramp, max_size_px=50, max_diff_px=1.0), ramp)
    assert np.isnan(remove_speckles(ramp, max_size_px=90, max_diff_px=1.0)).all()
    assert remove_speckles(d, max_size_px=0, max_diff_px=1.0) is d
    with pytest.raises(ValueError, match="disparity_px"):
        remove_speckles(d[0], max_size_px=10, max_diff_px=1.0)



def test_speckles_equal_opencv_on_a_matcher_output():
    from mrstereo.matching import compute_disparity, preset_config
    from mrstereo.world import default_scene, default_stereo, render_stereo_frame

    stereo = default_stereo()
    frame = render_stereo_frame(default_scene(0), stereo, pose=(0.5, 0.0, 0.0), supersample=1)
    raw = compute_disparity(frame.left_rect, frame.right_rect, calibration=stereo,
                            config=preset_config("robust").replace(postfilter={"speckle_size_px": 0, "gap_fill_px": 0})).disparity_px
    for size, diff in ((300, 1.0), (50, 2.0)):
        want = opencv_speckles(raw, size, diff)
        assert 0 < np.isnan(want).sum() - np.isnan(raw).sum()       # it removes something
        np.testing.assert_array_equal(remove_speckles(raw, max_size_px=size, max_diff_px=diff), want)
