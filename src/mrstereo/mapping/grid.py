"""The 2D grid geometry shared by ground-truth maps, occupancy grids and planning.

Cells are indexed ``[row, col]`` with row 0 at the *lowest* y (the map_server
image is flipped on write, its top row being max y). World frame: x forward,
y left, z up (REP 103). Conventions: docs/conventions.md.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .. import _checks

__all__ = ["GridSpec", "BYTES_PER_CELL"]

BYTES_PER_CELL = 160.0
"""Memory a map needs per cell, with a margin: log-odds and heights, each view's ray-casting buffers, the
known-occupied copy, the metrics and the figure."""


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
        rows, cols = self.height_m / self.resolution_m, self.width_m / self.resolution_m
        _checks.fits_in_memory("width_m, height_m and resolution_m", rows * cols * BYTES_PER_CELL,
                               f"a grid of {rows:.4g} x {cols:.4g} cells")

    @property
    def shape(self) -> tuple[int, int]:
        """``(rows, cols)``: rows along y, columns along x."""
        return (int(round(self.height_m / self.resolution_m)), int(round(self.width_m / self.resolution_m)))

    @property
    def extent_m(self) -> tuple[float, float, float, float]:
        """``(x_min, x_max, y_min, y_max)`` of the cells (matplotlib's ``extent``)."""
        rows, cols = self.shape
        return (self.origin_x_m, self.origin_x_m + cols * self.resolution_m,
                self.origin_y_m, self.origin_y_m + rows * self.resolution_m)

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


def distance_cells(mask: np.ndarray) -> np.ndarray:
    """Exact Euclidean distance (float64, in cells) from every cell to the nearest ``True`` cell.

    ``cv2.distanceTransform`` (precise L2 mask: the exact transform) returns float32; the
    squared distances are integers, so they are recovered exactly and the root is taken in
    float64 (the values of ``scipy.ndimage.distance_transform_edt(~mask)``). ``mask`` must
    have a ``True`` cell.
    """
    d32 = cv2.distanceTransform(np.where(mask, 0, 255).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return np.sqrt(np.rint(d32.astype(np.float64) ** 2))


def dilate_cells(mask: np.ndarray, radius_cells: int) -> np.ndarray:
    """``mask`` grown by a ``(2 r + 1)``-square of cells (outside the grid counts as ``False``)."""
    if radius_cells <= 0:
        return mask.copy()
    size = 2 * radius_cells + 1
    grown = cv2.dilate(mask.astype(np.uint8), np.ones((size, size), np.uint8),
                       borderType=cv2.BORDER_CONSTANT, borderValue=0)
    return grown.astype(bool)
