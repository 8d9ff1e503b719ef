"""Matcher settings: one frozen dataclass per concern, composed by :class:`MatchingConfig`, and three presets.

``paper`` is exactly the paper's matcher (section 3.3-3.4: NSSD eq. (9), winner-take-all eq. (10),
median, gating eq. (11), union eq. (12)); ``robust`` (the default) adds what OpenCV StereoBM / ROS
stereo_image_proc users expect and the steps beyond the paper; ``mapping`` is ``robust`` with
stricter acceptance for the robot's map. What each adds and how the defaults were chosen:
docs/matching.md ("Presets"). No kernel sees a config object: :func:`mrstereo.matching.compute_disparity`
unpacks the groups into keyword arguments. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from .. import _checks

__all__ = ["MatchingConfig", "CostConfig", "SearchConfig", "AcceptanceConfig", "SubpixelConfig", "NearGuardConfig",
           "AmbiguityConfig", "PostFilterConfig", "PRESETS", "preset_config", "COSTS", "PREFILTERS"]

COSTS = ("nssd", "zncc")
PREFILTERS = ("none", "xsobel")


@dataclass(frozen=True)
class CostConfig:
    """The window cost of eq. (9) and the images it compares.

    Attributes
    ----------
    window_px : int
        Odd window size ``W`` of eq. (9) (``w = (W - 1) / 2``), in pixels of each level, 3-31.
    kind : {"nssd", "zncc"}
        ``"nssd"``: eq. (9) (the paper's reference). ``"zncc"``: 1 - zero-mean normalized
        cross-correlation.
    prefilter : {"none", "xsobel"}
        ``"none"``: the raw intensities (eq. 9); ``"xsobel"``: OpenCV StereoBM's pre-filter
        (see :func:`mrstereo.matching.cost.prefilter`).
    prefilter_cap : int
        Clip bound of the pre-filter (OpenCV StereoBM: 31; why the robust default is 7:
        docs/matching.md).
    """

    window_px: int = 9
    kind: str = "zncc"
    prefilter: str = "xsobel"
    prefilter_cap: int = 7

    def __post_init__(self) -> None:
        window = _checks.positive_int("window_px", self.window_px, minimum=3)
        if window % 2 == 0:
            raise ValueError(f"window_px must be odd, got {window}")
        if window > 31:
            raise ValueError(f"window_px must be <= 31, got {window}")
        if self.kind not in COSTS:
            raise ValueError(f"cost kind must be one of {COSTS}, got {self.kind!r}")
        if self.prefilter not in PREFILTERS:
            raise ValueError(f"prefilter must be one of {PREFILTERS}, got {self.prefilter!r}")
        _checks.positive_int("prefilter_cap", self.prefilter_cap)


@dataclass(frozen=True)
class SearchConfig:
    """The multi-range plan: levels and bands (sections 3.1-3.2, eq. 11).

    Attributes
    ----------
    multi_range : bool
        False: one level at full resolution searching ``[0, max]`` of the given search.
    decimations : tuple of int, optional
        Horizontal decimation of each level, ordered like the bands from the nearest
        (largest disparities) to the farthest; default ``(4, 2, 1)`` for three bands,
        ``(2, 1)`` for two, ``(1,)`` for one. Given with ``max_disparity_px``, its length
        sets the number of default bands.
    min_band_level_px : float
        With ``max_disparity_px`` and no ``decimations``: the level count rule of
        :func:`mrstereo.matching.multirange.default_level_count`. 0: always three levels.
    band_margin_px : int
        Extra disparities searched beyond each band edge (level pixels); a winner in the
        margin lies outside the band and is gated away (eq. 11) instead of sticking to
        the band edge.
    """

    multi_range: bool = True
    decimations: tuple[int, ...] | None = None
    min_band_level_px: float = 4.0
    band_margin_px: int = 2

    def __post_init__(self) -> None:
        if self.decimations is not None:
            if len(self.decimations) == 0:
                raise ValueError("decimations must not be empty")
            for k in self.decimations:
                _checks.positive_int("decimations", k)
        _checks.finite_number("min_band_level_px", self.min_band_level_px, nonnegative=True)
        _checks.positive_int("band_margin_px", self.band_margin_px, minimum=0)


@dataclass(frozen=True)
class AcceptanceConfig:
    """What a level's winner (eq. 10) must pass to be kept.

    Attributes
    ----------
    lr_max_diff_px : float or None
        Left-right check tolerance in level pixels (None = off).
    uniqueness_ratio : float
        Reject when the second-best cost (2+ px from the winner) is within this fraction
        of the best: ``c2 * (1 - ratio) < c1`` (0 = off; StereoBM's uniquenessRatio/100).
    max_cost : float or None
        Reject winners whose cost exceeds this (None = off). For ZNCC the cost is
        ``1 - correlation``, so 0.6 keeps correlations above 0.4; it drops matches of
        pixels whose true disparity lies outside the level's band and weak matches on
        plain walls and floors.
    median_size : int
        Median filter per level (section 3.4): 0 (off), 3 or 5.
    """

    lr_max_diff_px: float | None = 1.0
    uniqueness_ratio: float = 0.10
    max_cost: float | None = 0.6
    median_size: int = 5

    def __post_init__(self) -> None:
        if self.lr_max_diff_px is not None:
            _checks.finite_number("lr_max_diff_px", self.lr_max_diff_px, nonnegative=True)
        ratio = _checks.finite_number("uniqueness_ratio", self.uniqueness_ratio, nonnegative=True)
        if ratio >= 1:
            raise ValueError(f"uniqueness_ratio must be < 1, got {ratio}")
        if self.max_cost is not None:
            _checks.finite_number("max_cost", self.max_cost, positive=True)
        if self.median_size not in (0, 3, 5):
            raise ValueError(f"median_size must be 0, 3 or 5, got {self.median_size}")


@dataclass(frozen=True)
class SubpixelConfig:
    """Disparity finer than a level pixel.

    Attributes
    ----------
    parabola : bool
        Parabola through the costs at ``d - 1, d, d + 1``.
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
    """

    parabola: bool = True
    refine: bool = True
    refine_margin_px: int = 1
    refine_min_decimation: int = 3

    def __post_init__(self) -> None:
        _checks.positive_int("refine_margin_px", self.refine_margin_px, minimum=0)
        _checks.positive_int("refine_min_decimation", self.refine_min_decimation, minimum=2)


@dataclass(frozen=True)
class NearGuardConfig:
    """Too-near detection (beyond the paper; ``MatchingConfig.near_guard = None``: off, the paper).

    A search of its own covers ``D`` to ``reach * D``; pixels whose confirmed match lies there are
    "too near" (NaN, flagged in ``DisparityResult.too_near``; docs/matching.md).

    Attributes
    ----------
    reach : float
        The guard searches up to ``reach`` times the near limit ``D`` (at least 1).
    decimation : int or None
        Horizontal decimation of the guard's search (see
        :func:`mrstereo.matching.multirange.plan_levels`); None: twice the nearest band's
        when the near limit spans at least 8 pixels of those images, else the nearest band's.
    """

    reach: float = 2.0
    decimation: int | None = None

    def __post_init__(self) -> None:
        reach = _checks.finite_number("near_guard reach", self.reach, positive=True)
        if reach < 1:
            raise ValueError(f"near_guard reach must be >= 1, got {reach}")
        if self.decimation is not None:
            _checks.positive_int("near_guard decimation", self.decimation)


@dataclass(frozen=True)
class AmbiguityConfig:
    """Cross-band ambiguity test (beyond the paper; ``MatchingConfig.ambiguity = None``: off).

    A united value is dropped when another band's own best minimum costs less than the value's
    winner cost plus ``margin`` (repeated patterns, docs/matching.md). Applied when the area of
    interest spans every row.

    Attributes
    ----------
    margin : float
        Cost margin (for ZNCC a correlation margin).
    rival_max_cost : float
        A rival counts only when its cost is at most this (a confident minimum: a repeated
        high-contrast pattern, not weak texture).
    """

    margin: float = 0.15
    rival_max_cost: float = 0.2

    def __post_init__(self) -> None:
        _checks.finite_number("ambiguity margin", self.margin, nonnegative=True)
        _checks.finite_number("ambiguity rival_max_cost", self.rival_max_cost, nonnegative=True)


@dataclass(frozen=True)
class PostFilterConfig:
    """Filters of the united disparity map.

    Attributes
    ----------
    speckle_size_px : int
        Remove connected regions smaller than this (full-resolution pixels; 0 = off).
    speckle_range_px : float
        Disparity step that still connects two pixels of one speckle region.
    edge_guard_px : int or None
        Drop pixels with a disparity more than 2 px above the lowest one within this many
        columns (foreground side of depth edges, where windows fatten objects; see
        :func:`mrstereo.matching.postfilter.guard_depth_edges`). None: a window radius + 2
        (:attr:`MatchingConfig.fattening_px`); 0: off.
    gap_fill_px : int
        Longest run of invalid pixels filled on one surface (beyond the paper,
        :func:`mrstereo.matching.postfilter.fill_gaps`). 0: off.
    gap_fill_support_px : int or None
        Consecutive valid pixels (the end included) within 1 px of each end. None: half a
        window (``window_px // 2 + 1``); 1: the ends alone (ELAS).
    """

    speckle_size_px: int = 300
    speckle_range_px: float = 1.0
    edge_guard_px: int | None = None
    gap_fill_px: int = 12
    gap_fill_support_px: int | None = None

    def __post_init__(self) -> None:
        _checks.positive_int("speckle_size_px", self.speckle_size_px, minimum=0)
        _checks.finite_number("speckle_range_px", self.speckle_range_px, positive=True)
        if self.edge_guard_px is not None:
            _checks.positive_int("edge_guard_px", self.edge_guard_px, minimum=0)
        _checks.positive_int("gap_fill_px", self.gap_fill_px, minimum=0)
        if self.gap_fill_support_px is not None:
            _checks.positive_int("gap_fill_support_px", self.gap_fill_support_px)


# Disparity step that counts as a depth edge for the edge guard, and the largest difference
# between the two ends of a filled gap: one surface varies less than this between neighbours.
EDGE_JUMP_PX = 2.0
GAP_FILL_DIFF_PX = 1.0

_OPTIONAL = {"near_guard": NearGuardConfig, "ambiguity": AmbiguityConfig}


@dataclass(frozen=True)
class MatchingConfig:
    """Settings of :func:`mrstereo.matching.compute_disparity`, one group per concern.

    Attributes
    ----------
    cost : CostConfig
        Window, cost (eq. 9 or ZNCC) and pre-filter.
    search : SearchConfig
        Levels and bands of the multi-range plan.
    acceptance : AcceptanceConfig
        Left-right, uniqueness and maximum-cost checks and the median per level.
    subpixel : SubpixelConfig
        Parabola and full-resolution re-scoring of coarse levels.
    near_guard : NearGuardConfig or None
        Too-near detection (None: off, the paper).
    ambiguity : AmbiguityConfig or None
        Cross-band ambiguity test of the union (None: off).
    postfilter : PostFilterConfig
        Speckles, depth-edge guard, gap filling.
    """

    cost: CostConfig = CostConfig()
    search: SearchConfig = SearchConfig()
    acceptance: AcceptanceConfig = AcceptanceConfig()
    subpixel: SubpixelConfig = SubpixelConfig()
    near_guard: NearGuardConfig | None = NearGuardConfig()
    ambiguity: AmbiguityConfig | None = None
    postfilter: PostFilterConfig = PostFilterConfig()

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            group = _OPTIONAL.get(f.name) or type(f.default)
            if not (isinstance(value, group) or (value is None and f.name in _OPTIONAL)):
                allowed = f"a {group.__name__}" + (" or None" if f.name in _OPTIONAL else "")
                raise TypeError(f"MatchingConfig.{f.name} must be {allowed}, got {type(value).__name__}")

    @property
    def fattening_px(self) -> int:
        """How far a window carries a nearer surface past its edge: a window radius + 2 px (the
        default edge guard, and the margin the near guard clears around a too-near region)."""
        return self.cost.window_px // 2 + 2

    @property
    def edge_guard(self) -> int:
        """Effective ``postfilter.edge_guard_px`` (None resolved from the window)."""
        guard = self.postfilter.edge_guard_px
        return self.fattening_px if guard is None else guard

    @property
    def gap_support(self) -> int:
        """Effective ``postfilter.gap_fill_support_px`` (None resolved from the window)."""
        support = self.postfilter.gap_fill_support_px
        return self.cost.window_px // 2 + 1 if support is None else support

    def replace(self, **changes) -> MatchingConfig:
        """A copy with some groups changed. Each value is a group, None (``near_guard``,
        ``ambiguity``: off) or a dict of the group's fields to change, e.g.
        ``config.replace(postfilter={"gap_fill_px": 0}, near_guard=None)``."""
        for name, value in changes.items():
            if isinstance(value, dict):
                if name not in _OPTIONAL and name not in {f.name for f in dataclasses.fields(self)}:
                    raise TypeError(f"MatchingConfig has no group {name!r}")
                current = getattr(self, name)
                current = _OPTIONAL[name]() if current is None else current
                changes[name] = dataclasses.replace(current, **value)
        return dataclasses.replace(self, **changes)


PRESETS: dict[str, MatchingConfig] = {
    # Exactly eq. (9)-(12): raw intensities, NSSD, WTA, median per level, gate, union.
    "paper": MatchingConfig(
        cost=CostConfig(kind="nssd", prefilter="none"), search=SearchConfig(min_band_level_px=0.0),
        acceptance=AcceptanceConfig(lr_max_diff_px=None, uniqueness_ratio=0.0, max_cost=None),
        subpixel=SubpixelConfig(parabola=False, refine=False), near_guard=None,
        postfilter=PostFilterConfig(speckle_size_px=0, edge_guard_px=0, gap_fill_px=0)),
    "robust": MatchingConfig(),
    # The robust matcher as the robot's mapping chain uses it: stricter acceptance (a wrong
    # match becomes an obstacle cell that later frames must clear) and StereoBM's pre-filter
    # clip, which keeps more texture on plain corridor walls; chosen by the map and obstacle
    # metrics of the synthetic corridor (docs/matching.md). No gap filling: map cells come
    # from measured points only. The cross-band ambiguity test keeps a repeated pattern from
    # giving a value one period off (chosen on randomized worlds, plain and with striped walls).
    "mapping": MatchingConfig(
        cost=CostConfig(prefilter_cap=31), acceptance=AcceptanceConfig(max_cost=0.5),
        postfilter=PostFilterConfig(speckle_range_px=2.0, gap_fill_px=0),
        ambiguity=AmbiguityConfig(margin=0.15, rival_max_cost=0.2)),
}


def preset_config(name: str) -> MatchingConfig:
    """The named preset (``"robust"``, ``"mapping"`` or ``"paper"``)."""
    if name not in PRESETS:
        raise ValueError(f"preset must be one of {tuple(PRESETS)}, got {name!r}")
    return PRESETS[name]
