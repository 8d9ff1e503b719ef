"""PNG figures of stereo frames and disparity maps (matplotlib Agg), written atomically.

Disparity colours come from ``mrstereo.viz.plot``, as everywhere. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..viz.plot import new_figure as _figure
from ..viz.plot import save_figure as _save

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
    """Colourised disparity (NaN transparent over ``background``, else black) with a colour bar in px.

    The scale spans ``0 .. max_disparity_px`` when given, else robust percentiles of the map.
    """
    from ..viz.plot import save_disparity_preview

    range_px = (0.0, float(max_disparity_px)) if max_disparity_px else None
    return save_disparity_preview(path, disparity_px, title=title, range_px=range_px, background=background)
