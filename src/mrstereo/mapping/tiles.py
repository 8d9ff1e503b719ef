"""A map that grows: the log-odds occupancy grid (:mod:`.occupancy`) stored as square tiles of cells.

The cells lie on one lattice anchored at the world origin (cell ``[row, col]`` spans
``x in [col r, (col + 1) r)``, ``y in [row r, (row + 1) r)`` for the resolution ``r``). A tile of
:data:`TILE_CELLS` x :data:`TILE_CELLS` cells is created when a view first reaches it, so memory grows
with the area seen, not with the extent of the path: a 1 km corridor at 5 cm holds the tiles along it,
not a square kilometre. Each view is fused in a window just large enough for its sensor and its points
(:meth:`TiledOccupancyGrid.update`): the window is cut from the tiles as an :class:`OccupancyGrid`,
updated with the same sensor model, and written back. :meth:`TiledOccupancyGrid.to_grid` gives the
dense grid of the cells seen (or of any window on the lattice) for the ROS map, the figures and
the metrics. Conventions: docs/conventions.md. User guide: docs/mapping.md.
"""
from __future__ import annotations

import math

import numpy as np

from .. import _checks
from .grid import GridSpec
from .occupancy import GridUpdate, MappingConfig, OccupancyGrid, _finite_bounds, _points_xy

__all__ = ["TiledOccupancyGrid", "TILE_CELLS"]

TILE_CELLS = 128
"""Cells along a tile's side (6.4 m at 5 cm): 256 KiB of log-odds and heights per tile."""


