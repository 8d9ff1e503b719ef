"""Fit reports (JSON + markdown) and the residual figure of paper Figs. 2-3."""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Sequence

import numpy as np

from ..camera import Camera
from ..io import atomic_write
from .calibrate import CalibrationResult
from .targets import CalibrationView

__all__ = ["write_json", "markdown_report", "write_text", "residual_figure"]


def write_json(path: str | os.PathLike, data: dict) -> None:
    """Write a JSON report atomically."""
    with atomic_write(path) as tmp:
        tmp.write_text(json.dumps(data, indent=2) + "\n")


def write_text(path: str | os.PathLike, text: str) -> None:
    with atomic_write(path) as tmp:
        tmp.write_text(text)


def markdown_report(result: CalibrationResult, *, title: str = "Camera calibration") -> str:
    """Human-readable fit report: parameters with sigmas, RMS, per-view RMS, outliers."""
    c = result.camera
    lines = [f"# {title}", "", f"- method: `{result.method}`, success: {result.success}",
             f"- message: {result.message}", f"- image size: {c.width} x {c.height}",
             f"- RMS reprojection error: {result.rms_px:.4f} px"]
    if np.isfinite(result.ga_rms_px):
        lines.append(f"- GA only: {result.ga_rms_px:.4f} px after {result.generations} generations")
    if np.isfinite(result.lm_rms_px):
        lines.append(f"- after LM: {result.lm_rms_px:.4f} px")
    lines += ["", "| parameter | value | sigma |", "|---|---|---|"]
    for k in ("fx", "fy", "cx", "cy", "k1", "k2"):
        s = result.sigmas.get(k)
        lines.append(f"| {k} | {getattr(c, k):.6g} | {'' if s is None else f'{s:.3g}'} |")
    lines += ["", "| view | RMS [px] | outlier |", "|---|---|---|"]
    for i, (n, r) in enumerate(zip(result.view_names, result.per_view_rms_px)):
        lines.append(f"| {n} | {r:.4f} | {'yes' if i in result.outlier_views else ''} |")
    return "\n".join(lines) + "\n"


def residual_figure(path: str | os.PathLike, camera: Camera, views: Sequence[CalibrationView], *,
                    max_views: int = 4) -> None:
    """PNG like paper Figs. 2-3: detected (+) vs distortion-corrected (o) points, and the
    distortion magnitude over the image (|corrected - raw| in px, horizontal and vertical)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    ax = axes[0]
    for view in list(views)[:max_views]:
        ax.plot(view.uv[:, 0], view.uv[:, 1], "+", color="tab:red", ms=5)
        und = camera.undistort_pixels(view.uv)
        ax.plot(und[:, 0], und[:, 1], "o", mfc="none", color="tab:blue", ms=4)
    ax.set_xlim(0, camera.width)
    ax.set_ylim(camera.height, 0)
    ax.set_aspect("equal")
    ax.set_title("detected (+) vs corrected (o)")
    step = max(camera.width, camera.height) // 64 or 1
    u, v = np.meshgrid(np.arange(0, camera.width, step, dtype=float), np.arange(0, camera.height, step, dtype=float))
    und = camera.undistort_pixels(np.stack([u.ravel(), v.ravel()], 1))
    d = und - np.stack([u.ravel(), v.ravel()], 1)
    for k, (a, name) in enumerate(zip(axes[1:], ("x", "y"))):
        lim = max(float(np.abs(d[:, k]).max()), 1e-9)
        im = a.imshow(d[:, k].reshape(u.shape), extent=(0, camera.width, camera.height, 0), cmap="RdBu_r",
                      vmin=-lim, vmax=lim)
        a.set_title(f"correction in {name} [px]")
        fig.colorbar(im, ax=a, shrink=0.8)
    fig.tight_layout()
    with atomic_write(Path(path)) as tmp:
        fig.savefig(tmp, dpi=80)
    plt.close(fig)
