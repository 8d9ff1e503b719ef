"""Matcher settings: one frozen dataclass and three presets.

``paper`` is exactly the paper's matcher (section 3.3-3.4): NSSD of eq. (9) on the
raw intensities, winner-take-all eq. (10), a median filter per level, gating
(eq. 11) and union (eq. 12), nothing else. ``robust`` (the default) adds what
robot users expect from OpenCV StereoBM / ROS stereo_image_proc: an x-Sobel
pre-filter (gain/offset differences of real cameras), ZNCC, a left-right check,
uniqueness ratio, maximum cost, sub-pixel parabola and speckle removal, plus four steps
beyond the paper: fewer levels for a small search range, full-resolution re-scoring of
the coarsest level, a guard against window "fattening" at depth edges and the filling of
short gaps between two ends on one surface. ``mapping`` is ``robust`` with stricter
acceptance, no gap filling and the cross-band ambiguity test, for the robot's map. Defaults were
chosen by measurement on Middlebury/KITTI (docs/matching.md).
Conventions: docs/conventions.md.
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace

from .. import _checks
from .cost import COSTS, PREFILTERS

__all__ = ["MatchingConfig", "PRESETS", "preset_config"]

UNIONS = ("finer", "confidence", "reject")


@dataclass(frozen=True)
class MatchingConfig:
    """Settings of :func:`mrstereo.matching.compute_disparity`.

    Attributes
    ----------
    window_px : int
        Odd window size ``W`` of eq. (9) (``w = (W - 1) / 2``), in pixels of each level.
    cost : {"nssd", "zncc"}
        ``"nssd"``: eq. (9). ``"zncc"``: 1 - zero-mean normalized cross-correlation.
    prefilter : {"none", "xsobel", "mean"}
        Image pre-filter before the cost (see :func:`mrstereo.matching.cost.prefilter`).
    prefilter_cap : int
        Clip bound of the pre-filter (OpenCV StereoBM: 31). The robust default 7 keeps
        little more than the sign of the x-derivative beyond the noise (the pre-filter is
        ``Sobel_x / 4``; 1 grey level of noise becomes about 0.9): one strong edge then
        weighs no more in a window than weak texture, which cuts errors at depth edges
        (docs/matching.md).
    multi_range : bool
        False: one level at full resolution searching ``[0, max]`` of the given search.
    decimations : tuple of int, optional
        Horizontal decimation of each level, ordered like the bands from the nearest
        (largest disparities) to the farthest; default ``(4, 2, 1)`` for three bands,
        ``(2, 1)`` for two, ``(1,)`` for one. Given with ``max_disparity_px``, its length
        sets the number of default bands.
    min_band_level_px : float
        With ``max_disparity_px`` and no ``decimations``: use the most levels (up to 3)
        whose nearest band ``[D/2, D]`` still spans this many level pixels at its
        decimation (:func:`mrstereo.matching.multirange.default_level_count`; 4: three
        levels for ``D >= 32``, two for ``D >= 16``, else one). 0: always three levels.
    band_margin_px : int
        Extra disparities searched beyond each band edge (level pixels); a winner in the
        margin lies outside the band and is gated away (eq. 11) instead of sticking to
        the band edge.
    median_size : int
        Median filter per level (section 3.4): 0 (off), 3 or 5.
    lr_max_diff_px : float or None
        Left-right check tolerance in level pixels (None = off).
    uniqueness_ratio : float
        Reject when the second-best cost (2+ px from the winner) is within this fraction
        of the best: ``c2 * (1 - ratio) < c1`` (0 = off; StereoBM's uniquenessRatio/100).
    ambiguity_margin : float or None
        Cross-band ambiguity test (beyond the paper; None = off): a united value is dropped
        when another band's own best minimum (a rival, at least 2 of its level pixels away)
        costs less than the value's winner cost plus this margin (cost units: for ZNCC a
        correlation margin). Repeated patterns whose period spans more than a band otherwise
        give a far (or near) band a unique, confident winner one period off (docs/matching.md).
        Applied when the area of interest spans every row (the levels then hold whole images).
    ambiguity_max_cost : float
        A rival counts only when its cost is at most this (a confident minimum: a repeated
        high-contrast pattern, not weak texture).
    texture_threshold : float
        Reject when the window's standard deviation of the gray image is below this (grey
        levels; 0 = off).
    max_cost : float or None
        Reject winners whose cost exceeds this (None = off). For ZNCC the cost is
        ``1 - correlation``, so 0.6 keeps correlations above 0.4; it drops matches of
        pixels whose true disparity lies outside the level's band and weak matches on
        plain walls and floors.
    subpixel : bool
        Parabola through the costs at ``d - 1, d, d + 1``.
    speckle_size_px : int
        Remove connected regions smaller than this (full-resolution pixels; 0 = off).
    speckle_range_px : float
        Disparity step that still connects two pixels of one speckle region.
    union : {"finer", "confidence", "reject"}
        Eq. (12) where several levels report a disparity for one pixel: keep the finer
        level, the more confident one, or drop the pixel when the two disagree.
    refine : bool
        Re-score each decimated level's winner ``d`` (full-resolution pixels) at full
        resolution over ``d - h .. d + h``, ``h = ceil(k / 2) + refine_margin_px`` (beyond the
        paper; see :func:`mrstereo.matching.cost.refine_candidates`).
    refine_margin_px : int
        Extra offsets searched by the refinement beyond the level's half pixel.
    refine_min_decimation : int
        Only levels decimated by at least this much are refined (default 3: the ``k = 4``
        level; its winners are off by up to 2 px, those of ``k = 2`` by about 1 px, which
        bad-2 tolerates, so refining them costs more time than it gains).
    edge_guard_px : int or None
        Drop pixels with a disparity more than ``edge_jump_px`` above the lowest one
        within this many columns (foreground side of depth edges, where windows fatten
        objects; see :func:`mrstereo.matching.postfilter.guard_depth_edges`). None:
        ``window_px // 2 + 2``; 0: off.
    edge_jump_px : float
        Disparity step that counts as a depth edge for ``edge_guard_px``.
    gap_fill_px : int
        Fill runs of at most this many invalid pixels along rows, then columns, by
        linear interpolation, when the two ends differ by at most ``gap_fill_diff_px``
        and each is backed by ``gap_fill_support_px`` valid pixels agreeing with it (one
        surface on both sides; beyond the paper, see
        :func:`mrstereo.matching.postfilter.fill_gaps`). 0: off (holes stay holes).
    gap_fill_diff_px : float
        Largest disparity difference between the two ends of a filled gap.
    gap_fill_support_px : int or None
        Consecutive valid pixels (the end included) within ``gap_fill_diff_px`` of each
        end. None: ``window_px // 2 + 1`` (half a window); 1: the ends alone (ELAS).
    near_guard : float
        Too-near detection (beyond the paper): a search of its own covers the disparities
        from the largest one ``D`` to ``near_guard * D``; pixels whose confirmed match lies
        there are "too near" (NaN, flagged in ``DisparityResult.too_near``) instead of
        keeping a smaller, wrong disparity from a band they do not belong to. The bands'
        results are not touched unless a too-near region is found (docs/matching.md).
        0: off (the paper); else at least 1.
    near_guard_decimation : int or None
        Horizontal decimation of the guard's search (see
        :func:`mrstereo.matching.multirange.plan_levels`); None: twice the nearest band's
        when the near limit spans at least 8 pixels of those images, else the nearest band's.
    """

    window_px: int = 9
    cost: str = "zncc"
    prefilter: str = "xsobel"
    prefilter_cap: int = 7
    multi_range: bool = True
    decimations: tuple[int, ...] | None = None
    min_band_level_px: float = 4.0
    band_margin_px: int = 2
    median_size: int = 5
    lr_max_diff_px: float | None = 1.0
    uniqueness_ratio: float = 0.10
    ambiguity_margin: float | None = None
    ambiguity_max_cost: float = 0.2
    texture_threshold: float = 0.0
    max_cost: float | None = 0.6
    subpixel: bool = True
    speckle_size_px: int = 300
    speckle_range_px: float = 1.0
    union: str = "confidence"
    refine: bool = True
    refine_margin_px: int = 1
    refine_min_decimation: int = 3
    edge_guard_px: int | None = None
    edge_jump_px: float = 2.0
    gap_fill_px: int = 12
    gap_fill_diff_px: float = 1.0
    gap_fill_support_px: int | None = None
    near_guard: float = 2.0
    near_guard_decimation: int | None = None
    too_near_margin_px: int | None = None

    def __post_init__(self) -> None:
        window = _checks.positive_int("window_px", self.window_px, minimum=3)
        if window % 2 == 0:
            raise ValueError(f"window_px must be odd, got {window}")
        if self.cost not in COSTS:
            raise ValueError(f"cost must be one of {COSTS}, got {self.cost!r}")
        if self.prefilter not in PREFILTERS:
            raise ValueError(f"prefilter must be one of {PREFILTERS}, got {self.prefilter!r}")
        _checks.positive_int("prefilter_cap", self.prefilter_cap)
        if self.decimations is not None:
            if len(self.decimations) == 0:
                raise ValueError("decimations must not be empty")
            for k in self.decimations:
                _checks.positive_int("decimations", k)
        _checks.finite_number("min_band_level_px", self.min_band_level_px, nonnegative=True)
        _checks.positive_int("band_margin_px", self.band_margin_px, minimum=0)
        if self.median_size not in (0, 3, 5):
            raise ValueError(f"median_size must be 0, 3 or 5, got {self.median_size}")
        if self.lr_max_diff_px is not None:
            _checks.finite_number("lr_max_diff_px", self.lr_max_diff_px, nonnegative=True)
        ratio = _checks.finite_number("uniqueness_ratio", self.uniqueness_ratio, nonnegative=True)
        if ratio >= 1:
            raise ValueError(f"uniqueness_ratio must be < 1, got {ratio}")
        if self.ambiguity_margin is not None:
            _checks.finite_number("ambiguity_margin", self.ambiguity_margin, nonnegative=True)
        _checks.finite_number("ambiguity_max_cost", self.ambiguity_max_cost, nonnegative=True)
        _checks.finite_number("texture_threshold", self.texture_threshold, nonnegative=True)
        if self.max_cost is not None:
            _checks.finite_number("max_cost", self.max_cost, positive=True)
        _checks.positive_int("speckle_size_px", self.speckle_size_px, minimum=0)
        _checks.finite_number("speckle_range_px", self.speckle_range_px, positive=True)
        _checks.positive_int("refine_margin_px", self.refine_margin_px, minimum=0)
        _checks.positive_int("refine_min_decimation", self.refine_min_decimation, minimum=2)
        if self.edge_guard_px is not None:
            _checks.positive_int("edge_guard_px", self.edge_guard_px, minimum=0)
        _checks.finite_number("edge_jump_px", self.edge_jump_px, positive=True)
        _checks.positive_int("gap_fill_px", self.gap_fill_px, minimum=0)
        _checks.finite_number("gap_fill_diff_px", self.gap_fill_diff_px, nonnegative=True)
        if self.gap_fill_support_px is not None:
            _checks.positive_int("gap_fill_support_px", self.gap_fill_support_px)
        guard = _checks.finite_number("near_guard", self.near_guard, nonnegative=True)
        if 0 < guard < 1:
            raise ValueError(f"near_guard must be 0 (off) or >= 1, got {guard}")
        if self.near_guard_decimation is not None:
            _checks.positive_int("near_guard_decimation", self.near_guard_decimation)
        if self.too_near_margin_px is not None:
            _checks.positive_int("too_near_margin_px", self.too_near_margin_px, minimum=0)
        if window > 31:
            raise ValueError(f"window_px must be <= 31, got {window}")
        if self.union not in UNIONS:
            raise ValueError(f"union must be one of {UNIONS}, got {self.union!r}")

    @property
    def edge_guard(self) -> int:
        """Effective ``edge_guard_px`` (None resolved from the window)."""
        return self.window_px // 2 + 2 if self.edge_guard_px is None else self.edge_guard_px

    @property
    def too_near_margin(self) -> int:
        """Effective ``too_near_margin_px`` (None resolved from the window)."""
        return self.window_px // 2 + 2 if self.too_near_margin_px is None else self.too_near_margin_px

    @property
    def gap_support(self) -> int:
        """Effective ``gap_fill_support_px`` (None resolved from the window)."""
        return self.window_px // 2 + 1 if self.gap_fill_support_px is None else self.gap_fill_support_px

    def replace(self, **changes) -> MatchingConfig:
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)


PRESETS: dict[str, MatchingConfig] = {
    # Exactly eq. (9)-(12): raw intensities, NSSD, WTA, median per level, gate, union.
    "paper": MatchingConfig(cost="nssd", prefilter="none", min_band_level_px=0.0, band_margin_px=2,
                            median_size=5, lr_max_diff_px=None, uniqueness_ratio=0.0, texture_threshold=0.0,
                            max_cost=None, subpixel=False, speckle_size_px=0, union="confidence",
                            refine=False, edge_guard_px=0, gap_fill_px=0, near_guard=0.0),
    "robust": MatchingConfig(),
    # The robust matcher as the robot's mapping chain uses it: stricter acceptance (a wrong
    # match becomes an obstacle cell that later frames must clear) and StereoBM's pre-filter
    # clip, which keeps more texture on plain corridor walls. Chosen by the map and obstacle
    # metrics of the synthetic corridor (seeds 0, 1; checked on 2): precision 0.909 vs 0.879
    # with the robust values, obstacle-cell recall 0.971 vs 0.926 (docs/matching.md).
    # No gap filling: map cells come from measured points only. The cross-band ambiguity test
    # (a repeated pattern gives no value one period off): margin 0.15, rivals within cost 0.2,
    # chosen on randomized worlds 0-9, plain and with striped walls (docs/matching.md).
    "mapping": MatchingConfig(prefilter_cap=31, max_cost=0.5, speckle_range_px=2.0, gap_fill_px=0,
                              ambiguity_margin=0.15, ambiguity_max_cost=0.2),
}


def preset_config(name: str) -> MatchingConfig:
    """The named preset (``"robust"``, ``"mapping"`` or ``"paper"``)."""
    if name not in PRESETS:
        raise ValueError(f"preset must be one of {tuple(PRESETS)}, got {name!r}")
    return PRESETS[name]


def config_fields() -> tuple[str, ...]:
    """Names of the settings (for CLI/YAML overrides)."""
    return tuple(f.name for f in fields(MatchingConfig))
