"""Pinhole camera with radial distortion, paper eq. (1)-(3).

Two parameterizations of the same model, converted exactly
(conventions: docs/conventions.md):

* :class:`Camera` -- OpenCV/ROS: ``fx, fy, cx, cy`` in pixels, ``k1, k2`` on
  normalized image coordinates ``(X/Z, Y/Z)`` (plumb_bob with p1 = p2 = k3 = 0).
* :class:`PaperCamera` -- the paper's: focal length ``f`` in mm, pixel densities
  ``alpha_x, alpha_y`` in px/mm, principal point ``(u0, v0)`` in px and ``k1, k2``
  on metric image-plane coordinates ``x = f X/Z`` in mm (eq. 1-3).

With ``x_mm = f_mm * x_n``: ``fx = f_mm * alpha_x``, ``k1_n = k1_mm * f_mm**2`` and
``k2_n = k2_mm * f_mm**4``.

Extrinsics are Euler angles ``(alpha, beta, gamma)`` and a translation ``t``:
``points_cam = R @ points_world + t`` with ``R = Rz(gamma) @ Ry(beta) @ Rx(alpha)``
(rotation about x first, then y, then z, all about fixed axes).

All functions broadcast: parameters may carry leading batch dimensions (a GA
population) and points are ``(..., N, 3)`` or ``(..., N, 2)``.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .. import _checks

__all__ = [
    "Camera", "PaperCamera", "rotation_from_euler", "euler_from_rotation",
    "distort_normalized", "undistort_normalized", "project_points",
    "pixels_from_normalized", "normalized_from_pixels",
]


def rotation_from_euler(alpha, beta, gamma) -> np.ndarray:
    """Rotation ``Rz(gamma) @ Ry(beta) @ Rx(alpha)``; broadcasts, returns (..., 3, 3)."""
    a, b, g = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (alpha, beta, gamma)))
    ca, sa, cb, sb, cg, sg = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(g), np.sin(g)
    R = np.empty(a.shape + (3, 3))
    R[..., 0, 0] = cg * cb
    R[..., 0, 1] = cg * sb * sa - sg * ca
    R[..., 0, 2] = cg * sb * ca + sg * sa
    R[..., 1, 0] = sg * cb
    R[..., 1, 1] = sg * sb * sa + cg * ca
    R[..., 1, 2] = sg * sb * ca - cg * sa
    R[..., 2, 0] = -sb
    R[..., 2, 1] = cb * sa
    R[..., 2, 2] = cb * ca
    return R


def euler_from_rotation(R) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inverse of :func:`rotation_from_euler` (beta in [-pi/2, pi/2])."""
    R = np.asarray(R, dtype=np.float64)
    beta = np.arcsin(np.clip(-R[..., 2, 0], -1.0, 1.0))
    alpha = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    gamma = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    return alpha, beta, gamma


def distort_normalized(xy_n, k1, k2) -> np.ndarray:
    """Radial distortion eq. (3) on normalized coordinates: ``xy (1 + k1 r^2 + k2 r^4)``.

    ``xy_n`` is (..., N, 2); ``k1``, ``k2`` broadcast against its leading dims.
    """
    xy_n = np.asarray(xy_n, dtype=np.float64)
    k1 = np.asarray(k1, dtype=np.float64)[..., None]
    k2 = np.asarray(k2, dtype=np.float64)[..., None]
    r2 = np.sum(xy_n * xy_n, axis=-1)
    return xy_n * (1.0 + k1 * r2 + k2 * r2 * r2)[..., None]


def undistort_normalized(xy_d, k1, k2, *, iterations: int = 30) -> np.ndarray:
    """Invert :func:`distort_normalized` by Newton's method on the radius.

    Solves ``r_d = r (1 + k1 r^2 + k2 r^4)`` per point, starting at ``r = r_d``;
    converges to machine precision within the image for physical lenses
    (monotonic distortion). Points beyond the fold of a barrel lens keep the
    last iterate.
    """
    xy_d = np.asarray(xy_d, dtype=np.float64)
    k1 = np.asarray(k1, dtype=np.float64)[..., None]
    k2 = np.asarray(k2, dtype=np.float64)[..., None]
    rd = np.sqrt(np.sum(xy_d * xy_d, axis=-1))
    r = rd.copy()
    for _ in range(iterations):
        r2 = r * r
        f = r * (1.0 + k1 * r2 + k2 * r2 * r2) - rd
        df = 1.0 + 3.0 * k1 * r2 + 5.0 * k2 * r2 * r2
        step = f / np.where(np.abs(df) > 1e-12, df, 1e-12)
        r = r - step
        if np.all(np.abs(step) < 1e-15):
            break
    scale = np.where(rd > 0, r / np.where(rd > 0, rd, 1.0), 1.0)
    return xy_d * scale[..., None]


