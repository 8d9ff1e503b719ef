"""The near guard (beyond the paper): pixels whose match lies beyond the largest searched disparity.

A multi-range search ends at a near limit ``D``; a pixel nearer than that has no match in any
band, yet a band may still find a (wrong, smaller) disparity for it. The guard searches past ``D``
on its own decimated images (``plan.guard``), confirms candidates at full resolution
(:func:`.cost.refine_candidates`), and reports the pixels that are too near; the candidates
clustered with a too-near region lose their values (:func:`.postfilter.near_side`). Without a
too-near region the values are those of the matcher without a guard. :func:`too_near` is the
entry point, called by :func:`mrstereo.matching.compute_disparity`. The steps and why they are
ordered so: docs/matching.md ("Too near"). Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from . import _guard_kernels
from .config import MatchingConfig
from .cost import match_prepared, refine_candidates
from .multirange import MultiRangePlan, RangeLevel, _level_cols
from .postfilter import near_side, remove_speckles

__all__ = ["too_near", "drop_cut_off"]


@dataclass(frozen=True)
class _GuardSearch:
    """Step 1: the guard's search and its candidates, and what the later steps compare them with.

    (H, w_level) maps at the guard's level: the winners' ``cost`` and ``d_level``, those past the
    near limit (``beyond``) and passing the checks (``candidate``), the bands' values
    (``value_level``); ``source``: the level column of each AOI column.
    """

    level: RangeLevel
    rows: tuple[int, int]
    cols: tuple[int, int]
    level_pair: tuple
    pair_at: Callable
    disparity: np.ndarray
    cost: np.ndarray
    d_level: np.ndarray
    beyond: np.ndarray
    candidate: np.ndarray
    value_level: np.ndarray
    source: np.ndarray


@dataclass(frozen=True)
class _Clusters:
    """Steps 2-3 on the candidates' large clusters: ``labels_level`` (their clusters at the
    guard's level, numbered from 1), ``boxes`` (their full-resolution boxes, or None), the
    columns each level column spans, ``field`` (the winners beyond the near limit up-sampled:
    the shifts of the re-scoring's windows), and the confirmed disparity and cost (full
    resolution)."""

    large: np.ndarray
    labels_level: np.ndarray
    boxes: np.ndarray | None
    first_col: np.ndarray
    end_col: np.ndarray
    field: np.ndarray
    confirmed_px: np.ndarray
    confirmed_cost: np.ndarray


def too_near(plan: MultiRangePlan, pair_at: Callable, disparity: np.ndarray, config: MatchingConfig
             ) -> tuple[np.ndarray, np.ndarray | None]:
    """The near guard's verdict (module docstring): ``(too_near, beside)``.

    Parameters
    ----------
    plan : MultiRangePlan
        With its ``guard`` search.
    pair_at : callable
        ``pair_at(width)``: the prepared whole-image pair at that level width.
    disparity : ndarray float32 (H, W)
        The bands' united disparity (full-resolution pixels, NaN none).
    config : MatchingConfig
        The matcher's settings.
    """
    search = _guard_search(plan, pair_at, disparity, config)
    clusters = _confirmed_clusters(search, config)
    if clusters is None:
        return np.zeros(disparity.shape, bool), None
    found = _too_near_regions(search, clusters, config)
    if found is None:
        return np.zeros(disparity.shape, bool), None
    regions, crowded, wins = found
    return regions, _beside(search, clusters, regions, crowded, wins, config)


def _guard_search(plan: MultiRangePlan, pair_at: Callable, disparity: np.ndarray,
                  config: MatchingConfig) -> _GuardSearch:
    """Step 1, and the bands' values at the guard's level: a candidate that does not beat them
    there (as eq. 10 with the uniqueness test over both searches would decide) is no candidate."""
    guard = plan.guard
    width = disparity.shape[1]
    row0, row1, col0, col1 = plan.aoi
    w_level = guard.size[0]
    level_pair = pair_at(w_level)
    d_int, sub, c1, c2, d_right = match_prepared(*level_pair, d_lo=guard.search_px[0], d_hi=guard.search_px[1],
                                                 rows=(row0, row1), cols=_level_cols(col0, col1, guard.scale, w_level),
                                                 right_check=True)
    d_level, beyond, candidate = _guard_candidates(d_int, sub, c1, c2, d_right, guard, config)
    centre = np.minimum(((np.arange(w_level) + 0.5) * guard.scale).astype(np.intp), width - 1)
    # nearest-neighbour up-sampling along x; distinct clusters stay apart (a level column
    # between them spans a column at least)
    source = np.minimum(((np.arange(col0, col1) + 0.5) / guard.scale).astype(np.intp), w_level - 1)
    return _GuardSearch(level=guard, rows=(row0, row1), cols=(col0, col1), level_pair=level_pair, pair_at=pair_at,
                        disparity=disparity, cost=c1, d_level=d_level, beyond=beyond, candidate=candidate,
                        value_level=disparity[:, centre] / np.float32(guard.scale), source=source)


def _guard_candidates(d_int, sub, c1, c2, d_right, guard: RangeLevel, config: MatchingConfig):
    """Step 1 in one kernel (:func:`._guard_kernels.guard_candidates`): ``(d_level, beyond,
    candidate)``, the level disparity ``d_int (+ sub)`` in float32, the winners above
    ``guard.too_near_above_px`` and those that pass the maximum cost, the left-right and the
    uniqueness checks; each in the float type numpy gives the expression."""
    checks = config.acceptance
    f32 = np.float32
    product = np.result_type(f32, guard.scale)
    wide = 2 if product == np.float64 else int(np.result_type(product, guard.too_near_above_px) == np.float64)
    keep = 1.0 - checks.uniqueness_ratio
    check_values = (-1.0 if checks.max_cost is None else float(checks.max_cost),
                    checks.max_cost is not None and np.result_type(f32, checks.max_cost) == np.float64,
                    -1.0 if checks.lr_max_diff_px is None else float(checks.lr_max_diff_px),
                    float(keep) if checks.uniqueness_ratio > 0 else -1.0, np.result_type(f32, keep) == np.float64)
    shape = d_int.shape
    out = np.empty(shape, f32), np.empty(shape, bool), np.empty(shape, bool)
    _guard_kernels.guard_candidates((d_int, sub, c1, c2, d_right), bool(config.subpixel.parabola), float(guard.scale),
                              float(guard.too_near_above_px), wide, check_values, out)
    return out


def _near_match_wins(cost: np.ndarray, d_px: np.ndarray, value_cost: np.ndarray, value_px: np.ndarray,
                     ratio: float, value_beyond: np.ndarray) -> np.ndarray:
    """Where a match past the near limit beats the bands' value: by the uniqueness margin
    (``cost < (1 - ratio) value_cost``) when the two lie at least 2 px apart (two minima), by a
    lower cost when nearer; and always when the value's own re-scored minimum lies past the
    near limit (``value_beyond``: one minimum, cut by the band's edge, which eq. (10) over both
    searches would place beyond it). A value without a cost (inf: no minimum near it) loses."""
    with np.errstate(invalid="ignore"):
        apart = ~(np.abs(d_px - value_px) < 2.0)
        return value_beyond | np.where(apart, ~(value_cost * (1.0 - ratio) <= cost), ~(value_cost <= cost))


def _contest_at_level(search: _GuardSearch, among: np.ndarray, ratio: float) -> np.ndarray:
    """Step 2 on the guard's images: the candidates among ``among`` that beat the bands' value
    (or have none)."""
    guard = search.level
    contest = among & np.isfinite(search.value_level)
    ys, xs = np.flatnonzero(contest.any(axis=1)), np.flatnonzero(contest.any(axis=0))
    if not ys.size:
        return among
    value_min, value_cost = refine_candidates(*search.level_pair, search.value_level, contest, rows=search.rows,
                                              half_px=1, boxes=[(ys[0], ys[-1] + 1, xs[0], xs[-1] + 1)])
    # (whole level images: pixel by pixel the same verdict as on the contest's pixels)
    wins = _near_match_wins(search.cost, search.d_level, value_cost, search.value_level, ratio,
                            value_min > guard.too_near_above_px / guard.scale)
    return among & (wins | ~contest)


def _confirmed_clusters(search: _GuardSearch, config: MatchingConfig) -> _Clusters | None:
    """Steps 2 (guard's images) and 3 on the clusters of candidates that can hold a too-near
    region; None without any. Clusters of candidates before step 2 hold those after it (a
    subset's clusters are parts of them)."""
    guard = search.level
    height, width = search.disparity.shape
    col0, col1 = search.cols
    w_level = guard.size[0]
    min_level = config.postfilter.speckle_size_px // math.ceil(guard.scale)
    large = _in_large_clusters(search.candidate, min_level)
    labels_level, level_boxes = _large_clusters(_contest_at_level(search, large, config.acceptance.uniqueness_ratio),
                                                min_level)
    if not labels_level.any():
        return None
    # every winner beyond D shapes the re-scoring's windows; only the candidates are re-scored
    field = np.empty((height, width), np.float32)
    want = np.empty((height, width), np.bool_)
    first_col, end_col = _level_spans(search.source, col0, w_level)
    _guard_kernels.guard_upsample(search.beyond, search.d_level, labels_level, first_col, end_col, float(guard.scale),
                            field, want)
    boxes = _full_boxes(level_boxes, guard.scale, col0, col1)
    confirmed_px, confirmed_cost = refine_candidates(*search.pair_at(width), field, want, rows=search.rows,
                                                     max_cost=config.acceptance.max_cost,
                                                     half_px=_half_px(guard, config), boxes=boxes)
    return _Clusters(large=large, labels_level=labels_level, boxes=boxes, first_col=first_col, end_col=end_col,
                     field=field, confirmed_px=confirmed_px, confirmed_cost=confirmed_cost)


def _half_px(guard: RangeLevel, config: MatchingConfig) -> int:
    """Offsets of step 3's re-scoring on each side: half a level pixel and the refinement's margin."""
    return int(math.ceil(guard.scale / 2)) + config.subpixel.refine_margin_px


def _too_near_regions(search: _GuardSearch, clusters: _Clusters, config: MatchingConfig):
    """Steps 2 (full resolution) and 4 on the confirmed candidates of the clusters holding more
    than ``speckle_size_px`` of them (a too-near region lies in one), as pixel lists: those of
    the clusters' level pixels (the only ones re-scored). Returns ``(too_near, (ys, xs), wins)``:
    the regions, those pixels and which of them won; or None without a region."""
    disparity = search.disparity
    shape = disparity.shape
    speckle = config.postfilter.speckle_size_px
    n_labels = int(clusters.labels_level.max()) + 1
    ys, xs, cluster = _finite_in_clusters(clusters.confirmed_px, clusters.labels_level, clusters.first_col,
                                          clusters.end_col)
    crowd = np.bincount(cluster, minlength=n_labels) > speckle
    crowd[0] = False
    keep = crowd[cluster]
    ys, xs, cluster = ys[keep], xs[keep], cluster[keep]
    px, cost, value = clusters.confirmed_px[ys, xs], clusters.confirmed_cost[ys, xs], disparity[ys, xs]
    # the winners are a subset of these pixels, and a subset's regions are parts of theirs:
    # without a region larger than a speckle among them there is none among the winners
    if not ys.size or _regions(ys, xs, px, shape, config, search.level.scale) is None:
        return None
    wins = ~np.isfinite(value)
    contest = ~wins
    if contest.any():
        wanted = np.zeros(shape, bool)
        wanted[ys[contest], xs[contest]] = True
        value_min, value_cost = refine_candidates(*search.pair_at(shape[1]), disparity, wanted, rows=search.rows,
                                                  half_px=2,
                                                  boxes=None if clusters.boxes is None else clusters.boxes[crowd[1:]])
        yc, xc = ys[contest], xs[contest]
        wins[contest] = _near_match_wins(cost[contest], px[contest], value_cost[yc, xc], value[contest],
                                         config.acceptance.uniqueness_ratio,
                                         value_min[yc, xc] > search.level.band_px[0] + 0.5)
    crowd = np.bincount(cluster[wins], minlength=n_labels) > speckle
    crowd[0] = False
    if not crowd.any():
        return None
    regions = _regions(ys[wins], xs[wins], px[wins], shape, config, search.level.scale)
    if regions is None:
        return None
    return regions, (ys, xs), wins


def _winning(search: _GuardSearch, confirmed_px: np.ndarray, confirmed_cost: np.ndarray, among: np.ndarray,
             valued: np.ndarray, ratio: float) -> np.ndarray:
    """Step 2 at full resolution on the confirmed candidates ``among``: those without a value
    or that beat it."""
    contest = among & valued
    wins = among & ~valued
    if contest.any():
        disparity = search.disparity
        value_min, value_cost = refine_candidates(*search.pair_at(disparity.shape[1]), disparity, contest,
                                                  rows=search.rows, half_px=2)
        wins |= contest & _near_match_wins(confirmed_cost, confirmed_px, value_cost, disparity, ratio,
                                           value_min > search.level.band_px[0] + 0.5)
    return wins


def _beside(search: _GuardSearch, clusters: _Clusters, regions: np.ndarray, crowded, wins: np.ndarray,
            config: MatchingConfig) -> np.ndarray:
    """Step 5: every candidate that wins (the confirmed ones of the crowded clusters, pixels
    ``crowded`` where ``wins``; those of the other clusters; the candidates outside the
    clusters of step 3, after step 2 on the guard's images) clustered with a too-near region,
    with the margin."""
    disparity = search.disparity
    shape = disparity.shape
    col0, col1 = search.cols
    ratio = config.acceptance.uniqueness_ratio
    candidates = np.zeros(shape, bool)
    ys, xs = crowded
    candidates[ys[wins], xs[wins]] = True
    valued = np.isfinite(disparity)
    others = np.isfinite(clusters.confirmed_px)
    others[ys, xs] = False
    if others.any():
        candidates |= _winning(search, clusters.confirmed_px, clusters.confirmed_cost, others, valued, ratio)
    rest_level = (_contest_at_level(search, search.candidate & ~clusters.large, ratio)
                  | (_contest_at_level(search, clusters.large, ratio) & (clusters.labels_level == 0)))
    rest = np.zeros(shape, bool)
    rest[:, col0:col1] = rest_level[:, search.source]
    if rest.any():
        rest_px, rest_cost = refine_candidates(*search.pair_at(shape[1]), clusters.field, rest, rows=search.rows,
                                               max_cost=config.acceptance.max_cost,
                                               half_px=_half_px(search.level, config))
        candidates |= _winning(search, rest_px, rest_cost, np.isfinite(rest_px), valued, ratio)
    grown = near_side(candidates, margin_px=config.fattening_px)
    _, labels = cv2.connectedComponents(grown.view(np.uint8), connectivity=8)
    keep = np.unique(labels[regions])
    return np.isin(labels, keep[keep > 0])


def _regions(ys: np.ndarray, xs: np.ndarray, px: np.ndarray, shape, config: MatchingConfig, scale: float):
    """Step 4's speckle filter on the pixels ``(ys, xs)`` of disparities ``px`` (not empty):
    the mask (``shape``) of those in regions larger than a speckle (``speckle_size_px``,
    connected within ``speckle_range_px`` level pixels), or None without any. Runs on their
    bounding box (its regions are those of the image)."""
    post = config.postfilter
    top, left = int(ys.min()), int(xs.min())
    box = np.full((int(ys.max()) + 1 - top, int(xs.max()) + 1 - left), np.nan, np.float32)
    box[ys - top, xs - left] = px
    if post.speckle_size_px > 0:
        box = remove_speckles(box, max_size_px=post.speckle_size_px, max_diff_px=post.speckle_range_px * scale)
    box = np.isfinite(box)
    if not box.any():
        return None
    mask = np.zeros(shape, bool)
    mask[top:top + box.shape[0], left:left + box.shape[1]] = box
    return mask


def _level_spans(source: np.ndarray, col0: int, w_level: int) -> tuple[np.ndarray, np.ndarray]:
    """``(first_col, end_col)``: the full-resolution columns ``first_col[c] .. end_col[c] - 1`` that
    up-sample from level column ``c`` (column ``col0 + i`` from ``source[i]``, non-decreasing)."""
    levels = np.arange(w_level)
    return (col0 + np.searchsorted(source, levels, side="left"),
            col0 + np.searchsorted(source, levels, side="right"))


def _finite_in_clusters(values: np.ndarray, labels_level: np.ndarray, first_col: np.ndarray,
                        end_col: np.ndarray):
    """``(ys, xs, cluster)``: the pixels where ``values`` is finite among the full-resolution
    pixels of the labelled level pixels (level column ``c`` spanning ``first_col[c] ..
    end_col[c] - 1``), in row-major order, and their level labels."""
    n_max = np.count_nonzero(labels_level) * int((end_col - first_col).max(initial=0))
    ys, xs, cluster = np.empty(n_max, np.intp), np.empty(n_max, np.intp), np.empty(n_max, labels_level.dtype)
    n = _guard_kernels.guard_finite(values, labels_level, first_col, end_col, ys, xs, cluster)
    return ys[:n], xs[:n], cluster[:n]


def _label_type(shape) -> int:
    """The label type of cv2's connected components: 16 bit where every label fits (much faster
    with statistics), else 32 bit."""
    return cv2.CV_16U if ((shape[0] + 1) // 2) * ((shape[1] + 1) // 2) < 2 ** 16 - 1 else cv2.CV_32S


def _in_large_clusters(mask: np.ndarray, size_px: int) -> np.ndarray:
    """``mask`` where its 8-connected cluster has more than ``size_px`` pixels (all of it for 0)."""
    if size_px <= 0 or not mask.any():
        return mask
    n_labels, labels = cv2.connectedComponents(mask.view(np.uint8), connectivity=8, ltype=_label_type(mask.shape))
    out = np.empty(mask.shape, bool)
    _guard_kernels.in_large_labels(labels, n_labels, size_px, out)
    return out


def _large_clusters(mask: np.ndarray, size_px: int) -> tuple[np.ndarray, np.ndarray | None]:
    """``(labels, boxes)``: the 8-connected clusters of ``mask`` with more than ``size_px``
    pixels numbered from 1 (0 elsewhere) and their bounding boxes ``(row0, row1, col0, col1)``
    in that order; for ``size_px`` 0 every cluster, and boxes None."""
    if size_px <= 0:
        return cv2.connectedComponents(mask.view(np.uint8), connectivity=8, ltype=_label_type(mask.shape))[1], None
    _, labels, stats, _ = cv2.connectedComponentsWithStats(mask.view(np.uint8), connectivity=8,
                                                           ltype=_label_type(mask.shape))
    large = stats[:, cv2.CC_STAT_AREA] > size_px
    large[0] = False
    number = np.zeros(len(large), labels.dtype)
    number[large] = np.arange(1, np.count_nonzero(large) + 1)
    x, y, w, h = (stats[large, i] for i in (cv2.CC_STAT_LEFT, cv2.CC_STAT_TOP, cv2.CC_STAT_WIDTH,
                                             cv2.CC_STAT_HEIGHT))
    numbered = np.empty(labels.shape, labels.dtype)
    _guard_kernels.map_labels(labels, number, numbered)
    return numbered, np.stack([y, y + h, x, x + w], axis=1)


def _full_boxes(level_boxes, scale: float, col0: int, col1: int):
    """Boxes of the guard's level as full-resolution boxes (the columns their pixels up-sample to)."""
    if level_boxes is None:
        return None
    out = level_boxes.astype(np.float64)
    out[:, 2] = np.maximum(np.floor(out[:, 2] * scale) - 1, col0)
    out[:, 3] = np.minimum(np.ceil(out[:, 3] * scale) + 1, col1)
    return out.astype(np.intp)


def drop_cut_off(disparity: np.ndarray, beside: np.ndarray, config: MatchingConfig) -> None:
    """In place: NaN on the regions that the too-near margins ``beside`` cut down to speckles
    (speckle regions touching the margins; the rest of the map was filtered before)."""
    kept = remove_speckles(disparity, max_size_px=config.postfilter.speckle_size_px,
                           max_diff_px=config.postfilter.speckle_range_px)
    dropped = np.isfinite(disparity) & ~np.isfinite(kept)
    if not dropped.any():
        return
    _, labels = cv2.connectedComponents(dropped.view(np.uint8), connectivity=4)
    ring = cv2.dilate(beside.view(np.uint8), np.ones((3, 3), np.uint8)).view(np.bool_)
    touching = np.unique(labels[ring & dropped])
    disparity[np.isin(labels, touching[touching > 0])] = np.nan
