"""Stereo rectification by Fusiello, Trucco & Verri (2000), for every camera model.

Both cameras turn about their optical centres into one orientation ``R_n`` and share new
intrinsics ``A``, so that corresponding points lie on the same row. With ``x_right = R x_left + T``
the right centre is ``c2 = -R^T T`` in the left frame; the rows of ``R_n`` are ``e1 = c2 / |c2|``
(left to right, not the paper's ``c1 - c2``: the usual rig then hardly turns), ``e2 = z x e1``
(normalized) and ``e3 = e1 x e2``. The raw frames turn into the rectified one by ``R_n`` (left)
and ``R_n R^T`` (right); ``P_left = A [I | 0]``, ``P_right = A [I | (-b, 0, 0)]``. How ``A``
follows from ``alpha`` and the raw borders, and a fisheye's focal length: docs/calibration.md
(Rectification). Conventions: docs/conventions.md.

References
----------
A. Fusiello, E. Trucco, A. Verri, "A compact algorithm for rectification of stereo pairs",
Machine Vision and Applications 12:16-22, 2000.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import _checks
from .camera_info import CameraInfo, StereoCamera, stereo_projections
from .model import Camera

__all__ = ["FusielloRectification", "rectify_fusiello", "fusiello_rotation", "check_not_swapped",
           "check_baseline", "rectified_px_from_raw_px", "raw_px_from_rectified_px"]

MIN_BASELINE_M = 1e-4
"""Baselines shorter than this (0.1 mm) are taken as zero: the same view given twice."""
MAX_RAY_ANGLE_RAD = np.radians(80.0)
"""The rectified field of view is chosen from raw border rays at most this far off the axis."""


@dataclass(frozen=True)
class FusielloRectification:
    """Result of :func:`rectify_fusiello`: the ``stereo`` (raw ``K``, ``D``, ``R`` raw -> rectified,
    rectified ``P``), the common orientation ``R_new`` (rows = new axes, left-camera coordinates),
    the shared intrinsics ``A`` and ``baseline_m``.
    """

    stereo: StereoCamera
    R_new: np.ndarray
    A: np.ndarray
    baseline_m: float


def fusiello_rotation(R, T) -> np.ndarray:
    """Rectified orientation ``R_n`` (rows e1, e2, e3) in left-camera coordinates.

    ``R`` (3, 3), ``T`` (3,) map left-camera points to the right camera,
    ``x_right = R x_left + T``.
    """
    R = _checks.matrix("R", R, (3, 3))
    T = _checks.matrix("T", np.ravel(T), (3,))
    c2 = -R.T @ T
    norm = float(np.linalg.norm(c2))
    if norm <= 0:
        raise ValueError("T must be non-zero: the two optical centres coincide (the baseline is zero)")
    e1 = c2 / norm
    e2 = np.cross(np.array([0.0, 0.0, 1.0]), e1)
    n2 = float(np.linalg.norm(e2))
    if n2 < 1e-9:
        raise ValueError("the baseline is parallel to the optical axis; cannot rectify")
    e2 /= n2
    e3 = np.cross(e1, e2)
    return np.stack([e1, e2, e3])


def _border_pixels(width: int, height: int, n: int = 64) -> dict[str, np.ndarray]:
    us = np.linspace(0.0, width - 1.0, n)
    vs = np.linspace(0.0, height - 1.0, n)
    return {
        "left": np.stack([np.zeros(n), vs], 1), "right": np.stack([np.full(n, width - 1.0), vs], 1),
        "top": np.stack([us, np.zeros(n)], 1), "bottom": np.stack([us, np.full(n, height - 1.0)], 1),
    }


def check_baseline(R, T, *, where: str = "stereo calibration") -> float:
    """Baseline ``|c2 - c1|`` in metres; ``ValueError`` below ``MIN_BASELINE_M`` (one view given twice)."""
    R = _checks.matrix("R", R, (3, 3))
    T = _checks.matrix("T", np.ravel(T), (3,))
    baseline_m = float(np.linalg.norm(T))
    if baseline_m < MIN_BASELINE_M:
        raise ValueError(f"{where}: the baseline is zero ({baseline_m:.2g} m): both views were taken from "
                         "the same place; are the same images (or topic) given as left and right?")
    return baseline_m


def check_not_swapped(R, T, *, where: str = "stereo calibration") -> None:
    """Refuse a pair (``x_right = R x_left + T``) whose right camera sits on the left of the left one.

    The right centre ``c2 = -R^T T`` must lie at +x; otherwise the rectified pair would be
    mirrored (negative disparities). The ``ValueError`` says to exchange left and right.
    """
    R = _checks.matrix("R", R, (3, 3))
    T = _checks.matrix("T", np.ravel(T), (3,))
    c2 = -R.T @ T
    if c2[0] < 0 and abs(c2[0]) >= 0.5 * float(np.linalg.norm(c2)):
        raise ValueError(f"{where}: the left and right views look swapped: the camera given as right sits "
                         f"{abs(c2[0]):.4g} m to the LEFT of the one given as left; exchange --left and "
                         "--right (or the left and right topics/files)")


def _border_rays(camera: Camera, uv: np.ndarray, *, steps: int = 64) -> np.ndarray:
    """Rays (N, 3) of border pixels, or of the outermost usable pixel on the line to the principal point.

    Usable: the ray exists, lies at most ``MAX_RAY_ANGLE_RAD`` off the axis on the pixel's side, and
    the angle grows outward all the way from the centre (a distortion polynomial may fold back
    beyond the calibrated area, where its inverse jumps to another branch).
    """
    centre = np.array([camera.cx, camera.cy])
    frac = np.linspace(0.0, 1.0, steps)[:, None, None]                     # centre -> border
    pts = centre + frac * (uv - centre)                                     # (steps, N, 2)
    rays = camera.rays(pts.reshape(-1, 2)).reshape(steps, len(uv), 3)
    with np.errstate(invalid="ignore"):
        radius = np.hypot(rays[..., 0], rays[..., 1])
        ok = np.isfinite(radius) & (radius <= np.tan(MAX_RAY_ANGLE_RAD))
        ok[1:] &= radius[1:] > radius[:-1]
        ok &= np.sum(rays[..., :2] * ((uv - centre) / [camera.fx, camera.fy]), axis=-1) >= 0   # not mirrored
    ok = np.logical_and.accumulate(ok, axis=0)
    last = steps - 1 - np.argmax(ok[::-1], axis=0)                          # outermost usable sample
    return rays[last, np.arange(len(uv))]


def _rectified_border(camera: Camera, R_rect: np.ndarray) -> dict[str, np.ndarray]:
    """Border pixels of the raw image in rectified normalized coordinates (rays in front only)."""
    out = {}
    for side, uv in _border_pixels(camera.width, camera.height).items():
        rays = _border_rays(camera, uv) @ R_rect.T
        keep = np.isfinite(rays).all(axis=1) & (rays[:, 2] > 1e-6)
        out[side] = rays[keep, :2] / rays[keep, 2:3]
    return out


def rectified_px_from_raw_px(info: CameraInfo, uv) -> np.ndarray:
    """Raw (distorted) pixels (N, 2) of one camera -> its rectified image (``R``, ``P``)."""
    from .camera_info import CameraInfo

    _checks.instance("info", info, CameraInfo)
    rays = info.camera.rays(np.asarray(uv, dtype=np.float64)) @ info.R.T
    p = rays @ info.P[:3, :3].T
    with np.errstate(divide="ignore", invalid="ignore"):
        return p[:, :2] / p[:, 2:3]


def raw_px_from_rectified_px(info: CameraInfo, uv_rect) -> np.ndarray:
    """Inverse of :func:`rectified_px_from_raw_px` (NaN where the ray is behind the raw camera)."""
    uv_rect = np.asarray(uv_rect, dtype=np.float64)
    if uv_rect.ndim != 2 or uv_rect.shape[1] != 2:
        raise ValueError(f"uv_rect must have shape (N, 2), got {uv_rect.shape}")
    q = np.concatenate([uv_rect, np.ones((len(uv_rect), 1))], 1) @ np.linalg.inv(info.P[:3, :3]).T
    return info.camera.project(q @ info.R)          # R^T q: rectified frame -> raw frame


def rectify_fusiello(left: Camera, right: Camera, R, T, *, alpha: float = 0.0) -> FusielloRectification:
    """Rectify a calibrated stereo pair (Fusiello, Trucco & Verri 2000).

    Parameters
    ----------
    left, right : Camera
        Raw intrinsics (any distortion model, same image size).
    R, T : ndarray of shape (3, 3) and (3,)
        ``x_right = R x_left + T`` (metres).
    alpha : float, optional
        0 = only valid pixels (zoom in), 1 = all raw pixels visible.
    """
    if not isinstance(left, Camera) or not isinstance(right, Camera):
        raise TypeError(f"left and right must be Camera instances, got {type(left).__name__} and "
                        f"{type(right).__name__}")
    if left.size != right.size:
        raise ValueError(f"left and right image sizes differ: {left.size} vs {right.size}")
    alpha = _checks.finite_number("alpha", alpha)
    if not 0.0 <= alpha <= 1.0:
        raise ValueError(f"alpha must be within [0, 1], got {alpha}")
    R = _checks.matrix("R", R, (3, 3))
    T = _checks.matrix("T", np.ravel(T), (3,))
    baseline_m = check_baseline(R, T, where="rectify")
    check_not_swapped(R, T, where="rectify")
    R_new = fusiello_rotation(R, T)
    R_right = R_new @ R.T
    width, height = left.size

    borders = [_rectified_border(left, R_new), _rectified_border(right, R_right)]
    for name, b in zip(("left", "right"), borders):
        empty = [side for side, pts in b.items() if len(pts) == 0]
        if empty:
            raise ValueError(f"the {empty[0]} border of the {name} image has no viewing ray in front of the "
                             "rectified camera; check the intrinsics, R and T")
    inner = (max(b["left"][:, 0].max() for b in borders), min(b["right"][:, 0].min() for b in borders),
             max(b["top"][:, 1].max() for b in borders), min(b["bottom"][:, 1].min() for b in borders))
    allpts = np.concatenate([np.concatenate(list(b.values())) for b in borders])
    outer = (allpts[:, 0].min(), allpts[:, 0].max(), allpts[:, 1].min(), allpts[:, 1].max())
    if inner[1] <= inner[0] or inner[3] <= inner[2]:
        raise ValueError("the two rectified views do not overlap (the cameras look in too different "
                         "directions); check R and T")

    def fit(box, zoom_in: bool):
        x0, x1, y0, y1 = box
        f_x, f_y = (width - 1.0) / (x1 - x0), (height - 1.0) / (y1 - y0)
        return max(f_x, f_y) if zoom_in else min(f_x, f_y)

    f_inner, f_outer = fit(inner, True), fit(outer, False)
    focal = (1.0 - alpha) * f_inner + alpha * f_outer
    centre = [(1.0 - alpha) * 0.5 * (inner[0] + inner[1]) + alpha * 0.5 * (outer[0] + outer[1]),
              (1.0 - alpha) * 0.5 * (inner[2] + inner[3]) + alpha * 0.5 * (outer[2] + outer[3])]
    fisheyes = [c for c in (left, right) if c.is_fisheye]
    f_fisheye = min(min(c.fx, c.fy) for c in fisheyes) if fisheyes else 0.0
    if focal < f_fisheye:             # a fisheye: keep the centre's resolution
        focal = f_fisheye
        axes = np.stack([R_new[:, 2], R_right[:, 2]])          # raw optical axes, rectified frame
        centre = list(np.mean(axes[:, :2] / axes[:, 2:3], axis=0))
    cx = (width - 1.0) / 2.0 - focal * centre[0]
    cy = (height - 1.0) / 2.0 - focal * centre[1]
    A = np.array([[focal, 0.0, cx], [0.0, focal, cy], [0.0, 0.0, 1.0]])
    P_left, P_right = stereo_projections(A, baseline_m)
    stereo = StereoCamera(left=CameraInfo(left, R=R_new, P=P_left, name="left"),
                          right=CameraInfo(right, R=R_right, P=P_right, name="right"))
    return FusielloRectification(stereo=stereo, R_new=R_new, A=A, baseline_m=baseline_m)
