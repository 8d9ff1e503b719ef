"""Stereo calibration: two cameras against the same target poses, then rectification.

Each camera is calibrated alone (:func:`calibrate_camera`); the relative pose ``x_right = R x_left
+ T`` starts at the chordal mean of ``R_r R_l^T`` and the median of ``t_r - R t_l`` over the views
and is refined jointly with both intrinsics and the left poses by Levenberg-Marquardt (``method !=
"ga"``); the pair is rectified by :func:`mrstereo.camera.rectify_fusiello`. Conventions:
docs/conventions.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .. import _checks
from ..camera import (MIN_BASELINE_M, StereoCamera, check_not_swapped, rectified_px_from_raw_px,
                      rectify_fusiello)
from ..transforms import T_from_R_t, rotation_from_rpy
from .calibrate import CalibrationResult, _rms, calibrate_camera, reprojection_residuals, zhang_init
from .ga import GABounds, GAConfig
from .refine import (CalibrationModel, calibration_model, fit_statistics, grouped_jacobian, least_squares_fit,
                     pose_matrix, pose_vector, project_views)
from .targets import CalibrationView, agree_with_left

__all__ = ["StereoCalibrationResult", "calibrate_stereo", "rectified_points", "rectified_vertical_error_px"]


@dataclass(frozen=True)
class StereoCalibrationResult:
    """A calibrated and rectified stereo pair.

    ``stereo`` (what ``write_stereo`` stores); ``x_right = R x_left + T`` (metres); the single-camera
    ``left`` and ``right`` results (before the joint refinement); the joint ``rms_px`` and
    ``per_view_rms_px`` (V, 2); ``sigmas`` of the jointly refined intrinsics (``left_fx``, ...) and of
    ``T`` (``Tx``, ...); ``vertical_error_px`` (mean ``|y_left - y_right|`` after rectification) and
    its ``per_view_vertical_error_px``; ``outlier_views`` over 3x the median RMS; ``success``,
    ``message`` of the joint fit; ``view_names``.
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
    _checks.instance("stereo", stereo, StereoCamera)
    out = []
    for a, b in zip(left_uv, right_uv):
        ya = rectified_points(stereo, a, side="left")[:, 1]
        yb = rectified_points(stereo, b, side="right")[:, 1]
        out.append(float(np.mean(np.abs(ya - yb))))
    return np.asarray(out)


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


def _check_view_pairs(left_views: list, right_views: list) -> None:
    if len(left_views) != len(right_views):
        raise ValueError(f"left and right need the same number of views, got {len(left_views)} and "
                         f"{len(right_views)}")
    if len(left_views) < 2:
        raise ValueError(f"stereo calibration needs at least 2 view pairs, got {len(left_views)}")
    for i, (a, b) in enumerate(zip(left_views, right_views)):
        if a.points_target.shape != b.points_target.shape or not np.allclose(a.points_target, b.points_target):
            raise ValueError(f"pair {i}: left and right views must hold the same target points")


def _check_swapped_early(left_views: list, right_views: list, *, width: int, height: int) -> None:
    """Before the (slow) GA: the closed-form poses of a planar target already tell a swapped or zero baseline."""
    if not all(v.is_planar for v in left_views):
        return
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


