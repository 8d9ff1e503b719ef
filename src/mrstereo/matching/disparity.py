"""Public entry point of the matcher: :func:`compute_disparity` (paper section 3).

Area of interest (3.1) -> per level: horizontal decimation (3.2), pre-filter,
window cost eq. (9) and winner-take-all eq. (10) (3.3), checks, median (3.4) ->
up-sampling, full-resolution refinement of the coarsest level (beyond the paper),
gating eq. (11) -> union eq. (12) -> near guard -> cross-band ambiguity test (beyond the paper)
-> speckle removal -> depth-edge guard -> gap filling.
Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from .. import _checks
from . import _kernels
from .config import MatchingConfig, preset_config
from .cost import match_checked, match_prepared, prepare, prepare_gray, refine_candidates
from .multirange import (DEFAULT_DEPTH_EDGES_M, LevelOutput, MultiRangePlan, RangeLevel, _level_cols,
                         bands_px_from_depth_m, decimate_horizontally, default_bands_px, default_level_count,
                         plan_levels, run_levels)
from .postfilter import fill_gaps, guard_depth_edges, median_filter, near_side, remove_speckles, textured

__all__ = ["DisparityResult", "compute_disparity", "make_plan", "solve_level"]


@dataclass(frozen=True)
class DisparityResult:
    """Result of :func:`compute_disparity`.

    Attributes
    ----------
    disparity_px : ndarray float32 (H, W)
        ``d = x_left - x_right`` in full-resolution pixels, NaN invalid (also where too near).
    too_near : ndarray bool (H, W)
        Pixels whose match lies beyond the largest searched disparity (nearer than the near
        limit): detected by the near guard (``config.near_guard``, ``plan.guard``; see
        ``_near_guard``), NaN in ``disparity_px``. Robot code treats them as an obstacle at
        the near limit (docs/obstacles.md).
    confidence : ndarray float32 (H, W)
        In [0, 1]; 0 where invalid (see :func:`.postfilter.confidence_from_costs`).
    plan : MultiRangePlan
        The levels searched and their work (``plan.describe()``).
    levels : tuple of ndarray float32 (H, W)
        Each level's gated, full-width disparity (finest level first; refined levels after
        their full-resolution re-scoring), before the union.
    """

    disparity_px: np.ndarray
    confidence: np.ndarray
    plan: MultiRangePlan
    levels: tuple[np.ndarray, ...]
    too_near: np.ndarray

    @property
    def near_limit_px(self) -> float:
        """The largest disparity of the search (full-resolution pixels): too-near pixels lie beyond it."""
        return max(level.band_px[1] for level in self.plan.levels)


def _aoi(aoi, width: int, height: int) -> tuple[int, int, int, int]:
    if aoi is None:
        return (0, height, 0, width)
    if len(aoi) != 4:
        raise ValueError(f"aoi must be (row0, row1, col0, col1), got {aoi!r}")
    row0, row1, col0, col1 = (int(v) for v in aoi)
    if not (0 <= row0 < row1 <= height and 0 <= col0 < col1 <= width):
        raise ValueError(f"aoi {tuple(aoi)} must satisfy 0 <= row0 < row1 <= {height} and "
                         f"0 <= col0 < col1 <= {width}")
    return (row0, row1, col0, col1)


def make_plan(image_size: tuple[int, int], *, max_disparity_px=None, disparity_bands_px=None,
              calibration=None, depth_bands_m=None, config: MatchingConfig | None = None,
              preset: str = "robust", aoi=None) -> MultiRangePlan:
    """The multi-range plan :func:`compute_disparity` would run (same arguments, no images).

    Exactly one of ``max_disparity_px``, ``disparity_bands_px``, ``depth_bands_m`` (with
    ``calibration``) or ``calibration`` alone (default depth bands
    ``0.5-1, 1-2.5, 2.5-15 m``) determines the search.
    """
    config = preset_config(preset) if config is None else config
    if not isinstance(config, MatchingConfig):
        raise TypeError(f"config must be a MatchingConfig, got {type(config).__name__}")
    width, height = image_size
    given = [name for name, value in (("max_disparity_px", max_disparity_px),
                                      ("disparity_bands_px", disparity_bands_px),
                                      ("depth_bands_m", depth_bands_m)) if value is not None]
    if len(given) > 1:
        raise ValueError(f"give only one of max_disparity_px, disparity_bands_px, depth_bands_m; "
                         f"got {', '.join(given)}")
    if depth_bands_m is not None and calibration is None:
        raise ValueError("depth_bands_m needs calibration (focal_px and baseline_m)")
    if not given and calibration is None:
        raise ValueError("the search is undetermined: give max_disparity_px, disparity_bands_px, "
                         "or calibration (with optional depth_bands_m)")
    focal = baseline = None
    doffs = 0.0
    if calibration is not None:
        for attr in ("focal_px", "baseline_m"):
            if not hasattr(calibration, attr):
                raise TypeError(f"calibration must be a StereoCamera, got {type(calibration).__name__}")
        focal, baseline = float(calibration.focal_px), float(calibration.baseline_m)
        doffs = float(getattr(calibration, "doffs_px", 0.0))
    depth_bands = None
    if max_disparity_px is not None:
        d_max = _checks.finite_number("max_disparity_px", max_disparity_px, positive=True)
        n = (len(config.decimations) if config.decimations is not None
             else default_level_count(d_max, min_band_level_px=config.min_band_level_px))
        bands = default_bands_px(d_max, n) if config.multi_range else ((0.0, d_max),)
    elif disparity_bands_px is not None:
        bands = tuple(tuple(band) for band in disparity_bands_px)
    else:
        edges = DEFAULT_DEPTH_EDGES_M if depth_bands_m is None else depth_bands_m
        pairs = bands_px_from_depth_m(edges, focal_px=focal, baseline_m=baseline, doffs_px=doffs)
        bands = tuple(p[0] for p in pairs)
        depth_bands = tuple(p[1] for p in pairs)
    if depth_bands is None and focal is not None:
        depth_bands = tuple((_depth(band[1], focal, baseline, doffs), _depth(band[0], focal, baseline, doffs))
                            for band in bands)
    decimations = config.decimations
    if not config.multi_range and len(bands) > 1:
        bands = ((min(b[0] for b in bands), max(b[1] for b in bands)),)
        near = min(z[0] for z in depth_bands) if depth_bands else None
        depth_bands = None if depth_bands is None else ((near, max(z[1] for z in depth_bands)),)
    if not config.multi_range:
        decimations = (1,)
    return plan_levels((width, height), bands, decimations=decimations,
                       band_margin_px=config.band_margin_px, aoi=_aoi(aoi, width, height),
                       depth_bands_m=depth_bands, focal_px=focal, baseline_m=baseline,
                       near_guard=config.near_guard, near_guard_decimation=config.near_guard_decimation)


def _depth(d: float, focal: float, baseline: float, doffs: float) -> float:
    return baseline * focal / (d + doffs) if d + doffs > 0 else math.inf


def _check_search_memory(plan, config: MatchingConfig, *, given: str) -> None:
    """Refuse a search whose per-thread cost buffers (disparities x columns) exceed the memory."""
    import numba

    threads = numba.get_num_threads()
    widest = max(plan.levels, key=lambda lv: (lv.search_px[1] - lv.search_px[0] + 1) * lv.size[0])
    n_disp = widest.search_px[1] - widest.search_px[0] + 1
    nbytes = threads * n_disp * (widest.size[0] + config.window_px) * 12.0
    _checks.fits_in_memory(given, nbytes, f"the matching cost buffers ({n_disp:.4g} disparities x "
                                          f"{widest.size[0]} columns x {threads} threads)")


def _prepare_pair(left: np.ndarray, right: np.ndarray, config: MatchingConfig):
    """Pre-filter both images and prepare them for the kernels."""
    pair = tuple(prepare_gray(img, kind=config.prefilter, cap=config.prefilter_cap, window=config.window_px,
                              cost=config.cost) for img in (left, right))
    if pair[0].padded.dtype != pair[1].padded.dtype:      # one exact, the other not: both float64
        pair = tuple(prepare(p.padded[p.window // 2:-(p.window // 2), p.window // 2:-(p.window // 2)],
                             window=config.window_px, cost=config.cost, dtype=np.float64) for p in pair)
    return pair


def _solve_prepared(pair, left: np.ndarray, level: RangeLevel, rows: tuple[int, int], cols: tuple[int, int],
                    config: MatchingConfig) -> LevelOutput:
    # the band without its search margins, in level pixels, for the cross-band ambiguity test
    alt_band = None if config.ambiguity_margin is None else (math.ceil(level.band_px[0] / level.scale),
                                                             math.floor(level.band_px[1] / level.scale))
    disparity, confidence, alt_px, alt_cost, best_cost = match_checked(
        *pair, d_lo=level.search_px[0], d_hi=level.search_px[1], rows=rows, cols=cols,
        lr_max_diff_px=config.lr_max_diff_px, uniqueness_ratio=config.uniqueness_ratio, max_cost=config.max_cost,
        subpixel=config.subpixel, alt_band=alt_band)
    if config.texture_threshold > 0:
        disparity[~textured(left, window_px=config.window_px, threshold=config.texture_threshold)] = np.nan
    if config.median_size:
        disparity = median_filter(disparity, size=config.median_size,
                                  max_px=level.search_px[1] + 0.5)      # (+ the parabola offset)
        _kernels.zero_where_invalid(disparity, confidence)
    return LevelOutput(disparity_px=disparity, confidence=confidence, alt_px=alt_px, alt_cost=alt_cost,
                       best_cost=best_cost)


def solve_level(left: np.ndarray, right: np.ndarray, level: RangeLevel, rows: tuple[int, int],
                cols: tuple[int, int], *, config: MatchingConfig) -> LevelOutput:
    """The per-level solver: pre-filter, eq. (9)-(10) over ``level.search_px``, checks, median.

    Checks (each off when its setting is): left-right consistency, uniqueness ratio,
    maximum cost, texture. Disparities are in level pixels; the driver gates and
    up-samples them.
    """
    return _solve_prepared(_prepare_pair(left, right, config), left, level, rows, cols, config)


def _ambiguous_across_bands(plan: MultiRangePlan, outputs: dict, disparity: np.ndarray,
                            config: MatchingConfig) -> np.ndarray:
    """Pixels whose united value another band contests (beyond the paper; eq. 12 over the bands).

    Each level searches only its band, so its uniqueness test never sees a minimum in another
    band: on a repeated pattern (stripes, tiles) whose period spans more than a band, a far
    band finds the pattern one period off as a unique, confident winner while the true band,
    which holds two minima, rejects its own (or the reverse). Here each band's own best minimum
    (``LevelOutput.alt_px``: the lowest strict local minimum of its cost inside the band,
    whatever the checks) is a rival of the pixel's value when the value lies in another band,
    at least 2 level pixels of that band away, and the rival is a confident match (cost at
    most ``config.ambiguity_max_cost``: the minima of a repeated high-contrast pattern, not the
    shallow ones of weak texture). The value is ambiguous when a rival costs less than the
    value's own winner cost (``LevelOutput.best_cost`` of the level whose band holds it) plus
    ``config.ambiguity_margin``: the uniqueness test of eq. (10) applied across the bands, with
    an absolute margin (ZNCC costs of a repeated pattern are near 0, where the ratio test is
    lenient), each cost at its own level's resolution. Returns a bool mask (H, W).
    """
    height, width = disparity.shape
    ambiguous = np.zeros((height, width), bool)
    levels = [(level, outputs[level]) for level in plan.levels
              if level in outputs and outputs[level].alt_px is not None]
    if len(levels) < 2:
        return ambiguous
    sources = [np.minimum(((np.arange(width) + 0.5) / level.scale).astype(np.intp), level.size[0] - 1)
               for level, _ in levels]
    value_cost = np.full((height, width), np.inf, np.float32)
    for (level, out), source in zip(levels, sources):
        _kernels.band_value_cost(disparity, out.best_cost, source, np.float32(level.band_px[0]),
                                 np.float32(level.band_px[1]), value_cost)
    for (level, out), source in zip(levels, sources):
        _kernels.band_rivals(disparity, out.alt_px, out.alt_cost, source, np.float32(level.scale),
                             np.float32(level.band_px[0]), np.float32(level.band_px[1]),
                             np.float32(2.0 * level.scale), np.float32(config.ambiguity_max_cost),
                             np.float32(config.ambiguity_margin), value_cost, ambiguous)
    return ambiguous


def _beats(cost: np.ndarray, d_px: np.ndarray, value_cost: np.ndarray, value_px: np.ndarray,
           ratio: float, value_beyond: np.ndarray) -> np.ndarray:
    """Where a match past the near limit beats the bands' value: by the uniqueness margin
    (``cost < (1 - ratio) value_cost``) when the two lie at least 2 px apart (two minima), by a
    lower cost when nearer; and always when the value's own re-scored minimum lies past the
    near limit (``value_beyond``: one minimum, cut by the band's edge, which eq. (10) over both
    searches would place beyond it). A value without a cost (inf: no minimum near it) loses."""
    with np.errstate(invalid="ignore"):
        apart = ~(np.abs(d_px - value_px) < 2.0)
        return value_beyond | np.where(apart, ~(value_cost * (1.0 - ratio) <= cost), ~(value_cost <= cost))


def _near_guard(plan: MultiRangePlan, pair_at, disparity: np.ndarray, config: MatchingConfig
                ) -> tuple[np.ndarray, np.ndarray | None]:
    """The near guard's verdict (beyond the paper): ``(too_near, beside)``.

    1. The guard's search (``plan.guard``: decimated images, disparities from the near limit
       ``D`` to ``near_guard * D``) runs apart from the bands, whose winners and checks stay
       exactly those of the plan without a guard. A winner above ``D`` plus half a level pixel
       that passes the maximum cost, the left-right and the uniqueness checks is a candidate.
    2. Where the bands gave the pixel a value, the candidate must beat it (:func:`_beats`),
       first on the guard's images (the value re-scored over ``+-1`` level px), then at full
       resolution (step 3; the value re-scored over ``+-2`` px): its cost below
       ``(1 - uniqueness_ratio)`` times the value's when the two lie 2 px apart or more (the
       uniqueness test's distance), else below the value's; and always when the value's own
       re-scored minimum lies past the near limit (one minimum, cut by the band's edge).
       (The first test is cheap and removes most stray candidates before step 3.)
    3. Each candidate is re-scored at full resolution as the refinement does (offsets
       ``+-(ceil(k / 2) + refine_margin_px)``, the maximum cost; a minimum on the edge fails).
    4. Too near: the confirmed candidates without a value or whose value lost, in regions
       larger than a speckle (``speckle_size_px``, connected within ``speckle_range_px`` level
       pixels).
    5. ``beside``: the candidates clustered with a too-near region (within
       ``too_near_margin_px`` of each other) and that margin around them; they lose their
       values (:func:`.postfilter.near_side`: silhouettes, thin parts, a repeated pattern's
       wrong matches on the near object). None without a too-near region: a candidate
       elsewhere (a repeated pattern, plain paint) changes nothing, so a search that covers
       the scene gives the values of the matcher without a guard.

    The order of the work keeps its cost low without changing the verdict: a too-near region
    lies inside one 8-connected cluster of more than ``speckle_size_px`` confirmed candidates,
    which comes from a cluster of more than ``speckle_size_px / ceil(k)`` candidates at the
    guard's level (each level pixel spans at most ``ceil(k)`` columns). Steps 2-4 run on those
    clusters only, each in its own box (:func:`.cost.refine_candidates`); the other candidates
    matter only for step 5, when a too-near region is found.
    """
    guard = plan.guard
    height, width = disparity.shape
    row0, row1, col0, col1 = plan.aoi
    rows = (row0, row1)
    w_level = guard.size[0]
    level_pair = pair_at(w_level)
    d_int, sub, c1, c2, d_right = match_prepared(*level_pair, d_lo=guard.search_px[0], d_hi=guard.search_px[1],
                                                 rows=rows, cols=_level_cols(col0, col1, guard.scale, w_level),
                                                 right_check=True)
    d_level, beyond, candidate = _guard_candidates(d_int, sub, c1, c2, d_right, guard, config)
    # the bands' value where they have one, at the guard's level (its centre column): a
    # candidate that does not beat it there (as eq. 10 with the uniqueness test over both
    # searches would decide) is no candidate
    centre = np.minimum(((np.arange(w_level) + 0.5) * guard.scale).astype(np.intp), width - 1)
    value_level = disparity[:, centre] / np.float32(guard.scale)
    ratio = config.uniqueness_ratio

    def level_contest(among):
        """Step 2 on the guard's images: the candidates among ``among`` that beat the value."""
        contest = among & np.isfinite(value_level)
        ys, xs = np.flatnonzero(contest.any(axis=1)), np.flatnonzero(contest.any(axis=0))
        if not ys.size:
            return among
        value_min, value_cost = refine_candidates(*level_pair, value_level, contest, rows=rows, half_px=1,
                                                  boxes=[(ys[0], ys[-1] + 1, xs[0], xs[-1] + 1)])
        # (whole level images: pixel by pixel the same verdict as on the contest's pixels)
        beats = _beats(c1, d_level, value_cost, value_level, ratio,
                       value_min > guard.too_near_above_px / guard.scale)
        return among & (beats | ~contest)

    min_level = config.speckle_size_px // math.ceil(guard.scale)
    # clusters of candidates before step 2 hold those after it (a subset's clusters are parts of them)
    large = _in_large_clusters(candidate, min_level)
    labels_level, level_boxes = _large_clusters(level_contest(large), min_level)
    if not labels_level.any():
        return np.zeros((height, width), bool), None
    # Step 2 up-sampling (nearest neighbour along x, disparities times the scale), AOI columns;
    # distinct clusters stay apart (a level column between them spans a column at least)
    source = np.minimum(((np.arange(col0, col1) + 0.5) / guard.scale).astype(np.intp), w_level - 1)
    # (every winner beyond D shapes the re-scoring's windows; only the candidates are re-scored)
    field = np.empty((height, width), np.float32)
    want = np.empty((height, width), np.bool_)
    first_col, end_col = _level_spans(source, col0, w_level)
    _kernels.guard_upsample(beyond, d_level, labels_level, first_col, end_col, float(guard.scale), field, want)
    n_labels = int(labels_level.max()) + 1
    full = pair_at(width)
    half_px = int(math.ceil(guard.scale / 2)) + config.refine_margin_px
    boxes = _full_boxes(level_boxes, guard.scale, col0, col1)
    confirmed_px, confirmed_cost = refine_candidates(*full, field, want, rows=rows, max_cost=config.max_cost,
                                                     half_px=half_px, boxes=boxes)
    # Steps 2 (full resolution) and 4 on the confirmed candidates of the clusters holding more
    # than speckle_size_px of them (a too-near region lies in one), as pixel lists: those of
    # the clusters' level pixels (the only ones re-scored), each level column spanning the
    # full-resolution columns that up-sample from it
    ys, xs, cluster = _finite_in_clusters(confirmed_px, labels_level, first_col, end_col)
    crowd = np.bincount(cluster, minlength=n_labels) > config.speckle_size_px
    crowd[0] = False
    keep = crowd[cluster]
    ys, xs, cluster = ys[keep], xs[keep], cluster[keep]
    px, cost, value = confirmed_px[ys, xs], confirmed_cost[ys, xs], disparity[ys, xs]
    # the winners are a subset of these pixels, and a subset's regions are parts of theirs:
    # without a region larger than a speckle among them there is none among the winners
    if not ys.size or _regions(ys, xs, px, (height, width), config, guard.scale) is None:
        return np.zeros((height, width), bool), None
    wins = ~np.isfinite(value)
    contest = ~wins
    if contest.any():
        wanted = np.zeros((height, width), bool)
        wanted[ys[contest], xs[contest]] = True
        value_min, value_cost = refine_candidates(*full, disparity, wanted, rows=rows, half_px=2,
                                                  boxes=None if boxes is None else boxes[crowd[1:]])
        yc, xc = ys[contest], xs[contest]
        wins[contest] = _beats(cost[contest], px[contest], value_cost[yc, xc], value[contest], ratio,
                               value_min[yc, xc] > guard.band_px[0] + 0.5)
    crowd = np.bincount(cluster[wins], minlength=n_labels) > config.speckle_size_px
    crowd[0] = False
    if not crowd.any():
        return np.zeros((height, width), bool), None
    too_near = _regions(ys[wins], xs[wins], px[wins], (height, width), config, guard.scale)
    if too_near is None:
        return np.zeros((height, width), bool), None
    # step 5 needs every candidate that wins: also the confirmed ones of the other clusters, and
    # the candidates outside the clusters of step 3 (after step 2 on the guard's images)
    candidates = np.zeros((height, width), bool)
    candidates[ys[wins], xs[wins]] = True
    valued = np.isfinite(disparity)

    def winners(confirmed_px, confirmed_cost, among):
        contest = among & valued
        wins = among & ~valued
        if contest.any():
            value_min, value_cost = refine_candidates(*full, disparity, contest, rows=rows, half_px=2)
            wins |= contest & _beats(confirmed_cost, confirmed_px, value_cost, disparity, ratio,
                                     value_min > guard.band_px[0] + 0.5)
        return wins

    others = np.isfinite(confirmed_px)
    others[ys, xs] = False
    if others.any():
        candidates |= winners(confirmed_px, confirmed_cost, others)
    rest_level = level_contest(candidate & ~large) | (level_contest(large) & (labels_level == 0))
    rest = np.zeros((height, width), bool)
    rest[:, col0:col1] = rest_level[:, source]
    if rest.any():
        rest_px, rest_cost = refine_candidates(*full, field, rest, rows=rows, max_cost=config.max_cost,
                                               half_px=half_px)
        candidates |= winners(rest_px, rest_cost, np.isfinite(rest_px))
    grown = near_side(candidates, margin_px=config.too_near_margin)
    _, labels = cv2.connectedComponents(grown.view(np.uint8), connectivity=8)
    keep = np.unique(labels[too_near])
    return too_near, np.isin(labels, keep[keep > 0])


def _regions(ys: np.ndarray, xs: np.ndarray, px: np.ndarray, shape, config: MatchingConfig, scale: float):
    """Step 4's speckle filter on the pixels ``(ys, xs)`` of disparities ``px`` (not empty):
    the mask (``shape``) of those in regions larger than a speckle (``speckle_size_px``,
    connected within ``speckle_range_px`` level pixels), or None without any. Runs on their
    bounding box (its regions are those of the image)."""
    top, left = int(ys.min()), int(xs.min())
    box = np.full((int(ys.max()) + 1 - top, int(xs.max()) + 1 - left), np.nan, np.float32)
    box[ys - top, xs - left] = px
    if config.speckle_size_px > 0:
        box = remove_speckles(box, max_size_px=config.speckle_size_px, max_diff_px=config.speckle_range_px * scale)
    box = np.isfinite(box)
    if not box.any():
        return None
    mask = np.zeros(shape, bool)
    mask[top:top + box.shape[0], left:left + box.shape[1]] = box
    return mask


def _guard_candidates(d_int, sub, c1, c2, d_right, guard: RangeLevel, config: MatchingConfig):
    """Step 1 of :func:`_near_guard` in one kernel (:func:`._kernels.guard_candidates`):
    ``(d_level, beyond, candidate)``, the level disparity ``d_int (+ sub)`` in float32, the
    winners above ``guard.too_near_above_px`` and those that pass the maximum cost, the
    left-right (:func:`.postfilter.left_right_consistent`) and the uniqueness
    (:func:`.postfilter.unique`) checks; each in the float type numpy gives the expression."""
    f32 = np.float32
    product = np.result_type(f32, guard.scale)
    wide = 2 if product == np.float64 else int(np.result_type(product, guard.too_near_above_px) == np.float64)
    max_cost = -1.0 if config.max_cost is None else float(config.max_cost)
    wide_cost = config.max_cost is not None and np.result_type(f32, config.max_cost) == np.float64
    lr = -1.0 if config.lr_max_diff_px is None else float(config.lr_max_diff_px)
    keep = 1.0 - config.uniqueness_ratio
    wide_keep = np.result_type(f32, keep) == np.float64
    shape = d_int.shape
    d_level, beyond, candidate = np.empty(shape, f32), np.empty(shape, bool), np.empty(shape, bool)
    _kernels.guard_candidates(d_int, sub, c1, c2, d_right, bool(config.subpixel), float(guard.scale),
                              float(guard.too_near_above_px), wide, max_cost, bool(wide_cost), lr,
                              float(keep) if config.uniqueness_ratio > 0 else -1.0, bool(wide_keep),
                              d_level, beyond, candidate)
    return d_level, beyond, candidate


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
    n = _kernels.guard_finite(values, labels_level, first_col, end_col, ys, xs, cluster)
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
    _kernels.in_large_labels(labels, n_labels, size_px, out)
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
    _kernels.map_labels(labels, number, numbered)
    return numbered, np.stack([y, y + h, x, x + w], axis=1)


def _full_boxes(level_boxes, scale: float, col0: int, col1: int):
    """Boxes of the guard's level as full-resolution boxes (the columns their pixels up-sample to)."""
    if level_boxes is None:
        return None
    out = level_boxes.astype(np.float64)
    out[:, 2] = np.maximum(np.floor(out[:, 2] * scale) - 1, col0)
    out[:, 3] = np.minimum(np.ceil(out[:, 3] * scale) + 1, col1)
    return out.astype(np.intp)


def _drop_cut_off(disparity: np.ndarray, beside: np.ndarray, config: MatchingConfig) -> None:
    """In place: NaN on the regions that the too-near margins ``beside`` cut down to speckles
    (speckle regions touching the margins; the rest of the map was filtered before)."""
    kept = remove_speckles(disparity, max_size_px=config.speckle_size_px, max_diff_px=config.speckle_range_px)
    dropped = np.isfinite(disparity) & ~np.isfinite(kept)
    if not dropped.any():
        return
    _, labels = cv2.connectedComponents(dropped.view(np.uint8), connectivity=4)
    ring = cv2.dilate(beside.view(np.uint8), np.ones((3, 3), np.uint8)).view(np.bool_)
    touching = np.unique(labels[ring & dropped])
    disparity[np.isin(labels, touching[touching > 0])] = np.nan


def compute_disparity(left, right, *, max_disparity_px=None, disparity_bands_px=None, calibration=None,
                      depth_bands_m=None, config: MatchingConfig | None = None, preset: str = "robust",
                      aoi=None) -> DisparityResult:
    """Multi-range area-based disparity of a rectified pair (paper section 3, eq. 9-12).

    Parameters
    ----------
    left, right : ndarray (H, W) or (H, W, 3)
        Rectified images (gray or BGR; uint8 or float), same size.
    max_disparity_px : float, optional
        Search ``[0, D]``, split into bands ``[0, D/4], [D/4, D/2], [D/2, D]`` at
        decimations 1, 2, 4 when ``D >= 32``; for a smaller range fewer levels
        (``[0, D/2], [D/2, D]`` at 1, 2 when ``D >= 16``, else ``[0, D]``: see
        ``config.min_band_level_px``); one band ``[0, D]`` when ``config.multi_range``
        is False.
    disparity_bands_px : sequence of (float, float), optional
        Explicit bands in full-resolution pixels, one level each.
    calibration : StereoCamera, optional
        Rectified rig (``focal_px``, ``baseline_m``, ``doffs_px``); alone it selects the
        default depth bands ``0.5-1, 1-2.5, 2.5-15 m``; with other arguments it only
        labels the plan with depths.
    depth_bands_m : sequence, optional
        Depth band edges ``(z0, ..., zn)`` or ``(near, far)`` pairs in metres; converted
        with ``d = b f / Z`` (eq. 14). Needs ``calibration``.
    config : MatchingConfig, optional
        Settings; default the preset's.
    preset : {"robust", "mapping", "paper"}
        ``"paper"``: exactly eq. (9)-(12) (+ median); ``"robust"`` and ``"mapping"`` (its
        stricter variant used by the mapping chain): see :mod:`mrstereo.matching.config`.
        Ignored when ``config`` is given.
    aoi : (row0, row1, col0, col1), optional
        Area of interest (section 3.1), half-open; NaN and no work outside it.

    Returns
    -------
    DisparityResult

    Notes
    -----
    Eq. (9) with our sign: ``x_right = x_left - d``, so the paper's ``I_R(x + i + d)``
    is evaluated as ``I_R(x + i - d)`` with ``d >= 0`` (see :mod:`.cost`). A level of
    decimation ``k`` matches images of width ``W / k``; its disparity ``d_k`` becomes
    ``k d_k`` at full resolution before gating to its band (eq. 11). Where several
    levels keep a value, ``config.union`` decides (eq. 12; default: the more confident).
    """
    _checks.image("left", left)
    _checks.image("right", right)
    _checks.same_shape("left", left, "right", right)
    left_gray = _checks.gray_float32("left", left)
    right_gray = _checks.gray_float32("right", right)
    height, width = left_gray.shape
    config = preset_config(preset) if config is None else config
    plan = make_plan((width, height), max_disparity_px=max_disparity_px,
                     disparity_bands_px=disparity_bands_px, calibration=calibration,
                     depth_bands_m=depth_bands_m, config=config, aoi=aoi)
    if calibration is not None and hasattr(calibration, "size") and tuple(calibration.size) != (width, height):
        raise ValueError(f"images are {width}x{height} but the calibration is "
                         f"{calibration.size[0]}x{calibration.size[1]}")
    if config.window_px > min(width, height):
        raise ValueError(f"window_px {config.window_px} is larger than the image ({width}x{height})")
    _check_search_memory(plan, config, given=next(
        (name for name, value in (("max_disparity_px", max_disparity_px), ("disparity_bands_px", disparity_bands_px),
                                  ("depth_bands_m", depth_bands_m)) if value is not None), "calibration"))

    # prepared (pre-filtered, padded, window terms) whole-image pairs by level width: the
    # finest level's pair also serves the refinement of the coarser ones
    pairs: dict[int, tuple] = {}
    decimated: dict[int, tuple] = {}      # whole-image decimated pairs, shared with run_levels

    def pair_at(w_level: int):
        if w_level not in pairs:
            if w_level not in decimated:
                decimated[w_level] = (decimate_horizontally(left_gray, w_level),
                                      decimate_horizontally(right_gray, w_level))
            pairs[w_level] = _prepare_pair(*decimated[w_level], config)
        return pairs[w_level]

    outputs: dict[RangeLevel, LevelOutput] = {}     # for the cross-band ambiguity test

    def solve(lv, rv, level, rows, cols):
        if lv.shape[0] == height:          # whole-height images: share the prepared pair
            out = _solve_prepared(pair_at(lv.shape[1]), lv, level, rows, cols, config)
        else:
            out = solve_level(lv, rv, level, rows, cols, config=config)
        if config.ambiguity_margin is not None and lv.shape[0] == height:     # (whole-height levels)
            outputs[level] = out
        return out

    def refine(level, coarse_px, want):
        """Full-resolution re-scoring of a coarse level (beyond the paper)."""
        refined, _ = refine_candidates(*pair_at(width), coarse_px, want, rows=plan.aoi[:2],
                                       half_px=int(math.ceil(level.scale / 2)) + config.refine_margin_px,
                                       max_cost=config.max_cost)
        return refined

    disparity, confidence, levels = run_levels(
        left_gray, right_gray, plan, solve, row_pad_px=config.window_px // 2 + 2, union=config.union,
        refine=refine if config.refine else None, refine_min_scale=config.refine_min_decimation - 0.5,
        decimated=decimated)
    too_near = np.zeros((height, width), bool)
    beside = None
    if plan.guard is not None:     # (contests the bands' values before the ambiguity test drops any)
        too_near, beside = _near_guard(plan, pair_at, disparity, config)
    if outputs and len(plan.levels) > 1:
        _kernels.invalidate(disparity, confidence,
                            _ambiguous_across_bands(plan, outputs, disparity, config))
    disparity = remove_speckles(disparity, max_size_px=config.speckle_size_px,
                                max_diff_px=config.speckle_range_px)
    disparity = guard_depth_edges(disparity, guard_px=config.edge_guard, jump_px=config.edge_jump_px)
    if beside is not None:
        _kernels.invalidate(disparity, confidence, beside)
    disparity, confidence = fill_gaps(disparity, confidence, max_gap_px=config.gap_fill_px,
                                      max_diff_px=config.gap_fill_diff_px, support_px=config.gap_support)
    if beside is not None:
        # gap filling may have bridged them; cut off from their surroundings, values left
        # between too-near regions are speckles again
        _kernels.invalidate(disparity, confidence, beside)
        _drop_cut_off(disparity, beside, config)
    _kernels.zero_where_invalid(disparity, confidence)
    return DisparityResult(disparity_px=disparity, confidence=confidence, plan=plan, levels=levels,
                           too_near=too_near)
