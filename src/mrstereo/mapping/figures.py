"""Map figure in the manner of paper Fig. 14: occupied cells, robot path, views, true walls.

Drawn with matplotlib's Agg backend (no display needed), written atomically.
Conventions (world x forward = figure right, y left = figure up): docs/conventions.md.
"""
from __future__ import annotations

import math
import os

import numpy as np

from .. import _checks
from ..io import atomic_write
from ..viz.plot import new_figure
from .rosmap import RosMap

__all__ = ["plot_map", "DROP_COLOUR"]

_UNKNOWN = "#cfd8e6"      # pale blue: cells never observed
DROP_COLOUR = "#c51b8a"   # magenta: drop cells (the floor ends there; lethal), in every map figure


def _probability(value) -> tuple[np.ndarray, object]:
    if isinstance(value, RosMap):
        return value.occupancy, value.grid
    if hasattr(value, "probability") and hasattr(value, "grid"):
        return value.probability(), value.grid
    raise TypeError(f"grid_or_rosmap must be an OccupancyGrid or RosMap, got {type(value).__name__}")


def _array(name: str, value, columns: int) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] < columns:
        raise ValueError(f"{name} must have shape (K, {columns}) or wider, got {arr.shape}")
    return arr


def plot_map(grid_or_rosmap, path_png: str | os.PathLike, *, robot_path=None, fov_views=None,
             planned_path=None, ground_truth=None, title: str | None = None, drop_cells=None) -> None:
    """Draw the map and write it as an image (PNG/PDF/SVG by suffix).

    Parameters
    ----------
    grid_or_rosmap : OccupancyGrid or RosMap
        Occupancy shown as gray (black occupied, white free, 1 - p between), unknown pale blue;
        the legend under the map names the shades, the path and the start and goal.
    path_png : path-like
        Output file, written atomically.
    robot_path : ndarray of shape (K, 3) or (K, 2), optional
        Robot poses ``(x_m, y_m, yaw_rad)``; drawn as a line with heading ticks.
    fov_views : list of (x_m, y_m, heading_rad, half_fov_rad, range_m), optional
        Fields of view of the stereo views (the paper's front, left and right views).
    planned_path : ndarray of shape (K, 2), optional
        A planned path (e.g. ``PlanResult.path_xy``).
    ground_truth : RosMap, optional
        True map; its occupied cells are overlaid in red (the paper's solid lines).
    title : str, optional
    drop_cells : ndarray of bool, optional
        The drop cells (where the floor ends, lethal), drawn in :data:`DROP_COLOUR`; default those of an
        :class:`~mrstereo.mapping.occupancy.OccupancyGrid` (its ``drop``).
    """
    import matplotlib
    from matplotlib.patches import Patch, Wedge

    probability, grid = _probability(grid_or_rosmap)
    rows, cols = grid.shape
    extent = grid.extent_m
    width_in = 10.0
    height_in = max(3.0, width_in * rows / cols + 1.0) + 0.8     # + the legend under the map
    fig = new_figure(width_in, height_in)
    ax = fig.add_subplot()
    cmap = matplotlib.colormaps["gray"].with_extremes(bad=_UNKNOWN)
    ax.imshow(np.ma.masked_invalid(1.0 - probability), cmap=cmap, vmin=0.0, vmax=1.0,
              origin="lower", extent=extent, interpolation="nearest")
    drop_cells = getattr(grid_or_rosmap, "drop", None) if drop_cells is None else np.asarray(drop_cells, bool)
    if drop_cells is not None and drop_cells.shape != (rows, cols):
        raise ValueError(f"drop_cells must have the map's shape {(rows, cols)}, got {drop_cells.shape}")
    has_drops = drop_cells is not None and bool(drop_cells.any())
    if has_drops:
        ax.imshow(np.ma.masked_where(~drop_cells, np.ones((rows, cols))),
                  cmap=matplotlib.colors.ListedColormap([DROP_COLOUR]), vmin=0.0, vmax=1.0, origin="lower",
                  extent=extent, interpolation="nearest")
    if ground_truth is not None:
        _checks.instance("ground_truth", ground_truth, RosMap)
        ax.contour(ground_truth.occupied.astype(float), levels=[0.5], colors="tab:red", linewidths=1.0,
                   origin="lower", extent=ground_truth.grid.extent_m)
        ax.plot([], [], color="tab:red", lw=1.0, label="true walls and obstacles")
    for view in fov_views or ():
        if len(view) != 5:
            raise ValueError("each fov_views entry must be (x_m, y_m, heading_rad, half_fov_rad, "
                             f"range_m), got {view!r}")
        x, y, heading, half_fov, range_m = (float(v) for v in view)
        ax.add_patch(Wedge((x, y), range_m, math.degrees(heading - half_fov),
                           math.degrees(heading + half_fov), fill=False, edgecolor="tab:orange",
                           alpha=0.35, lw=0.6, linestyle="--"))
    if fov_views:
        ax.plot([], [], color="tab:orange", lw=0.8, linestyle="--", label="fields of view")
    if robot_path is not None:
        poses = _array("robot_path", robot_path, 2)
        ax.plot(poses[:, 0], poses[:, 1], "-o", color="tab:blue", ms=3, lw=1.5,
                label="robot path")
        if poses.shape[1] >= 3:
            tick = 0.3
            ax.quiver(poses[:, 0], poses[:, 1], tick * np.cos(poses[:, 2]),
                      tick * np.sin(poses[:, 2]), color="tab:blue", angles="xy",
                      scale_units="xy", scale=1.0, width=0.003)
    if planned_path is not None:
        path = _array("planned_path", planned_path, 2)
        if len(path):
            ax.plot(path[:, 0], path[:, 1], "-", color="tab:green", lw=2, label="planned path")
            ax.plot(path[0, 0], path[0, 1], "o", color="tab:green", mec="k", ms=8, label="start")
            ax.plot(path[-1, 0], path[-1, 1], "*", color="tab:green", mec="k", ms=13, label="goal")
    ax.set_xlim(extent[0], extent[1])
    ax.set_ylim(extent[2], extent[3])
    ax.set_aspect("equal")
    ax.set_xlabel("x [m] (forward)")
    ax.set_ylabel("y [m] (left)")
    if title:
        ax.set_title(title)
    shades = [Patch(facecolor="white", edgecolor="0.5", label="free"),
              Patch(facecolor="black", edgecolor="0.5", label="occupied"),
              Patch(facecolor=_UNKNOWN, edgecolor="0.5", label="unknown (never observed)")]
    if has_drops:
        shades.insert(2, Patch(facecolor=DROP_COLOUR, edgecolor="0.5", label="drop: the floor ends (lethal)"))
    known = probability[np.isfinite(probability)]
    if np.any((known > 0.02) & (known < 0.98)):
        shades.insert(1, Patch(facecolor="0.55", edgecolor="0.5", label="gray: 1 - p(occupied)"))
    handles, _ = ax.get_legend_handles_labels()
    ax.legend(handles=shades + handles, loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=4,
              fontsize=8, frameon=False)
    fig.tight_layout()
    with atomic_write(path_png) as tmp:
        fig.savefig(tmp)
