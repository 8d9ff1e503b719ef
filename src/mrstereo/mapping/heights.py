"""Height layer: per map cell the highest and lowest point seen, relative to the floor (a grid_map layer).

Beside the occupancy grid, it shows why a cell is lethal (a wall: high points; a drop: low ones) and gives
a planner for rough ground the heights. Fed with world-frame points whose z is the height above the floor
(the pipeline's ``FrameObservation.obstacle_points_world`` and ``floor_points_world``); saved as float32
arrays, a YAML description in the spirit of ROS ``grid_map`` and a figure. User guide: docs/obstacles.md,
"Drops". Conventions: docs/conventions.md.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import yaml

from .. import _checks
from ..io import atomic_write
from ..viz.plot import new_figure, save_figure
from .grid import GridSpec

__all__ = ["HeightLayer", "read_height_layer"]

_LAYERS = ("max_height_m", "min_height_m", "drop")


class HeightLayer:
    """Highest and lowest point height [m] per cell of ``grid`` (NaN where no point fell), the count, and the
    drop cells: where at least ``min_drop_frames`` frames each put ``min_drop_points`` drop-test points
    (:meth:`add_drops`).

    The occupancy grid's rays clear a cell that later views look past, which erodes a drop edge (flat, at
    floor level) once the robot sees beyond it; the drop cells keep it: :meth:`lethal` ORs them into a map.
    """

    def __init__(self, grid: GridSpec = GridSpec(), *, min_drop_points: int = 5, min_drop_frames: int = 1) -> None:
        _checks.instance("grid", grid, GridSpec)
        self.grid = grid
        self.min_drop_points = _checks.positive_int("min_drop_points", min_drop_points)
        self.min_drop_frames = _checks.positive_int("min_drop_frames", min_drop_frames)
        self.drop_frames = np.zeros(grid.shape, np.int64)
        self.max_height_m = np.full(grid.shape, np.nan, np.float32)
        self.min_height_m = np.full(grid.shape, np.nan, np.float32)
        self.count = np.zeros(grid.shape, np.int64)
        self.drop = np.zeros(grid.shape, bool)

    def _cells(self, points_world) -> tuple[np.ndarray, np.ndarray]:
        """Flat cell index and z of the finite points (N, 3) inside the grid."""
        p = np.asarray(points_world, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 3:
            raise ValueError(f"points_world must have shape (N, 3), got {p.shape}")
        p = p[np.isfinite(p).all(axis=1)]
        row, col = self.grid.cells_from_xy(p[:, :2])
        rows, cols = self.grid.shape
        inside = (row >= 0) & (row < rows) & (col >= 0) & (col < cols)
        return row[inside] * cols + col[inside], p[inside, 2]

    def add_drops(self, points_world) -> int:
        """Mark the cells where this frame's drop points (``ObstacleResult.drop_points_robot`` in the world
        frame) number at least ``min_drop_points``; returns how many cells that makes."""
        flat, _ = self._cells(points_world)
        hits = np.bincount(flat, minlength=self.drop.size).reshape(self.drop.shape) >= self.min_drop_points
        self.drop_frames += hits
        self.drop = self.drop_frames >= self.min_drop_frames
        return int(hits.sum())

    def lethal(self, ros_map):
        """``ros_map`` (a :class:`~mrstereo.mapping.rosmap.RosMap` on this layer's grid) with the drop cells
        occupied."""
        from dataclasses import replace

        if ros_map.grid != self.grid:
            raise ValueError("ros_map must be on the height layer's grid")
        occupancy = np.array(ros_map.occupancy, dtype=np.float64, copy=True)
        occupancy[self.drop] = 1.0
        return replace(ros_map, occupancy=occupancy)

    def add(self, points_world) -> int:
        """Add world-frame points (N, 3) (z above the floor; rows with NaN skipped); returns how many fell
        in the grid."""
        flat, z = self._cells(points_world)
        z = z.astype(np.float32)
        rows, cols = self.grid.shape
        if not flat.size:
            return 0
        hi = np.full(rows * cols, -np.inf, np.float32)
        lo = np.full(rows * cols, np.inf, np.float32)
        np.maximum.at(hi, flat, z)
        np.minimum.at(lo, flat, z)
        hit = np.isfinite(hi).reshape(rows, cols)
        self.max_height_m[hit] = np.fmax(self.max_height_m[hit], hi.reshape(rows, cols)[hit])
        self.min_height_m[hit] = np.fmin(self.min_height_m[hit], lo.reshape(rows, cols)[hit])
        self.count += np.bincount(flat, minlength=rows * cols).reshape(rows, cols)
        return int(flat.size)

    def save(self, folder: str | os.PathLike, *, frame_id: str = "map") -> dict[str, Path]:
        """Write ``heights.yaml``, ``max_height_m.npy``, ``min_height_m.npy`` (float32, row 0 at the grid's
        lowest y, as the occupancy grid), ``drop.npy`` (bool) and ``heights.png`` into ``folder``; each file
        atomically."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        out = {}
        for name in _LAYERS:
            path = folder / f"{name}.npy"
            with atomic_write(path) as tmp:
                with open(tmp, "wb") as f:
                    np.save(f, getattr(self, name))
            out[name] = path
        g = self.grid
        meta = {"frame_id": frame_id, "resolution": float(g.resolution_m),
                "length": [float(g.width_m), float(g.height_m)], "origin": [float(g.origin_x_m), float(g.origin_y_m)],
                "size": [int(g.shape[1]), int(g.shape[0])], "unit": "m above the floor",
                "layers": {name: f"{name}.npy" for name in _LAYERS}}
        out["yaml"] = folder / "heights.yaml"
        with atomic_write(out["yaml"]) as tmp:
            tmp.write_text(yaml.safe_dump(meta, sort_keys=False))
        out["png"] = self.plot(folder / "heights.png")
        return out

    def plot(self, path: str | os.PathLike) -> Path:
        """The two layers side by side with colour bars in metres (unknown cells blank)."""
        import matplotlib

        fig = new_figure(12.0, 4.0 + 8.0 * self.grid.shape[0] / self.grid.shape[1])
        cmap = matplotlib.colormaps["coolwarm"].with_extremes(bad="#dde6f0")
        values = np.concatenate([a[np.isfinite(a)] for a in (self.max_height_m, self.min_height_m)])
        limit = float(max(0.1, np.percentile(np.abs(values), 99))) if values.size else 1.0
        for k, (name, title) in enumerate(zip(_LAYERS[:2], ("highest point", "lowest point"))):
            ax = fig.add_subplot(1, 2, k + 1)
            im = ax.imshow(np.ma.masked_invalid(getattr(self, name)), cmap=cmap, vmin=-limit, vmax=limit,
                           origin="lower", extent=self.grid.extent_m, interpolation="nearest")
            ax.set_title(f"{title} above the floor")
            ax.set_xlabel("x [m]")
            ax.set_ylabel("y [m]")
            fig.colorbar(im, ax=ax, label="height [m]", shrink=0.8)
        return save_figure(fig, path)


def read_height_layer(folder: str | os.PathLike) -> HeightLayer:
    """The layer :meth:`HeightLayer.save` wrote into ``folder`` (the count is not saved: 0)."""
    folder = Path(folder)
    meta_path = folder / "heights.yaml"
    if not meta_path.is_file():
        raise ValueError(f"folder {folder} has no heights.yaml")
    meta = yaml.safe_load(meta_path.read_text())
    try:
        cols, rows = (int(v) for v in meta["size"])
        res = float(meta["resolution"])
        grid = GridSpec(width_m=cols * res, height_m=rows * res, resolution_m=res,
                        origin_x_m=float(meta["origin"][0]), origin_y_m=float(meta["origin"][1]))
        layer = HeightLayer(grid)
        for name in _LAYERS:
            array = np.load(folder / meta["layers"][name])
            dtype = np.bool_ if name == "drop" else np.float32
            if array.shape != grid.shape or array.dtype != dtype:
                raise ValueError(f"{name} is {array.dtype} {array.shape}, expected {np.dtype(dtype)} {grid.shape}")
            setattr(layer, name, array)
    except (KeyError, TypeError, IndexError, OSError) as exc:
        raise ValueError(f"{meta_path} is not a height layer: {exc}") from None
    return layer
