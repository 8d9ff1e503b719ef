"""Multi-range area-based stereo matching (paper sections 3.1-3.4, eq. 9-12).

``compute_disparity(left, right, max_disparity_px=96)`` returns a
:class:`DisparityResult`; :class:`MatchingConfig` (one group of settings per concern) and
the ``paper``/``robust``/``mapping`` presets set the matcher; :func:`make_plan` shows the
levels and their work.
User guide: docs/matching.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

from .config import (PRESETS, AcceptanceConfig, AmbiguityConfig, CostConfig, MatchingConfig, NearGuardConfig,
                     PostFilterConfig, SearchConfig, SubpixelConfig, preset_config)
from .cost import BandMatch, match_band, prefilter
from .disparity import DisparityResult, compute_disparity, make_plan, solve_level
from .multirange import (DEFAULT_DEPTH_EDGES_M, LevelOutput, MultiRangePlan, RangeLevel, bands_px_from_depth_m,
                         default_bands_px, plan_levels, run_levels)

__all__ = [
    "compute_disparity", "DisparityResult", "MatchingConfig", "CostConfig", "SearchConfig", "AcceptanceConfig",
    "SubpixelConfig", "NearGuardConfig", "AmbiguityConfig", "PostFilterConfig", "PRESETS", "preset_config", "make_plan",
    "MultiRangePlan", "RangeLevel", "LevelOutput", "plan_levels", "run_levels", "default_bands_px",
    "bands_px_from_depth_m", "DEFAULT_DEPTH_EDGES_M", "match_band", "BandMatch", "prefilter",
    "solve_level",
]
