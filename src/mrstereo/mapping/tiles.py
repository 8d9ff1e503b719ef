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

import json
import math
import os
import warnings
from dataclasses import asdict
from pathlib import Path

import numpy as np

from .. import _checks
from ..io import atomic_write, write_image
from .grid import BYTES_PER_CELL, GridSpec
from .occupancy import (DROP_COLUMNS, GridUpdate, MappingConfig, OccupancyGrid, _finite_bounds, _points_xy, _voted,
                        disc_cells, log_odds_from_probability)
from .rosmap import FREE, OCCUPIED, UNKNOWN, write_map_yaml

__all__ = ["TiledOccupancyGrid", "TILE_CELLS", "DENSE_MAP_MAX_CELLS", "OVERVIEW_MAX_PX"]

TILE_CELLS = 128
"""Cells along a tile's side (6.4 m at 5 cm): 512 KiB of log-odds, heights and drop votes per tile."""

DENSE_MAP_MAX_CELLS = 2048 * 2048
"""The most cells of a map written whole as one dense grid (map.pgm, log_odds.npy, map.png, the metrics):
2048 x 2048, a 102.4 m square at 5 cm, about 670 MB while it is written. A larger map's dense grid is the
square of this size around a given point (the last pose); the whole map is in the tiles and the overview."""

OVERVIEW_MAX_PX = 4096
"""The longest side of the overview image in pixels (each pixel a square of 2^k cells)."""

_LAYERS = ("_log_odds", "_z_range_m", "_heights_m", "_drop_votes")
"""The :class:`OccupancyGrid` arrays a tile holds, in order (saved as ``log_odds``, ``z``, ``heights``, ``drop``)."""
_SAVED = ("log_odds", "z", "heights", "drop")


