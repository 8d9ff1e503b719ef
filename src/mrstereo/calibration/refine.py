"""Levenberg-Marquardt refinement of camera parameters (beyond the paper).

Minimizes the GA's objective, eq. (6), locally (``scipy.optimize.least_squares``) over the
intrinsics, the free coefficients of the fitted model (:data:`CALIBRATION_MODELS`) and six pose
parameters per view, with central differences grouped by the block structure (about 24
residual evaluations whatever the number of views). Standard deviations: ``cov = s^2 (J^T
J)^-1``, ``s^2 = |r|^2 / (m - n)``. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from .. import _checks
from ..camera import Camera, get_distortion_model, project_points
from ..transforms import T_from_R_t, rotation_from_rpy, rpy_from_rotation
from .targets import CalibrationView

__all__ = ["CALIBRATION_MODELS", "CalibrationModel", "calibration_model", "LMFit",
           "refine_views", "project_views", "grouped_jacobian", "least_squares_fit", "pose_vector", "pose_matrix",
           "fit_statistics"]


@dataclass(frozen=True)
class CalibrationModel:
    """What a calibration fits: a ROS distortion model and how many of its leading coefficients.

    ``k1k2`` (the paper's eq. 3, the GA's model) is ``plumb_bob`` with the first
    two coefficients free and p1 = p2 = k3 = 0.
    """

    name: str
    distortion_model: str
    n_free: int

    @property
    def coefficient_names(self) -> tuple[str, ...]:
        return get_distortion_model(self.distortion_model).params_info[:self.n_free]

    def seed(self, camera: Camera) -> np.ndarray:
        """Free coefficients to start from: the camera's where the models agree, else zero.

        A pinhole model seeds a pinhole one (k1, k2, p1, p2, k3 share their
        order); a fisheye starts without distortion.
        """
        x = np.zeros(self.n_free)
        if camera.is_fisheye == get_distortion_model(self.distortion_model).is_fisheye:
            n = min(self.n_free, camera.D.size)
            x[:n] = camera.D[:n]
        return x

    def full_coefficients(self, free) -> np.ndarray:
        """Free coefficients zero-padded to the model's coefficient vector."""
        size = get_distortion_model(self.distortion_model).sizes[0]
        return np.concatenate([np.asarray(free, dtype=np.float64), np.zeros(size - self.n_free)])

    def camera(self, width: int, height: int, fx, fy, cx, cy, free) -> Camera:
        """The :class:`Camera` of an intrinsic parameter vector."""
        return Camera(width=width, height=height, fx=float(fx), fy=float(fy), cx=float(cx), cy=float(cy),
                      distortion_model=self.distortion_model,
                      coefficients=tuple(float(v) for v in self.full_coefficients(free)))


CALIBRATION_MODELS = {
    "k1k2": CalibrationModel("k1k2", "plumb_bob", 2),
    "plumb_bob": CalibrationModel("plumb_bob", "plumb_bob", 5),
    "rational": CalibrationModel("rational", "rational_polynomial", 8),
    "fisheye": CalibrationModel("fisheye", "equidistant", 4),
}


def calibration_model(name) -> CalibrationModel:
    """The :class:`CalibrationModel` of ``k1k2``, ``plumb_bob``, ``rational`` or ``fisheye``."""
    if isinstance(name, CalibrationModel):
        return name
    if name not in CALIBRATION_MODELS:
        raise ValueError(f"model must be one of {', '.join(CALIBRATION_MODELS)}, got {name!r}")
    return CALIBRATION_MODELS[name]


