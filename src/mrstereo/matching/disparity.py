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
from dataclasses import dataclass, field

import numpy as np

from .. import _checks
from ..profiling import stage
from . import _union_kernels
from .config import EDGE_JUMP_PX, GAP_FILL_DIFF_PX, MatchingConfig, preset_config
from .cost import match_checked, prepare, prepare_gray, refine_candidates, scratch
from .multirange import (DEFAULT_DEPTH_EDGES_M, LevelOutput, MultiRangePlan, RangeLevel, bands_px_from_depth_m,
                         decimate_horizontally, default_bands_px, default_level_count, plan_levels, run_levels)
from .near_guard import drop_cut_off, too_near
from .postfilter import fill_gaps, guard_depth_edges, median_filter, remove_speckles

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
        :mod:`.near_guard`), NaN in ``disparity_px``. Robot code treats them as an obstacle at
        the near limit (docs/obstacles.md).
    confidence : ndarray float32 (H, W)
        In [0, 1]: the winner's margin ``1 - c1 / c2`` over the best cost at least 2 px away (1
        without one); 0 where invalid.
    plan : MultiRangePlan
        The levels searched and their work (``plan.describe()``).
    levels : tuple of ndarray float32 (H, W)
        Each level's gated, full-width disparity (finest level first; a refined level re-scored
        at full resolution where the union can take its values, up-sampled elsewhere), before the
        union.
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

    Parameters
    ----------
    image_size : (int, int)
        ``(width, height)`` of the images.
    max_disparity_px, disparity_bands_px, calibration, depth_bands_m, config, preset, aoi
        As :func:`compute_disparity`.
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
    search = config.search
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
        n = (len(search.decimations) if search.decimations is not None
             else default_level_count(d_max, min_band_level_px=search.min_band_level_px))
        bands = default_bands_px(d_max, n) if search.multi_range else ((0.0, d_max),)
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
    decimations = search.decimations
    if not search.multi_range and len(bands) > 1:
        bands = ((min(b[0] for b in bands), max(b[1] for b in bands)),)
        near = min(z[0] for z in depth_bands) if depth_bands else None
        depth_bands = None if depth_bands is None else ((near, max(z[1] for z in depth_bands)),)
    if not search.multi_range:
        decimations = (1,)
    return plan_levels((width, height), bands, decimations=decimations,
                       band_margin_px=search.band_margin_px, aoi=_aoi(aoi, width, height),
                       depth_bands_m=depth_bands, focal_px=focal, baseline_m=baseline,
                       near_guard_reach=None if config.near_guard is None else config.near_guard.reach,
                       near_guard_decimation=None if config.near_guard is None else config.near_guard.decimation)


def _depth(d: float, focal: float, baseline: float, doffs: float) -> float:
    return baseline * focal / (d + doffs) if d + doffs > 0 else math.inf


def _check_search_memory(plan, config: MatchingConfig, *, given: str) -> None:
    """Refuse a search whose per-thread cost buffers (disparities x columns) exceed the memory."""
    import numba

    threads = numba.get_num_threads()
    widest = max(plan.levels, key=lambda lv: (lv.search_px[1] - lv.search_px[0] + 1) * lv.size[0])
    n_disp = widest.search_px[1] - widest.search_px[0] + 1
    nbytes = threads * n_disp * (widest.size[0] + config.cost.window_px) * 12.0
    _checks.fits_in_memory(given, nbytes, f"the matching cost buffers ({n_disp:.4g} disparities x "
                                          f"{widest.size[0]} columns x {threads} threads)")


