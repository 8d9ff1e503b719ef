"""Levenberg-Marquardt refinement of camera parameters (beyond the paper).

Minimizes the same objective as the GA, eq. (6) -- the sum of squared
reprojection errors -- but with a local, gradient-based method
(``scipy.optimize.least_squares``), from a GA result or from a closed-form
initialisation. Parameters are the intrinsics ``[fx, fy, cx, cy, k1, k2]`` (or
``[f, cx, cy, k1, k2]`` with ``fy = aspect * fx`` fixed) followed by six pose
parameters ``(alpha, beta, gamma, tx, ty, tz)`` per view (conventions:
docs/conventions.md). The Jacobian is computed by central differences grouped by
the block structure (the poses of different views touch different residuals), so
one Jacobian costs about 24 residual evaluations whatever the number of views.

Standard deviations: ``cov = s^2 (J^T J)^-1`` with ``s^2 = |r|^2 / (m - n)``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from ..camera import Camera, euler_from_rotation, project_points, rotation_from_euler
from .targets import CalibrationView

__all__ = ["INTRINSIC_NAMES", "LMFit", "refine_views", "grouped_jacobian", "pose_vector", "pose_matrix",
           "fit_statistics"]

INTRINSIC_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2")
POSE_NAMES = ("alpha", "beta", "gamma", "tx", "ty", "tz")


def pose_vector(T: np.ndarray) -> np.ndarray:
    """``(alpha, beta, gamma, tx, ty, tz)`` of a 4x4 ``T_cam_from_target``."""
    a, b, g = euler_from_rotation(T[:3, :3])
    return np.array([a, b, g, *T[:3, 3]], dtype=np.float64)


def pose_matrix(x: np.ndarray) -> np.ndarray:
    """4x4 ``T_cam_from_target`` of a pose vector."""
    T = np.eye(4)
    T[:3, :3] = rotation_from_euler(x[0], x[1], x[2])
    T[:3, 3] = x[3:6]
    return T


def grouped_jacobian(fun: Callable[[np.ndarray], np.ndarray], x: np.ndarray, col_block: np.ndarray,
                     col_local: np.ndarray, row_block: np.ndarray) -> np.ndarray:
    """Dense Jacobian by central differences, perturbing block-disjoint columns together.

    ``col_block[j]`` is -1 for a column that may touch every residual, or the
    block (view) that column ``j`` belongs to; ``col_local[j]`` its index within
    the block; ``row_block[i]`` the block of residual ``i``. Columns of different
    blocks with the same local index are perturbed in one evaluation.
    """
    n = x.size
    J = np.zeros((row_block.size, n))
    h = 1e-6 * np.maximum(np.abs(x), 1e-2)
    groups: list[np.ndarray] = [np.array([j]) for j in range(n) if col_block[j] < 0]
    for k in np.unique(col_local[col_block >= 0]):
        groups.append(np.flatnonzero((col_block >= 0) & (col_local == k)))
    for cols in groups:
        step = np.zeros(n)
        step[cols] = h[cols]
        diff = (fun(x + step) - fun(x - step))
        if len(cols) == 1 and col_block[cols[0]] < 0:
            J[:, cols[0]] = diff / (2 * h[cols[0]])
        else:
            for j in cols:
                rows = row_block == col_block[j]
                J[rows, j] = diff[rows] / (2 * h[j])
    return J


@dataclass(frozen=True)
class LMFit:
    """Refined parameters of :func:`refine_views`."""

    camera: Camera
    poses: tuple[np.ndarray, ...]
    residuals_px: tuple[np.ndarray, ...]
    sigmas: dict
    success: bool
    message: str
    evaluations: int


def fit_statistics(residuals: np.ndarray, J: np.ndarray) -> np.ndarray:
    """Parameter standard deviations ``sqrt(diag(s^2 (J^T J)^-1))``."""
    m, n = J.shape
    dof = max(m - n, 1)
    s2 = float(residuals @ residuals) / dof
    cov = s2 * np.linalg.pinv(J.T @ J)
    return np.sqrt(np.clip(np.diag(cov), 0.0, None))


def _intrinsics(x: np.ndarray, fix_aspect: float | None):
    if fix_aspect is None:
        return x[0], x[1], x[2], x[3], x[4], x[5]
    return x[0], x[0] * fix_aspect, x[1], x[2], x[3], x[4]


def refine_views(views: Sequence[CalibrationView], camera: Camera, poses: Sequence[np.ndarray], *,
                 fix_aspect: float | None = None, method: str = "lm", max_evaluations: int = 200
                 ) -> LMFit:
    """Levenberg-Marquardt over shared intrinsics and one pose per view.

    Parameters
    ----------
    views : sequence of CalibrationView
    camera : Camera
        Initial intrinsics (image size is kept).
    poses : sequence of ndarray (4, 4)
        Initial ``T_cam_from_target`` per view.
    fix_aspect : float, optional
        Estimate one focal length with ``fy = fix_aspect * fx`` (needed for a
        single planar view, where ``fx`` and ``fy`` are not separable).
    method : {"lm", "trf"}
        ``scipy.optimize.least_squares`` method ("trf" uses ``x_scale="jac"``).
    """
    n_int = 6 if fix_aspect is None else 5
    x0_int = (np.array([camera.fx, camera.fy, camera.cx, camera.cy, camera.k1, camera.k2]) if fix_aspect is None
              else np.array([camera.fx, camera.cx, camera.cy, camera.k1, camera.k2]))
    x0 = np.concatenate([x0_int] + [pose_vector(T) for T in poses])
    counts = [len(v.uv) for v in views]
    row_block = np.repeat(np.arange(len(views)), [2 * c for c in counts])
    col_block = np.concatenate([np.full(n_int, -1), np.repeat(np.arange(len(views)), 6)])
    col_local = np.concatenate([np.arange(n_int), np.tile(np.arange(6), len(views))])

    def residuals(x: np.ndarray) -> np.ndarray:
        fx, fy, cx, cy, k1, k2 = _intrinsics(x, fix_aspect)
        out = []
        for i, view in enumerate(views):
            p = x[n_int + 6 * i: n_int + 6 * i + 6]
            uv = project_points(view.points_target, fx=fx, fy=fy, cx=cx, cy=cy, k1=k1, k2=k2,
                                R=rotation_from_euler(p[0], p[1], p[2]), t=p[3:6])
            out.append((uv - view.uv).ravel())
        r = np.concatenate(out)
        return np.where(np.isfinite(r), r, 1e6)

    def jac(x: np.ndarray) -> np.ndarray:
        return grouped_jacobian(residuals, x, col_block, col_local, row_block)

    kwargs = {"x_scale": "jac"} if method == "trf" else {}
    from scipy.optimize import least_squares   # lazy: 0.4 s to import, every CLI start paid it
    sol = least_squares(residuals, x0, jac=jac, method=method, max_nfev=max_evaluations, **kwargs)
    x = sol.x
    fx, fy, cx, cy, k1, k2 = _intrinsics(x, fix_aspect)
    try:
        cam = Camera(width=camera.width, height=camera.height, fx=float(fx), fy=float(fy), cx=float(cx),
                     cy=float(cy), k1=float(k1), k2=float(k2))
        ok = bool(sol.success)
        message = str(sol.message)
    except ValueError as exc:            # e.g. a negative focal length: keep the start, report
        cam, ok, message, x = camera, False, f"LM left the valid region: {exc}", x0
    r = residuals(x)
    sig = fit_statistics(r, jac(x))
    names = INTRINSIC_NAMES if fix_aspect is None else ("fx", "cx", "cy", "k1", "k2")
    sigmas = {name: float(s) for name, s in zip(names, sig[:n_int])}
    if fix_aspect is not None:
        sigmas["fy"] = sigmas["fx"] * fix_aspect
    split = np.cumsum([2 * c for c in counts])[:-1]
    res_views = tuple(part.reshape(-1, 2) for part in np.split(r, split))
    poses_out = tuple(pose_matrix(x[n_int + 6 * i: n_int + 6 * i + 6]) for i in range(len(views)))
    if not math.isfinite(float(r @ r)):
        ok, message = False, "non-finite residuals"
    return LMFit(camera=cam, poses=poses_out, residuals_px=res_views, sigmas=sigmas, success=ok,
                 message=message, evaluations=int(sol.nfev))