def least_squares_fit(residuals: Callable[[np.ndarray], np.ndarray], x0: np.ndarray,
                      jac: Callable[[np.ndarray], object], n_residuals: int):
    """``scipy.optimize.least_squares`` of the calibrations: MINPACK's Levenberg-Marquardt on the dense
    Jacobian; past 2 million Jacobian entries (e.g. 54 views of 450 corners: 48,600 x 330, whose dense QR
    takes seconds per iteration) a trust region scaled like LM's on the sparse Jacobian, its steps solved by
    LSMR to 1e-12 (it lands where LM lands, to 1e-8 px on that capture, in half the time)."""
    from scipy.optimize import least_squares  # lazy: slow to import, most commands never calibrate

    if n_residuals * x0.size <= 2_000_000:
        return least_squares(residuals, x0, jac=lambda x: jac(x).toarray(), method="lm", max_nfev=200)
    return least_squares(residuals, x0, jac=jac, method="trf", tr_solver="lsmr", x_scale="jac",
                         tr_options=dict(atol=1e-12, btol=1e-12), max_nfev=200)


def pose_vector(T: np.ndarray) -> np.ndarray:
    """``(alpha, beta, gamma, tx, ty, tz)`` of a 4x4 ``T_cam_from_target``."""
    a, b, g = rpy_from_rotation(T[:3, :3])
    return np.array([a, b, g, *T[:3, 3]], dtype=np.float64)


def pose_matrix(x: np.ndarray) -> np.ndarray:
    """4x4 ``T_cam_from_target`` of a pose vector."""
    return T_from_R_t(rotation_from_rpy(x[0], x[1], x[2]), x[3:6])


def grouped_jacobian(fun: Callable[[np.ndarray], np.ndarray], x: np.ndarray, col_block: np.ndarray,
                     col_local: np.ndarray, row_block: np.ndarray):
    """Block-sparse Jacobian (``scipy.sparse`` CSR) by central differences, perturbing block-disjoint
    columns together.

    ``col_block[j]`` is -1 for a column that may touch every residual, or the
    block (view) that column ``j`` belongs to; ``col_local[j]`` its index within
    the block; ``row_block[i]`` the block of residual ``i``. Columns of different
    blocks with the same local index are perturbed in one evaluation; a block's
    column holds entries in its block's rows only.
    """
    from scipy import sparse  # lazy: slow to import, most commands never calibrate

    n, m = x.size, row_block.size
    h = 1e-6 * np.maximum(np.abs(x), 1e-2)
    groups: list[np.ndarray] = [np.array([j]) for j in range(n) if col_block[j] < 0]
    for k in np.unique(col_local[col_block >= 0]):
        groups.append(np.flatnonzero((col_block >= 0) & (col_local == k)))
    rows, cols, values = [], [], []
    column_of_block = np.full(max(int(row_block.max(initial=-1)), int(col_block.max(initial=-1))) + 1, -1)
    for group in groups:
        step = np.zeros(n)
        step[group] = h[group]
        diff = (fun(x + step) - fun(x - step))
        if len(group) == 1 and col_block[group[0]] < 0:
            column = np.full(m, group[0])
        else:
            column_of_block[:] = -1
            column_of_block[col_block[group]] = group
            column = column_of_block[row_block]         # the group's column in each residual's block, or -1
        touched = np.flatnonzero(column >= 0)
        rows.append(touched)
        cols.append(column[touched])
        values.append(diff[touched] / (2 * h[column[touched]]))
    return sparse.csr_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(cols))), shape=(m, n))


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
    JtJ = J.T @ J
    cov = s2 * np.linalg.pinv(JtJ.toarray() if hasattr(JtJ, "toarray") else JtJ)
    return np.sqrt(np.clip(np.diag(cov), 0.0, None))


def _intrinsics(x: np.ndarray, fix_aspect: float | None):
    """``fx, fy, cx, cy, free coefficients`` of the intrinsic block of ``x``."""
    if fix_aspect is None:
        return x[0], x[1], x[2], x[3], x[4:]
    return x[0], x[0] * fix_aspect, x[1], x[2], x[3:]