class TiledOccupancyGrid:
    """A log-odds occupancy grid of tiles created where views reach (a map that grows with the path).

    Parameters
    ----------
    resolution_m : float
        Cell size [m].
    config : MappingConfig, optional
        Sensor model and fusion (as :class:`OccupancyGrid`'s).
    view_reach_m : float
        A view's window reaches at most this far from its sensor (the mapping range and a margin);
        points beyond are counted in ``points_outside`` and their rays cut at the window's border.
    tile_cells : int
        Cells along a tile's side.
    """

    def __init__(self, resolution_m: float = 0.05, *, config: MappingConfig | None = None,
                 view_reach_m: float = 20.0, tile_cells: int = TILE_CELLS) -> None:
        self.resolution_m = _checks.finite_number("resolution_m", resolution_m, positive=True)
        self.config = MappingConfig() if config is None else config
        if not isinstance(self.config, MappingConfig):
            raise TypeError(f"config must be a MappingConfig, got {type(self.config).__name__}")
        self.view_reach_m = _checks.finite_number("view_reach_m", view_reach_m, positive=True)
        self.tile_cells = _checks.positive_int("tile_cells", tile_cells)
        self._tiles: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}
        self.n_updates = 0
        self.points_outside = 0

    # ------------------------------------------------------------------ windows
    def spec(self, row0: int, col0: int, rows: int, cols: int) -> GridSpec:
        """The :class:`GridSpec` of the lattice window with lower-left cell ``[row0, col0]``."""
        r = self.resolution_m
        return GridSpec(width_m=round(cols * r, 9), height_m=round(rows * r, 9), resolution_m=r,
                        origin_x_m=round(col0 * r, 9), origin_y_m=round(row0 * r, 9))

    def _cells_of(self, spec: GridSpec) -> tuple[int, int, int, int]:
        """``(row0, col0, rows, cols)`` of a grid on the lattice (same resolution, origin on a cell corner)."""
        r = self.resolution_m
        col0, row0 = spec.origin_x_m / r, spec.origin_y_m / r
        if (abs(spec.resolution_m - r) > 1e-9 * r or abs(col0 - round(col0)) > 1e-6
                or abs(row0 - round(row0)) > 1e-6):
            raise ValueError(f"the grid (origin ({spec.origin_x_m:g}, {spec.origin_y_m:g}) m, cells of "
                             f"{spec.resolution_m:g} m) is not on the map's lattice of {r:g} m cells from (0, 0)")
        return (int(round(row0)), int(round(col0))) + spec.shape

    def _overlaps(self, row0: int, col0: int, rows: int, cols: int):
        """``(tile key, window slice, tile slice)`` of every tile position the window overlaps."""
        t = self.tile_cells
        for ty in range(row0 // t, (row0 + rows - 1) // t + 1):
            for tx in range(col0 // t, (col0 + cols - 1) // t + 1):
                r0, r1 = max(row0, ty * t), min(row0 + rows, (ty + 1) * t)
                c0, c1 = max(col0, tx * t), min(col0 + cols, (tx + 1) * t)
                yield ((ty, tx), (slice(r0 - row0, r1 - row0), slice(c0 - col0, c1 - col0)),
                       (slice(r0 - ty * t, r1 - ty * t), slice(c0 - tx * t, c1 - tx * t)))

    def to_grid(self, spec: GridSpec | None = None) -> OccupancyGrid:
        """The dense grid of a lattice window (default :meth:`bounds`): log-odds and heights copied from the
        tiles, unknown where no view reached."""
        spec = self.bounds() if spec is None else spec
        row0, col0, rows, cols = self._cells_of(spec)
        log_odds = np.full((rows, cols), np.nan)
        z = np.empty((rows, cols, 2), np.float32)
        z[..., 0], z[..., 1] = np.inf, -np.inf
        for key, win, tile in self._overlaps(row0, col0, rows, cols):
            if key in self._tiles:
                log_odds[win] = self._tiles[key][0][tile]
                z[win] = self._tiles[key][1][tile]
        grid = OccupancyGrid(spec, config=self.config, log_odds=log_odds)
        grid._z_range_m[...] = z
        grid.n_updates, grid.points_outside = self.n_updates, self.points_outside
        return grid

    def _store(self, grid: OccupancyGrid) -> None:
        """Write a window back into the tiles, creating those it holds known cells or heights of."""
        row0, col0, rows, cols = self._cells_of(grid.grid)
        t = self.tile_cells
        for key, win, tile in self._overlaps(row0, col0, rows, cols):
            values, z = grid._log_odds[win], grid._z_range_m[win]
            if key not in self._tiles:
                if np.isnan(values).all() and not np.isfinite(z).any():
                    continue
                zt = np.empty((t, t, 2), np.float32)
                zt[..., 0], zt[..., 1] = np.inf, -np.inf
                self._tiles[key] = (np.full((t, t), np.nan), zt)
            self._tiles[key][0][tile] = values
            self._tiles[key][1][tile] = z

    def bounds(self) -> GridSpec:
        """The smallest lattice window holding every known cell (one cell at the origin when none is)."""
        rows, cols = [], []
        t = self.tile_cells
        for (ty, tx), (values, _) in self._tiles.items():
            known = ~np.isnan(values)
            if known.any():
                r, c = np.flatnonzero(known.any(axis=1)), np.flatnonzero(known.any(axis=0))
                rows += [ty * t + r[0], ty * t + r[-1]]
                cols += [tx * t + c[0], tx * t + c[-1]]
        if not rows:
            return self.spec(0, 0, 1, 1)
        return self.spec(min(rows), min(cols), max(rows) - min(rows) + 1, max(cols) - min(cols) + 1)

    @property
    def n_tiles(self) -> int:
        return len(self._tiles)

    @property
    def nbytes(self) -> int:
        """Bytes held by the tiles."""
        return sum(a.nbytes + b.nbytes for a, b in self._tiles.values())

    # ------------------------------------------------------------------ updates
    def _window(self, point_sets, centre_xy_m) -> tuple[int, int, int, int]:
        """The lattice window of the points (a sequence of (N, 2 or 3) arrays) and ``centre``, within
        ``view_reach_m`` of ``centre``."""
        r = self.resolution_m
        cx, cy = float(centre_xy_m[0]), float(centre_xy_m[1])
        lo = np.array([cx, cy]) - self.view_reach_m
        hi = np.array([cx, cy]) + self.view_reach_m
        bounds = _finite_bounds(*point_sets)
        if bounds is not None:
            lo = np.maximum(lo, np.minimum(bounds[:2], [cx, cy]))
            hi = np.minimum(hi, np.maximum(bounds[2:], [cx, cy]))
        else:
            lo = hi = np.array([cx, cy])
        c0, r0 = (int(math.floor(v / r)) - 1 for v in lo)
        c1, r1 = (int(math.floor(v / r)) + 1 for v in hi)
        return r0, c0, r1 - r0 + 1, c1 - c0 + 1

    def update(self, points_obstacle_world, points_free_world, sensor_origin_world, *,
               baseline_focal_m_px: float | None = None) -> GridUpdate:
        """Add one view (:meth:`OccupancyGrid.update`) in the window of its sensor and points."""
        sensor = np.asarray(sensor_origin_world, dtype=np.float64).ravel()
        if sensor.shape not in ((2,), (3,)) or not np.isfinite(sensor).all():
            raise ValueError(f"sensor_origin_world must be 2 or 3 finite numbers (x, y[, z]), got {sensor_origin_world!r}")
        obstacles = _points_xy("points_obstacle_world", points_obstacle_world)
        floor = _points_xy("points_free_world", points_free_world)
        window = self.to_grid(self.spec(*self._window((obstacles, floor), sensor[:2])))
        window.points_outside = 0
        result = window.update(obstacles, floor, sensor_origin_world,
                               baseline_focal_m_px=baseline_focal_m_px)
        self._store(window)
        self.n_updates += 1
        self.points_outside += result.points_outside
        return result

    def clear_disc(self, xy_m, radius_m: float) -> int:
        """Mark the cells a disc of ``radius_m`` at ``xy_m`` touches free (:meth:`OccupancyGrid.clear_disc`)."""
        r = self.resolution_m
        x, y = float(xy_m[0]), float(xy_m[1])
        c0, r0 = int(math.floor((x - radius_m) / r)) - 1, int(math.floor((y - radius_m) / r)) - 1
        n = int(math.ceil(2 * radius_m / r)) + 3
        window = self.to_grid(self.spec(r0, c0, n, n))
        cleared = window.clear_disc(xy_m, radius_m)
        self._store(window)
        return cleared
