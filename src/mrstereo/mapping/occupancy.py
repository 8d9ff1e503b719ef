"""Occupancy grid built along the robot path (paper section 5.2), log-odds or union fusion.

The paper's fusion is the union of the occupied cells of all views (``fusion="union"``); the
default is OctoMap's: rays from the sensor clear the cells they cross (a *miss*), their end cells
are hit, and clamped log-odds accumulate, so later views clear a moved obstacle or a stereo ghost.
Unknown cells stay NaN. Beside the log-odds each cell keeps the lowest and highest point height seen (the
height layer) and its drop votes (the drop layer: cells where the floor ends, which rays never clear;
:meth:`OccupancyGrid.add_layers`). User guide: docs/mapping.md; grid conventions: docs/conventions.md.

References
----------
.. [1] Multi-Range Approach of Stereo Vision for Mobile Robot Navigation in Uncertain
   Environments, section 5.2 "Experiments for grid mapping of corridor profile".
.. [2] A. Hornung, K. M. Wurm, M. Bennewitz, C. Stachniss, W. Burgard, "OctoMap: an efficient
   probabilistic 3D mapping framework based on octrees", Autonomous Robots 34(3), 2013.
.. [3] J. Amanatides, A. Woo, "A fast voxel traversal algorithm for ray tracing",
   Eurographics 1987.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .. import _checks
from ..geometry.drops import CANDIDATE_COLUMNS
from ..io import atomic_write
from ..profiling import stage
from . import _kernels
from .grid import GridSpec
from .rosmap import RosMap

__all__ = ["MappingConfig", "OccupancyGrid", "GridUpdate", "ViewCells", "view_cells",
           "log_odds_from_probability", "probability_from_log_odds"]

FUSIONS = ("log_odds", "union")

CONFIRM_WALK_M = 4.0
"""How far back from a drop candidate's edge the map looks for the floor that confirms it
(:meth:`OccupancyGrid.add_layers`)."""

DROP_COLUMNS = 4
"""The drop votes per cell (int16): the drop test's votes, its weak points' votes, the views that put a weak vote
and the views that put floor points and no vote (:meth:`OccupancyGrid.add_layers`)."""


def log_odds_from_probability(p) -> np.ndarray:
    """``l = log(p / (1 - p))``."""
    p = np.asarray(p, dtype=np.float64)
    return np.log(p / (1.0 - p))


def probability_from_log_odds(log_odds) -> np.ndarray:
    """``p = 1 / (1 + exp(-l))``; NaN (unknown) stays NaN."""
    return 1.0 / (1.0 + np.exp(-np.asarray(log_odds, dtype=np.float64)))


@dataclass(frozen=True)
class MappingConfig:
    """Sensor model and fusion of the occupancy grid.

    The defaults are the stereo sensor model of ``mrstereo map``; each rule, why a stereo point
    needs it and its measured effect: docs/mapping.md, "The stereo sensor model". OctoMap's plain ray model is
    ``p_miss=0.4``, ``min_points_per_cell=1`` and the optional rules None / False.

    Parameters
    ----------
    p_hit, p_miss : float
        Probability that a cell is occupied given a hit / a miss (OctoMap: 0.7 / 0.4).
    p_clamp_min, p_clamp_max : float
        Log-odds clamping bounds as probabilities (OctoMap: 0.1192 / 0.971).
    occupied_thresh : float
        A known cell is occupied when its probability is above this, free otherwise.
    max_range_m : float or None
        Points farther than this from the sensor mark no hit; their ray clears up to the range.
    fusion : {"log_odds", "union"}
        ``"union"`` is the paper's fusion: a cell once hit stays occupied.
    min_points_per_cell : int
        A cell is hit only when at least this many obstacle points of one update fall in it.
    disparity_sigma_px : float or None
        Disparity uncertainty: a point at range ``r`` clears only up to ``r - k sigma_r``,
        ``sigma_r = r^2 sigma_d / (b f)`` (eq. 14 differentiated), ``k = clear_margin_sigmas``;
        needs ``baseline_focal_m_px`` of :func:`view_cells`.
    clear_margin_sigmas : float
    occlusion_gap_m : float or None
        A ray entering a cell hit in the same view more than this before its end stops there and
        its point is no hit.
    see_through_ratio : float or None
        A hit cell through which the view sees more floor points than this times its own obstacle
        points is cleared instead.
    height_tolerance_m : float
        Slack of the height tests of the occlusion rules.
    overhang_shadow : bool
        A sight line that passes below a solid cell's obstacle points clears nothing from there on.
    map_occlusion_p : float or None
        Cells the map holds occupied with at least this probability are solid for later views.
    clear_below_m : float or None
        A ray clears only cells where its sight line runs at most this high above the floor.
    footprint_radius_m : float or None
        The robot's radius: the cells its footprint touches along the path (a disc at every pose,
        swept between poses) are free (:meth:`OccupancyGrid.clear_disc`), since the robot stood
        there. The default is ``mrstereo plan``'s radius (0.25 m) and a cell. None or 0: off.
    drop_min_points : int
        The drop layer (:meth:`OccupancyGrid.add_layers`): a view with at least this many drop-test points in
        a cell votes for a drop there (+1, at most ``drop_max_votes``); a view with at least
        ``drop_clear_points`` floor points and no drop vote in the cell votes against (-1, at least 0). A cell
        with a vote is lethal (:attr:`OccupancyGrid.drop`) whatever the log-odds: a ray passing over it never
        clears it, only floor measured in it (and the robot's footprint).
    drop_clear_points : int
    drop_max_votes : int
    drop_weak_views : int
        The drop test's weak points (``DropConfig.weak_n_sigma``: drops within the noise margin) vote the same
        way in a layer of their own (up to ``max(drop_max_votes, drop_weak_views)``): a cell with weak votes
        from at least this many views is lethal too (docs/mapping.md, "Height and drop layers").
    drop_weak_share : float
        ... and when those views are at least this share of all the views that put weak votes or floor points
        (and no vote) in the cell: a drop below the noise margin shows in many of the views that see it, far
        floor's noise in a few, however many frames see it (frames of a robot standing still are one view).
        0: off. Chosen on a drive over the tuning worlds (docs/obstacles.md, "Drops").
    drop_low_m : float or None
        The height layer's edge: a cell with a point at floor level next to a cell whose lowest point lies
        more than this below the floor is a drop cell too (the floor ends there and the view goes on lower).
        None (the default): off; on the tuning worlds 0.1 m raised the edge recall from 0.675 to 0.700 and
        the false drops on flat floor from 2.3 % to 7.1 % (docs/obstacles.md, "Drops").
    """

    p_hit: float = 0.7
    p_miss: float = 0.35
    p_clamp_min: float = 0.1192
    p_clamp_max: float = 0.971
    occupied_thresh: float = 0.5
    max_range_m: float | None = None
    fusion: str = "log_odds"
    min_points_per_cell: int = 5
    disparity_sigma_px: float | None = 0.25
    clear_margin_sigmas: float = 2.0
    occlusion_gap_m: float | None = 0.25
    see_through_ratio: float | None = 1.0
    height_tolerance_m: float = 0.05
    overhang_shadow: bool = True
    map_occlusion_p: float | None = 0.8
    clear_below_m: float | None = 0.8
    footprint_radius_m: float | None = 0.3
    drop_min_points: int = 3
    drop_clear_points: int = 20
    drop_max_votes: int = 3
    drop_weak_views: int = 2
    drop_weak_share: float = 0.25
    drop_low_m: float | None = None

    def __post_init__(self) -> None:
        for name in ("drop_min_points", "drop_clear_points", "drop_max_votes", "drop_weak_views"):
            _checks.positive_int(name, getattr(self, name))
        if not 0.0 <= _checks.finite_number("drop_weak_share", self.drop_weak_share) < 1.0:
            raise ValueError(f"drop_weak_share must be in [0, 1), got {self.drop_weak_share}")
        if self.drop_low_m is not None:
            _checks.finite_number("drop_low_m", self.drop_low_m, positive=True)
        if self.footprint_radius_m is not None:
            _checks.finite_number("footprint_radius_m", self.footprint_radius_m, nonnegative=True)
        _checks.positive_int("min_points_per_cell", self.min_points_per_cell)
        if self.disparity_sigma_px is not None:
            _checks.finite_number("disparity_sigma_px", self.disparity_sigma_px, positive=True)
        _checks.finite_number("clear_margin_sigmas", self.clear_margin_sigmas, nonnegative=True)
        if self.occlusion_gap_m is not None:
            _checks.finite_number("occlusion_gap_m", self.occlusion_gap_m, nonnegative=True)
        if self.see_through_ratio is not None:
            _checks.finite_number("see_through_ratio", self.see_through_ratio, nonnegative=True)
        _checks.finite_number("height_tolerance_m", self.height_tolerance_m, nonnegative=True)
        if not isinstance(self.overhang_shadow, (bool, np.bool_)):
            raise TypeError(f"overhang_shadow must be a bool, got {type(self.overhang_shadow).__name__}")
        if self.clear_below_m is not None:
            _checks.finite_number("clear_below_m", self.clear_below_m, positive=True)
        if self.map_occlusion_p is not None:
            p = _checks.finite_number("map_occlusion_p", self.map_occlusion_p)
            if not self.occupied_thresh <= p < 1.0:
                raise ValueError(f"map_occlusion_p must be in [occupied_thresh, 1), got {p}")
        for name in ("p_hit", "p_miss", "p_clamp_min", "p_clamp_max", "occupied_thresh"):
            value = _checks.finite_number(name, getattr(self, name))
            if not 0.0 < value < 1.0:
                raise ValueError(f"{name} must be in (0, 1), got {value}")
        if not self.p_hit > 0.5:
            raise ValueError(f"p_hit must be > 0.5, got {self.p_hit}")
        if not self.p_miss < 0.5:
            raise ValueError(f"p_miss must be < 0.5, got {self.p_miss}")
        if not self.p_clamp_min < 0.5 < self.p_clamp_max:
            raise ValueError(f"need p_clamp_min < 0.5 < p_clamp_max, got {self.p_clamp_min} and "
                             f"{self.p_clamp_max}")
        if self.max_range_m is not None:
            _checks.finite_number("max_range_m", self.max_range_m, positive=True)
        if self.fusion not in FUSIONS:
            raise ValueError(f"fusion must be one of {FUSIONS}, got {self.fusion!r}")

    @property
    def l_hit(self) -> float:
        return float(log_odds_from_probability(self.p_hit))

    @property
    def l_miss(self) -> float:
        return float(log_odds_from_probability(self.p_miss))

    @property
    def l_min(self) -> float:
        return float(log_odds_from_probability(self.p_clamp_min))

    @property
    def l_max(self) -> float:
        return float(log_odds_from_probability(self.p_clamp_max))


class GridUpdate(NamedTuple):
    """What one :meth:`OccupancyGrid.update` did: distinct cells hit and missed, points cut."""

    hit_cells: int
    miss_cells: int
    points_outside: int


def _points_xy(name: str, value) -> np.ndarray:
    if value is None:
        return np.empty((0, 2))
    arr = np.asarray(value)
    if arr.size == 0:
        return np.empty((0, 2))
    if arr.ndim != 2 or arr.shape[1] not in (2, 3):
        raise ValueError(f"{name} must have shape (N, 2) or (N, 3), got {arr.shape}")
    if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise TypeError(f"{name} must hold numbers, got dtype {arr.dtype}")
    # float32 and float64 points as they are (the kernels take each coordinate as float64)
    return np.ascontiguousarray(arr, dtype=arr.dtype if arr.dtype in (np.float32, np.float64) else np.float64)


def _voted(votes: np.ndarray, config: MappingConfig) -> np.ndarray:
    """The cells of drop votes ``votes`` (..., 4: the drop test's, its weak points', the views that put weak
    votes, those that put floor points and no vote) that are drop cells: a vote, or weak votes from
    ``config.drop_weak_views`` views that are at least ``config.drop_weak_share`` of the views counted
    (:meth:`OccupancyGrid.add_layers`)."""
    share = config.drop_weak_share
    weak = votes[..., 2].astype(np.float32)
    return (votes[..., 0] > 0) | ((votes[..., 1] >= config.drop_weak_views)
                                  & ((1.0 - share) * weak >= share * votes[..., 3]))


def _layer_points(name: str, value) -> np.ndarray:
    """(N, 3) float32 or float64 points for :meth:`OccupancyGrid.add_layers` (None: none)."""
    arr = _points_xy(name, value)
    if len(arr) and arr.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3) (z is the height), got {arr.shape}")
    return arr


def _finite_bounds(*point_sets: np.ndarray) -> np.ndarray | None:
    """``(x_min, y_min, x_max, y_max)`` of the points with finite (x, y) of (N, 2 or 3) arrays (None: none)."""
    out = None
    for points in point_sets:
        bounds = np.empty(4)
        if len(points) and _kernels.finite_bounds(points, bounds):
            out = bounds if out is None else np.r_[np.minimum(out[:2], bounds[:2]), np.maximum(out[2:], bounds[2:])]
    return out


def _cell_indices(name: str, value, n_cells: int) -> np.ndarray:
    """Flat cell indices as int64 within ``[0, n_cells)`` (the kernel writes where they point)."""
    arr = np.asarray(value)
    if arr.size == 0:
        return np.empty(0, np.int64)
    if arr.ndim != 1 or arr.dtype.kind not in "iu":
        raise TypeError(f"{name} must be a 1-D array of integer cell indices, got {arr.dtype} {arr.shape}")
    low, high = int(arr.min()), int(arr.max())
    if low < 0 or high >= n_cells:
        raise ValueError(f"{name} holds cell indices from {low} to {high}, outside the grid's 0..{n_cells - 1}")
    return np.ascontiguousarray(arr, dtype=np.int64)


class ViewCells(NamedTuple):
    """The cells one view hits and clears, ready to be added to a grid in order.

    Computing them is the per-frame part of mapping (independent between frames, so it runs on
    parallel workers); :meth:`OccupancyGrid.apply` is the cheap ordered part. ``hit`` and ``miss``
    are ascending flat indices into ``grid.shape`` (int64); ``points_outside`` counts the rays cut
    at the grid border, ``occluded`` the hit cells dropped by the occlusion and see-through tests;
    ``hit_z_m`` (len(hit), 2) float32 is the lowest and highest obstacle point of each hit cell
    (inf, -inf without heights); ``sensor_model`` the config's fields of :func:`_sensor_model`.
    """

    hit: np.ndarray
    miss: np.ndarray
    points_outside: int
    grid: GridSpec
    max_range_m: float | None
    min_points_per_cell: int
    sensor_model: tuple = ()
    occluded: int = 0
    hit_z_m: np.ndarray | None = None

    def fits(self, grid: GridSpec, config: MappingConfig) -> bool:
        """True when these cells are what ``grid`` and ``config`` would compute."""
        return (self.grid == grid and self.max_range_m == config.max_range_m
                and self.min_points_per_cell == config.min_points_per_cell
                and self.sensor_model == _sensor_model(config))


def _sensor_model(config: MappingConfig) -> tuple:
    return (config.disparity_sigma_px, config.clear_margin_sigmas, config.occlusion_gap_m, config.see_through_ratio,
            config.height_tolerance_m, config.overhang_shadow, config.clear_below_m)


def view_cells(points_obstacle_world, points_free_world, sensor_origin_world, *,
               grid: GridSpec = GridSpec(), config: MappingConfig = MappingConfig(),
               baseline_focal_m_px: float | None = None, known_occupied=None) -> ViewCells:
    """The cells one view hits and clears (OctoMap's per-scan key sets [2]).

    Parameters
    ----------
    points_obstacle_world : ndarray of shape (N, 3) or (N, 2), or None
        Obstacle points in the world frame (metres); z is ignored, rows with NaN skipped.
    points_free_world : ndarray of shape (M, 3) or (M, 2), or None
        Floor points (ground-suppressed by eq. 13): their rays and their own cells are free.
    sensor_origin_world : sequence of 2 or 3 floats
        World (x, y) of the sensor (the left camera's optical centre), and its height z above
        the floor (needed for the height-aware occlusion and see-through tests).
    grid : GridSpec
    config : MappingConfig
        Everything but the fusion matters here.
    baseline_focal_m_px : float, optional
        ``b f`` of the rig (baseline in metres times rectified focal length in pixels), for the
        range uncertainty of ``config.disparity_sigma_px``; without it rays clear up to the point.
    known_occupied : (ndarray of bool, ndarray of float), optional
        ``(mask, z_range_m)`` of the cells the map already holds occupied, shapes ``grid.shape``
        and ``grid.shape + (2,)`` (:meth:`OccupancyGrid.known_occupied`): they are solid for this
        view's rays like its own hit cells (occlusion by the map).

    Returns
    -------
    ViewCells

    Notes
    -----
    A cell counts at most once per view for a hit and once for a miss; a hit cancels a miss. One
    ray is traced to the representative point of each distinct end cell (Amanatides-Woo [3]); a
    ray leaving the grid or ``max_range_m`` is cut there. The sensor-model rules of ``config``:
    docs/mapping.md.
    """
    _checks.instance("grid", grid, GridSpec)
    _checks.instance("config", config, MappingConfig)
    obstacles = _points_xy("points_obstacle_world", points_obstacle_world)
    floor = _points_xy("points_free_world", points_free_world)
    origin = np.asarray(sensor_origin_world, dtype=np.float64).ravel()
    if origin.shape not in ((2,), (3,)) or not np.isfinite(origin).all():
        raise ValueError(f"sensor_origin_world must be 2 or 3 finite numbers (x, y[, z]), "
                         f"got {sensor_origin_world!r}")
    sx = (origin[0] - grid.origin_x_m) / grid.resolution_m
    sy = (origin[1] - grid.origin_y_m) / grid.resolution_m
    max_range_cells = -1.0 if config.max_range_m is None else config.max_range_m / grid.resolution_m
    margin_per_cell2 = 0.0
    if config.disparity_sigma_px is not None and baseline_focal_m_px is not None:
        bf = _checks.finite_number("baseline_focal_m_px", baseline_focal_m_px, positive=True)
        # sigma_r [cells] = (r res)^2 sigma_d / (b f) / res = r^2 res sigma_d / (b f)
        margin_per_cell2 = config.clear_margin_sigmas * grid.resolution_m * config.disparity_sigma_px / bf
    gap_cells = -1.0 if config.occlusion_gap_m is None else config.occlusion_gap_m / grid.resolution_m
    keep = _supported(obstacles, grid, config.min_points_per_cell) if config.min_points_per_cell > 1 else None
    flags, ends, n_points, z_range, outside = _ray_ends(obstacles, keep, floor, sx, sy, grid, max_range_cells,
                                                        margin_per_cell2)
    miss = np.zeros(grid.shape, np.uint8)
    occluded = np.zeros(grid.shape, np.uint8)
    sz = float(origin[2]) if origin.shape == (3,) else np.nan
    z_tol = float(config.height_tolerance_m)
    n_occluded = 0
    if config.see_through_ratio is not None:
        through = np.zeros(grid.shape, np.float64)
        n_occluded += _kernels.drop_seen_through(flags, ends, n_points, z_range, sx, sy, sz, max(gap_cells, 0.0),
                                                 z_tol, config.see_through_ratio, through, miss, occluded)
    if known_occupied is not None:
        known, known_z = _known_occupied(known_occupied, grid)
        solid = known & ((flags & _kernels.HIT) == 0)
        flags[solid] |= _kernels.BLOCK
        z_range[solid] = _solid_heights(known_z[solid])
    z_clear = np.inf if config.clear_below_m is None else float(config.clear_below_m)
    n_occluded += _kernels.cast_rays(flags, ends, z_range, sx, sy, sz, gap_cells, z_tol, bool(config.overhang_shadow),
                                     z_clear, miss, occluded)
    hit = ((flags & _kernels.HIT) != 0) & (occluded == 0)
    hit_index = np.flatnonzero(hit)
    return ViewCells(hit=hit_index, miss=np.flatnonzero((miss != 0) & ~hit), points_outside=int(outside),
                     grid=grid, max_range_m=config.max_range_m, min_points_per_cell=config.min_points_per_cell,
                     sensor_model=_sensor_model(config), occluded=int(n_occluded),
                     hit_z_m=z_range.reshape(-1, 2)[hit_index].astype(np.float32))


def _ray_ends(obstacles: np.ndarray, keep: np.ndarray | None, floor: np.ndarray, sx: float, sy: float,
              grid: GridSpec, max_range_cells: float, margin_per_cell2: float) -> tuple:
    """``(flags, ends, n_points, z_range, points_outside)``: the end cell of every ray of a view marked
    (:func:`_kernels.mark_endpoints`; ``flags`` a bit set per cell, ``ends`` each end cell's representative
    point and clearing margin, ``z_range`` the lowest and highest obstacle point in each cell); ``keep``
    selects the obstacle points (None: all)."""
    flags = np.zeros(grid.shape, np.uint8)
    ends = np.empty(grid.shape + (4,), np.float64)
    n_points = np.zeros(grid.shape, np.float64)
    z_range = np.empty(grid.shape + (2,), np.float64)
    z_range[..., 0] = np.inf
    z_range[..., 1] = -np.inf
    outside = 0
    every = np.empty(0, bool)
    for points, selected, is_obstacle in ((obstacles, keep, True), (floor, None, False)):
        if len(points):
            outside += _kernels.mark_endpoints(points, every if selected is None else selected, sx, sy,
                                               float(grid.origin_x_m), float(grid.origin_y_m),     # one signature
                                               grid.resolution_m, max_range_cells, is_obstacle, margin_per_cell2,
                                               flags, ends, n_points, z_range)
    return flags, ends, n_points, z_range, outside


def _known_occupied(value, grid: GridSpec) -> tuple[np.ndarray, np.ndarray]:
    """``(mask, z_range_m)`` of :meth:`OccupancyGrid.known_occupied` checked against ``grid`` (not copied)."""
    try:
        mask, z = value
    except (TypeError, ValueError):
        raise TypeError("known_occupied must be (mask, z_range_m), e.g. OccupancyGrid.known_occupied()") from None
    mask, z = np.asarray(mask), np.asarray(z)
    if mask.shape != grid.shape or mask.dtype != bool:
        raise ValueError(f"known_occupied mask must be a bool array of the grid's shape {grid.shape}, "
                         f"got {mask.dtype} {mask.shape}")
    if z.shape != grid.shape + (2,) or z.dtype.kind not in "fiu":
        raise ValueError(f"known_occupied z_range_m must be numbers of shape {grid.shape + (2,)}, "
                         f"got {z.dtype} {z.shape}")
    return mask, z


def _solid_heights(z) -> np.ndarray:
    """The heights (K, 2) of known-occupied cells as float64; a cell without heights reaches from -inf to inf
    (every sight line meets it)."""
    z = np.array(z, dtype=np.float64)
    z[~(np.isfinite(z).all(axis=-1) & (z[:, 0] <= z[:, 1]))] = (-np.inf, np.inf)
    return z


def _supported(points: np.ndarray, grid: GridSpec, min_points: int) -> np.ndarray:
    """``keep`` (N,) bool: the obstacle points whose cell holds at least ``min_points`` of them, counted per
    cell by a kernel inside the grid, grouped by ``(row, col)`` keys with ``np.unique`` outside it.
    """
    keep = np.empty(len(points), bool)
    if not len(points):
        return keep
    counts = np.zeros(grid.shape, np.int64)
    cell = np.empty(len(points), np.int64)
    outside = _kernels.count_cells(points, float(grid.origin_x_m), float(grid.origin_y_m), float(grid.resolution_m),
                                   counts, cell)
    _kernels.keep_supported(cell, counts, min_points, keep)
    if outside:
        idx = np.flatnonzero(cell == -2)
        col = np.floor((points[idx, 0].astype(np.float64) - grid.origin_x_m) / grid.resolution_m)
        row = np.floor((points[idx, 1].astype(np.float64) - grid.origin_y_m) / grid.resolution_m)
        if max(np.abs(col).max(), np.abs(row).max()) >= 2.0 ** 31:      # keys may collide: group all at once
            return _supported_by_keys(points, grid, min_points)
        key = (row.astype(np.int64) << 32) + col.astype(np.int64)
        _, inverse, n_per_key = np.unique(key, return_inverse=True, return_counts=True)
        n = n_per_key[inverse]
        n[key == -1] += np.count_nonzero(cell == -1)    # cell (0, -1) shares key -1 with the non-finite points
        keep[idx] = n >= min_points
    return keep


def _supported_by_keys(points: np.ndarray, grid: GridSpec, min_points: int) -> np.ndarray:
    """:func:`_supported` by grouping ``(row << 32) + col`` keys of all points with ``np.unique``."""
    col = np.floor((points[:, 0].astype(np.float64) - grid.origin_x_m) / grid.resolution_m)
    row = np.floor((points[:, 1].astype(np.float64) - grid.origin_y_m) / grid.resolution_m)
    finite = np.isfinite(col) & np.isfinite(row)
    key = np.full(len(points), -1, np.int64)
    key[finite] = (row[finite].astype(np.int64) << 32) + col[finite].astype(np.int64)
    _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    return finite & (counts[inverse] >= min_points)


def disc_cells(grid: GridSpec, xy_m, radius_m: float) -> tuple[np.ndarray, np.ndarray]:
    """``(rows, cols)`` of the cells of ``grid`` a disc of ``radius_m`` at ``xy_m`` touches (its square comes within
    ``radius_m`` of the centre): :meth:`OccupancyGrid.clear_disc`."""
    xy = np.asarray(xy_m, dtype=np.float64).ravel()
    if xy.shape != (2,) and xy.shape != (3,) or not np.isfinite(xy[:2]).all():
        raise ValueError(f"xy_m must be two finite numbers (x, y) in metres, got {xy_m!r}")
    radius = _checks.finite_number("radius_m", radius_m, nonnegative=True)
    half = 0.5 * grid.resolution_m
    (r0, c0), (r1, c1) = (grid.cells_from_xy(xy[:2] + d) for d in (-radius - half, radius + half))
    rows, cols = grid.shape
    r0, c0, r1, c1 = max(int(r0), 0), max(int(c0), 0), min(int(r1), rows - 1), min(int(c1), cols - 1)
    if r0 > r1 or c0 > c1:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    rr, cc = np.mgrid[r0:r1 + 1, c0:c1 + 1]
    centres = grid.xy_from_cells(rr, cc)
    gap = np.maximum(np.abs(centres - xy[:2]) - half, 0.0)
    touched = (gap ** 2).sum(axis=-1) <= radius * radius + 1e-12
    return rr[touched], cc[touched]


WINDOW_MIN_CELLS = 1 << 18
"""In a grid with more cells, a view's cells are computed in its own window of the grid (each view
allocates a few arrays of the grid's size: about 70 bytes per cell)."""


def _view_window(grid: GridSpec, obstacles: np.ndarray, floor: np.ndarray, sensor_origin_world) -> tuple:
    """``(r0, r1, c0, c1)``: the cells of the bounding box of a view's points and its sensor, a cell of
    margin around, within the grid (a ray between two points of a box stays in it)."""
    origin = np.asarray(sensor_origin_world, dtype=np.float64).ravel()[:2]
    bounds = _finite_bounds(obstacles, floor, origin[None, :] if origin.size == 2 else np.empty((0, 2)))
    rows, cols = grid.shape
    if bounds is None:
        return 0, rows, 0, cols
    lo, hi = bounds[:2], bounds[2:]
    c0 = int(np.clip(np.floor((lo[0] - grid.origin_x_m) / grid.resolution_m) - 1, 0, cols))
    c1 = int(np.clip(np.floor((hi[0] - grid.origin_x_m) / grid.resolution_m) + 2, 0, cols))
    r0 = int(np.clip(np.floor((lo[1] - grid.origin_y_m) / grid.resolution_m) - 1, 0, rows))
    r1 = int(np.clip(np.floor((hi[1] - grid.origin_y_m) / grid.resolution_m) + 2, 0, rows))
    if r1 <= r0 or c1 <= c0:            # the view lies wholly outside: the whole grid, rays cut at its border
        return 0, rows, 0, cols
    return r0, r1, c0, c1


def _subgrid(grid: GridSpec, r0: int, r1: int, c0: int, c1: int) -> GridSpec:
    """The cells ``[r0:r1, c0:c1]`` of ``grid`` as a grid of their own."""
    res = grid.resolution_m
    return GridSpec(width_m=(c1 - c0) * res, height_m=(r1 - r0) * res, resolution_m=res,
                    origin_x_m=grid.origin_x_m + c0 * res, origin_y_m=grid.origin_y_m + r0 * res)


def _cells_in(flat: np.ndarray, window_cols: int, r0: int, c0: int, cols: int) -> np.ndarray:
    """Flat indices of a window's cells as flat indices of the whole grid (the order is kept)."""
    return (flat // window_cols + r0) * cols + flat % window_cols + c0


class OccupancyGrid:
    """A 2D occupancy grid that accumulates stereo views (paper section 5.2).

    Parameters
    ----------
    grid : GridSpec, optional
        Geometry (default: the paper's 12 m x 6 m region in 5 cm cells, origin (0, -3)).
    config : MappingConfig, optional
        Sensor model and fusion (default: the stereo sensor model of ``mrstereo map``).
    log_odds : ndarray of shape grid.shape, optional
        Initial state (NaN = unknown), e.g. from :meth:`load_log_odds`; copied.

    Notes
    -----
    Log-odds update (OctoMap [2]): ``L <- clamp(L + log(p / (1 - p)), l_min, l_max)``, ``p = p_hit``
    for a hit and ``p_miss`` for a miss; ``P(occupied) = 1 / (1 + exp(-L))``.
    """

    def __init__(self, grid: GridSpec | None = None, *, config: MappingConfig | None = None,
                 log_odds: np.ndarray | None = None) -> None:
        grid = GridSpec() if grid is None else grid
        config = MappingConfig() if config is None else config
        self.grid = _checks.instance("grid", grid, GridSpec)
        self.config = _checks.instance("config", config, MappingConfig)
        if log_odds is None:
            self._log_odds = np.full(grid.shape, np.nan)
        else:
            arr = np.array(log_odds, dtype=np.float64, order="C")
            if arr.shape != grid.shape:
                raise ValueError(f"log_odds must have shape {grid.shape} (the grid), got {arr.shape}")
            if np.isinf(arr).any():
                raise ValueError("log_odds must be finite or NaN (unknown)")
            self._log_odds = arr
        # lowest and highest obstacle point seen in each hit cell (inf, -inf: none), for map occlusion
        self._z_range_m = np.empty(grid.shape + (2,), np.float32)
        self._z_range_m[..., 0] = np.inf
        self._z_range_m[..., 1] = -np.inf
        # the height layer (lowest, highest point height seen in the cell; NaN: none) and the drop votes
        # (the drop test's, its weak points', the views that put weak votes and those that put floor points)
        self._heights_m = np.full(grid.shape + (2,), np.nan, np.float32)
        self._drop_votes = np.zeros(grid.shape + (DROP_COLUMNS,), np.int16)
        self._counts = self._stamp = None       # add_layers' per-view point counts per cell, and their view
        self._view = 0
        self.n_updates = 0
        self.points_outside = 0
        """Points of all updates so far whose ray was cut at the grid's border (they fell outside it)."""

    # ---------------------------------------------------------------- update
    def update(self, points_obstacle_world, points_free_world, sensor_origin_world, *,
               baseline_focal_m_px: float | None = None, layers: tuple | None = None) -> GridUpdate:
        """Add one view: ``apply(view_cells(..., known_occupied=self.known_occupied()))`` with this
        grid and config (``known_occupied`` only with ``config.map_occlusion_p``); the parameters as
        :func:`view_cells`. Returns the :class:`GridUpdate`. In a grid of more than
        :data:`WINDOW_MIN_CELLS` cells the cells are computed in the part of the grid the view can reach
        (the bounding box of its points and the sensor: every ray lies in it), so a view costs the same
        in a large map as in a small one. ``layers``: the arguments of :meth:`add_layers`, added after.
        """
        obstacles = _points_xy("points_obstacle_world", points_obstacle_world)
        floor = _points_xy("points_free_world", points_free_world)
        rows, cols = self.grid.shape
        # a window computes cell positions from its own corner (the same cells but for rounding at
        # cell borders): it is used where the whole grid's per-view arrays would cost more than the view
        whole = rows * cols <= WINDOW_MIN_CELLS
        r0, r1, c0, c1 = (0, rows, 0, cols) if whole else _view_window(self.grid, obstacles, floor,
                                                                       sensor_origin_world)
        window = self.grid if whole else _subgrid(self.grid, r0, r1, c0, c1)
        known = None
        if self.config.map_occlusion_p is not None:
            level = float(log_odds_from_probability(self.config.map_occlusion_p))
            known = (self._log_odds[r0:r1, c0:c1] >= level, self._z_range_m[r0:r1, c0:c1])     # (NaN: False)
        cells = view_cells(obstacles, floor, sensor_origin_world, grid=window, config=self.config,
                           baseline_focal_m_px=baseline_focal_m_px, known_occupied=known)
        if not whole:
            cells = cells._replace(hit=_cells_in(cells.hit, c1 - c0, r0, c0, cols),
                                   miss=_cells_in(cells.miss, c1 - c0, r0, c0, cols), grid=self.grid)
        result = self.apply(cells)
        if layers is not None:
            self.add_layers(*layers)
        return result

    def add_layers(self, obstacle_points_world, floor_points_world, drop_points_world=None,
                   drop_candidates_world=None, drop_weak_points_world=None) -> int:
        """The height and drop layers of one view (with its :meth:`update`, after :meth:`apply`).

        Every point (N, 3) (z above the floor: obstacle, floor and the drop test's points, the latter at their
        measured height) widens its cell's lowest and highest height. First the drop test's candidates (K, 11)
        (:data:`mrstereo.geometry.drops.CANDIDATE_COLUMNS`: runs below the floor one frame cannot tell from a
        ramp starting out of view) are checked against the floor the views before this one measured: floor
        seen before a candidate's edge, higher than any drivable slope from it reaches, makes it a drop; floor
        seen beyond its edge, under its sight line, makes it a mismatch (``_kernels.confirm_drops``); the
        confirmed ones' edges join ``drop_points_world``. A cell with at least
        ``config.drop_min_points`` of ``drop_points_world`` gets a drop vote (up to ``drop_max_votes``); a
        cell with at least ``drop_clear_points`` of ``floor_points_world`` and no vote from this view loses
        one (``drop_points_world`` None: no drop test, no votes either way). The drop test's weak points
        (``drop_weak_points_world``, N, 3; :attr:`mrstereo.geometry.drops.DropResult.weak_points_robot`) vote
        the same way in the weak layer (up to ``max(drop_max_votes, drop_weak_views)``, the floor taking one
        back; none without ``drop_points_world``); they widen no height. Votes change only here and under the
        footprint (:meth:`clear_disc`), never by a ray passing over the cell. Returns the number of cells that
        got a vote (of the drop test's points).
        """
        with stage("grid.layers"):
            c = self.config
            g = self.grid
            rows, cols = g.shape
            at = (float(g.origin_x_m), float(g.origin_y_m), float(g.resolution_m), rows, cols)
            heights = self._heights_m.reshape(-1, 2)
            if drop_candidates_world is not None and len(drop_candidates_world):
                confirmed = self._confirm_drops(drop_candidates_world, at, heights)
                drop_points_world = confirmed if drop_points_world is None else np.concatenate(
                    [np.asarray(drop_points_world, dtype=confirmed.dtype).reshape(-1, 3), confirmed])
            sets = [_layer_points(name, p) for name, p in (("obstacle_points_world", obstacle_points_world),
                                                              ("floor_points_world", floor_points_world),
                                                              ("drop_points_world", drop_points_world),
                                                              ("drop_weak_points_world", drop_weak_points_world))]
            if self._counts is None:    # per-view scratch: counts of floor, drop and weak drop points per cell
                self._counts = np.zeros((rows * cols, 3), np.int32)
                self._stamp = np.full(rows * cols, -1, np.int32)
            self._view = (self._view + 1) % (1 << 31)           # the cells stamped with another view count from 0
            votes = self._drop_votes.reshape(-1, DROP_COLUMNS)
            scratch = (self._counts, self._stamp, self._view, votes, c.drop_clear_points)
            _kernels.layer_points(sets[2], 1, *at, heights, *scratch)
            voted = _kernels.drop_votes(sets[2], 1, *at, self._counts, votes, c.drop_min_points, c.drop_max_votes)
            if drop_points_world is not None:
                _kernels.layer_points(sets[3], 2, *at, heights, *scratch)
                _kernels.drop_votes(sets[3], 2, *at, self._counts, votes, c.drop_min_points,
                                    max(c.drop_max_votes, c.drop_weak_views))
            _kernels.layer_points(sets[1], 0 if drop_points_world is not None else -1, *at, heights, *scratch,
                                  drop_weak_points_world is not None)
            _kernels.layer_points(sets[0], -1, *at, heights, *scratch)
            return int(voted)

    def _confirm_drops(self, candidates, at, heights) -> np.ndarray:
        """The drop points (N, 3) of the candidates the height layer confirms (:meth:`add_layers`)."""
        rows = np.ascontiguousarray(candidates, dtype=np.float64)
        if rows.ndim != 2 or rows.shape[1] != len(CANDIDATE_COLUMNS) or not np.isfinite(rows).all():
            raise ValueError(f"drop_candidates_world must be finite with shape (K, {len(CANDIDATE_COLUMNS)}), "
                             f"got {rows.shape}")
        spacing = 0.2 * self.grid.resolution_m
        longest = float(np.hypot(rows[:, 2] - rows[:, 0], rows[:, 3] - rows[:, 1]).max())
        out = np.empty((len(rows) * (int(longest / spacing) + 4), 3), np.float32)
        n = _kernels.confirm_drops(rows, *at, heights, self._drop_votes.reshape(-1, DROP_COLUMNS),
                                   float(self.config.height_tolerance_m), CONFIRM_WALK_M, out)
        return out[:n]

    def known_occupied(self, p_min: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(mask, z_range_m)``: the cells held occupied with probability at least ``p_min`` (default
        ``config.map_occlusion_p``, else ``occupied_thresh``), and the lowest and highest obstacle point
        (metres above the floor) over the views that hit each cell ((inf, -inf) without heights).
        """
        if p_min is None:
            p_min = self.config.map_occlusion_p if self.config.map_occlusion_p is not None else self.config.occupied_thresh
        p_min = _checks.finite_number("p_min", p_min)
        if not 0.0 < p_min < 1.0:
            raise ValueError(f"p_min must be in (0, 1), got {p_min}")
        level = float(log_odds_from_probability(p_min))
        return np.nan_to_num(self._log_odds, nan=-np.inf) >= level, self._z_range_m.copy()

    def apply(self, cells: ViewCells) -> GridUpdate:
        """Add one view's hit and missed cells (from :func:`view_cells`) to the log-odds.

        Each cell changes once per view: ``L <- clamp(L + l_hit)`` for a hit, ``clamp(L + l_miss)``
        for a miss (``fusion="union"``: ``l_max`` for a hit, ``l_min`` for a miss of a cell that
        is not occupied). Views must be applied in their order (clamping does not commute).
        """
        if not isinstance(cells, ViewCells):
            raise TypeError(f"cells must be ViewCells (from view_cells), got {type(cells).__name__}")
        if not cells.fits(self.grid, self.config):
            raise ValueError("cells were computed for another grid or another max_range_m / "
                             "min_points_per_cell / sensor model than this OccupancyGrid's")
        n_cells = self._log_odds.size
        hit, miss = _cell_indices("cells.hit", cells.hit, n_cells), _cell_indices("cells.miss", cells.miss, n_cells)
        if cells.hit_z_m is not None and np.shape(cells.hit_z_m) != (len(hit), 2):
            raise ValueError(f"cells.hit_z_m must have shape ({len(hit)}, 2) (one row per hit cell), "
                             f"got {np.shape(cells.hit_z_m)}")
        c = self.config
        _kernels.apply_cells(self._log_odds.reshape(-1), hit, miss, c.l_hit, c.l_miss, c.l_min,
                             c.l_max, c.fusion == "union")
        if cells.hit_z_m is not None and len(hit):
            z = self._z_range_m.reshape(-1, 2)
            z[hit, 0] = np.minimum(z[hit, 0], cells.hit_z_m[:, 0])
            z[hit, 1] = np.maximum(z[hit, 1], cells.hit_z_m[:, 1])
        self.n_updates += 1
        self.points_outside += int(cells.points_outside)
        return GridUpdate(len(cells.hit), len(cells.miss), cells.points_outside)

    def clear_disc(self, xy_m, radius_m: float) -> int:
        """Mark free every cell a disc of ``radius_m`` at ``xy_m`` touches: the robot's footprint.

        The robot stood there, so the cells are observed free with certainty: their log-odds become
        ``l_min`` (later views may still hit them, a moved obstacle). A cell is touched when its square
        comes within ``radius_m`` of the centre; then every cell whose centre lies within ``radius_m`` of
        the centre of the robot's own cell is free too, so a planner inflating obstacles by the robot's
        radius can start there. Returns the number of cells cleared (inside the grid).
        """
        rows, cols = disc_cells(self.grid, xy_m, radius_m)
        self._log_odds[rows, cols] = self.config.l_min
        self._drop_votes[rows, cols] = 0
        return len(rows)

    # ---------------------------------------------------------------- outputs
    @property
    def log_odds(self) -> np.ndarray:
        """Log-odds of occupancy, shape ``grid.shape``, NaN = unknown (a read-only view)."""
        view = self._log_odds.view()
        view.flags.writeable = False
        return view

    def probability(self) -> np.ndarray:
        """Occupancy probability, shape ``grid.shape``, row 0 = min y, NaN = unknown."""
        return probability_from_log_odds(self._log_odds)

    @property
    def drop(self) -> np.ndarray:
        """The drop cells, occupied whatever the log-odds: those with a drop vote or weak votes from
        ``config.drop_weak_views`` views (:meth:`add_layers`), and the floor's last cells before a lower one
        (the height layer: a cell with a point at floor level next to a cell whose lowest point lies more than
        ``config.drop_low_m`` below the floor)."""
        from scipy.ndimage import binary_dilation

        voted = _voted(self._drop_votes, self.config)
        if self.config.drop_low_m is None:
            return voted
        low = np.nan_to_num(self._heights_m[..., 0], nan=0.0) < -self.config.drop_low_m
        if not low.any():
            return voted
        lo, hi = self._heights_m[..., 0], self._heights_m[..., 1]
        floor = (np.nan_to_num(hi, nan=-np.inf) > -self.config.drop_low_m) & ~low
        return voted | (binary_dilation(low, np.ones((3, 3), bool)) & floor)

    @property
    def heights_m(self) -> np.ndarray:
        """The height layer: lowest and highest point height seen per cell [m above the floor], shape
        ``grid.shape + (2,)``, float32, NaN where no point fell (a read-only view)."""
        view = self._heights_m.view()
        view.flags.writeable = False
        return view

    @property
    def unknown(self) -> np.ndarray:
        return np.isnan(self._log_odds) & ~self.drop

    @property
    def occupied(self) -> np.ndarray:
        threshold = float(log_odds_from_probability(self.config.occupied_thresh))
        return (np.nan_to_num(self._log_odds, nan=-np.inf) > threshold) | self.drop

    @property
    def free(self) -> np.ndarray:
        return ~(self.occupied | self.unknown)

    def to_ros_map(self) -> RosMap:
        """Trinary map (occupied 1, free 0, unknown NaN) for :func:`write_ros_map`."""
        occupancy = np.where(self.occupied, 1.0, 0.0)
        occupancy[self.unknown] = np.nan
        return RosMap(occupancy=occupancy, grid=self.grid)

    def save_log_odds(self, path: str | os.PathLike) -> None:
        """Write the log-odds array (float64, NaN unknown, row 0 = min y) as ``.npy``, atomically."""
        path = Path(path)
        if path.suffix != ".npy":
            raise ValueError(f"log-odds file must end in .npy, got {path}")
        with atomic_write(path) as tmp:
            np.save(tmp, self._log_odds)

    @classmethod
    def load_log_odds(cls, path: str | os.PathLike, grid: GridSpec | None = None, *,
                      config: MappingConfig | None = None) -> "OccupancyGrid":
        """Rebuild a grid from :meth:`save_log_odds` output (the GridSpec is not in the file)."""
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"log-odds file not found: {path}")
        try:
            arr = np.load(path, allow_pickle=False)
        except (ValueError, OSError) as exc:
            raise ValueError(f"cannot read log-odds file {path}: {exc}") from None
        return cls(grid, config=config, log_odds=arr)

    def copy(self) -> "OccupancyGrid":
        out = OccupancyGrid(self.grid, config=self.config, log_odds=self._log_odds)
        out._z_range_m[...] = self._z_range_m
        out._heights_m[...] = self._heights_m
        out._drop_votes[...] = self._drop_votes
        out.n_updates = self.n_updates
        out.points_outside = self.points_outside
        return out

    def __repr__(self) -> str:
        rows, cols = self.grid.shape
        return (f"OccupancyGrid({rows}x{cols} cells of {self.grid.resolution_m:g} m, "
                f"fusion={self.config.fusion!r}, updates={self.n_updates}, "
                f"occupied={int(self.occupied.sum())}, free={int(self.free.sum())})")

