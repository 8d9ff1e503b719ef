"""PNG figures of stereo frames and disparity maps (matplotlib Agg).

Reusable by every command that shows results (``mrstereo demo``). Each function
writes one PNG atomically and returns its path. Disparity colours follow
:func:`mrstereo.io.colorize_disparity` (turbo, invalid black).
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .._plot import new_figure as _figure
from .._plot import save_figure as _save

__all__ = ["save_stereo_figure", "save_disparity_figure"]


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