@dataclass(frozen=True)
class _JointFit:
    """The joint refinement's parameter vector: both cameras' intrinsics (``n`` each), the left poses
    (6 per view pair) and the relative pose (6); residuals of all left views, then all right views."""

    spec: CalibrationModel
    left_views: tuple
    right_views: tuple

    @property
    def n(self) -> int:
        return 4 + self.spec.n_free                 # fx, fy, cx, cy and the model's coefficients

    def pack(self, cam_l, cam_r, poses_l, R, T) -> np.ndarray:
        return np.concatenate([[c.fx, c.fy, c.cx, c.cy, *self.spec.seed(c)] for c in (cam_l, cam_r)]
                              + [pose_vector(P) for P in poses_l] + [pose_vector(T_from_R_t(R, T))])

    def unpack(self, x) -> tuple:
        n, V = self.n, len(self.left_views)
        poses = [x[2 * n + 6 * i: 2 * n + 6 + 6 * i] for i in range(V)]
        return x[:n], x[n:2 * n], poses, pose_matrix(x[2 * n + 6 * V:])

    def residuals(self, x) -> np.ndarray:
        il, ir, pl, relT = self.unpack(x)
        pl = np.asarray(pl)
        Rl, tl = rotation_from_rpy(pl[:, 0], pl[:, 1], pl[:, 2]), pl[:, 3:6]
        Rr, tr = relT[:3, :3] @ Rl, tl @ relT[:3, :3].T + relT[:3, 3]
        return np.concatenate([project_views(views, R_, t_, fx=intr[0], fy=intr[1], cx=intr[2], cy=intr[3],
                                             distortion_model=self.spec.distortion_model,
                                             D=self.spec.full_coefficients(intr[4:]))
                               for intr, R_, t_, views in ((il, Rl, tl, self.left_views),
                                                           (ir, Rr, tr, self.right_views))])

    def jacobian(self, x) -> np.ndarray:
        """Central differences, perturbing the columns of different view pairs together."""
        V, n = len(self.left_views), self.n
        col_block = np.concatenate([np.full(2 * n, -1), np.repeat(np.arange(V), 6), np.full(6, -1)])
        col_local = np.concatenate([np.arange(2 * n), np.tile(np.arange(6), V), np.arange(6)])
        row_block = np.concatenate([np.repeat(np.arange(V), [2 * len(v.uv) for v in views])
                                    for views in (self.left_views, self.right_views)])
        return grouped_jacobian(self.residuals, x, col_block, col_local, row_block)


def _refine_jointly(fit: _JointFit, cam_l, cam_r, poses_l, R, T, *, width: int, height: int) -> tuple:
    """Levenberg-Marquardt over both intrinsics, the left poses and the relative pose.

    Returns ``(cam_l, cam_r, poses_l, R, T, sigmas, success, message)``; the inputs unchanged
    (``success`` False) when the fit fails or increases the error.
    """
    x0 = fit.pack(cam_l, cam_r, poses_l, R, T)
    sol = least_squares_fit(fit.residuals, x0, fit.jacobian,
                            sum(2 * len(v.uv) for v in (*fit.left_views, *fit.right_views)))
    try:
        il, ir, pl, relT = fit.unpack(sol.x)
        new_l = fit.spec.camera(width, height, *il[:4], il[4:])
        new_r = fit.spec.camera(width, height, *ir[:4], ir[4:])
        start = fit.residuals(x0)
        if sol.fun @ sol.fun > start @ start + 1e-9:
            raise ValueError("joint fit increased the error")
    except ValueError as exc:
        return cam_l, cam_r, poses_l, R, T, {}, False, f" | joint LM failed: {exc}"
    refined = (new_l, new_r, [pose_matrix(p) for p in pl], relT[:3, :3], relT[:3, 3])
    try:
        sig = fit_statistics(sol.fun, fit.jacobian(sol.x))
    except ValueError as exc:           # LinAlgError: the fit stands, its uncertainty is unknown
        return (*refined, {}, False, f" | joint LM failed: {exc}")
    n = fit.n
    names = ("fx", "fy", "cx", "cy") + fit.spec.coefficient_names
    sigmas = {f"{side}_{name}": float(s) for side, block in (("left", sig[:n]), ("right", sig[n:2 * n]))
              for name, s in zip(names, block)}
    sigmas.update({f"T{a}": float(s) for a, s in zip("xyz", sig[-3:])})
    return (*refined, sigmas, bool(sol.success), f" | joint LM: {sol.message}")


