"""Height layer: per map cell the highest and lowest point seen, relative to the floor (a grid_map layer).

Beside the occupancy grid, it shows why a cell is lethal (a wall: high points; a drop: low ones) and gives
a planner for rough ground the heights. The occupancy grid keeps the layers as it fuses the views
(:meth:`~mrstereo.mapping.occupancy.OccupancyGrid.add_layers`); :class:`HeightLayer` saves them as float32
arrays, a YAML description in the spirit of ROS ``grid_map`` and a figure (``mrstereo map`` writes them to
``heights/``). User guide: docs/obstacles.md,
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
    """Highest and lowest point height [m above the floor] per cell of ``grid`` (float32, NaN where no point
    fell) and the drop cells (bool): the layers an :class:`~mrstereo.mapping.occupancy.OccupancyGrid` keeps
    beside its log-odds (:meth:`OccupancyGrid.add_layers`, :meth:`of`)."""

    def __init__(self, grid: GridSpec, max_height_m, min_height_m, drop) -> None:
        self.grid = _checks.instance("grid", grid, GridSpec)
        for name, value, dtype in (("max_height_m", max_height_m, np.float32), ("min_height_m", min_height_m, np.float32),
                                   ("drop", drop, np.bool_)):
            array = np.asarray(value)
            if array.shape != grid.shape or array.dtype != dtype:
                raise ValueError(f"{name} must be {np.dtype(dtype)} of the grid's shape {grid.shape}, "
                                 f"got {array.dtype} {array.shape}")
            setattr(self, name, array)

    @classmethod
    def of(cls, occupancy) -> "HeightLayer":
        """The height and drop layers of an :class:`~mrstereo.mapping.occupancy.OccupancyGrid` (copies)."""
        heights = occupancy.heights_m
        return cls(occupancy.grid, heights[..., 1].copy(), heights[..., 0].copy(), occupancy.drop.copy())

    def save(self, folder: str | os.PathLike, *, frame_id: str = "map") -> dict[str, Path]:
        """Write ``heights.yaml``, ``max_height_m.npy``, ``min_height_m.npy`` (float32, row 0 at the grid's
        lowest y, as the occupancy grid), ``drop.npy`` (bool) and ``heights.png`` into ``folder``; each file
        atomically. Returns them by name (``heights_yaml``, ``heights_png``, ``heights_<layer>``)."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        out = {}
        for name in _LAYERS:
            path = folder / f"{name}.npy"
            with atomic_write(path) as tmp:
                with open(tmp, "wb") as f:
                    np.save(f, getattr(self, name))
            out[f"heights_{name}"] = path
        g = self.grid
        meta = {"frame_id": frame_id, "resolution": float(g.resolution_m),
                "length": [float(g.width_m), float(g.height_m)], "origin": [float(g.origin_x_m), float(g.origin_y_m)],
                "size": [int(g.shape[1]), int(g.shape[0])], "unit": "m above the floor",
                "layers": {name: f"{name}.npy" for name in _LAYERS}}
        out["heights_yaml"] = folder / "heights.yaml"
        with atomic_write(out["heights_yaml"]) as tmp:
            tmp.write_text(yaml.safe_dump(meta, sort_keys=False))
        out["heights_png"] = self.plot(folder / "heights.png")
        return out

    def plot(self, path: str | os.PathLike) -> Path:
        """The two layers side by side with colour bars in metres (unknown cells blank), the drop cells in
        :data:`~mrstereo.mapping.figures.DROP_COLOUR` with a legend entry."""
        import matplotlib
        from matplotlib.patches import Patch

        from .figures import DROP_COLOUR

        fig = new_figure(12.0, 4.0 + 8.0 * self.grid.shape[0] / self.grid.shape[1])
        cmap = matplotlib.colormaps["coolwarm"].with_extremes(bad="#dde6f0")
        values = np.concatenate([a[np.isfinite(a)] for a in (self.max_height_m, self.min_height_m)])
        limit = float(max(0.1, np.percentile(np.abs(values), 99))) if values.size else 1.0
        for k, (name, title) in enumerate(zip(_LAYERS[:2], ("highest point", "lowest point"))):
            ax = fig.add_subplot(1, 2, k + 1)
            im = ax.imshow(np.ma.masked_invalid(getattr(self, name)), cmap=cmap, vmin=-limit, vmax=limit,
                           origin="lower", extent=self.grid.extent_m, interpolation="nearest")
            if self.drop.any():
                ax.imshow(np.ma.masked_where(~self.drop, np.ones(self.drop.shape)),
                          cmap=matplotlib.colors.ListedColormap([DROP_COLOUR]), vmin=0.0, vmax=1.0, origin="lower",
                          extent=self.grid.extent_m, interpolation="nearest", alpha=0.8)
                ax.legend(handles=[Patch(facecolor=DROP_COLOUR, label="drop: the floor ends (lethal)")],
                          loc="upper right", fontsize=8)
            ax.set_title(f"{title} above the floor")
            ax.set_xlabel("x [m]")
            ax.set_ylabel("y [m]")
            fig.colorbar(im, ax=ax, label="height above the floor [m]", shrink=0.8)
        return save_figure(fig, path)


def read_height_layer(folder: str | os.PathLike) -> HeightLayer:
    """The layer :meth:`HeightLayer.save` wrote into ``folder``."""
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
        return HeightLayer(grid, *(np.load(folder / meta["layers"][name], allow_pickle=False) for name in _LAYERS))
    except (KeyError, TypeError, IndexError, OSError) as exc:
        raise ValueError(f"{meta_path} is not a height layer: {exc}") from None