def pixels_from_normalized(xy_n, fx, fy, cx, cy) -> np.ndarray:
    """Eq. (2): ``u = fx x + cx``, ``v = fy y + cy`` on (..., N, 2)."""
    xy_n = np.asarray(xy_n, dtype=np.float64)
    f = np.stack(np.broadcast_arrays(np.asarray(fx, float), np.asarray(fy, float)), -1)[..., None, :]
    c = np.stack(np.broadcast_arrays(np.asarray(cx, float), np.asarray(cy, float)), -1)[..., None, :]
    return xy_n * f + c


def normalized_from_pixels(uv, fx, fy, cx, cy) -> np.ndarray:
    """Inverse of :func:`pixels_from_normalized`."""
    uv = np.asarray(uv, dtype=np.float64)
    f = np.stack(np.broadcast_arrays(np.asarray(fx, float), np.asarray(fy, float)), -1)[..., None, :]
    c = np.stack(np.broadcast_arrays(np.asarray(cx, float), np.asarray(cy, float)), -1)[..., None, :]
    return (uv - c) / f


def project_points(points_world, *, fx, fy, cx, cy, k1=0.0, k2=0.0, R=None, t=None) -> np.ndarray:
    """Project world points to distorted pixels, eq. (1)-(3).

    ``points_world`` (..., N, 3); ``R`` (..., 3, 3) and ``t`` (..., 3) map world
    to camera (``points_cam = R p + t``); identity/zero when omitted. Points
    behind the camera (Z <= 0) give NaN.
    """
    p = np.asarray(points_world, dtype=np.float64)
    if R is not None:
        p = np.einsum("...ij,...nj->...ni", np.asarray(R, dtype=np.float64), p)
    if t is not None:
        p = p + np.asarray(t, dtype=np.float64)[..., None, :]
    z = p[..., 2:3]
    with np.errstate(divide="ignore", invalid="ignore"):
        xy = np.where(z > 0, p[..., :2] / z, np.nan)
    return pixels_from_normalized(distort_normalized(xy, k1, k2), fx, fy, cx, cy)