def _prepare_pair(left: np.ndarray, right: np.ndarray, config: MatchingConfig):
    """Pre-filter both images and prepare them for the kernels."""
    cost = config.cost
    pair = tuple(prepare_gray(img, kind=cost.prefilter, cap=cost.prefilter_cap, window=cost.window_px, cost=cost.kind)
                 for img in (left, right))
    if pair[0].padded.dtype != pair[1].padded.dtype:      # one exact, the other not: both float64
        pair = tuple(prepare(p.padded[p.window // 2:-(p.window // 2), p.window // 2:-(p.window // 2)],
                             window=cost.window_px, cost=cost.kind, dtype=np.float64) for p in pair)
    return pair


def _solve_prepared(pair, level: RangeLevel, rows: tuple[int, int], cols: tuple[int, int],
                    config: MatchingConfig) -> LevelOutput:
    checks = config.acceptance
    # the band without its search margins, in level pixels, for the cross-band ambiguity test
    alt_band = None if config.ambiguity is None else (math.ceil(level.band_px[0] / level.scale),
                                                      math.floor(level.band_px[1] / level.scale))
    disparity, confidence, alt_px, alt_cost, best_cost = match_checked(
        *pair, d_lo=level.search_px[0], d_hi=level.search_px[1], rows=rows, cols=cols,
        lr_max_diff_px=checks.lr_max_diff_px, uniqueness_ratio=checks.uniqueness_ratio, max_cost=checks.max_cost,
        subpixel=config.subpixel.parabola, alt_band=alt_band)
    if checks.median_size:
        disparity = median_filter(disparity, size=checks.median_size,
                                  max_px=level.search_px[1] + 0.5)      # (+ the parabola offset)
        _union_kernels.zero_where_invalid(disparity, confidence)
    return LevelOutput(disparity_px=disparity, confidence=confidence, alt_px=alt_px, alt_cost=alt_cost,
                       best_cost=best_cost)


def solve_level(left: np.ndarray, right: np.ndarray, level: RangeLevel, rows: tuple[int, int],
                cols: tuple[int, int], *, config: MatchingConfig) -> LevelOutput:
    """The per-level solver: pre-filter, eq. (9)-(10) over ``level.search_px``, checks, median.

    Checks (each off when its setting is): left-right consistency, uniqueness ratio,
    maximum cost. Disparities are in level pixels; the driver gates and up-samples them.

    Parameters
    ----------
    left, right : ndarray float32 (h, w_level)
        The level's images.
    level : RangeLevel
        The level (its search).
    rows, cols : (int, int)
        Half-open rows and columns to evaluate (level coordinates).
    config : MatchingConfig
        The matcher's settings.
    """
    return _solve_prepared(_prepare_pair(left, right, config), level, rows, cols, config)


@dataclass
class _Levels:
    """What the levels of one :func:`compute_disparity` call share: the prepared (pre-filtered,
    padded, window terms) whole-image pairs by level width, made on first use (the finest
    level's pair also serves the refinement of the coarser ones and the near guard), the
    decimated images (shared with :func:`.multirange.run_levels`) and, for the cross-band
    ambiguity test, each whole-height level's output."""

    left: np.ndarray
    right: np.ndarray
    config: MatchingConfig
    rows: tuple[int, int]
    decimated: dict = field(default_factory=dict)
    pairs: dict = field(default_factory=dict)
    outputs: dict = field(default_factory=dict)

    def pair_at(self, w_level: int):
        if w_level not in self.pairs:
            with stage("match.prepare"):
                if w_level not in self.decimated:
                    self.decimated[w_level] = (decimate_horizontally(self.left, w_level),
                                               decimate_horizontally(self.right, w_level))
                self.pairs[w_level] = _prepare_pair(*self.decimated[w_level], self.config)
        return self.pairs[w_level]

    def solve(self, left: np.ndarray, right: np.ndarray, level: RangeLevel, rows, cols) -> LevelOutput:
        """:func:`solve_level`, on the shared pair when the level's images have the whole height."""
        whole = left.shape[0] == self.left.shape[0]
        pair = self.pair_at(left.shape[1]) if whole else None
        with stage("match.search"):
            if whole:
                out = _solve_prepared(pair, level, rows, cols, self.config)
            else:
                out = solve_level(left, right, level, rows, cols, config=self.config)
        if self.config.ambiguity is not None and whole:
            self.outputs[level] = out
        return out

    def refine(self, level: RangeLevel, coarse_px: np.ndarray, want: np.ndarray) -> np.ndarray:
        """Full-resolution re-scoring of a coarse level (beyond the paper)."""
        pair = self.pair_at(self.left.shape[1])
        half_px = int(math.ceil(level.scale / 2)) + self.config.subpixel.refine_margin_px
        with stage("match.refine"):       # in place: the wanted pixels are the valid ones it can change
            refined, _ = refine_candidates(*pair, coarse_px, want, rows=self.rows, half_px=half_px,
                                           max_cost=self.config.acceptance.max_cost,
                                           into=(coarse_px, scratch("refine_cost", coarse_px.shape, np.float32)))
        return refined


def _ambiguous_across_bands(plan: MultiRangePlan, outputs: dict, disparity: np.ndarray,
                            config: MatchingConfig) -> np.ndarray:
    """Pixels whose united value another band contests (beyond the paper; eq. 12 over the bands).

    The uniqueness test of eq. (10) across the bands, with an absolute margin: another band's
    own best minimum (``LevelOutput.alt_px``, at least 2 of its level pixels away, costing at
    most ``config.ambiguity.rival_max_cost``) is a rival; the value is ambiguous when a rival
    costs less than its winner cost plus ``config.ambiguity.margin`` (docs/matching.md,
    "Repeated patterns"). Returns a bool mask (H, W).
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
        _union_kernels.band_value_cost(disparity, out.best_cost, source, np.float32(level.band_px[0]),
                                 np.float32(level.band_px[1]), value_cost)
    for (level, out), source in zip(levels, sources):
        _union_kernels.band_rivals(disparity, out.alt_px, out.alt_cost, source, np.float32(level.scale),
                             np.float32(level.band_px[0]), np.float32(level.band_px[1]),
                             np.float32(2.0 * level.scale), np.float32(config.ambiguity.rival_max_cost),
                             np.float32(config.ambiguity.margin), value_cost, ambiguous)
    return ambiguous


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
        decimations 1, 2, 4 (fewer for a small ``D``; docs/matching.md).
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
    Eq. (9) with our sign convention (:mod:`.cost`); a level's disparity ``d_k`` becomes
    ``k d_k`` before gating (eq. 11); the more confident level wins (eq. 12).
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
    if config.cost.window_px > min(width, height):
        raise ValueError(f"window_px {config.cost.window_px} is larger than the image ({width}x{height})")
    _check_search_memory(plan, config, given=next(
        (name for name, value in (("max_disparity_px", max_disparity_px), ("disparity_bands_px", disparity_bands_px),
                                  ("depth_bands_m", depth_bands_m)) if value is not None), "calibration"))

    shared = _Levels(left_gray, right_gray, config, rows=plan.aoi[:2])
    sub = config.subpixel
    disparity, confidence, levels = run_levels(
        left_gray, right_gray, plan, shared.solve, row_pad_px=config.cost.window_px // 2 + 2,
        refine=shared.refine if sub.refine else None, refine_min_scale=sub.refine_min_decimation - 0.5,
        decimated=shared.decimated)
    near, beside = np.zeros((height, width), bool), None
    if plan.guard is not None:     # (contests the bands' values before the ambiguity test drops any)
        shared.pair_at(plan.guard.size[0])
        with stage("match.guard"):
            near, beside = too_near(plan, shared.pair_at, disparity, config)
    with stage("match.post"):
        if shared.outputs and len(plan.levels) > 1:
            ambiguous = _ambiguous_across_bands(plan, shared.outputs, disparity, config)
            _union_kernels.invalidate(disparity, confidence, ambiguous)
        disparity, confidence = _post_filter(disparity, confidence, beside, config)
    return DisparityResult(disparity_px=disparity, confidence=confidence, plan=plan, levels=levels, too_near=near)


def _post_filter(disparity: np.ndarray, confidence: np.ndarray, beside: np.ndarray | None,
                 config: MatchingConfig) -> tuple[np.ndarray, np.ndarray]:
    """Speckles, depth-edge guard, gap filling; the near guard's margins ``beside`` (None: no
    too-near region) lose their values before the gaps are filled and again after (gap filling
    may have bridged them), and values left between too-near regions are speckles again."""
    post = config.postfilter
    disparity = remove_speckles(disparity, max_size_px=post.speckle_size_px, max_diff_px=post.speckle_range_px)
    disparity = guard_depth_edges(disparity, guard_px=config.edge_guard, jump_px=EDGE_JUMP_PX)
    if beside is not None:
        _union_kernels.invalidate(disparity, confidence, beside)
    disparity, confidence = fill_gaps(disparity, confidence, max_gap_px=post.gap_fill_px,
                                      max_diff_px=GAP_FILL_DIFF_PX, support_px=config.gap_support)
    if beside is not None:
        _union_kernels.invalidate(disparity, confidence, beside)
        drop_cut_off(disparity, beside, config)
    _union_kernels.zero_where_invalid(disparity, confidence)
    return disparity, confidence
