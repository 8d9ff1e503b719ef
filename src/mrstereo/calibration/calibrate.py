"""Calibrate one camera from control points: GA (paper sec. 2.2), GA + LM, or LM.

``"ga"`` is the paper's genetic algorithm alone (:mod:`mrstereo.calibration.ga`), ``"ga+lm"``
polishes its best chromosome by Levenberg-Marquardt, ``"lm"`` starts LM from Zhang's closed form
(planar views only). A ``model`` other than the paper's ``k1k2`` (what the GA searches) is fitted
by a further LM started from the ``k1k2`` fit. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import cv2
import numpy as np

from .. import _checks
from ..camera import Camera
from ..transforms import T_from_rvec_t
from .ga import MULTIVIEW_GA, GABounds, GAConfig, GAResult, ga_calibrate_intrinsics, ga_calibrate_single
from .refine import CALIBRATION_MODELS, calibration_model, refine_views
from .targets import CalibrationView

__all__ = ["METHODS", "MODELS", "CalibrationResult", "calibrate_camera", "zhang_init", "reprojection_residuals",
           "check_view_geometry"]

MODELS = tuple(CALIBRATION_MODELS)

METHODS = ("ga", "ga+lm", "lm")
OUTLIER_FACTOR = 3.0


@dataclass(frozen=True)
class CalibrationResult:
    """A calibrated camera and how well it fits.

    ``camera`` (OpenCV/ROS parameterization) and ``T_cam_from_target`` ``poses`` per view; ``rms_px``
    ``sqrt(sum |e|^2 / n_points)`` (as ``cv2.calibrateCamera``) and ``per_view_rms_px``; ``sigmas`` of
    the intrinsics, ``s^2 (J^T J)^-1`` (empty for ``method="ga"``); ``outlier_views`` with an RMS over
    3x the median; ``success``, ``message``, ``method``; ``ga_rms_px`` and ``lm_rms_px`` after each
    stage (NaN where it did not run); the fitted ``model``; ``generations`` and the GA's full result
    ``ga`` (or None); ``view_names``.
    """

    camera: Camera
    poses: tuple
    rms_px: float
    per_view_rms_px: np.ndarray
    sigmas: dict
    outlier_views: tuple
    success: bool
    message: str
    method: str
    ga_rms_px: float = math.nan
    lm_rms_px: float = math.nan
    generations: int = 0
    ga: GAResult | None = field(default=None, repr=False)
    view_names: tuple = ()
    model: str = "k1k2"

    def summary(self) -> dict:
        """Plain-Python summary for JSON reports."""
        c = self.camera
        names = c.distortion.params_info[:c.D.size]
        return {
            "method": self.method, "model": self.model, "success": self.success, "message": self.message,
            "image_size": [c.width, c.height],
            "camera": {**{k: float(getattr(c, k)) for k in ("fx", "fy", "cx", "cy")},
                       "distortion_model": c.distortion_model, "D": [float(v) for v in c.D],
                       **{k: float(v) for k, v in zip(names, c.D)}},
            "sigmas": {k: float(v) for k, v in self.sigmas.items()},
            "rms_px": float(self.rms_px), "ga_rms_px": _num(self.ga_rms_px), "lm_rms_px": _num(self.lm_rms_px),
            "generations": int(self.generations),
            "per_view_rms_px": {n: float(r) for n, r in zip(self.view_names, self.per_view_rms_px)},
            "outlier_views": [self.view_names[i] for i in self.outlier_views],
        }


def _num(v: float):
    return None if not math.isfinite(v) else float(v)


def _views_and_camera(views, camera) -> None:
    """Views must be CalibrationViews and the camera a Camera (before any field of theirs is read)."""
    _checks.instances("views", views, CalibrationView)
    if camera is not None:
        _checks.instance("camera", camera, Camera)


def reprojection_residuals(views: Sequence[CalibrationView], camera: Camera, poses) -> list[np.ndarray]:
    """Projected minus measured pixels (N, 2) per view."""
    _views_and_camera(views, camera)
    out = []
    for view, T in zip(views, poses):
        cam_pts = view.points_target @ T[:3, :3].T + T[:3, 3]
        out.append(camera.project(cam_pts) - view.uv)
    return out


def _rms(residuals: Sequence[np.ndarray]) -> tuple[float, np.ndarray]:
    per = np.array([math.sqrt(np.sum(r**2) / len(r)) if np.isfinite(r).all() else math.inf for r in residuals])
    total = sum(float(np.sum(r**2)) for r in residuals)
    n = sum(len(r) for r in residuals)
    return (math.sqrt(total / n) if math.isfinite(total) else math.inf), per


def check_view_geometry(view: CalibrationView) -> None:
    """Refuse control points that cannot determine a camera: collinear or coincident.

    The target points and their pixels must span a plane (second singular value of the centred
    points above 1e-6 of the first); such points would otherwise "fit" with an RMS of zero.
    """
    _checks.instance("view", view, CalibrationView)
    for what, pts in (("target points", view.points_target), ("pixels", view.uv)):
        centred = pts - pts.mean(axis=0)
        s = np.linalg.svd(centred, compute_uv=False)
        scale = float(np.abs(pts).max()) or 1.0
        if s[0] <= 1e-9 * scale:
            raise ValueError(f"view {view.name}: all {len(pts)} {what} coincide; calibration needs points "
                             "spread over a plane or in 3D")
        if s[1] <= 1e-6 * s[0]:
            raise ValueError(f"view {view.name}: the {len(pts)} {what} are collinear; calibration needs points "
                             "spread over a plane or in 3D")


def zhang_init(views: Sequence[CalibrationView], *, width: int, height: int,
               fix_aspect: float | None = None) -> tuple[Camera, list[np.ndarray]]:
    """Closed-form start: ``cv2.initCameraMatrix2D`` (Zhang) and ``cv2.solvePnP`` poses, no distortion."""
    if not all(v.is_planar for v in views):
        raise ValueError("method 'lm' needs planar targets (Z = 0); use 'ga+lm' for 3D control points")
    obj = [v.points_target.astype(np.float32) for v in views]
    img = [v.uv.astype(np.float32) for v in views]
    K = cv2.initCameraMatrix2D(obj, img, (width, height), 1.0 if fix_aspect is not None else 0.0)
    if not np.isfinite(K).all() or K[0, 0] <= 0 or K[1, 1] <= 0:
        K = np.array([[width, 0, (width - 1) / 2], [0, width, (height - 1) / 2], [0, 0, 1.0]])
    cam = Camera(width=width, height=height, fx=float(K[0, 0]), fy=float(K[1, 1]), cx=float(K[0, 2]),
                 cy=float(K[1, 2]))
    poses = []
    for o, i in zip(obj, img):
        _, rvec, tvec = cv2.solvePnP(o, i, cam.K, None, flags=cv2.SOLVEPNP_ITERATIVE)
        poses.append(T_from_rvec_t(rvec, tvec))
    return cam, poses


def calibrate_camera(views: Sequence[CalibrationView], *, width: int, height: int, method: str = "ga+lm",
                     model: str = "k1k2", ga_config: GAConfig | None = None, bounds: GABounds | None = None,
                     pixel_density_px_per_mm: float | None = None, rng=None, progress=None) -> CalibrationResult:
    """Calibrate one camera from one or more views of known control points.

    Parameters
    ----------
    views : sequence of CalibrationView (or one CalibrationView)
    width, height : int
        Image size in pixels.
    method : {"ga", "ga+lm", "lm"}
        GA, GA polished by LM, or LM from Zhang's closed form.
    model : {"k1k2", "plumb_bob", "rational", "fisheye"}
        Distortion model; anything but ``k1k2`` needs LM.
    ga_config, bounds, pixel_density_px_per_mm :
        GA settings (:class:`GAConfig`, :class:`GABounds`, pixel density of eq. 2).
    rng : numpy Generator, int or None
        Seed of the GA.
    progress : callable(generation, best_fitness), optional

    Returns
    -------
    CalibrationResult
        ``success`` False (with a ``message``) when the fit did not converge.
    """
    if isinstance(views, CalibrationView):
        views = [views]
    views = list(views)
    if not views:
        raise ValueError("views is empty: no control points to calibrate from")
    if not all(isinstance(v, CalibrationView) for v in views):
        raise TypeError("views must be CalibrationView instances")
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    spec = calibration_model(model)
    if spec.name != "k1k2" and method == "ga":
        raise ValueError(f"the GA fits the paper's k1k2 model only; model {spec.name!r} needs method 'ga+lm' "
                         "or 'lm'")
    for view in views:
        check_view_geometry(view)
    width = _checks.positive_int("width", width)
    height = _checks.positive_int("height", height)
    single = len(views) == 1
    fix_aspect = 1.0 if single else None
    ga_res, ga_rms, lm_rms = None, math.nan, math.nan
    sigmas: dict = {}
    success, message = True, "ok"
    if method in ("ga", "ga+lm"):
        if ga_config is None:
            ga_config = GAConfig() if single else MULTIVIEW_GA
        kw = dict(width=width, height=height, bounds=bounds, config=ga_config,
                  pixel_density_px_per_mm=pixel_density_px_per_mm, rng=rng, progress=progress)
        ga_res = ga_calibrate_single(views[0], **kw) if single else ga_calibrate_intrinsics(views, **kw)
        camera, poses = ga_res.camera, list(ga_res.poses)
        ga_rms = _rms(reprojection_residuals(views, camera, poses))[0]
        message = f"GA: {ga_res.stop_reason} after {ga_res.generations} generations"
    else:
        camera, poses = zhang_init(views, width=width, height=height, fix_aspect=fix_aspect)
    if method in ("ga+lm", "lm"):
        fit = refine_views(views, camera, poses, fix_aspect=fix_aspect)
        lm_rms = _rms(fit.residuals_px)[0]
        if fit.success and (not math.isfinite(ga_rms) or lm_rms <= ga_rms + 1e-9):
            camera, poses, sigmas = fit.camera, list(fit.poses), fit.sigmas
            message = (message + "; " if ga_res else "") + f"LM: {fit.message}"
        else:
            success = False
            message = (message + "; " if ga_res else "") + f"LM did not improve: {fit.message}"
    if spec.name != "k1k2" and success:
        fit = refine_views(views, camera, poses, fix_aspect=fix_aspect, model=spec)
        if fit.success or _rms(fit.residuals_px)[0] < _rms(reprojection_residuals(views, camera, poses))[0]:
            camera, poses, sigmas = fit.camera, list(fit.poses), fit.sigmas
            message += f"; LM {spec.name}: {fit.message}"
        else:
            success = False
            message += f"; LM {spec.name} failed: {fit.message}"
    rms, per_view = _rms(reprojection_residuals(views, camera, poses))
    if not math.isfinite(rms):
        success, message = False, message + "; non-finite reprojection error"
    median = float(np.median(per_view))
    outliers = tuple(int(i) for i in np.flatnonzero(per_view > OUTLIER_FACTOR * median)) if len(views) > 2 else ()
    return CalibrationResult(camera=camera, poses=tuple(poses), rms_px=rms, per_view_rms_px=per_view,
                             sigmas=sigmas, outlier_views=outliers, success=success, message=message,
                             method=method, ga_rms_px=ga_rms, lm_rms_px=lm_rms,
                             generations=0 if ga_res is None else ga_res.generations, ga=ga_res,
                             view_names=tuple(v.name for v in views), model=spec.name)