@dataclass(frozen=True)
class Camera:
    """Intrinsics in the OpenCV/ROS parameterization (pixels, normalized k1, k2).

    Attributes
    ----------
    width, height : int
        Image size in pixels.
    fx, fy, cx, cy : float
        Focal lengths and principal point in pixels.
    k1, k2 : float
        Radial distortion on normalized coordinates (eq. 3).
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    k1: float = 0.0
    k2: float = 0.0

    def __post_init__(self) -> None:
        _checks.positive_int("width", self.width)
        _checks.positive_int("height", self.height)
        for name in ("fx", "fy"):
            _checks.finite_number(name, getattr(self, name), positive=True)
        for name in ("cx", "cy", "k1", "k2"):
            _checks.finite_number(name, getattr(self, name))

    @property
    def K(self) -> np.ndarray:
        """3x3 camera matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def dist_coeffs(self) -> np.ndarray:
        """OpenCV/ROS plumb_bob coefficients ``(k1, k2, p1, p2, k3)``."""
        return np.array([self.k1, self.k2, 0.0, 0.0, 0.0])

    @property
    def size(self) -> tuple[int, int]:
        """``(width, height)`` as OpenCV expects it."""
        return (self.width, self.height)

    def project(self, points_cam) -> np.ndarray:
        """Distorted pixel coordinates (N, 2) of camera-frame points (N, 3)."""
        return project_points(_checks.points3("points_cam", points_cam), fx=self.fx, fy=self.fy,
                              cx=self.cx, cy=self.cy, k1=self.k1, k2=self.k2)

    def rays(self, uv) -> np.ndarray:
        """Undistorted viewing rays ``(x, y, 1)`` (N, 3) of distorted pixels (N, 2)."""
        uv = np.asarray(uv, dtype=np.float64)
        if uv.ndim != 2 or uv.shape[1] != 2:
            raise ValueError(f"uv must have shape (N, 2), got {uv.shape}")
        xy = undistort_normalized(normalized_from_pixels(uv, self.fx, self.fy, self.cx, self.cy),
                                  self.k1, self.k2)
        return np.concatenate([xy, np.ones((len(xy), 1))], axis=1)

    def undistort_pixels(self, uv) -> np.ndarray:
        """Pixel positions (N, 2) the points would have without distortion."""
        xy = self.rays(uv)[:, :2]
        return pixels_from_normalized(xy, self.fx, self.fy, self.cx, self.cy)

    def undistort_rectify_maps(self, *, R=None, P=None, size=None) -> tuple[np.ndarray, np.ndarray]:
        """``cv2.remap`` maps (float32 map_x, map_y) to a new pinhole view.

        ``R`` rotates the old camera frame into the new one, ``P`` (3x3 or 3x4)
        holds the new intrinsics (default: this camera without distortion).
        """
        R = np.eye(3) if R is None else _checks.matrix("R", R, (3, 3))
        P = self.K if P is None else np.asarray(P, dtype=np.float64)[:3, :3]
        size = self.size if size is None else tuple(int(s) for s in size)
        return cv2.initUndistortRectifyMap(self.K, self.dist_coeffs, R, P, size, cv2.CV_32FC1)

    def to_paper(self, *, f_mm: float) -> PaperCamera:
        """Exact conversion to the paper's parameterization for a focal length in mm."""
        f_mm = _checks.finite_number("f_mm", f_mm, positive=True)
        return PaperCamera(width=self.width, height=self.height, f_mm=f_mm,
                           alpha_x=self.fx / f_mm, alpha_y=self.fy / f_mm, u0=self.cx, v0=self.cy,
                           k1_mm=self.k1 / f_mm**2, k2_mm=self.k2 / f_mm**4)


@dataclass(frozen=True)
class PaperCamera:
    """Intrinsics in the paper's parameterization (eq. 1-3, Table 1).

    ``f_mm`` focal length [mm]; ``alpha_x``, ``alpha_y`` pixel densities [px/mm];
    ``u0``, ``v0`` principal point [px]; ``k1_mm`` [mm^-2], ``k2_mm`` [mm^-4]
    radial distortion on metric image-plane coordinates.
    """

    width: int
    height: int
    f_mm: float
    alpha_x: float
    alpha_y: float
    u0: float
    v0: float
    k1_mm: float = 0.0
    k2_mm: float = 0.0

    def __post_init__(self) -> None:
        for name in ("f_mm", "alpha_x", "alpha_y"):
            _checks.finite_number(name, getattr(self, name), positive=True)
        for name in ("u0", "v0", "k1_mm", "k2_mm"):
            _checks.finite_number(name, getattr(self, name))

    def to_camera(self) -> Camera:
        """Exact conversion to the OpenCV/ROS parameterization."""
        f = self.f_mm
        return Camera(width=self.width, height=self.height, fx=self.alpha_x * f, fy=self.alpha_y * f,
                      cx=self.u0, cy=self.v0, k1=self.k1_mm * f**2, k2=self.k2_mm * f**4)

    def project(self, points_cam) -> np.ndarray:
        """Eq. (1)-(3) literally: metric image plane, distortion in mm, then pixels."""
        p = _checks.points3("points_cam", points_cam)
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = np.where(p[:, 2:3] > 0, self.f_mm * p[:, :2] / p[:, 2:3], np.nan)   # eq. (1)
        r2 = np.sum(xy * xy, axis=1, keepdims=True)
        xy_d = xy + xy * (self.k1_mm * r2 + self.k2_mm * r2 * r2)                  # eq. (3)
        return xy_d * np.array([self.alpha_x, self.alpha_y]) + np.array([self.u0, self.v0])  # eq. (2)
