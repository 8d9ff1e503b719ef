"""OpenCV baselines: accuracy on Tsukuba, scaling of OpenCV's int16 output, known synthetic shift."""

import cv2
import numpy as np
import pytest

from mrstereo.evaluation.baselines import BMSettings, disparity_from_opencv, num_disparities, stereo_bm, stereo_sgbm
from mrstereo.evaluation.datasets import load_scene
from mrstereo.evaluation.metrics import disparity_metrics
from mrstereo.recordings.samples import local_path

needs_data = pytest.mark.sample_data("tsukuba")


@pytest.fixture(scope="module")
def tsukuba():
    return load_scene(local_path("tsukuba"))


@needs_data
@pytest.mark.parametrize("matcher", [stereo_bm, stereo_sgbm])
def test_baselines_beat_constant_predictor_on_tsukuba(tsukuba, matcher):
    gt, mask = tsukuba.gt_disparity_px, tsukuba.nonocc_mask
    constant = np.full(gt.shape, np.nanmedian(gt[mask]), np.float32)  # the best constant guess
    baseline = disparity_metrics(constant, gt, nonocc_mask=mask)
    d = matcher(tsukuba.left, tsukuba.right, max_disparity_px=tsukuba.max_disparity_px)
    m = disparity_metrics(d, gt, nonocc_mask=mask)
    assert d.dtype == np.float32 and d.shape == gt.shape
    assert baseline.dense.bad_2_pct > 30.0
    assert m.dense.bad_2_pct < 0.5 * baseline.dense.bad_2_pct  # BM 13.5 %, SGBM 4.0 % vs 33.5 %
    assert m.estimated.bad_2_pct < 0.15 * baseline.dense.bad_2_pct  # about 2.1 % / 2.5 %
    assert m.density_pct > 80.0


@needs_data
def test_bm_output_is_opencv_int16_over_16(tsukuba):
    gl = cv2.cvtColor(tsukuba.left, cv2.COLOR_BGR2GRAY)
    gr = cv2.cvtColor(tsukuba.right, cv2.COLOR_BGR2GRAY)
    bm = cv2.StereoBM_create(numDisparities=16, blockSize=9)
    bm.setPreFilterCap(31)
    bm.setTextureThreshold(10)
    bm.setUniquenessRatio(15)
    bm.setSpeckleWindowSize(100)
    bm.setSpeckleRange(4)
    bm.setDisp12MaxDiff(1)
    raw = bm.compute(gl, gr)
    ours = stereo_bm(tsukuba.left, tsukuba.right, max_disparity_px=14)
    valid = raw >= 0
    assert raw.min() == -16 and valid.mean() > 0.5
    np.testing.assert_array_equal(np.isnan(ours), ~valid)
    np.testing.assert_array_equal(ours[valid], raw[valid] / 16.0)
    row, col = np.argwhere(valid & (raw % 16 != 0))[17]  # a sub-pixel value, off-centre
    assert ours[row, col] == raw[row, col] / 16.0 and ours[row, col] != np.round(ours[row, col])


def test_constant_shift_recovered():
    rng = np.random.default_rng(3)
    texture = cv2.GaussianBlur(rng.integers(0, 256, (90, 170)).astype(np.uint8), (3, 3), 0)
    left, right = texture[:, :150], texture[:, 11:161]  # left(x) = right(x - 11)
    for matcher in (stereo_bm, stereo_sgbm):
        d = matcher(left, right, max_disparity_px=20)
        inner = d[10:-10, 40:-10]
        assert np.isfinite(inner).mean() > 0.95
        assert np.nanmedian(inner) == pytest.approx(11.0, abs=0.1)


def test_disparity_from_opencv_and_num_disparities():
    raw = np.array([[-16, 0, 37, 160]], np.int16)
    np.testing.assert_array_equal(disparity_from_opencv(raw), [[np.nan, 0.0, 2.3125, 10.0]])
    np.testing.assert_array_equal(disparity_from_opencv(np.array([[16, 31, 32]], np.int16), min_disparity=2),
                                  [[np.nan, np.nan, 2.0]])
    assert [num_disparities(v) for v in (1, 14, 16, 16.5, 33)] == [16, 16, 16, 32, 48]
    with pytest.raises(TypeError, match="OpenCV's int16"):
        disparity_from_opencv(raw.astype(np.float32))
    with pytest.raises(ValueError, match="max_disparity_px must be > 0"):
        num_disparities(0)


def test_bad_input():
    img = np.zeros((20, 30), np.uint8)
    with pytest.raises(ValueError, match="same size"):
        stereo_bm(img, img[:, :20], max_disparity_px=16)
    with pytest.raises(TypeError, match="left must be a numpy array"):
        stereo_sgbm([[0]], img, max_disparity_px=16)
    with pytest.raises(ValueError, match="must be finite"):
        stereo_sgbm(img, img, max_disparity_px=float("nan"))
    assert stereo_bm(img, img, max_disparity_px=16, settings=BMSettings(window_px=5)).shape == (20, 30)