def _padded(votes: np.ndarray, columns: int) -> np.ndarray:
    """Drop votes of a map saved with fewer columns (T, T) or (T, T, c) as (T, T, ``columns``), the missing ones
    zero (no weak votes, no views counted)."""
    votes = votes.reshape(votes.shape[:2] + (-1,))
    return np.concatenate([votes, np.zeros(votes.shape[:2] + (columns - votes.shape[2],), votes.dtype)], axis=-1)


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
        # a view is fused in a dense window of up to (2 reach)^2: refused here, before any frame is matched
        side = 2.0 * self.view_reach_m / self.resolution_m + 3.0
        _checks.fits_in_memory("resolution_m and view_reach_m", side * side * BYTES_PER_CELL,
                               f"one view's window of up to {side:.4g} x {side:.4g} cells of {self.resolution_m:g} m "
                               f"({self.view_reach_m:g} m each way from the sensor)")
        _checks.fits_in_memory("tile_cells", 32.0 * self.tile_cells ** 2, f"a tile of {self.tile_cells} x "
                               f"{self.tile_cells} cells")
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
        """The dense grid of a lattice window (default :meth:`bounds`): log-odds, heights and drop votes copied
        from the tiles, unknown where no view reached."""
        spec = self.bounds() if spec is None else spec
        row0, col0, rows, cols = self._cells_of(spec)
        grid = OccupancyGrid(spec, config=self.config)          # all unknown, no heights: filled from the tiles
        for key, win, tile in self._overlaps(row0, col0, rows, cols):
            if key in self._tiles:
                for name, values in zip(_LAYERS, self._tiles[key]):
                    getattr(grid, name)[win] = values[tile]
        grid.n_updates, grid.points_outside = self.n_updates, self.points_outside
        return grid

    def seed(self, grid: OccupancyGrid) -> None:
        """Write the cells of ``grid`` into the tiles: a saved map to map on (:func:`mrstereo.mapping.prior.
        prior_grid`), before any view. Its origin must be on the lattice (whole cells from (0, 0): maps written
        by ``mrstereo map`` are), else ``ValueError``."""
        if not isinstance(grid, OccupancyGrid):
            raise TypeError(f"grid must be an OccupancyGrid, got {type(grid).__name__}")
        self._store(grid)

    def _tile(self, key: tuple[int, int]) -> tuple[np.ndarray, ...]:
        """The tile at ``key`` (the arrays of :data:`_LAYERS`), created unknown without heights when missing."""
        if key not in self._tiles:
            t = self.tile_cells
            z = np.empty((t, t, 2), np.float32)
            z[..., 0], z[..., 1] = np.inf, -np.inf
            self._tiles[key] = (np.full((t, t), np.nan), z, np.full((t, t, 2), np.nan, np.float32),
                                np.zeros((t, t, DROP_COLUMNS), np.int16))
        return self._tiles[key]

    def _store(self, grid: OccupancyGrid) -> None:
        """Write a window back into the tiles, creating those it holds known cells, heights or drops of."""
        row0, col0, rows, cols = self._cells_of(grid.grid)
        for key, win, tile in self._overlaps(row0, col0, rows, cols):
            arrays = [getattr(grid, name)[win] for name in _LAYERS]
            if key not in self._tiles and not (~np.isnan(arrays[0]).all() or np.isfinite(arrays[1]).any()
                                               or np.isfinite(arrays[2]).any() or arrays[3].any()):
                continue
            for stored, values in zip(self._tile(key), arrays):
                stored[tile] = values

    def _known_cells(self) -> tuple[int, int, int, int]:
        """``(row0, col0, rows, cols)`` of the smallest lattice window holding every known cell (one cell at the
        origin when none is)."""
        rows, cols = [], []
        t = self.tile_cells
        for (ty, tx), (values, _, _, votes) in self._tiles.items():
            known = ~np.isnan(values) | _voted(votes, self.config)
            if known.any():
                r, c = np.flatnonzero(known.any(axis=1)), np.flatnonzero(known.any(axis=0))
                rows += [ty * t + r[0], ty * t + r[-1]]
                cols += [tx * t + c[0], tx * t + c[-1]]
        if not rows:
            return 0, 0, 1, 1
        return min(rows), min(cols), max(rows) - min(rows) + 1, max(cols) - min(cols) + 1

    def bounds(self) -> GridSpec:
        """The smallest lattice window holding every known cell (one cell at the origin when none is); a
        ValueError when a dense grid of it would not fit in memory (:meth:`extent_m` has no limit)."""
        return self.spec(*self._known_cells())

    def extent_m(self) -> tuple[float, float, float, float]:
        """``(x_min, x_max, y_min, y_max)`` of the known cells (GridSpec's ``extent_m`` of :meth:`bounds`)."""
        row0, col0, rows, cols = self._known_cells()
        r = self.resolution_m
        return col0 * r, (col0 + cols) * r, row0 * r, (row0 + rows) * r

    @property
    def n_tiles(self) -> int:
        return len(self._tiles)

    @property
    def nbytes(self) -> int:
        """Bytes held by the tiles."""
        return sum(a.nbytes for arrays in self._tiles.values() for a in arrays)

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
               baseline_focal_m_px: float | None = None, layers: tuple | None = None) -> GridUpdate:
        """Add one view (:meth:`OccupancyGrid.update`, with its ``layers``) in the window of its sensor and
        points."""
        sensor = np.asarray(sensor_origin_world, dtype=np.float64).ravel()
        if sensor.shape not in ((2,), (3,)) or not np.isfinite(sensor).all():
            raise ValueError(f"sensor_origin_world must be 2 or 3 finite numbers (x, y[, z]), got {sensor_origin_world!r}")
        obstacles = _points_xy("points_obstacle_world", points_obstacle_world)
        floor = _points_xy("points_free_world", points_free_world)
        # the drop test's weak points (no obstacle points, :meth:`OccupancyGrid.add_layers`) lie in the window too
        weak = _points_xy("drop_weak_points_world", layers[4] if layers is not None and len(layers) > 4 else None)
        window = self.to_grid(self.spec(*self._window((obstacles, floor, weak), sensor[:2])))
        window.points_outside = 0
        result = window.update(obstacles, floor, sensor_origin_world,
                               baseline_focal_m_px=baseline_focal_m_px, layers=layers)
        self._store(window)
        self.n_updates += 1
        self.points_outside += result.points_outside
        return result

    def clear_disc(self, xy_m, radius_m: float) -> int:
        """Mark the cells a disc of ``radius_m`` at ``xy_m`` touches free (:meth:`OccupancyGrid.clear_disc`), written
        into the tiles (created where missing)."""
        r = self.resolution_m
        x, y = float(xy_m[0]), float(xy_m[1])
        c0, r0 = int(math.floor((x - radius_m) / r)) - 1, int(math.floor((y - radius_m) / r)) - 1
        n = int(math.ceil(2 * radius_m / r)) + 3
        rows, cols = disc_cells(self.spec(r0, c0, n, n), xy_m, radius_m)
        rows, cols = rows + r0, cols + c0
        t = self.tile_cells
        keys = (rows // t) * (1 << 32) + cols // t
        for key in np.unique(keys):
            sel = keys == key
            ty, tx = int(rows[sel][0] // t), int(cols[sel][0] // t)
            tile = self._tile((ty, tx))
            tile[0][rows[sel] - ty * t, cols[sel] - tx * t] = self.config.l_min
            tile[3][rows[sel] - ty * t, cols[sel] - tx * t] = 0
        return len(rows)

    # ------------------------------------------------------------------ outputs
    def map_window(self, centre_xy_m=None, *, max_cells: int = DENSE_MAP_MAX_CELLS) -> GridSpec:
        """The window of the dense grid to write: :meth:`bounds` when it holds at most ``max_cells`` cells, else
        the square of ``sqrt(max_cells)`` cells a side centred on ``centre_xy_m`` (default the map's centre),
        kept within the bounds, with one warning that says so."""
        max_cells = _checks.positive_int("max_cells", max_cells)
        row0, col0, rows, cols = self._known_cells()
        if rows * cols <= max_cells:
            return self.spec(row0, col0, rows, cols)
        side = max(1, int(math.isqrt(int(max_cells))))
        if centre_xy_m is None:
            centre = (col0 + cols / 2.0, row0 + rows / 2.0)
        else:
            centre = (float(centre_xy_m[0]) / self.resolution_m, float(centre_xy_m[1]) / self.resolution_m)
        h, w = min(side, rows), min(side, cols)
        r = int(np.clip(math.floor(centre[1]) - h // 2, row0, row0 + rows - h))
        c = int(np.clip(math.floor(centre[0]) - w // 2, col0, col0 + cols - w))
        window = self.spec(r, c, h, w)
        warnings.warn(f"the map covers {cols * self.resolution_m:g} x {rows * self.resolution_m:g} m ({cols} x {rows} "
                      f"cells), more than "
                      f"one dense map of {max_cells} cells: map.pgm, log_odds.npy and map.png hold the "
                      f"{window.width_m:g} x {window.height_m:g} m around ({window.origin_x_m + window.width_m / 2:g}, "
                      f"{window.origin_y_m + window.height_m / 2:g}) m; the whole map is in tiles.npz and "
                      "overview.png/overview.yaml", stacklevel=2)
        return window

    def save(self, path: str | os.PathLike) -> None:
        """Write the tiles as one compressed ``.npz`` (atomically): per tile ``t<row>_<col>_log_odds`` (float64,
        NaN unknown, row 0 = min y) and ``t<row>_<col>_z`` (lowest and highest obstacle point, float32), the tile
        ``<row>, <col>`` covering cells ``[row T, (row + 1) T) x [col T, (col + 1) T)`` of the lattice from the
        world origin (``T`` = ``tile_cells``); ``meta`` a JSON string (resolution, tile_cells, view_reach_m, the
        config, n_updates, points_outside). :meth:`load` reads it back."""
        path = Path(path)
        if path.suffix != ".npz":
            raise ValueError(f"tiles file must end in .npz, got {path}")
        meta = {"resolution_m": self.resolution_m, "tile_cells": self.tile_cells, "view_reach_m": self.view_reach_m,
                "config": asdict(self.config), "n_updates": self.n_updates, "points_outside": self.points_outside}
        arrays = {"meta": np.array(json.dumps(meta))}
        for (ty, tx), tile in sorted(self._tiles.items()):
            for name, values in zip(_SAVED, tile):
                arrays[f"t{ty}_{tx}_{name}"] = values
        with atomic_write(path) as tmp, open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)

    @classmethod
    def load(cls, path: str | os.PathLike) -> "TiledOccupancyGrid":
        """The map :meth:`save` wrote."""
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"tiles file not found: {path}")
        try:
            with np.load(path, allow_pickle=False) as data:
                meta = json.loads(str(data["meta"]))
                out = cls(meta["resolution_m"], config=MappingConfig(**meta["config"]),
                          view_reach_m=meta["view_reach_m"], tile_cells=meta["tile_cells"])
                t = out.tile_cells
                for name in data.files:
                    if name.endswith("_log_odds"):
                        ty, tx = (int(v) for v in name[1:-len("_log_odds")].split("_"))
                        tile = out._tile((ty, tx))
                        for saved, stored in zip(_SAVED, tile):
                            key = name[:-len("log_odds")] + saved
                            if key not in data.files and saved in ("heights", "drop"):
                                continue                    # (a map saved before the height and drop layers)
                            values = data[key]
                            if saved == "drop" and values.shape[:2] == stored.shape[:2] and \
                                    values.size < stored.size:  # (a map saved before the weak votes or their views)
                                values = _padded(values, stored.shape[2])
                            if values.shape != stored.shape:
                                raise ValueError(f"tile {key} has shape {values.shape}, not {stored.shape}")
                            stored[...] = values
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise ValueError(f"cannot read tiles file {path}: {exc}") from None
        out.n_updates, out.points_outside = int(meta["n_updates"]), int(meta["points_outside"])
        return out

    def overview(self, *, max_px: int = OVERVIEW_MAX_PX) -> tuple[np.ndarray, GridSpec]:
        """``(image, grid)``: the whole map downsampled, one pixel per square of ``2^k`` cells (the smallest ``k``
        with both sides at most ``max_px``), computed tile by tile (no dense raster of the map). A pixel is
        occupied (0) when one of its cells is, else free (254) when one is, else unknown (205): map_server's
        trinary values, row 0 at the lowest y (flip it for an image file), ``grid`` its geometry."""
        max_px = _checks.positive_int("max_px", max_px)
        row0, col0, rows, cols = self._known_cells()
        k = 1
        while math.ceil((row0 + rows) / k) - row0 // k > max_px or math.ceil((col0 + cols) / k) - col0 // k > max_px:
            k *= 2
        r_lo, c_lo = row0 // k, col0 // k
        shape = (-(-(row0 + rows) // k) - r_lo, -(-(col0 + cols) // k) - c_lo)
        level = np.zeros(shape, np.uint8)                 # 0 unknown, 1 free, 2 occupied: the largest wins
        threshold = float(log_odds_from_probability(self.config.occupied_thresh))
        t = self.tile_cells
        for (ty, tx), (values, _, _, votes) in self._tiles.items():
            known = ~np.isnan(values) | _voted(votes, self.config)
            if not known.any():
                continue
            cls = known.astype(np.uint8) + ((np.nan_to_num(values, nan=-np.inf) > threshold)
                                            | _voted(votes, self.config))
            # (known cells lie within the bounds, so every index below is inside ``level``)
            if t % k == 0:                                # whole blocks inside the tile: a reshape
                block = cls.reshape(t // k, k, t // k, k).max(axis=(1, 3))
                r, c = ty * (t // k) - r_lo, tx * (t // k) - c_lo
                rs, cs = slice(max(r, 0), min(r + t // k, shape[0])), slice(max(c, 0), min(c + t // k, shape[1]))
                sub = block[rs.start - r:rs.stop - r, cs.start - c:cs.stop - c]
                level[rs, cs] = np.maximum(level[rs, cs], sub)
            elif k % t == 0:                              # the tile inside one pixel
                r, c = (ty * t) // k - r_lo, (tx * t) // k - c_lo
                level[r, c] = max(level[r, c], cls.max())
            else:
                rr, cc = np.nonzero(cls)
                np.maximum.at(level, ((ty * t + rr) // k - r_lo, (tx * t + cc) // k - c_lo), cls[rr, cc])
        image = np.choose(level, np.array([UNKNOWN, FREE, OCCUPIED], np.uint8))
        res = self.resolution_m * k
        grid = GridSpec(width_m=round(shape[1] * res, 9), height_m=round(shape[0] * res, 9), resolution_m=res,
                        origin_x_m=round(c_lo * res, 9), origin_y_m=round(r_lo * res, 9))
        return image, grid

    def write_overview(self, yaml_path: str | os.PathLike, *, max_px: int = OVERVIEW_MAX_PX) -> Path:
        """Write :meth:`overview` as a map_server map: ``NAME.yaml`` and the image ``NAME.png`` beside it (trinary,
        top row max y), atomically; returns the image's path."""
        yaml_path = Path(yaml_path)
        image, grid = self.overview(max_px=max_px)
        png = yaml_path.with_suffix(".png")
        write_image(png, np.flipud(image))
        write_map_yaml(yaml_path, png.name, grid)
        return png
