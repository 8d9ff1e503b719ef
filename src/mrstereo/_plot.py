"""Shared figure plumbing: an Agg figure without pyplot state, saved atomically as PNG."""
from __future__ import annotations

import os
from pathlib import Path

from .io import atomic_write


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
