"""The 2D grid geometry shared by ground-truth maps, occupancy grids and planning.

Cells are indexed ``[row, col]`` with row 0 at the *lowest* y (the map_server
image is flipped on write, its top row being max y). World frame: x forward,
y left, z up (REP 103). Conventions: docs/conventions.md.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import _checks

__all__ = ["GridSpec"]


@dataclass(frozen=True)
class GridSpec:
    """A regular grid: ``origin_m`` is the world (x, y) of the lower-left corner of cell [0, 0].

    Defaults: the paper's 12 m x 6 m corridor region in 5 cm cells.
    """

    width_m: float = 12.0
    height_m: float = 6.0
    resolution_m: float = 0.05
    origin_x_m: float = 0.0
    origin_y_m: float = -3.0

    def __post_init__(self) -> None:
        for name in ("width_m", "height_m", "resolution_m"):
            _checks.finite_number(name, getattr(self, name), positive=True)
        for name in ("origin_x_m", "origin_y_m"):
            _checks.finite_number(name, getattr(self, name))

    @property
    def shape(self) -> tuple[int, int]:
        """``(rows, cols)``: rows along y, columns along x."""
        return (int(round(self.height_m / self.resolution_m)), int(round(self.width_m / self.resolution_m)))

    def cells_from_xy(self, xy_m) -> tuple[np.ndarray, np.ndarray]:
        """Integer ``(row, col)`` of world points (N, 2); may be outside the grid."""
        xy = np.asarray(xy_m, dtype=np.float64)
        col = np.floor((xy[..., 0] - self.origin_x_m) / self.resolution_m).astype(np.int64)
        row = np.floor((xy[..., 1] - self.origin_y_m) / self.resolution_m).astype(np.int64)
        return row, col

    def xy_from_cells(self, row, col) -> np.ndarray:
        """World (x, y) of cell centres, shape (..., 2)."""
        x = self.origin_x_m + (np.asarray(col, dtype=np.float64) + 0.5) * self.resolution_m
        y = self.origin_y_m + (np.asarray(row, dtype=np.float64) + 0.5) * self.resolution_m
        return np.stack([x, y], axis=-1)

    def inside(self, row, col) -> np.ndarray:
        rows, cols = self.shape
        row, col = np.asarray(row), np.asarray(col)
        return (row >= 0) & (row < rows) & (col >= 0) & (col < cols)

    def cell_centres(self) -> np.ndarray:
        """World (x, y) of every cell centre, shape (rows, cols, 2)."""
        rows, cols = self.shape
        r, c = np.mgrid[0:rows, 0:cols]
        return self.xy_from_cells(r, c)
