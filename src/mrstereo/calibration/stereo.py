"""Stereo calibration: two cameras against the same target poses, then rectification.

Each camera is calibrated alone first (:func:`calibrate_camera`, GA, GA + LM or
LM); the relative pose ``x_right = R x_left + T`` is initialised from the
per-view poses (chordal mean of ``R_r R_l^T``, median of ``t_r - R t_l``) and
then refined jointly by Levenberg-Marquardt over both intrinsics, the left
poses and the relative pose (``method != "ga"``). The pair is rectified by
Fusiello, Trucco & Verri (:func:`mrstereo.camera.rectify_fusiello`).
Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .. import _checks
from ..camera import (MIN_BASELINE_M, RigMount, StereoCamera, check_not_swapped, rectified_px_from_raw_px,
                      rectify_fusiello)
from ..transforms import rotation_from_rpy
from .calibrate import CalibrationResult, _rms, calibrate_camera, reprojection_residuals, zhang_init
from .ga import GABounds, GAConfig
from .refine import calibration_model, fit_statistics, grouped_jacobian, pose_matrix, pose_vector, project_views
from .targets import CalibrationView

__all__ = ["StereoCalibrationResult", "calibrate_stereo", "rectified_points", "rectified_vertical_error_px"]


@dataclass(frozen=True)
class StereoCalibrationResult:
    """A calibrated and rectified stereo pair.

    Attributes
    ----------
    stereo : StereoCamera
        What ``write_stereo`` stores (raw K, D; R raw -> rectified; rectified P).
    R, T : ndarray
        Relative pose, ``x_right = R x_left + T`` (T in metres).
    left, right : CalibrationResult
        The single-camera calibrations (before the joint refinement).
    rms_px : float
        Joint RMS reprojection error over both cameras.
    per_view_rms_px : ndarray of shape (V, 2)
        Left and right RMS per pair after the joint fit.
    sigmas : dict
        Standard deviations of the jointly refined intrinsics (``left_fx``, ...,
        ``right_k2``) and of ``T`` (``Tx``, ``Ty``, ``Tz``).
    vertical_error_px : float
        Mean ``|y_left - y_right|`` of matching corners after rectification.
    per_view_vertical_error_px : ndarray of shape (V,)
    outlier_views : tuple of int
        Pairs whose RMS exceeds 3x the median.
    success, message :
        Convergence of the joint fit.
    view_names : tuple of str
    """

    stereo: StereoCamera
    R: np.ndarray
    T: np.ndarray
    left: CalibrationResult
    right: CalibrationResult
    rms_px: float
    per_view_rms_px: np.ndarray
    sigmas: dict
    vertical_error_px: float
    per_view_vertical_error_px: np.ndarray
    outlier_views: tuple
    success: bool
    message: str
    view_names: tuple = ()
    left_poses: tuple = field(default=(), repr=False)

    @property
    def baseline_m(self) -> float:
        return float(np.linalg.norm(self.T))

    def summary(self) -> dict:
        return {
            "success": self.success, "message": self.message, "rms_px": float(self.rms_px),
            "baseline_m": self.baseline_m, "R": self.R.tolist(), "T_m": self.T.tolist(),
            "rectified_vertical_error_px": float(self.vertical_error_px),
            "sigmas": {k: float(v) for k, v in self.sigmas.items()},
            "per_pair": {n: {"rms_left_px": float(a), "rms_right_px": float(b), "vertical_error_px": float(e)}
                         for n, (a, b), e in zip(self.view_names, self.per_view_rms_px,
                                                 self.per_view_vertical_error_px)},
            "outlier_pairs": [self.view_names[i] for i in self.outlier_views],
            "left": self.left.summary(), "right": self.right.summary(),
        }


def rectified_points(stereo: StereoCamera, uv: np.ndarray, *, side: str) -> np.ndarray:
    """Raw distorted pixels (N, 2) of one camera mapped to its rectified image."""
    if side not in ("left", "right"):
        raise ValueError(f"side must be 'left' or 'right', got {side!r}")
    return rectified_px_from_raw_px(stereo.left if side == "left" else stereo.right, uv)


def rectified_vertical_error_px(stereo: StereoCamera, left_uv: Sequence[np.ndarray],
                                right_uv: Sequence[np.ndarray]) -> np.ndarray:
    """Mean ``|y_left - y_right|`` per pair of matching raw points after rectification."""
    out = []
    for a, b in zip(left_uv, right_uv):
        ya = rectified_points(stereo, a, side="left")[:, 1]
        yb = rectified_points(stereo, b, side="right")[:, 1]
        out.append(float(np.mean(np.abs(ya - yb))))
    return np.asarray(out)


def _agree_with_left(left: CalibrationView, right: CalibrationView) -> CalibrationView:
    """Undo a half-turn renumbering of a point-symmetric target (a chessboard) in the right view.

    Reversing the point order of a grid is the same as turning it by 180 degrees
    about its centre, so detectors may number the two images of one pair from
    opposite corners. When the target is symmetric that way and the right
    first-to-last direction opposes the left one, the right order is reversed.
    """
    p = left.points_target
    symmetric = np.allclose(p[::-1], 2.0 * p.mean(axis=0) - p, atol=1e-9)
    if symmetric and float(np.dot(left.uv[-1] - left.uv[0], right.uv[-1] - right.uv[0])) < 0:
        return CalibrationView(right.points_target, right.uv[::-1].copy(), name=right.name)
    return right


def _mean_rotation(Rs: Sequence[np.ndarray]) -> np.ndarray:
    U, _, Vt = np.linalg.svd(np.sum(Rs, axis=0))
    R = U @ Vt
    if np.linalg.det(R) < 0:
        U[:, -1] *= -1
        R = U @ Vt
    return R


def _relative_pose(poses_left, poses_right) -> tuple[np.ndarray, np.ndarray]:
    """``R``, ``T`` (``x_right = R x_left + T``) from per-view poses: chordal mean, median."""
    R = _mean_rotation([(Tr @ np.linalg.inv(Tl))[:3, :3] for Tl, Tr in zip(poses_left, poses_right)])
    T = np.median(np.stack([Tr[:3, 3] - R @ Tl[:3, 3] for Tl, Tr in zip(poses_left, poses_right)]), axis=0)
    return R, T


def _check_baseline(T: np.ndarray, poses_left: Sequence[np.ndarray]) -> None:
    """Refuse a (near) zero baseline: shorter than 0.1 mm or than 1e-4 of the target distance."""
    distance_m = float(np.median([np.linalg.norm(P[:3, 3]) for P in poses_left]))
    baseline_m = float(np.linalg.norm(T))
    if baseline_m < max(MIN_BASELINE_M, 1e-4 * distance_m):
        raise ValueError(f"stereo-calibrate: the baseline is zero ({baseline_m:.2g} m for a target "
                         f"{distance_m:.3g} m away): both views were taken from the same place; are the same "
                         "images given as --left and --right?")


def calibrate_stereo(left_views: Sequence[CalibrationView], right_views: Sequence[CalibrationView], *,
                     width: int, height: int, method: str = "ga+lm", ga_config: GAConfig | None = None,
                     bounds: GABounds | None = None, pixel_density_px_per_mm: float | None = None,
                     alpha: float = 0.0, rig: RigMount | None = None, rng=None, progress=None,
                     model: str = "k1k2") -> StereoCalibrationResult:
    """Calibrate a stereo pair from views of the same target poses, and rectify it.

    Parameters
    ----------
    left_views, right_views : sequence of CalibrationView
        Pair ``i`` shows the same target pose in both cameras (same target points).
        For a point-symmetric target (a chessboard) a right view numbered from the
        opposite corner (first-to-last direction opposing the left one) is reversed.
    width, height : int
        Image size (both cameras).
    method : {"ga", "ga+lm", "lm"}
        Per-camera method; anything but "ga" also refines the pair jointly.
    alpha : float
        Rectified field of view, 0 = valid pixels only, 1 = every raw pixel
        (:func:`mrstereo.camera.rectify_fusiello`).
    rng : numpy Generator, int or None
        Seed of both GAs.
    model : {"k1k2", "plumb_bob", "rational", "fisheye"}
        Distortion model of both cameras (:func:`calibrate_camera`).

    Raises
    ------
    ValueError
        Also when the baseline is (near) zero (the same images given twice)
        or the views look swapped (the right camera sits on the left,
        :func:`mrstereo.camera.check_not_swapped`).
    """
    spec = calibration_model(model)
    left_views, right_views = list(left_views), list(right_views)
    if len(left_views) != len(right_views):
        raise ValueError(f"left and right need the same number of views, got {len(left_views)} and "
                         f"{len(right_views)}")
    if len(left_views) < 2:
        raise ValueError(f"stereo calibration needs at least 2 view pairs, got {len(left_views)}")
    for i, (a, b) in enumerate(zip(left_views, right_views)):
        if a.points_target.shape != b.points_target.shape or not np.allclose(a.points_target, b.points_target):
            raise ValueError(f"pair {i}: left and right views must hold the same target points")
    width = _checks.positive_int("width", width)
    height = _checks.positive_int("height", height)
    right_views = [_agree_with_left(a, b) for a, b in zip(left_views, right_views)]
    gen = _checks.rng(rng)
    kw = dict(width=width, height=height, method=method, ga_config=ga_config, bounds=bounds,
              pixel_density_px_per_mm=pixel_density_px_per_mm, rng=gen, progress=progress, model=spec.name)
    if all(v.is_planar for v in left_views):
        # before the (slow) GA: the closed-form poses already tell a swapped or zero baseline
        poses = [zhang_init(views, width=width, height=height)[1] for views in (left_views, right_views)]
        R, T = _relative_pose(*poses)
        _check_baseline(T, poses[0])
        try:
            check_not_swapped(R, T, where="stereo-calibrate")
        except ValueError:      # confirm (and measure) with LM poses: the closed form ignores distortion
            poses = [calibrate_camera(views, width=width, height=height, method="lm").poses
                     for views in (left_views, right_views)]
            R, T = _relative_pose(*poses)
            check_not_swapped(R, T, where="stereo-calibrate")
    left = calibrate_camera(left_views, **kw)
    right = calibrate_camera(right_views, **kw)
    R, T = _relative_pose(left.poses, right.poses)
    _check_baseline(T, left.poses)
    check_not_swapped(R, T, where="stereo-calibrate")
    cam_l, cam_r = left.camera, right.camera
    poses_l = list(left.poses)
    success = left.success and right.success
    message = f"left: {left.message} | right: {right.message}"
    sigmas: dict = {}
    V = len(left_views)
    n = 4 + spec.n_free                 # fx, fy, cx, cy and the model's coefficients, per camera

    def unpack(x):
        rel_T = pose_matrix(x[2 * n + 6 * V:])
        return x[:n], x[n:2 * n], [x[2 * n + 6 * i: 2 * n + 6 + 6 * i] for i in range(V)], rel_T

    def residuals(x):
        il, ir, pl, relT = unpack(x)
        pl = np.asarray(pl)
        Rl, tl = rotation_from_rpy(pl[:, 0], pl[:, 1], pl[:, 2]), pl[:, 3:6]
        Rr, tr = relT[:3, :3] @ Rl, tl @ relT[:3, :3].T + relT[:3, 3]
        return np.concatenate([project_views(views, R_, t_, fx=intr[0], fy=intr[1], cx=intr[2], cy=intr[3],
                                             distortion_model=spec.distortion_model,
                                             D=spec.full_coefficients(intr[4:]))
                               for intr, R_, t_, views in ((il, Rl, tl, left_views), (ir, Rr, tr, right_views))])

    Trel = np.eye(4)
    Trel[:3, :3], Trel[:3, 3] = R, T
    x0 = np.concatenate([[c.fx, c.fy, c.cx, c.cy, *spec.seed(c)] for c in (cam_l, cam_r)]
                        + [pose_vector(P) for P in poses_l] + [pose_vector(Trel)])
    if method != "ga":
        row_block = np.concatenate([np.repeat(np.arange(V), [2 * len(v.uv) for v in views])
                                    for views in (left_views, right_views)])     # residuals: all left, all right
        col_block = np.concatenate([np.full(2 * n, -1), np.repeat(np.arange(V), 6), np.full(6, -1)])
        col_local = np.concatenate([np.arange(2 * n), np.tile(np.arange(6), V), np.arange(6)])

        def jac(x):
            return grouped_jacobian(residuals, x, col_block, col_local, row_block)

        from scipy.optimize import least_squares  # lazy: 0.4 s to import, every CLI start paid it
        sol = least_squares(residuals, x0, jac=jac, method="lm", max_nfev=200)
        try:
            il, ir, pl, relT = unpack(sol.x)
            new_l = spec.camera(width, height, *il[:4], il[4:])
            new_r = spec.camera(width, height, *ir[:4], ir[4:])
            if sol.fun @ sol.fun > residuals(x0) @ residuals(x0) + 1e-9:
                raise ValueError("joint fit increased the error")
            cam_l, cam_r, poses_l = new_l, new_r, [pose_matrix(p) for p in pl]
            R, T = relT[:3, :3], relT[:3, 3]
            sig = fit_statistics(sol.fun, jac(sol.x))
            names = ("fx", "fy", "cx", "cy") + spec.coefficient_names
            sigmas = {f"{side}_{name}": float(s) for side, block in (("left", sig[:n]), ("right", sig[n:2 * n]))
                      for name, s in zip(names, block)}
            sigmas.update({f"T{a}": float(s) for a, s in zip("xyz", sig[-3:])})
            success = success and bool(sol.success)
            message += f" | joint LM: {sol.message}"
        except ValueError as exc:
            success = False
            message += f" | joint LM failed: {exc}"
    Trel = np.eye(4)
    Trel[:3, :3], Trel[:3, 3] = R, T
    check_not_swapped(R, T, where="stereo-calibrate")
    poses_r = [Trel @ P for P in poses_l]
    res_l = reprojection_residuals(left_views, cam_l, poses_l)
    res_r = reprojection_residuals(right_views, cam_r, poses_r)
    rms = _rms(res_l + res_r)[0]
    per_view = np.stack([_rms(res_l)[1], _rms(res_r)[1]], axis=1)
    rect = rectify_fusiello(cam_l, cam_r, R, T, alpha=alpha, rig=rig)
    vert = rectified_vertical_error_px(rect.stereo, [v.uv for v in left_views], [v.uv for v in right_views])
    worst = per_view.max(axis=1)
    outliers = tuple(int(i) for i in np.flatnonzero(worst > 3.0 * np.median(worst))) if V > 2 else ()
    if not math.isfinite(rms):
        success = False
    return StereoCalibrationResult(
        stereo=rect.stereo, R=R, T=np.asarray(T, dtype=np.float64), left=left, right=right, rms_px=rms,
        per_view_rms_px=per_view, sigmas=sigmas, vertical_error_px=float(np.mean(vert)),
        per_view_vertical_error_px=vert, outlier_views=outliers, success=success, message=message,
        view_names=tuple(v.name for v in left_views), left_poses=tuple(poses_l))
