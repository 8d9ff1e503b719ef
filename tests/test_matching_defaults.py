"""Default plan by search range and the robust defaults (docs/matching.md, "Defaults")."""
from __future__ import annotations

import pytest

from mrstereo.matching import MatchingConfig, SearchConfig, make_plan, preset_config
from mrstereo.matching.multirange import default_level_count


@pytest.mark.parametrize("d_max, n", [(8, 1), (15.9, 1), (16, 2), (31, 2), (32, 3), (64, 3), (256, 3)])
def test_level_count_keeps_the_nearest_band_at_least_four_level_pixels_wide(d_max, n):
    assert default_level_count(d_max) == n
    # the nearest band [D/2, D] at decimation 2^(n-1) spans D / 2^n level pixels
    assert d_max / 2 ** n >= 4 or n == 1
    if n < 3:
        assert d_max / 2 ** (n + 1) < 4


def test_level_count_options():
    assert default_level_count(16, min_band_level_px=0) == 3
    assert default_level_count(1000, max_levels=2) == 2
    assert default_level_count(64, min_band_level_px=16) == 2       # [32, 64] at k = 2: 16 level px
    assert default_level_count(64, min_band_level_px=17) == 1
    with pytest.raises(ValueError, match="max_disparity_px"):
        default_level_count(0)
    with pytest.raises(ValueError, match="min_band_level_px"):
        default_level_count(16, min_band_level_px=-1)


def test_plan_from_max_disparity_follows_the_rule():
    def levels(d_max, **kw):
        plan = make_plan((384, 288), max_disparity_px=d_max, **kw)
        return [(lvl.decimation, lvl.band_px) for lvl in plan.levels]

    assert levels(16) == [(1, (0.0, 8.0)), (2, (8.0, 16.0))]
    assert levels(10) == [(1, (0.0, 10.0))]
    assert levels(64) == [(1, (0.0, 16.0)), (2, (16.0, 32.0)), (4, (32.0, 64.0))]
    # explicit decimations set the number of bands; the paper preset keeps its three ranges
    assert [d for d, _ in levels(16, config=MatchingConfig(search=SearchConfig(decimations=(4, 2, 1))))] == [1, 2, 4]
    assert [d for d, _ in levels(16, preset="paper")] == [1, 2, 4]
    assert [d for d, _ in levels(16, config=MatchingConfig(search=SearchConfig(min_band_level_px=0)))] == [1, 2, 4]
    # explicit bands are never merged
    assert len(make_plan((384, 288), disparity_bands_px=[(0, 4), (4, 8), (8, 16)]).levels) == 3


def test_speed_case_plan_is_unchanged():
    from mrstereo.camera import Camera, StereoCamera
    rig = StereoCamera.ideal(Camera(fx=451.0, fy=451.0, cx=320.0, cy=240.0, width=640, height=480), 0.075)
    plan = make_plan((640, 480), calibration=rig)
    assert [lvl.decimation for lvl in plan.levels] == [1, 2, 4]
    # pixel x disparity evaluations (docs/matching.md, Speed): the near guard searches 68-136 px
    # apart from the bands, at decimation 8 (level disparities 7-17 on 80 columns)
    assert plan.work == 8_409_600
    unguarded = make_plan((640, 480), calibration=rig, config=MatchingConfig(near_guard=None))
    assert unguarded.work == 7_987_200
    assert plan.levels == unguarded.levels and plan.levels[2].search_px == (6, 17)
    assert plan.guard.decimation == 8 and plan.guard.search_px == (7, 17)


def test_paper_preset_is_exactly_the_paper():
    paper = preset_config("paper")
    checks, post = paper.acceptance, paper.postfilter
    assert (paper.cost.kind, paper.cost.prefilter, checks.lr_max_diff_px, checks.uniqueness_ratio, checks.max_cost,
            paper.subpixel.parabola, post.speckle_size_px, paper.subpixel.refine, post.edge_guard_px,
            paper.search.min_band_level_px, paper.near_guard, paper.ambiguity, post.gap_fill_px
            ) == ("nssd", "none", None, 0.0, None, False, 0, False, 0, 0.0, None, None, 0)


def test_bad_min_band_level():
    with pytest.raises(ValueError, match="min_band_level_px"):
        SearchConfig(min_band_level_px=float("nan"))
