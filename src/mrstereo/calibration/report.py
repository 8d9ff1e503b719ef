"""Fit reports (JSON + markdown), the reprojection residual plot and the distortion figure (paper Figs. 2-3).

Conventions: docs/conventions.md.
"""
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

__all__ = ["write_json", "markdown_report", "write_text", "residual_figure", "camera_line"]


def _parameters(camera: Camera) -> list[tuple[str, float]]:
    """``(name, value)`` of the intrinsics and of every distortion coefficient of the camera's model."""
    names = camera.distortion.params_info[:camera.D.size]
    return [(k, getattr(camera, k)) for k in ("fx", "fy", "cx", "cy")] + list(zip(names, camera.D))


def camera_line(camera: Camera) -> str:
    """One line: ``fx=.. fy=.. cx=.. cy=.. <model> k1=.. ...`` (trailing zero coefficients left out)."""
    params = _parameters(camera)
    coeffs = params[4:]
    while coeffs and coeffs[-1][1] == 0.0 and len(coeffs) > 2:
        coeffs.pop()
    return (" ".join(f"{k}={v:.2f}" for k, v in params[:4]) + f" {camera.distortion_model} "
            + " ".join(f"{k}={v:.4g}" for k, v in coeffs))


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
    lines += [f"- model: `{result.model}` (ROS `{c.distortion_model}`)",
              "", "| parameter | value | sigma |", "|---|---|---|"]
    for k, value in _parameters(c):
        s = result.sigmas.get(k)
        lines.append(f"| {k} | {value:.6g} | {'' if s is None else f'{s:.3g}'} |")
    lines += ["", "| view | RMS [px] | outlier |", "|---|---|---|"]
    for i, (n, r) in enumerate(zip(result.view_names, result.per_view_rms_px)):
        lines.append(f"| {n} | {r:.4f} | {'yes' if i in result.outlier_views else ''} |")
    return "\n".join(lines) + "\n"


def residual_figure(path: str | os.PathLike, camera: Camera, views: Sequence[CalibrationView], *,
                    residuals: Sequence[np.ndarray] | None = None) -> None:
    """PNG: reprojection residuals per corner, and the distortion correction (paper Figs. 2-3).

    Left: each control point's error (``residuals``, projected minus detected, per view) as a
    magnified arrow coloured by its length, or without ``residuals`` detected (+) vs corrected (o)
    points of the first four views. Right: the correction ``undistorted - raw`` in x and
    y over the image. Axes in pixels.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(16, 4.6))
    ax = axes[0]
    if residuals is not None:
        uv = np.concatenate([v.uv for v in views])
        err = np.concatenate([np.asarray(r, dtype=np.float64) for r in residuals])
        mag = np.hypot(err[:, 0], err[:, 1])
        finite = np.isfinite(mag)
        uv, err, mag = uv[finite], err[finite], mag[finite]
        largest = float(mag.max()) if mag.size else 0.0
        largest = largest if largest > 0 else 1.0
        magnify = 0.06 * camera.width / largest
        q = ax.quiver(uv[:, 0], uv[:, 1], err[:, 0], err[:, 1], mag, cmap="viridis", angles="xy",
                      scale_units="xy", scale=1.0 / magnify, width=0.004)
        key_px = float(f"{0.5 * largest:.1g}")
        ax.quiverkey(q, 0.05, 1.03, key_px, f"= {key_px:g} px (arrows magnified x{magnify:.0f})", labelpos="E",
                     coordinates="axes")
        fig.colorbar(q, ax=ax, shrink=0.8, label="reprojection error [px]")
        rms = float(np.sqrt(np.mean(mag ** 2))) if mag.size else float("nan")
        ax.set_title(f"reprojection error ({len(mag)} points, RMS {rms:.3f} px)", pad=22)
    else:
        for view in list(views)[:4]:
            ax.plot(view.uv[:, 0], view.uv[:, 1], "+", color="tab:red", ms=5, label="detected")
            und = camera.undistort_pixels(view.uv)
            ax.plot(und[:, 0], und[:, 1], "o", mfc="none", color="tab:blue", ms=4, label="corrected")
        handles, labels = ax.get_legend_handles_labels()
        ax.legend(handles[:2], labels[:2], loc="upper right", fontsize=8)
        ax.set_title("detected (+) vs corrected (o)")
    ax.set_xlim(0, camera.width)
    ax.set_ylim(camera.height, 0)
    ax.set_aspect("equal")
    step = max(camera.width, camera.height) // 64 or 1
    u, v = np.meshgrid(np.arange(0, camera.width, step, dtype=float), np.arange(0, camera.height, step, dtype=float))
    und = camera.undistort_pixels(np.stack([u.ravel(), v.ravel()], 1))
    d = und - np.stack([u.ravel(), v.ravel()], 1)
    for k, (a, name) in enumerate(zip(axes[1:], ("x", "y"))):
        finite = d[:, k][np.isfinite(d[:, k])]
        lim = max(float(np.abs(finite).max()) if finite.size else 0.0, 1e-9)
        im = a.imshow(d[:, k].reshape(u.shape), extent=(0, camera.width, camera.height, 0), cmap="RdBu_r",
                      vmin=-lim, vmax=lim)
        a.set_title(f"distortion correction in {name} ({camera.distortion_model})")
        fig.colorbar(im, ax=a, shrink=0.8, label=f"undistorted - raw {name} [px]")
    for a in axes:
        a.set_xlabel("u [px]")
        a.set_ylabel("v [px]")
    fig.tight_layout()
    with atomic_write(Path(path)) as tmp:
        fig.savefig(tmp, dpi=90)
    plt.close(fig)
