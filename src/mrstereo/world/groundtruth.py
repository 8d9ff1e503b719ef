"""Ground-truth occupancy map of a scene (the "real corridor" lines of paper Fig. 14).

Occupied: every cell whose square overlaps the footprint of a wall, door panel
or obstacle. Free: the remaining cells of the corridor's free space (including
the door recesses and the scene's ``free_regions_m``, e.g. side rooms). Unknown (NaN): everything else, e.g. behind the walls.
Drops (a world's floor at several heights): :func:`floor_heights` and :func:`drop_edges`.
Grid conventions: :class:`mrstereo.mapping.grid.GridSpec`, docs/conventions.md.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .. import _checks
from ..mapping.grid import GridSpec
from ..mapping.rosmap import RosMap
from .scene import LABEL_CEILING, LABEL_DOOR, LABEL_FLOOR, LABEL_OBSTACLE, Scene

__all__ = ["ground_truth_map", "occupied_footprint", "obstacle_footprints", "floor_heights", "drop_edges",
           "DROP_STEP_M"]

DROP_STEP_M = 0.05
"""The step a robot climbs (``ObstacleConfig.max_step_m``): a larger height difference between neighbouring
floor cells is a drop edge."""


def occupied_footprint(scene: Scene, grid: GridSpec, *, height_band_m=(0.02, 2.0)) -> np.ndarray:
    """Boolean (rows, cols): cells overlapping a solid box or cylinder within the height band.

    The floor and ceiling slabs are not footprints; parts entirely above or
    below ``height_band_m`` (e.g. the lintel over a door) are ignored.
    """
    _checks.instance("scene", scene, Scene)
    _checks.instance("grid", grid, GridSpec)
    z_lo, z_hi = _checks.ordered_pair("height_band_m", height_band_m)
    rows, cols = grid.shape
    res = grid.resolution_m
    x_lo = grid.origin_x_m + np.arange(cols) * res
    y_lo = grid.origin_y_m + np.arange(rows) * res
    occ = np.zeros((rows, cols), bool)
    for box in scene.boxes:
        if box.label in (LABEL_FLOOR, LABEL_CEILING) or box.max_m[2] <= z_lo or box.min_m[2] >= z_hi:
            continue
        in_x = (x_lo < box.max_m[0]) & (x_lo + res > box.min_m[0])
        in_y = (y_lo < box.max_m[1]) & (y_lo + res > box.min_m[1])
        occ |= in_y[:, None] & in_x[None, :]
    for cyl in scene.cylinders:
        if cyl.height_m <= z_lo:
            continue
        cx, cy = cyl.centre_m
        # Distance from the centre to the nearest point of each cell square.
        ex = np.maximum(np.maximum(x_lo - cx, cx - (x_lo + res)), 0.0)
        ey = np.maximum(np.maximum(y_lo - cy, cy - (y_lo + res)), 0.0)
        occ |= (ey[:, None] ** 2 + ex[None, :] ** 2) < cyl.radius_m ** 2
    return occ


def obstacle_footprints(scene: Scene, grid: GridSpec, *, height_band_m=(0.02, 2.0)) -> dict[int, np.ndarray]:
    """``{label: footprint}``: one boolean (rows, cols) footprint per obstacle of ``scene`` (its
    boxes and cylinders of label ``LABEL_OBSTACLE + k``, e.g. a table's top and legs together,
    as in the frames' label images); empty footprints (outside the grid or the height band) are
    left out."""
    _checks.instance("scene", scene, Scene)
    labels = sorted({p.label for p in (*scene.boxes, *scene.cylinders) if p.label >= LABEL_OBSTACLE})
    footprints = {}
    for label in labels:
        one = replace(scene, boxes=tuple(b for b in scene.boxes if b.label == label),
                      cylinders=tuple(c for c in scene.cylinders if c.label == label))
        cells = occupied_footprint(one, grid, height_band_m=height_band_m)
        if cells.any():
            footprints[label] = cells
    return footprints


def ground_truth_map(scene: Scene, grid: GridSpec | None = None, *,
                     height_band_m=(0.02, 2.0)) -> RosMap:
    """The true 2D map of ``scene`` on ``grid`` (default: 12 m x 6 m at 5 cm, origin (0, -3)).

    Only solids reaching into ``height_band_m`` above the floor are obstacles (the robot passes
    under a door lintel). Returns a RosMap: ``occupancy`` 1.0 occupied, 0.0 free, NaN unknown.
    """
    _checks.instance("scene", scene, Scene)
    grid = GridSpec() if grid is None else grid
    _checks.instance("grid", grid, GridSpec)
    occ = occupied_footprint(scene, grid, height_band_m=height_band_m)
    centres = grid.cell_centres()
    x, y = centres[..., 0], centres[..., 1]
    x0, x1 = scene.x_range_m
    free_space = (x > x0) & (x < x1) & (np.abs(y) < scene.half_width_m)
    occupancy = np.full(grid.shape, np.nan)
    occupancy[free_space] = 0.0
    occupancy[_recesses(scene, x, y)] = 0.0
    for rx0, rx1, ry0, ry1 in scene.free_regions_m:
        occupancy[(x > rx0) & (x < rx1) & (y > ry0) & (y < ry1)] = 0.0
    occupancy[occ] = 1.0
    return RosMap(occupancy=occupancy, grid=grid)


def _recesses(scene: Scene, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Cells between the wall plane and a recessed door panel (floor-level wall gaps)."""
    out = np.zeros(x.shape, bool)
    for box in scene.boxes:
        if box.label != LABEL_DOOR:
            continue
        if box.min_m[1] > 0:      # left wall: recess from the wall plane up to the panel
            ya, yb = scene.half_width_m, box.min_m[1]
        else:
            ya, yb = box.max_m[1], -scene.half_width_m
        out |= (x > box.min_m[0]) & (x < box.max_m[0]) & (y >= ya) & (y < yb)
    return out


def floor_heights(scene: Scene, grid: GridSpec | None = None) -> np.ndarray:
    """Height of the floor [m] at each cell centre (rows, cols) float64: the highest top of the floor boxes
    (``LABEL_FLOOR``) over it (0 on the plain floor, lower in pits and on ramps down, higher on kerbs), NaN
    where there is none."""
    _checks.instance("scene", scene, Scene)
    grid = GridSpec() if grid is None else grid
    _checks.instance("grid", grid, GridSpec)
    centres = grid.cell_centres()
    x, y = centres[..., 0], centres[..., 1]
    height = np.full(grid.shape, -np.inf)
    for box in scene.boxes:
        if box.label == LABEL_FLOOR:
            inside = (x >= box.min_m[0]) & (x < box.max_m[0]) & (y >= box.min_m[1]) & (y < box.max_m[1])
            height[inside] = np.maximum(height[inside], box.max_m[2])
    height[np.isinf(height)] = np.nan
    return height


def drop_edges(scene: Scene, grid: GridSpec | None = None, *, max_step_m: float = DROP_STEP_M) -> np.ndarray:
    """Drop-edge cells (rows, cols) bool: free cells of the true map whose floor is more than ``max_step_m``
    above that of a neighbouring cell (8-neighbourhood) -- where the drivable floor ends. A ramp of 1 cm
    risers, a kerb or a sunken step within ``max_step_m`` has none."""
    grid = GridSpec() if grid is None else grid
    step = _checks.finite_number("max_step_m", max_step_m, nonnegative=True)
    height = floor_heights(scene, grid)
    padded = np.pad(height, 1, constant_values=np.nan)
    rows, cols = height.shape
    lowest = np.full(height.shape, np.inf)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            if dr or dc:
                neighbour = padded[1 + dr:1 + dr + rows, 1 + dc:1 + dc + cols]
                lowest = np.fmin(lowest, np.where(np.isnan(neighbour), np.inf, neighbour))
    with np.errstate(invalid="ignore"):
        edge = height - lowest > step
    return edge & (ground_truth_map(scene, grid).occupancy == 0.0)
