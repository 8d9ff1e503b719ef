"""The near guard's kernels (matching/_guard_kernels.py) equal the numpy expressions they
replace, bit for bit: random winners with ties at the thresholds, both float widths."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from mrstereo.matching import _guard_kernels, preset_config
from mrstereo.matching._band_kernels import BIG
from mrstereo.matching.near_guard import (_finite_in_clusters, _guard_candidates, _in_large_clusters, _large_clusters,
                                         _level_spans)
from mrstereo.matching.multirange import RangeLevel


# the numpy expressions of the checks (left-right, uniqueness) the kernel replaces
def left_right_consistent(disparity_int: np.ndarray, right_disparity_int: np.ndarray, *,
                          max_diff_px: float) -> np.ndarray:
    """Mask of pixels whose right-image winner points back: ``|d_L(x) - d_R(x - d_L(x))| <= tol``.

    Both inputs are integer winner maps (-1 = none) of the same band search.
    """
    h, w = disparity_int.shape
    valid = disparity_int >= 0
    xr = np.arange(w)[None, :] - np.where(valid, disparity_int, 0)
    inside = valid & (xr >= 0)
    rows = np.broadcast_to(np.arange(h)[:, None], (h, w))
    back = right_disparity_int[rows, np.clip(xr, 0, w - 1)]
    return inside & (back >= 0) & (np.abs(disparity_int - back) <= max_diff_px)


def unique(best_cost: np.ndarray, second_cost: np.ndarray, *, ratio: float) -> np.ndarray:
    """Mask of winners whose second-best cost is clearly worse: ``c1 <= (1 - ratio) c2``."""
    with np.errstate(invalid="ignore"):
        return ~(best_cost > (1.0 - ratio) * second_cost)


def _winners(seed: int, shape=(60, 90)):
    rng = np.random.default_rng(seed)
    d_int = rng.integers(-1, 30, shape).astype(np.int32)
    sub = rng.uniform(-0.5, 0.5, shape).astype(np.float32)
    sub[rng.random(shape) < 0.2] = 0.5                     # d + 0.5: ties with the threshold
    c1 = rng.uniform(0, 1.2, shape).astype(np.float32)
    c2 = (c1 / rng.choice([0.85, 0.9, 1.0, 1.3], shape)).astype(np.float32)
    c2[rng.random(shape) < 0.1] = BIG
    d_right = np.where(rng.random(shape) < 0.7, d_int + rng.integers(-2, 3, shape), -1).astype(np.int32)
    return d_int, sub, c1, c2, d_right


def _numpy_candidates(d_int, sub, c1, c2, d_right, guard, config):
    """Step 1 of the near guard as numpy expressions (its code before the kernel)."""
    checks = config.acceptance
    d_level = (d_int + sub if config.subpixel.parabola else d_int).astype(np.float32)
    beyond = (d_int >= 0) & (d_level * guard.scale > guard.too_near_above_px)
    candidate = beyond if checks.max_cost is None else beyond & (c1 <= checks.max_cost)
    if checks.lr_max_diff_px is not None:
        candidate &= left_right_consistent(d_int, d_right, max_diff_px=checks.lr_max_diff_px)
    if checks.uniqueness_ratio > 0:
        candidate &= unique(c1, c2, ratio=checks.uniqueness_ratio)
    return d_level, beyond, candidate


def _guard(scale, above):
    return RangeLevel(decimation=4, scale=scale, size=(90, 60), band_px=(40.0, 80.0), search_px=(9, 21),
                      depth_band_m=None, work=0, too_near_above_px=above)


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("settings", [
    dict(), dict(subpixel={"parabola": False}),
    dict(acceptance={"max_cost": None, "lr_max_diff_px": None, "uniqueness_ratio": 0.0}),
    dict(acceptance={"max_cost": 0.7, "lr_max_diff_px": 1.0, "uniqueness_ratio": 0.15}),
    dict(acceptance={"max_cost": np.float64(0.3), "uniqueness_ratio": np.float64(0.1)}),   # float64: float64 numpy
])
@pytest.mark.parametrize("scale, above", [(4.0, 41.9), (3.3, 40.1), (np.float64(4.0), 42.0),
                                          (4.0, np.float64(41.9))])
def test_guard_candidates_equal_numpy(seed, settings, scale, above):
    config = preset_config("robust").replace(**settings)
    guard = _guard(scale, above)
    winners = _winners(seed)
    got = _guard_candidates(*winners, guard, config)
    want = _numpy_candidates(*winners, guard, config)
    assert want[2].any() and not want[2].all()
    for g, w in zip(got, want):
        assert g.dtype == w.dtype and np.array_equal(g, w)


@pytest.mark.parametrize("width, w_level, col0, col1", [(640, 80, 0, 640), (641, 160, 13, 600), (90, 45, 0, 90)])
def test_guard_upsample_and_cluster_pixels_equal_numpy(width, w_level, col0, col1):
    rng = np.random.default_rng(width)
    height = 40
    scale = width / w_level
    beyond = rng.random((height, w_level)) < 0.5
    d_level = rng.uniform(5, 30, (height, w_level)).astype(np.float32)
    labels_level = np.where(rng.random((height, w_level)) < 0.3, rng.integers(1, 5, (height, w_level)), 0)
    labels_level = labels_level.astype(np.uint16)
    source = np.minimum(((np.arange(col0, col1) + 0.5) / scale).astype(np.intp), w_level - 1)
    first_col, end_col = _level_spans(source, col0, w_level)
    field = np.empty((height, width), np.float32)
    want = np.empty((height, width), bool)
    _guard_kernels.guard_upsample(beyond, d_level, labels_level, first_col, end_col, scale, field, want)
    field_np = np.full((height, width), np.nan, np.float32)
    field_np[:, col0:col1] = np.where(beyond, d_level * np.float32(scale), np.float32(np.nan))[:, source]
    labels = np.zeros((height, width), labels_level.dtype)
    labels[:, col0:col1] = labels_level[:, source]
    assert np.array_equal(field, field_np, equal_nan=True)
    assert np.array_equal(want, labels > 0)
    # the finite values among the clusters' pixels (re-scoring writes only there), in row-major order
    values = np.where(want & (rng.random((height, width)) < 0.6), 1.0, np.nan).astype(np.float32)
    ys, xs, cluster = _finite_in_clusters(values, labels_level, first_col, end_col)
    ys_np, xs_np = np.nonzero(np.isfinite(values))
    assert ys_np.size and np.array_equal(ys, ys_np) and np.array_equal(xs, xs_np)
    assert np.array_equal(cluster, labels[ys_np, xs_np])


@pytest.mark.parametrize("size_px", [1, 4, 30])
def test_cluster_masks_equal_numpy(size_px):
    rng = np.random.default_rng(size_px)
    mask = cv2.GaussianBlur(rng.random((120, 90)).astype(np.float32), (0, 0), 1.5) > 0.5
    _, labels, stats, _ = cv2.connectedComponentsWithStats(mask.view(np.uint8), connectivity=8)
    large = stats[:, cv2.CC_STAT_AREA] > size_px
    large[0] = False
    assert large.any() and not large[1:].all()
    assert np.array_equal(_in_large_clusters(mask, size_px), large[labels])
    number = np.zeros(len(large), np.int64)
    number[large] = np.arange(1, np.count_nonzero(large) + 1)
    numbered, boxes = _large_clusters(mask, size_px)
    assert np.array_equal(numbered, number[labels]) and len(boxes) == np.count_nonzero(large)