def calibrate_stereo(left_views: Sequence[CalibrationView], right_views: Sequence[CalibrationView], *,
                     width: int, height: int, method: str = "ga+lm", ga_config: GAConfig | None = None,
                     bounds: GABounds | None = None, pixel_density_px_per_mm: float | None = None,
                     alpha: float = 0.0, rng=None, progress=None, model: str = "k1k2") -> StereoCalibrationResult:
    """Calibrate a stereo pair from views of the same target poses, and rectify it.

    Parameters
    ----------
    left_views, right_views : sequence of CalibrationView
        Pair ``i`` shows the same target pose in both cameras; a right view numbered from the opposite
        corner is reversed (:func:`agree_with_left`).
    width, height : int
    method : {"ga", "ga+lm", "lm"}
        Per-camera method; anything but "ga" also refines the pair jointly.
    ga_config, bounds, pixel_density_px_per_mm
        As :func:`calibrate_camera`.
    alpha : float
        Rectified field of view, 0 = valid pixels only, 1 = every raw pixel.
    rng : numpy Generator, int or None
    progress : callable, optional
    model : {"k1k2", "plumb_bob", "rational", "fisheye"}

    Raises
    ------
    ValueError
        Also for a (near) zero baseline (the same images twice) or swapped views
        (:func:`mrstereo.camera.check_not_swapped`).
    """
    spec = calibration_model(model)
    left_views, right_views = list(left_views), list(right_views)
    _check_view_pairs(left_views, right_views)
    width = _checks.positive_int("width", width)
    height = _checks.positive_int("height", height)
    right_views = [agree_with_left(a, b) for a, b in zip(left_views, right_views)]
    kw = dict(width=width, height=height, method=method, ga_config=ga_config, bounds=bounds,
              pixel_density_px_per_mm=pixel_density_px_per_mm, rng=_checks.rng(rng), progress=progress,
              model=spec.name)
    _check_swapped_early(left_views, right_views, width=width, height=height)
    left = calibrate_camera(left_views, **kw)
    right = calibrate_camera(right_views, **kw)
    R, T = _relative_pose(left.poses, right.poses)
    _check_baseline(T, left.poses)
    check_not_swapped(R, T, where="stereo-calibrate")
    cam_l, cam_r, poses_l = left.camera, right.camera, list(left.poses)
    success = left.success and right.success
    message = f"left: {left.message} | right: {right.message}"
    sigmas: dict = {}
    if method != "ga":
        cam_l, cam_r, poses_l, R, T, sigmas, ok, note = _refine_jointly(
            _JointFit(spec, tuple(left_views), tuple(right_views)), cam_l, cam_r, poses_l, R, T,
            width=width, height=height)
        success, message = success and ok, message + note
    check_not_swapped(R, T, where="stereo-calibrate")
    poses_r = [T_from_R_t(R, T) @ P for P in poses_l]
    res_l = reprojection_residuals(left_views, cam_l, poses_l)
    res_r = reprojection_residuals(right_views, cam_r, poses_r)
    rms = _rms(res_l + res_r)[0]
    per_view = np.stack([_rms(res_l)[1], _rms(res_r)[1]], axis=1)
    rect = rectify_fusiello(cam_l, cam_r, R, T, alpha=alpha)
    vert = rectified_vertical_error_px(rect.stereo, [v.uv for v in left_views], [v.uv for v in right_views])
    worst = per_view.max(axis=1)
    outliers = tuple(int(i) for i in np.flatnonzero(worst > 3.0 * np.median(worst))) if len(left_views) > 2 else ()
    return StereoCalibrationResult(
        stereo=rect.stereo, R=R, T=np.asarray(T, dtype=np.float64), left=left, right=right, rms_px=rms,
        per_view_rms_px=per_view, sigmas=sigmas, vertical_error_px=float(np.mean(vert)),
        per_view_vertical_error_px=vert, outlier_views=outliers, success=success and math.isfinite(rms),
        message=message, view_names=tuple(v.name for v in left_views), left_poses=tuple(poses_l))
