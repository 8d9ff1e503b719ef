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

__all__ = ["depth_m_from_disparity_px", "disparity_px_from_depth_m", "points_cam_from_disparity",
           "points_cam_from_raw_px"]


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


def points_cam_from_raw_px(stereo, uv_left, uv_right, *, frame: str = "rectified") -> np.ndarray:
    """Triangulate matching raw (distorted) pixels of a calibrated pair, eq. (14)-(16).

    Each raw pixel is rectified through its camera's model
    (:func:`mrstereo.camera.rectified_px_from_raw_px`), then ``Z = b f / (x_l - x_r + doffs)``,
    ``X = (x_l - cx) Z / f``, ``Y = (y - cy) Z / fy`` with ``y`` the mean rectified row.

    Parameters
    ----------
    stereo : StereoCamera
    uv_left, uv_right : ndarray of shape (N, 2)
        Matching raw pixels ``(u, v)``.
    frame : {"rectified", "raw_left"}
        The frame of the points returned (metres; NaN where the rectified disparity is not positive).
    """
    from ..camera import rectified_px_from_raw_px
    if frame not in ("rectified", "raw_left"):
        raise ValueError(f"frame must be 'rectified' or 'raw_left', got {frame!r}")
    uv_left = np.asarray(uv_left, dtype=np.float64)
    uv_right = np.asarray(uv_right, dtype=np.float64)
    for name, uv in (("uv_left", uv_left), ("uv_right", uv_right)):
        if uv.ndim != 2 or uv.shape[1] != 2:
            raise ValueError(f"{name} must have shape (N, 2), got {uv.shape}")
    if len(uv_left) != len(uv_right):
        raise ValueError(f"uv_left and uv_right must hold the same number of points, got {len(uv_left)} "
                         f"and {len(uv_right)}")
    a = rectified_px_from_raw_px(stereo.left, uv_left)
    b = rectified_px_from_raw_px(stereo.right, uv_right)
    P = stereo.left.P
    z = depth_m_from_disparity_px(a[:, 0] - b[:, 0], focal_px=P[0, 0], baseline_m=stereo.baseline_m,
                                  doffs_px=stereo.doffs_px)
    points = np.stack([(a[:, 0] - P[0, 2]) * z / P[0, 0], (0.5 * (a[:, 1] + b[:, 1]) - P[1, 2]) * z / P[1, 1], z], 1)
    return points if frame == "rectified" else points @ stereo.left.R      # R^T p: rectified -> raw left
