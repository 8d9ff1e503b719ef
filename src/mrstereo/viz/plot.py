"""Figure plumbing: an Agg figure without pyplot state, saved atomically as PNG; disparity colours.

Conventions: docs/conventions.md.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..io import atomic_write


def new_figure(width_in: float, height_in: float, *, dpi: int = 100):
    """A matplotlib Figure on the Agg canvas (thread-safe, no global pyplot state)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), dpi=dpi)
    FigureCanvasAgg(fig)
    return fig


def save_figure(fig, path: str | os.PathLike) -> Path:
    """Write ``fig`` to ``path`` (format from the suffix) atomically; return the path."""
    path = Path(path)
    with atomic_write(path) as tmp:
        fig.savefig(tmp, bbox_inches="tight")
    return path


# --------------------------------------------------------------------------- disparity colours
# The one place that turns disparities into colours: the `disparity --plot` preview, the demo's
# panels, colorize_disparity and mrstereo.world.figures all draw through it.

DISPARITY_CMAP = "turbo"
INVALID_RGB = (0.0, 0.0, 0.0)          # no disparity: black
TOO_NEAR_RGB = (1.0, 0.0, 1.0)         # too near (nearer than the search covers): magenta, outside turbo
DISPLAY_PERCENTILES = (1.0, 99.0)


def disparity_range_px(*disparities_px, percentiles: tuple[float, float] = DISPLAY_PERCENTILES) -> tuple[float, float]:
    """Colour-scale limits ``(low_px, high_px)``: robust percentiles of the valid values of all maps.

    Scaling to the data (not to the searched range) keeps a scene whose disparities fill a small
    part of the search readable; values outside are drawn in the end colours (the colour bar's
    arrows). ``(0, 1)`` when no map has a valid value.
    """
    values = [np.asarray(d, dtype=np.float32) for d in disparities_px]
    valid = np.concatenate([v[np.isfinite(v)].ravel() for v in values]) if values else np.empty(0)
    if valid.size == 0:
        return 0.0, 1.0
    low, high = (float(v) for v in np.percentile(valid, percentiles))
    if high - low < 1e-3:
        low, high = low - 0.5, high + 0.5
    return low, high


def disparity_colors(disparity_px, *, range_px: tuple[float, float], too_near=None):
    """RGBA float image (H, W, 4) of a disparity map: turbo over ``range_px``, invalid black,
    pixels of the ``too_near`` mask (``DisparityResult.too_near``) magenta."""
    import matplotlib
    d = np.asarray(disparity_px, dtype=np.float32)
    low, high = range_px
    cmap = matplotlib.colormaps[DISPARITY_CMAP].with_extremes(bad=(*INVALID_RGB, 1.0))
    rgba = cmap(np.ma.masked_invalid((d - low) / max(high - low, 1e-6)))
    if too_near is not None:
        mask = np.asarray(too_near, dtype=bool)
        if mask.shape != d.shape:
            raise ValueError(f"too_near must have the disparity's shape {d.shape}, got {mask.shape}")
        rgba[mask] = (*TOO_NEAR_RGB, 1.0)
    return rgba


def draw_disparity(ax, disparity_px, *, range_px: tuple[float, float], background=None, too_near=None):
    """Draw a disparity map on ``ax`` (over a gray ``background`` where invalid, else black;
    ``too_near`` pixels magenta).

    Returns a ScalarMappable with the same colours for ``fig.colorbar``.
    """
    import matplotlib
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    rgba = disparity_colors(disparity_px, range_px=range_px, too_near=too_near)
    if background is not None:
        ax.imshow(background, cmap="gray", vmin=0, vmax=255, interpolation="nearest")
        shown = np.isfinite(np.asarray(disparity_px, np.float32))
        if too_near is not None:
            shown |= np.asarray(too_near, dtype=bool)
        rgba[..., 3] = np.where(shown, 1.0, 0.0)
    ax.imshow(rgba, interpolation="nearest")
    return ScalarMappable(norm=Normalize(*range_px), cmap=matplotlib.colormaps[DISPARITY_CMAP])


def disparity_colorbar(fig, mappable, ax, *, range_px: tuple[float, float], **kwargs):
    """Colour bar in pixels that says what the colours and black mean."""
    return fig.colorbar(mappable, ax=ax, extend="both",
                        label=f"disparity [px], {DISPLAY_PERCENTILES[0]:g}-{DISPLAY_PERCENTILES[1]:g} "
                              f"percentile ({range_px[0]:.1f}-{range_px[1]:.1f} px)", **kwargs)


def save_disparity_preview(path: str | os.PathLike, disparity_px, *, title: str = "disparity",
                           range_px: tuple[float, float] | None = None, background=None,
                           too_near=None) -> Path:
    """A disparity preview PNG: the map in colour with a colour bar in pixels, invalid black,
    ``too_near`` pixels (nearer than the search covers) magenta.

    ``range_px`` defaults to :func:`disparity_range_px` (robust percentiles of the map).
    """
    d = np.asarray(disparity_px, dtype=np.float32)
    if d.ndim != 2:
        raise ValueError(f"disparity_px must be HxW, got shape {d.shape}")
    range_px = disparity_range_px(d) if range_px is None else range_px
    height, width = d.shape
    width_in = min(14.0, max(6.0, width / 100 + 1.8))
    image_w_in = width_in - 1.8
    fig = new_figure(width_in, image_w_in * height / width + 1.3)
    ax = fig.add_subplot(1, 1, 1)
    mappable = draw_disparity(ax, d, range_px=range_px, background=background, too_near=too_near)
    disparity_colorbar(fig, mappable, ax, range_px=range_px, fraction=0.04, pad=0.02)
    valid = float(np.isfinite(d).mean())
    near = float(np.asarray(too_near, dtype=bool).mean()) if too_near is not None else 0.0
    ax.set_title(f"{title}: {valid:.0%} of pixels with a disparity "
                 f"({'transparent' if background is not None else 'black'} = none"
                 + (f"; magenta = too near, {near:.0%}" if near > 0 else "") + ")", fontsize=10)
    ax.set_axis_off()
    return save_figure(fig, path)


def colorize_disparity(disparity_px: np.ndarray, *, max_disparity_px: float | None = None,
                       range_px: tuple[float, float] | None = None, too_near: np.ndarray | None = None) -> np.ndarray:
    """Colour image (BGR uint8) of a disparity map: turbo, invalid pixels black, pixels of the
    ``too_near`` mask (nearer than the search covers) magenta.

    The colour scale spans ``range_px`` (low, high) in pixels; default: the 1st-99th percentile of
    the valid values (:func:`disparity_range_px`), or ``0 .. max_disparity_px`` when that
    is given. Same colours as the ``disparity --plot`` preview, which adds a colour bar.
    """
    d = np.asarray(disparity_px, dtype=np.float32)
    if range_px is None:
        range_px = (0.0, float(max_disparity_px)) if max_disparity_px else disparity_range_px(d)
    rgb = np.rint(disparity_colors(d, range_px=range_px, too_near=too_near)[..., :3] * 255).astype(np.uint8)
    return np.ascontiguousarray(rgb[..., ::-1])
