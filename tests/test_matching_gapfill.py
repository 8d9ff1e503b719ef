"""Gap filling (beyond the paper): known answers and a plain-Python reference of the rule."""
from __future__ import annotations

import numpy as np
import pytest

from mrstereo.matching import MatchingConfig, PostFilterConfig, preset_config
from mrstereo.matching.postfilter import fill_gaps


def reference_line(d, c, max_gap, max_diff, support):
    """The rule of fill_gaps on one line, written plainly."""
    out_d, out_c, n = d.copy(), c.copy(), len(d)
    valid = np.isfinite(d)
    x = 0
    while x < n:
        if valid[x]:
            x += 1
            continue
        x0 = x
        while x < n and not valid[x]:
            x += 1
        if x - x0 > max_gap or x0 < support or x + support > n:
            continue
        a, b = d[x0 - 1], d[x]
        left, right = d[x0 - support:x0], d[x:x + support]
        if abs(a - b) <= max_diff and np.all(np.abs(left - a) <= max_diff) and np.all(np.abs(right - b) <= max_diff):
            gap = x - x0
            out_d[x0:x] = a + (b - a) * np.arange(1, gap + 1) / (gap + 1)
            out_c[x0:x] = min(c[x0 - 1], c[x])
    return out_d, out_c


def reference(d, c, **kw):
    rows = [reference_line(d[y], c[y], **kw) for y in range(d.shape[0])]
    td, tc = np.array([r[0] for r in rows]), np.array([r[1] for r in rows])
    cols = [reference_line(td[:, x], tc[:, x], **kw) for x in range(d.shape[1])]
    return np.array([r[0] for r in cols]).T, np.array([r[1] for r in cols]).T


def test_gap_on_a_slanted_plane_is_filled_exactly():
    d = np.tile(np.float32(20.0) + 0.1 * np.arange(40, dtype=np.float32), (30, 1))
    c = np.full_like(d, 0.5)
    c[10, 14], c[10, 21] = 0.3, 0.4
    holed = d.copy()
    holed[10, 15:21] = np.nan                       # 6 px within a row: filled along the row
    holed[3:8, 30] = np.nan                         # 5 px within a column: filled along the column
    out_d, out_c = fill_gaps(holed, c, max_gap_px=8, max_diff_px=1.0, support_px=5)
    np.testing.assert_allclose(out_d, d, atol=1e-5)
    assert np.all(out_c[10, 15:21] == np.float32(0.3))          # the lower confidence of the two ends
    assert np.isnan(holed[10, 15:21]).all()                    # the input is untouched


def test_gaps_that_must_stay_holes():
    d = np.full((1, 60), 10.0, np.float32)
    d[0, 30:] = 14.0                                      # a depth edge at x = 30
    d[0, 27:33] = np.nan                                   # gap across the edge: ends differ by 4 px
    d[0, 5:18] = np.nan                                    # 13 px: longer than max_gap 12
    d[0, 0:2] = np.nan                                     # touches the image border
    d[0, 52:54] = np.nan                                   # ... and a short gap with only 3 px of support
    d[0, 48] = np.nan
    c = np.ones_like(d)
    out_d, _ = fill_gaps(d, c, max_gap_px=12, max_diff_px=1.0, support_px=5)
    np.testing.assert_array_equal(np.isnan(out_d), np.isnan(d))
    # a lone survivor does not back a fill: one valid pixel between two gaps
    e = np.full((1, 30), 5.0, np.float32)
    e[0, 10:13] = np.nan
    e[0, 14:16] = np.nan
    out_e, _ = fill_gaps(e, np.ones_like(e), max_gap_px=12, max_diff_px=1.0, support_px=5)
    np.testing.assert_array_equal(np.isnan(out_e), np.isnan(e))


def test_kernel_equals_the_plain_rule_on_random_maps():
    rng = np.random.default_rng(3)
    filled = 0
    for _ in range(5):
        base = np.cumsum(rng.choice([0.0, 0.0, 0.0, 0.3, -0.3, 3.0, -3.0], size=(40, 70)), axis=1)
        d = (20 + base).astype(np.float32)
        for y, x in zip(*np.nonzero(rng.random(d.shape) < 0.03)):   # holes as runs along rows and columns
            length = rng.integers(1, 16)
            if rng.random() < 0.5:
                d[y, x:x + length] = np.nan
            else:
                d[y:y + length, x] = np.nan
        c = rng.random(d.shape).astype(np.float32)
        kw = dict(max_gap=int(rng.integers(1, 15)), max_diff=float(rng.choice([0.5, 1.0])),
                  support=int(rng.integers(1, 6)))
        out_d, out_c = fill_gaps(d, c, max_gap_px=kw["max_gap"], max_diff_px=kw["max_diff"],
                                 support_px=kw["support"])
        ref_d, ref_c = reference(d, c, **kw)
        np.testing.assert_allclose(out_d, ref_d, rtol=0, atol=1e-5, equal_nan=True)
        np.testing.assert_array_equal(out_c, ref_c.astype(np.float32))
        filled += np.isfinite(out_d).sum() - np.isfinite(d).sum()
    assert filled > 50


def test_presets_and_validation():
    assert preset_config("robust").postfilter.gap_fill_px == 12 and preset_config("robust").gap_support == 5
    assert preset_config("paper").postfilter.gap_fill_px == 0 and preset_config("mapping").postfilter.gap_fill_px == 0
    d = np.full((4, 4), np.nan, np.float32)
    assert fill_gaps(d, d, max_gap_px=0, max_diff_px=1.0, support_px=5)[0] is d
    with pytest.raises(ValueError, match="gap_fill_px"):
        PostFilterConfig(gap_fill_px=-1)
    with pytest.raises(ValueError, match="gap_fill_support_px"):
        PostFilterConfig(gap_fill_support_px=0)
    with pytest.raises(TypeError, match="postfilter must be a PostFilterConfig"):
        MatchingConfig(postfilter={"gap_fill_px": 0})
    with pytest.raises(TypeError, match="unexpected keyword"):
        preset_config("robust").replace(postfilter={"gap_fill_diff_px": 2.0})
    with pytest.raises(ValueError, match="confidence"):
        fill_gaps(d, np.zeros((3, 4), np.float32), max_gap_px=4, max_diff_px=1.0, support_px=5)
