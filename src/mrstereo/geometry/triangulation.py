"""Triangulation from disparity, paper eq. (14)-(16).

``Z = b f / d``, ``X = x Z / f``, ``Y = y Z / f`` with ``x = u - cx`` and
``y = v - cy`` measured from the principal point of the rectified left camera.
Conventions (camera frame x right, y down, z forward; d = x_left - x_right):
docs/conventions.md.
"""
from __future__ import annotations

import numpy as np

from .. import _checks
from . import _kernels

__all__ = ["depth_m_from_disparity_px", "disparity_px_from_depth_m", "points_cam_from_disparity"]


def depth_m_from_disparity_px(disparity_px, *, focal_px: float, baseline_m: float,
                              doffs_px: float = 0.0) -> np.ndarray:
    """Eq. (14): ``Z = b f / (d + doffs)``; NaN where the disparity is invalid or <= 0."""
    f = _checks.finite_number("focal_px", focal_px, positive=True)
    b = _checks.finite_number("baseline_m", baseline_m, positive=True)
    d = np.asarray(disparity_px, dtype=np.float64) + _checks.finite_number("doffs_px", doffs_px)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(d > 0, b * f / d, np.nan)


def disparity_px_from_depth_m(depth_m, *, focal_px: float, baseline_m: float,
                              doffs_px: float = 0.0) -> np.ndarray:
    """Inverse of eq. (14): ``d = b f / Z - doffs``; NaN where Z is invalid or <= 0."""
    f = _checks.finite_number("focal_px", focal_px, positive=True)
    b = _checks.finite_number("baseline_m", baseline_m, positive=True)
    z = np.asarray(depth_m, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(z > 0, b * f / z, np.nan) - _checks.finite_number("doffs_px", doffs_px)


def points_cam_from_disparity(disparity_px, *, focal_px: float, baseline_m: float, cx_px: float,
                              cy_px: float, fy_px: float | None = None,
                              doffs_px: float = 0.0) -> np.ndarray:
    """Eq. (14)-(16): camera-frame points (H, W, 3) of a disparity map; NaN where invalid.

    Parameters
    ----------
    disparity_px : ndarray of shape (H, W)
        Disparity ``d = x_left - x_right`` of the rectified left image, NaN invalid.
    focal_px, baseline_m : float
        ``f`` and ``b`` of eq. (14).
    cx_px, cy_px : float
        Principal point of the rectified left camera.
    fy_px : float, optional
        Vertical focal length when pixels are not square (default ``focal_px``).
    """
    d = np.asarray(disparity_px)
    if d.dtype not in (np.float32, np.float64):
        d = np.asarray(d, dtype=np.float64)
    if d.ndim != 2:
        raise ValueError(f"disparity_px must have shape (H, W), got {d.shape}")
    f = _checks.finite_number("focal_px", focal_px, positive=True)
    b = _checks.finite_number("baseline_m", baseline_m, positive=True)
    doffs = _checks.finite_number("doffs_px", doffs_px)
    cx = _checks.finite_number("cx_px", cx_px)
    cy = _checks.finite_number("cy_px", cy_px)
    fy = _checks.finite_number("fy_px", focal_px if fy_px is None else fy_px, positive=True)
    out = np.empty(d.shape + (3,), dtype=np.float64)
    _kernels.points_cam(d, f, b, doffs, cx, cy, fy, out)          # eq. (14), (15), (16) per pixel
    return out
