"""Multi-range matching (paper sections 3.1, 3.2, 3.4; eq. 11-12).

Each disparity band is searched on its own pair of horizontally decimated images (near objects:
coarse images); each level is median filtered, gated to its band (eq. 11), up-sampled to full
width and the levels are united (eq. 12). :func:`run_levels` is generic over the per-level
solver. User guide: docs/matching.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from .. import _checks
from . import _union_kernels

__all__ = ["RangeLevel", "MultiRangePlan", "LevelOutput", "plan_levels", "default_bands_px",
           "default_level_count", "bands_px_from_depth_m", "decimate_horizontally", "run_levels",
           "DEFAULT_DEPTH_EDGES_M"]

DEFAULT_DEPTH_EDGES_M = (0.5, 1.0, 2.5, 15.0)
# The near guard's search runs at twice the nearest band's decimation when the near limit D
# still spans this many pixels of those images (D >= 16 k), else at the nearest band's
# (chosen on Tsukuba and Venus cut to half their range, benchmarks/bench_too_near.py).
GUARD_MIN_LEVEL_PX = 8.0


@dataclass(frozen=True)
class RangeLevel:
    """One range of the multi-range plan (Range I/II/III of section 3.2).

    Attributes
    ----------
    decimation : int
        Nominal horizontal decimation ``k``.
    scale : float
        Exact horizontal scale ``W / W_level`` (equals ``k`` when ``k`` divides ``W``).
    size : (int, int)
        Level image ``(width, height)``.
    band_px : (float, float)
        Gate ``[Range(k)^-, Range(k)^+]`` of eq. (11) in full-resolution pixels.
    search_px : (int, int)
        Disparities searched, in level pixels (the band plus a margin).
    depth_band_m : (float, float) or None
        The band as depths ``(near, far)`` when the rig is calibrated.
    work : int
        Pixel x disparity evaluations of the level (inside the area of interest).
    too_near_above_px : float or None
        On the near guard's search (:attr:`MultiRangePlan.guard`): a winner above this
        disparity (full-resolution pixels) is a too-near candidate. None on the bands' levels.
    """

    decimation: int
    scale: float
    size: tuple[int, int]
    band_px: tuple[float, float]
    search_px: tuple[int, int]
    depth_band_m: tuple[float, float] | None
    work: int
    too_near_above_px: float | None = None


@dataclass(frozen=True)
class MultiRangePlan:
    """What :func:`mrstereo.matching.compute_disparity` will do, and what it costs.

    Attributes
    ----------
    levels : tuple of RangeLevel
        Finest (farthest) level first.
    image_size : (int, int)
        Full-resolution ``(width, height)``.
    aoi : (int, int, int, int)
        Area of interest ``(row0, row1, col0, col1)``, half-open (section 3.1).
    single_range_work : int
        Evaluations of one full-resolution search over the same disparities
        ``[min band, max band]`` (what a single-range matcher would do).
    focal_px, baseline_m : float or None
        Calibration used to express the bands as depths.
    guard : RangeLevel or None
        The near guard's search (beyond the paper; None when off): disparities past the
        near limit, searched apart from the bands (whose results it leaves unchanged) on
        images decimated at least as much as the nearest band's.
    """

    levels: tuple[RangeLevel, ...]
    image_size: tuple[int, int]
    aoi: tuple[int, int, int, int]
    single_range_work: int
    focal_px: float | None = None
    baseline_m: float | None = None
    guard: RangeLevel | None = None

    @property
    def work(self) -> int:
        """Total pixel x disparity evaluations of all levels and of the near guard."""
        return sum(level.work for level in self.levels) + (0 if self.guard is None else self.guard.work)

    def describe(self) -> str:
        """A human-readable table of the plan (the CLI's ``--explain``)."""
        w, h = self.image_size
        r0, r1, c0, c1 = self.aoi
        lines = [f"image {w}x{h}, area of interest rows {r0}:{r1}, cols {c0}:{c1}"]
        header = (f"{'level':>5} {'decim':>5} {'size':>9} {'band [px]':>15} {'search [lvl px]':>15} "
                  f"{'depth [m]':>13} {'work [Mev]':>10}")
        lines.append(header)
        for i, lvl in enumerate(self.levels):
            depth = "-" if lvl.depth_band_m is None else \
                f"{lvl.depth_band_m[0]:.2f}-{_fmt_depth(lvl.depth_band_m[1])}"
            lines.append(f"{i:>5} {lvl.decimation:>5} {lvl.size[0]:>4}x{lvl.size[1]:<4} "
                         f"{lvl.band_px[0]:>7.2f}-{lvl.band_px[1]:<7.2f} "
                         f"{lvl.search_px[0]:>7}-{lvl.search_px[1]:<7} {depth:>13} "
                         f"{lvl.work / 1e6:>10.2f}")
        lo = min(lvl.band_px[0] for lvl in self.levels)
        hi = max(lvl.band_px[1] for lvl in self.levels)
        ratio = self.work / max(self.single_range_work, 1)
        if self.guard is not None:
            g = self.guard
            top = g.search_px[1] * g.scale
            depth = "" if self.focal_px is None else f" ({self.baseline_m * self.focal_px / top:.2f} m)"
            lines.append(f"too-near guard: decimation {g.decimation} searches {g.search_px[0]}-{g.search_px[1]} "
                         f"level px, on to {top:.1f} px{depth}, {g.work / 1e6:.2f} Mev; a confirmed winner above "
                         f"{g.too_near_above_px:.1f} px marks the pixel too near (no value)")
        lines.append(f"total work {self.work / 1e6:.2f} Mev; single-range search "
                     f"{math.floor(lo)}-{math.ceil(hi)} px at full resolution: "
                     f"{self.single_range_work / 1e6:.2f} Mev (multi-range = {ratio:.2f} x)")
        return "\n".join(lines)


def _fmt_depth(z: float) -> str:
    return "inf" if not math.isfinite(z) else f"{z:.2f}"


@dataclass(frozen=True)
class LevelOutput:
    """What a per-level solver returns (level pixels, level resolution).

    Attributes
    ----------
    disparity_px : ndarray float32 (h, w_level)
        Disparity in level pixels, NaN invalid.
    confidence : ndarray float32 (h, w_level)
        In [0, 1], 0 where invalid.
    """

    disparity_px: np.ndarray
    confidence: np.ndarray
    alt_px: np.ndarray | None = None
    """Optional: the level's best strict local minimum inside its band, whatever the checks
    (level pixels, NaN none; for the cross-band ambiguity test of the union)."""
    alt_cost: np.ndarray | None = None
    """Its cost."""
    best_cost: np.ndarray | None = None
    """Optional: the winner's cost (whatever the checks)."""


def default_bands_px(max_disparity_px: float, n_levels: int = 3) -> tuple[tuple[float, float], ...]:
    """Bands for a maximum disparity ``D``: ``[0, D/4], [D/4, D/2], [D/2, D]`` for 3 levels.

    Each band doubles the previous one (the finest is ``[0, D / 2^(n-1)]``), so with decimations
    1, 2, 4 every level searches about ``D/4`` or ``D/8`` level pixels.
    """
    d = _checks.finite_number("max_disparity_px", max_disparity_px, positive=True)
    n = _checks.positive_int("n_levels", n_levels)
    edges = [0.0] + [d / 2 ** (n - 1 - i) for i in range(n)]
    return tuple((edges[i], edges[i + 1]) for i in range(n))


def default_level_count(max_disparity_px: float, *, min_band_level_px: float = 4.0,
                        max_levels: int = 3) -> int:
    """Number of levels for a search ``[0, D]``: the most (up to ``max_levels``) for which the
    nearest band ``[D/2, D]``, at decimation ``2^(n-1)``, still spans ``min_band_level_px``
    level pixels.

    With the default 4: ``D >= 32`` three levels (4, 2, 1), ``16 <= D < 32`` two (2, 1), else
    one; ``min_band_level_px = 0`` always gives ``max_levels`` (the paper's three ranges).
    """
    d = _checks.finite_number("max_disparity_px", max_disparity_px, positive=True)
    least = _checks.finite_number("min_band_level_px", min_band_level_px, nonnegative=True)
    n = _checks.positive_int("max_levels", max_levels)
    while n > 1 and d / 2 ** n < least:
        n -= 1
    return n


def bands_px_from_depth_m(depth_bands_m, *, focal_px: float, baseline_m: float,
                          doffs_px: float = 0.0) -> tuple[tuple[tuple[float, float], tuple[float, float]], ...]:
    """Convert depth bands to disparity bands with ``d = b f / Z - doffs`` (eq. 14).

    Parameters
    ----------
    depth_bands_m : sequence of float or of (near, far) pairs
        Either increasing edges ``(z0, z1, ..., zn)`` (``n`` adjacent bands) or pairs.

    Returns
    -------
    tuple of ((d_lo, d_hi), (z_near, z_far))
        Disparity band (full-resolution pixels) and its depth band, nearest first.
    """
    f = _checks.finite_number("focal_px", focal_px, positive=True)
    b = _checks.finite_number("baseline_m", baseline_m, positive=True)
    items = list(depth_bands_m)
    if not items:
        raise ValueError("depth_bands_m must not be empty")
    if all(np.ndim(item) == 0 for item in items):
        edges = [_checks.finite_number("depth_bands_m", z, positive=True) for z in items]
        if len(edges) < 2 or any(z1 <= z0 for z0, z1 in zip(edges, edges[1:])):
            raise ValueError(f"depth_bands_m edges must be >= 2 increasing depths, got {items}")
        pairs = list(zip(edges, edges[1:]))
    else:
        pairs = []
        for item in items:
            if np.ndim(item) != 1 or len(item) != 2:
                raise ValueError(f"depth_bands_m must hold depths or (near, far) pairs, got {item!r}")
            near = _checks.finite_number("depth_bands_m", item[0], positive=True)
            far = float(item[1])
            if not (far > near):
                raise ValueError(f"depth band must have far > near, got {item!r}")
            pairs.append((near, far))
    out = []
    for near, far in sorted(pairs):
        d_hi = b * f / near - doffs_px
        d_lo = max(b * f / far - doffs_px, 0.0) if math.isfinite(far) else max(-doffs_px, 0.0)
        if d_hi <= 0:
            raise ValueError(f"depth band {near}-{far} m lies beyond infinity for this rig "
                             f"(doffs {doffs_px} px)")
        out.append(((d_lo, d_hi), (near, far)))
    return tuple(out)


def decimate_horizontally(image: np.ndarray, width: int) -> np.ndarray:
    """Reduce the width only, anti-aliased (area average, ``cv2.INTER_AREA``)."""
    if width == image.shape[1]:
        return image
    return cv2.resize(image, (width, image.shape[0]), interpolation=cv2.INTER_AREA)


def plan_levels(image_size: tuple[int, int], bands_px: Sequence[tuple[float, float]], *,
                decimations: Sequence[int] | None = None, band_margin_px: int = 1,
                aoi: tuple[int, int, int, int] | None = None,
                depth_bands_m: Sequence[tuple[float, float]] | None = None,
                focal_px: float | None = None, baseline_m: float | None = None,
                near_guard_reach: float | None = None, near_guard_decimation: int | None = None) -> MultiRangePlan:
    """Build the multi-range plan: one level per disparity band.

    Parameters
    ----------
    image_size : (int, int)
        Full-resolution ``(width, height)``.
    bands_px : sequence of (float, float)
        Disparity bands in full-resolution pixels (any order).
    decimations : sequence of int, optional
        Decimation per band, in the order of the bands sorted from the largest
        disparities (nearest) to the smallest; default ``(2^(n-1), ..., 2, 1)``.
    band_margin_px : int
        Extra level pixels searched on each side of an inner band edge.
    aoi : (row0, row1, col0, col1), optional
        Area of interest (section 3.1); default the whole image.
    depth_bands_m : sequence of (near, far), optional
        The bands as depths (same order as ``bands_px``), for the description.
    near_guard_reach : float or None
        Too-near detection (beyond the paper): a search of its own (:attr:`MultiRangePlan.guard`)
        covers ``D .. near_guard_reach * D`` past the largest disparity ``D`` of the bands, and
        its winners above ``D`` plus half a level pixel are too-near candidates
        (:attr:`RangeLevel.too_near_above_px`). None = off; else at least 1.
    near_guard_decimation : int or None
        Decimation of the guard's search; None: twice the nearest band's ``k`` when ``D >= 16 k``
        (``GUARD_MIN_LEVEL_PX``), else ``k``.
    """
    width, height = image_size
    if near_guard_reach is not None:
        reach = _checks.finite_number("near_guard_reach", near_guard_reach, positive=True)
        if reach < 1:
            raise ValueError(f"near_guard_reach must be >= 1, got {reach}")
    bands = []
    for i, band in enumerate(bands_px):
        if np.ndim(band) != 1 or len(band) != 2:
            raise ValueError(f"disparity band must be a (low, high) pair, got {band!r}")
        lo = _checks.finite_number("disparity band low", band[0], nonnegative=True)
        hi = _checks.finite_number("disparity band high", band[1], positive=True)
        if hi <= lo:
            raise ValueError(f"disparity band must have high > low, got {band!r}")
        depth = None if depth_bands_m is None else tuple(depth_bands_m[i])
        bands.append(((lo, hi), depth))
    if not bands:
        raise ValueError("at least one disparity band is needed")
    bands.sort(key=lambda item: -item[0][1])      # nearest (largest disparities) first
    n = len(bands)
    if decimations is None:
        decimations = tuple(2 ** (n - 1 - i) for i in range(n))
    if len(decimations) != n:
        raise ValueError(f"decimations has {len(decimations)} entries for {n} disparity bands")
    row0, row1, col0, col1 = (0, height, 0, width) if aoi is None else aoi
    global_lo = min(b[0][0] for b in bands)
    global_hi = max(b[0][1] for b in bands)
    levels = []
    for ((lo, hi), depth), k in zip(bands, decimations):
        k = _checks.positive_int("decimations", k)
        w_level = max(1, int(round(width / k)))
        scale = width / w_level
        s_lo = math.floor(lo / scale) - (band_margin_px if lo > global_lo else 0)
        s_hi = math.ceil(hi / scale) + (band_margin_px if hi < global_hi else 0)
        s_lo = max(s_lo, 0)
        cols = _level_cols(col0, col1, scale, w_level)
        work = (row1 - row0) * (cols[1] - cols[0]) * (s_hi - s_lo + 1)
        levels.append(RangeLevel(decimation=k, scale=scale, size=(w_level, height), band_px=(lo, hi),
                                 search_px=(s_lo, s_hi), depth_band_m=depth, work=int(work)))
    levels.sort(key=lambda lvl: lvl.scale)        # finest first
    single = (row1 - row0) * (col1 - col0) * (math.ceil(global_hi) - math.floor(global_lo) + 1)
    near_guard_level = None
    if near_guard_reach is not None:
        nearest = max(levels, key=lambda lvl: lvl.band_px[1]).decimation
        if near_guard_decimation is not None:
            k = _checks.positive_int("near_guard_decimation", near_guard_decimation)
        else:       # twice the nearest band's decimation where D still spans enough level pixels
            k = 2 * nearest if global_hi / (2 * nearest) >= GUARD_MIN_LEVEL_PX else nearest
        w_level = max(1, int(round(width / k)))
        scale = width / w_level
        # from one level pixel below D (a winner at D is no candidate) to reach * D
        s_lo = max(0, math.floor(global_hi / scale) - 1)
        s_hi = max(s_lo + 2, math.ceil(reach * global_hi / scale))
        cols = _level_cols(col0, col1, scale, w_level)
        near_guard_level = RangeLevel(
            decimation=k, scale=scale, size=(w_level, height), band_px=(global_hi, reach * global_hi),
            search_px=(s_lo, s_hi), depth_band_m=None, too_near_above_px=global_hi + 0.5 * scale,
            work=int((row1 - row0) * (cols[1] - cols[0]) * (s_hi - s_lo + 1)))
    return MultiRangePlan(levels=tuple(levels), image_size=(width, height), aoi=(row0, row1, col0, col1),
                          single_range_work=int(single), focal_px=focal_px, baseline_m=baseline_m,
                          guard=near_guard_level)


def _level_cols(col0: int, col1: int, scale: float, w_level: int) -> tuple[int, int]:
    """Level columns whose full-resolution footprint meets ``[col0, col1)``."""
    return (max(0, int(math.floor(col0 / scale))), min(w_level, int(math.ceil(col1 / scale))))


Solver = Callable[[np.ndarray, np.ndarray, RangeLevel, tuple[int, int], tuple[int, int]], LevelOutput]
Refiner = Callable[[RangeLevel, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


def run_levels(left: np.ndarray, right: np.ndarray, plan: MultiRangePlan, solve: Solver, *,
               row_pad_px: int = 0, refine: Refiner | None = None,
               refine_min_scale: float | None = 2.0, decimated: dict | None = None
               ) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, ...]]:
    """Run a per-level solver on every level and unite the results (eq. 11-12).

    Parameters
    ----------
    left, right : ndarray (H, W)
        Rectified full-resolution gray images.
    plan : MultiRangePlan
        From :func:`plan_levels`.
    solve : callable
        ``solve(left_level, right_level, level, rows, cols) -> LevelOutput``: match one
        level's images over ``level.search_px``, evaluating only rows ``rows`` and columns
        ``cols`` (half-open, level coordinates) and leaving the rest invalid.
    row_pad_px : int
        Rows above/below the area of interest that the solver needs (window radius).
    refine : callable, optional
        ``refine(level, disparity_px, want) -> disparity_px``: re-score at full resolution
        the up-sampled map of a decimated level (``scale >= refine_min_scale``) at the pixels ``want`` (its
        values within one level pixel of the band that the union can take: where no finer level
        holds a value at least as confident), NaN = rejected, before the exact gate (beyond the
        paper, see :func:`.cost.refine_candidates`); ``disparity_px`` may be the input, refined in place.
    decimated : dict, optional
        Cache ``{width: (left, right)}`` of whole-height decimated images, filled and
        reused (the caller may share it with its own per-width work).

    Returns
    -------
    disparity_px, confidence : ndarray float32 (H, W)
        United disparity (full-resolution pixels, NaN invalid) and its confidence.
    levels : tuple of ndarray float32 (H, W)
        Each level's gated, up-sampled disparity (finest first); a refined level holds its
        re-scored values where the union can take them, its up-sampled ones elsewhere.

    The near guard (``plan.guard``) is not run here: it is not a band of eq. (11)-(12)
    (see :func:`mrstereo.matching.disparity.compute_disparity`).
    """
    height, width = left.shape
    row0, row1, col0, col1 = plan.aoi
    # only the rows of the area of interest (plus the window) are touched at all
    top = max(0, row0 - row_pad_px)
    bottom = min(height, row1 + row_pad_px)
    left_rows = left[top:bottom]
    right_rows = right[top:bottom]
    rows = (row0 - top, row1 - top)
    maps = []
    disparity = np.empty((height, width), np.float32)
    confidence = np.empty((height, width), np.float32)
    for level in plan.levels:
        w_level = level.size[0]
        if decimated is not None and top == 0 and bottom == height:
            if w_level not in decimated:
                decimated[w_level] = (decimate_horizontally(left, w_level), decimate_horizontally(right, w_level))
            left_level, right_level = decimated[w_level]
        else:
            left_level = decimate_horizontally(left_rows, w_level)
            right_level = decimate_horizontally(right_rows, w_level)
        out = solve(left_level, right_level, level, rows, _level_cols(col0, col1, level.scale, w_level))
        # Step 2: nearest-neighbour up-sampling along x (source column floor((x + 0.5) / scale));
        # disparities scale with the width. Eq. (11): keep only disparities inside the
        # level's band (and inside the AOI); a refined level is first cut one level pixel
        # outside its band, re-scored, then gated exactly.
        lo, hi = level.band_px
        refining = refine is not None and refine_min_scale is not None and level.scale >= refine_min_scale
        slack = level.scale if refining else 0.0
        d_full = np.empty((height, width), np.float32)
        c_full = np.empty((height, width), np.float32)
        source_cols = np.minimum(((np.arange(width) + 0.5) / level.scale).astype(np.intp), w_level - 1)
        _union_kernels.upsample_gate(out.disparity_px, out.confidence, source_cols, np.float32(level.scale),
                               np.float32(lo - slack), np.float32(hi + slack), top, row0, row1, col0, col1,
                               d_full, c_full)
        if refining:
            # only where the union (eq. 12) can take the value: elsewhere a finer level's is at least as confident
            want = np.empty((height, width), np.bool_)
            _union_kernels.can_win(d_full, c_full, disparity, confidence, not maps, want)
            d_full = refine(level, d_full, want)
            _union_kernels.gate(d_full, c_full, float(lo), float(hi))
        # Eq. (12), level by level (finest first): where several levels keep a value, the more confident wins
        _union_kernels.unite(d_full, c_full, not maps, disparity, confidence)
        maps.append(d_full)
    return disparity, confidence, tuple(maps)