def project_views(views: Sequence[CalibrationView], R: np.ndarray, t: np.ndarray, *, fx, fy, cx, cy,
                  distortion_model: str, D) -> np.ndarray:
    """Reprojection residuals (projected - measured), flattened view by view, non-finite as 1e6.

    ``R`` (V, 3, 3) and ``t`` (V, 3) are ``T_cam_from_target`` per view. Views
    with equal point counts (a chessboard set) are projected in one broadcast
    call.
    """
    kw = dict(fx=fx, fy=fy, cx=cx, cy=cy, distortion_model=distortion_model, D=D)
    if len({len(v.uv) for v in views}) == 1:
        pts = np.stack([v.points_target for v in views])
        r = (project_points(pts, R=R, t=t, **kw) - np.stack([v.uv for v in views])).ravel()
    else:
        r = np.concatenate([(project_points(v.points_target, R=R[i], t=t[i], **kw) - v.uv).ravel()
                            for i, v in enumerate(views)])
    return np.where(np.isfinite(r), r, 1e6)


def refine_views(views: Sequence[CalibrationView], camera: Camera, poses: Sequence[np.ndarray], *,
                 fix_aspect: float | None = None, model="k1k2") -> LMFit:
    """Levenberg-Marquardt over shared intrinsics and one pose per view.

    Parameters
    ----------
    views : sequence of CalibrationView
    camera : Camera
        Initial intrinsics (image size is kept); its distortion seeds the
        model's coefficients where the models agree (:meth:`CalibrationModel.seed`).
    poses : sequence of ndarray (4, 4)
        Initial ``T_cam_from_target`` per view.
    fix_aspect : float, optional
        Estimate one focal length with ``fy = fix_aspect * fx`` (needed for a
        single planar view, where ``fx`` and ``fy`` are not separable).
    model : {"k1k2", "plumb_bob", "rational", "fisheye"} or CalibrationModel
        The distortion model fitted (:data:`CALIBRATION_MODELS`).
    """
    _checks.instance("camera", camera, Camera)
    _checks.instances("views", views, CalibrationView)
    spec = calibration_model(model)
    n_int = (4 if fix_aspect is None else 3) + spec.n_free
    lin = [camera.fx, camera.fy, camera.cx, camera.cy] if fix_aspect is None else [camera.fx, camera.cx, camera.cy]
    x0 = np.concatenate([lin, spec.seed(camera)] + [pose_vector(T) for T in poses])
    counts = [len(v.uv) for v in views]
    row_block = np.repeat(np.arange(len(views)), [2 * c for c in counts])
    col_block = np.concatenate([np.full(n_int, -1), np.repeat(np.arange(len(views)), 6)])
    col_local = np.concatenate([np.arange(n_int), np.tile(np.arange(6), len(views))])

    def residuals(x: np.ndarray) -> np.ndarray:
        fx, fy, cx, cy, free = _intrinsics(x[:n_int], fix_aspect)
        p = x[n_int:].reshape(-1, 6)
        return project_views(views, rotation_from_rpy(p[:, 0], p[:, 1], p[:, 2]), p[:, 3:6], fx=fx, fy=fy, cx=cx,
                             cy=cy, distortion_model=spec.distortion_model, D=spec.full_coefficients(free))

    def jac(x: np.ndarray) -> np.ndarray:
        return grouped_jacobian(residuals, x, col_block, col_local, row_block)

    sol = least_squares_fit(residuals, x0, jac, int(row_block.size))
    x = sol.x
    try:
        cam = spec.camera(camera.width, camera.height, *_intrinsics(x[:n_int], fix_aspect))
        ok = bool(sol.success)
        message = str(sol.message)
    except ValueError as exc:            # e.g. a negative focal length: keep the start, report
        x = x0
        cam = spec.camera(camera.width, camera.height, *_intrinsics(x[:n_int], fix_aspect))
        ok, message = False, f"LM left the valid region: {exc}"
    r = residuals(x)
    sig = fit_statistics(r, jac(x))
    names = (("fx", "fy", "cx", "cy") if fix_aspect is None else ("fx", "cx", "cy")) + spec.coefficient_names
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
