"""Stereo rectification by Fusiello, Trucco & Verri (2000).

Given two calibrated cameras, both are rotated about their optical centres into
one common orientation whose x axis is parallel to the baseline; both get the
same new intrinsics ``A``. Corresponding points then lie on the same image row.
Conventions (frames, ``P[0, 3] = -fx * baseline_m``): docs/conventions.md.

Notes
-----
With the left camera frame as the world frame, the right camera maps
``x_right = R x_left + T`` and its optical centre is ``c2 = -R^T T`` (``c1 = 0``).
The new orientation ``R_n`` (rows = new axes in left-camera coordinates) is

* new x along the baseline, ``e1 = (c2 - c1) / |c2 - c1|``. Fusiello et al. write
  ``c1 - c2`` for their image axes; we orient it from the left to the right
  centre so that for the usual rig (right camera on the +x side) the new frame
  is close to the old one rather than rotated by 180 degrees;
* new y ``e2 = z_old x e1`` (``z_old`` the left camera's optical axis),
  normalized;
* new z ``e3 = e1 x e2``.

The new projection matrices are ``A [R_n | -R_n c_i]``; expressed in the
rectified left frame that is ``P_left = A [I | 0]`` and
``P_right = A [I | (-b, 0, 0)]`` with ``b = |c2 - c1|``, so the right
``P[0, 3] = -fx b``. The rotation from each raw camera frame into the rectified
one is ``R_n`` (left) and ``R_n R^T`` (right). Images are resampled by inverse
warping through ``cv2.initUndistortRectifyMap``, which also removes the radial
distortion.

Choice of ``A``: the raw image border of each camera is undistorted and rotated
into the rectified frame. The inner box (every pixel inside it is seen by both
cameras) and the outer box (every raw pixel kept) are computed;
``alpha = 0`` chooses the focal length and principal point so that the inner
box exactly fills the image (no invalid pixels, like ``cv2.stereoRectify``
with ``alpha=0``), ``alpha = 1`` so that the outer box fits in the image, and
values in between interpolate. Square pixels (``fx = fy``) and one shared
principal point (``doffs = 0``).

References
----------
A. Fusiello, E. Trucco, A. Verri, "A compact algorithm for rectification of
stereo pairs", Machine Vision and Applications 12:16-22, 2000.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import _checks
from .camera_info import CameraInfo, RigMount, StereoCamera
from .model import Camera, normalized_from_pixels, undistort_normalized

__all__ = ["FusielloRectification", "rectify_fusiello", "fusiello_rotation"]


@dataclass(frozen=True)
class FusielloRectification:
    """Result of :func:`rectify_fusiello`.

    Attributes
    ----------
    stereo : StereoCamera
        Raw ``K``, ``D`` per camera, ``R`` (raw -> rectified) and rectified ``P``.
    R_new : ndarray of shape (3, 3)
        Common rectified orientation in left-camera coordinates (rows = new axes).
    A : ndarray of shape (3, 3)
        Shared rectified intrinsics.
    baseline_m : float
        Distance between the optical centres.
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
        raise ValueError("T must be non-zero: the two optical centres coincide")
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


def _rectified_border(camera: Camera, R_rect: np.ndarray) -> dict[str, np.ndarray]:
    """Border pixels of the raw image in rectified normalized coordinates."""
    out = {}
    for side, uv in _border_pixels(camera.width, camera.height).items():
        xy = undistort_normalized(normalized_from_pixels(uv, camera.fx, camera.fy, camera.cx, camera.cy),
                                  camera.k1, camera.k2)
        rays = np.concatenate([xy, np.ones((len(xy), 1))], 1) @ R_rect.T
        out[side] = rays[:, :2] / rays[:, 2:3]
    return out


def rectify_fusiello(left: Camera, right: Camera, R, T, *, alpha: float = 0.0,
                     rig: RigMount | None = None) -> FusielloRectification:
    """Rectify a calibrated stereo pair (Fusiello, Trucco & Verri 2000).

    Parameters
    ----------
    left, right : Camera
        Raw intrinsics (with radial distortion) of both cameras, same image size.
    R : ndarray of shape (3, 3)
        Rotation from the left to the right camera frame.
    T : ndarray of shape (3,)
        Translation in metres, ``x_right = R x_left + T``.
    alpha : float, optional
        0 = only valid pixels (zoom in), 1 = all raw pixels visible; see Notes of
        the module.
    rig : RigMount, optional
        Stored with the result.

    Returns
    -------
    FusielloRectification
        Holds the :class:`StereoCamera` every other command reads.
    """
    if not isinstance(left, Camera) or not isinstance(right, Camera):
        raise TypeError("left and right must be Camera instances")
    if left.size != right.size:
        raise ValueError(f"left and right image sizes differ: {left.size} vs {right.size}")
    alpha = _checks.finite_number("alpha", alpha)
    if not 0.0 <= alpha <= 1.0:
        raise ValueError(f"alpha must be within [0, 1], got {alpha}")
    R = _checks.matrix("R", R, (3, 3))
    T = _checks.matrix("T", np.ravel(T), (3,))
    R_new = fusiello_rotation(R, T)
    R_right = R_new @ R.T
    baseline_m = float(np.linalg.norm(T))
    width, height = left.size

    borders = [_rectified_border(left, R_new), _rectified_border(right, R_right)]
    inner = (max(b["left"][:, 0].max() for b in borders), min(b["right"][:, 0].min() for b in borders),
             max(b["top"][:, 1].max() for b in borders), min(b["bottom"][:, 1].min() for b in borders))
    allpts = np.concatenate([np.concatenate(list(b.values())) for b in borders])
    outer = (allpts[:, 0].min(), allpts[:, 0].max(), allpts[:, 1].min(), allpts[:, 1].max())
    if inner[1] <= inner[0] or inner[3] <= inner[2]:
        raise ValueError("the two rectified views do not overlap; check R and T")

    def fit(box, zoom_in: bool):
        x0, x1, y0, y1 = box
        f_x, f_y = (width - 1.0) / (x1 - x0), (height - 1.0) / (y1 - y0)
        return max(f_x, f_y) if zoom_in else min(f_x, f_y)

    f_inner, f_outer = fit(inner, True), fit(outer, False)
    focal = (1.0 - alpha) * f_inner + alpha * f_outer
    centre = [(1.0 - alpha) * 0.5 * (inner[0] + inner[1]) + alpha * 0.5 * (outer[0] + outer[1]),
              (1.0 - alpha) * 0.5 * (inner[2] + inner[3]) + alpha * 0.5 * (outer[2] + outer[3])]
    cx = (width - 1.0) / 2.0 - focal * centre[0]
    cy = (height - 1.0) / 2.0 - focal * centre[1]
    A = np.array([[focal, 0.0, cx], [0.0, focal, cy], [0.0, 0.0, 1.0]])
    P_left = np.hstack([A, np.zeros((3, 1))])
    P_right = P_left.copy()
    P_right[0, 3] = -focal * baseline_m
    stereo = StereoCamera(left=CameraInfo(left, R=R_new, P=P_left, name="left"),
                          right=CameraInfo(right, R=R_right, P=P_right, name="right"), rig=rig)
    return FusielloRectification(stereo=stereo, R_new=R_new, A=A, baseline_m=baseline_m)
