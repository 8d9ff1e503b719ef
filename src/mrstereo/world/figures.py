"""PNG figures of stereo frames, disparity maps and occupancy maps (matplotlib Agg).

Reusable by every command that shows results (``mrstereo demo``). Each function
writes one PNG atomically and returns its path. Disparity colours follow
:func:`mrstereo.io.colorize_disparity` (turbo, invalid black).
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..io import atomic_write
from ..mapping.rosmap import RosMap

__all__ = ["save_stereo_figure", "save_disparity_figure", "save_map_figure"]


def _figure(width_in: float, height_in: float):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), dpi=100)
    FigureCanvasAgg(fig)
    return fig


def _save(fig, path: str | os.PathLike) -> Path:
    path = Path(path)
    with atomic_write(path) as tmp:
        fig.savefig(tmp, format="png", bbox_inches="tight")
    return path


def save_stereo_figure(path: str | os.PathLike, images: dict[str, np.ndarray], *, title: str = "") -> Path:
    """Grid of gray images, two per row, e.g. ``{"raw left": ..., "raw right": ...}``."""
    names = list(images)
    if not names:
        raise ValueError("images must hold at least one image")
    rows = (len(names) + 1) // 2
    fig = _figure(8.0, 3.0 * rows + 0.4)
    for k, name in enumerate(names):
        ax = fig.add_subplot(rows, 2, k + 1)
        ax.imshow(images[name], cmap="gray", vmin=0, vmax=255, interpolation="nearest")
        ax.set_title(name, fontsize=9)
        ax.set_axis_off()
    if title:
        fig.suptitle(title, fontsize=10)
    return _save(fig, path)


def save_disparity_figure(path: str | os.PathLike, disparity_px: np.ndarray, *, title: str = "disparity",
                          max_disparity_px: float | None = None, background: np.ndarray | None = None) -> Path:
    """Colourised disparity (turbo, NaN shown transparent over ``background`` or black) with a colour bar."""
    d = np.asarray(disparity_px, dtype=np.float32)
    if d.ndim != 2:
        raise ValueError(f"disparity_px must be HxW, got shape {d.shape}")
    top = max_disparity_px if max_disparity_px else (float(np.nanmax(d)) if np.isfinite(d).any() else 1.0)
    fig = _figure(5.5, 4.2)
    ax = fig.add_subplot(1, 1, 1)
    if background is not None:
        ax.imshow(background, cmap="gray", vmin=0, vmax=255)
    else:
        ax.imshow(np.zeros_like(d), cmap="gray", vmin=0, vmax=1)
    im = ax.imshow(np.ma.masked_invalid(d), cmap="turbo", vmin=0.0, vmax=top, interpolation="nearest")
    fig.colorbar(im, ax=ax, label="disparity [px]", fraction=0.04)
    ax.set_title(title, fontsize=10)
    ax.set_axis_off()
    return _save(fig, path)


def save_map_figure(path: str | os.PathLike, ros_map: RosMap, *, poses=None, title: str = "map",
                    truth: RosMap | None = None) -> Path:
    """Occupancy map in world coordinates (white free, black occupied, grey unknown).

    ``poses`` (N, 3) draws the robot path with heading ticks; ``truth`` overlays
    the occupied cells of a ground-truth map as red outlines (paper Fig. 14).
    """
    g = ros_map.grid
    shown = np.where(np.isnan(ros_map.occupancy), 0.5, 1.0 - np.clip(ros_map.occupancy, 0.0, 1.0))
    extent = (g.origin_x_m, g.origin_x_m + g.shape[1] * g.resolution_m,
              g.origin_y_m, g.origin_y_m + g.shape[0] * g.resolution_m)
    aspect = (extent[3] - extent[2]) / (extent[1] - extent[0])
    fig = _figure(10.0, max(2.5, 10.0 * aspect + 0.8))
    ax = fig.add_subplot(1, 1, 1)
    ax.imshow(shown, cmap="gray", vmin=0.0, vmax=1.0, origin="lower", extent=extent, interpolation="nearest")
    if truth is not None:
        tg = truth.grid
        t_extent = (tg.origin_x_m, tg.origin_x_m + tg.shape[1] * tg.resolution_m,
                    tg.origin_y_m, tg.origin_y_m + tg.shape[0] * tg.resolution_m)
        ax.contour(truth.occupied.astype(float), levels=[0.5], colors="red", linewidths=0.8,
                   origin="lower", extent=t_extent)
    if poses is not None:
        p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        ax.plot(p[:, 0], p[:, 1], "-o", color="tab:blue", markersize=3, linewidth=1, label="robot path")
        ax.quiver(p[:, 0], p[:, 1], np.cos(p[:, 2]), np.sin(p[:, 2]), color="tab:blue", scale=30, width=0.003)
        ax.legend(loc="upper right", fontsize=8)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title, fontsize=10)
    return _save(fig, path)
