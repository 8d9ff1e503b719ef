"""The floor seen by the stereo head, from the disparity itself: V-disparity and 3D RANSAC.

Beyond the paper, which assumes a known mount. With eq. (14)-(16) a camera at height ``h``
tilted down by ``theta`` sees the floor as the line ``d(v) = a (v - cy) + c``, ``a = b f
cos(theta) / (h f_y)``, ``c = b f sin(theta) / h``, of the row-by-disparity histogram (the
"V-disparity" of Labayrade et al.), on which obstacles stand as vertical segments; hence
``tan(theta) = c / (a f_y)``, ``h = b f cos(theta) / (a f_y)``. A 3D plane fit also recovers the
roll: ``n = (sin(roll) cos(tilt), cos(roll) cos(tilt), sin(tilt))``. User guide:
docs/obstacles.md. Conventions: docs/conventions.md.

References
----------
R. Labayrade, D. Aubert, J.-P. Tarel, "Real time obstacle detection in
stereovision on non flat road geometry through V-disparity representation",
IEEE Intelligent Vehicle Symposium, 2002.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .. import _checks
from ..camera import CameraMount, StereoCamera
from ..transforms import T_from_R_t, T_robot_from_cam
from . import _kernels
from .triangulation import points_cam_from_disparity

__all__ = [
    "GroundPlane", "ground_from_mount", "MIN_FLOOR_SHARE", "MAX_FLOOR_RESIDUAL_M", "v_disparity",
    "fit_ground_v_disparity", "fit_ground_plane",
    "estimate_ground", "T_robot_from_cam_ground", "height_above_ground_m", "FLOOR_FIT_RANGE_M",
]

# Below / above these a floor fit is weak: a floor in view supports at least this share of the valid
# points within a few centimetres, a scene without one (a wall, a desk) a few percent (docs/obstacles.md,
# Floor confidence).
MIN_FLOOR_SHARE = 0.12
MAX_FLOOR_RESIDUAL_M = 0.03
# RANSAC of both fits: valid points used at most, the score's penalty per point beyond the floor
# (below a plane, farther than a line under its horizon); the plane fit's inlier distance and roll
_MAX_SAMPLES = 20000
_BELOW_PENALTY = 1.0
_PLANE_THRESHOLD_M = 0.03
_MAX_ROLL_RAD = 0.35


FLOOR_FIT_RANGE_M = 6.0
"""Default range of a floor-plane fit [m] (:func:`fit_ground_plane`); farther when a rig maps farther."""


@dataclass(frozen=True)
class GroundPlane:
    """The floor in the left camera frame: ``normal_cam . P = height_m``.

    ``height_m`` of the optical centre, downward ``tilt_rad``, ``roll_rad`` about the optical axis;
    ``success`` False (fields NaN) when no plausible floor was found, ``message`` why; ``method``
    ``"mount"``, ``"v_disparity"`` or ``"plane"``; ``n_inliers``; ``line_px`` the V-disparity line
    ``(a, c)``; the fit's confidence, ``inlier_share`` (0..1) and RMS ``residual_m`` (NaN for a
    mount); ``T_base_from_cam`` (row-major 4x4) when the floor comes from a mount, which then
    replaces height / tilt / roll in :func:`T_robot_from_cam_ground`.
    """

    height_m: float
    tilt_rad: float
    roll_rad: float = 0.0
    success: bool = True
    message: str = ""
    method: str = "mount"
    n_inliers: int = 0
    line_px: tuple[float, float] = field(default=(math.nan, math.nan))
    inlier_share: float = math.nan
    residual_m: float = math.nan
    T_base_from_cam: tuple[float, ...] | None = None

    @property
    def confident(self) -> bool:
        """A fit the floor can be trusted to: found, at least :data:`MIN_FLOOR_SHARE` of
        the points support it, and their RMS residual is at most :data:`MAX_FLOOR_RESIDUAL_M`.
        A given mount is always confident."""
        if not self.success:
            return False
        if self.method == "mount":
            return True
        return bool(self.inlier_share >= MIN_FLOOR_SHARE and self.residual_m <= MAX_FLOOR_RESIDUAL_M)

    @property
    def confidence_text(self) -> str:
        """``"inliers 34.1 %, residual 0.012 m"`` (or ``"given"`` for a mount)."""
        if self.method == "mount":
            return "given"
        return f"inliers {100 * self.inlier_share:.1f} %, residual {self.residual_m:.3f} m"

    def summary(self) -> dict:
        """JSON-ready description: method, height, tilt, roll, confidence."""
        def num(v):
            return None if not math.isfinite(v) else round(float(v), 6)
        return {"method": self.method, "success": bool(self.success), "height_m": num(self.height_m),
                "tilt_rad": num(self.tilt_rad), "roll_rad": num(self.roll_rad),
                "inlier_share": num(self.inlier_share), "residual_m": num(self.residual_m),
                "confident": self.confident, "message": self.message}

    @property
    def normal_cam(self) -> np.ndarray:
        """Unit downward floor normal in the camera frame."""
        t, r = self.tilt_rad, self.roll_rad
        return np.array([math.sin(r) * math.cos(t), math.cos(r) * math.cos(t), math.sin(t)])


def ground_from_mount(mount: CameraMount, *, R_rect_from_cam=None) -> GroundPlane:
    """The floor (base ``z = 0``) of a camera mount in the rectified left frame (``T_base_from_rect =
    T_base_from_cam @ R^T`` with the left camera_info ``R_rect_from_cam``, default identity); keeps
    the transform.
    """
    _checks.instance("mount", mount, CameraMount)
    T = mount.T_base_from_rectified(R_rect_from_cam)
    n = -T[2, :3]                       # the base's down axis in the camera frame
    return GroundPlane(height_m=float(T[2, 3]), tilt_rad=math.asin(float(np.clip(n[2], -1.0, 1.0))),
                       roll_rad=math.atan2(float(n[0]), float(n[1])), method="mount", message="mount given",
                       T_base_from_cam=tuple(float(v) for v in T.ravel()))


def _failed(method: str, message: str, n: int = 0) -> GroundPlane:
    return GroundPlane(height_m=math.nan, tilt_rad=math.nan, roll_rad=math.nan, success=False,
                       message=message, method=method, n_inliers=n)


def _rotation_roll_cam(roll_rad: float) -> np.ndarray:
    c, s = math.cos(roll_rad), math.sin(roll_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def T_robot_from_cam_ground(ground: GroundPlane, *, pan_rad: float = 0.0) -> np.ndarray:
    """4x4 robot-from-camera transform of a fitted floor (roll, then tilt and pan).

    ``T_robot_from_cam(height_m, tilt_rad, pan_rad) @ Rz_cam(roll_rad)``; the
    floor maps to the robot plane ``z = 0``.
    """
    _checks.instance("ground", ground, GroundPlane)
    if not ground.success:
        raise ValueError(f"ground plane was not found: {ground.message}")
    if ground.T_base_from_cam is not None:
        return CameraMount(np.reshape(ground.T_base_from_cam, (4, 4))).T_base_from_rectified(pan_rad=pan_rad)
    T = T_robot_from_cam(height_m=ground.height_m, tilt_rad=ground.tilt_rad, pan_rad=pan_rad)
    return T @ T_from_R_t(_rotation_roll_cam(ground.roll_rad), np.zeros(3))


def height_above_ground_m(points_cam, ground: GroundPlane) -> np.ndarray:
    """Height of camera-frame points (..., 3) above the floor: ``h - n . P``."""
    _checks.instance("ground", ground, GroundPlane)
    p = np.asarray(points_cam, dtype=np.float64)
    return ground.height_m - p @ ground.normal_cam


def v_disparity(disparity_px, *, max_disparity_px: float | None = None,
                bin_px: float = 1.0) -> np.ndarray:
    """Row-by-disparity histogram (Labayrade et al. 2002): ``hist[v, k]`` (H, n_bins) int32 counts the
    pixels of row ``v`` with disparity in ``[k bin_px, (k + 1) bin_px)``, up to ``max_disparity_px``
    (default: the largest valid disparity).
    """
    d = np.asarray(disparity_px, dtype=np.float64)
    if d.ndim != 2:
        raise ValueError(f"disparity_px must have shape (H, W), got {d.shape}")
    b = _checks.finite_number("bin_px", bin_px, positive=True)
    valid = np.isfinite(d) & (d >= 0)
    if max_disparity_px is None:
        max_d = float(d[valid].max()) if valid.any() else 0.0
    else:
        max_d = _checks.finite_number("max_disparity_px", max_disparity_px, positive=True)
    n_bins = int(math.floor(max_d / b)) + 1
    v, _ = np.nonzero(valid)
    k = np.floor(d[valid] / b).astype(np.int64)
    keep = k < n_bins
    hist = np.bincount(v[keep] * n_bins + k[keep], minlength=d.shape[0] * n_bins)
    return hist.reshape(d.shape[0], n_bins).astype(np.int32)


def _subsample(n: int, max_samples: int, rng: np.random.Generator) -> np.ndarray:
    return np.arange(n) if n <= max_samples else rng.choice(n, size=max_samples, replace=False)


def _line_scores(a, c, v, dd, tol: float, below_penalty: float) -> np.ndarray:
    """RANSAC score of each line ``d = a v + c``: pixels within ``tol``, minus ``below_penalty`` per pixel
    farther than the line under its horizon (impossible for a floor)."""
    scores = np.zeros(a.size, dtype=np.float64)
    for start in range(0, a.size, 32):        # blocks keep the (hypotheses x samples) array small
        line = a[start:start + 32, None] * v[None, :] + c[start:start + 32, None]
        res = dd[None, :] - line
        below = (res < -tol) & (line > 0)
        scores[start:start + 32] = (np.abs(res) <= tol).sum(axis=1) - below_penalty * below.sum(axis=1)
    return scores


def _refine_line(a: float, c: float, v, dd, tol: float, *, bf: float, fy: float, height_range_m,
                 tilt_range_rad) -> tuple[float, float]:
    """Least squares on the inliers of ``d = a v + c``, three times, keeping the last line whose height
    ``bf cos(tilt) / (a fy)`` and tilt ``atan2(c, a fy)`` are plausible."""
    (h_lo, h_hi), (t_lo, t_hi) = height_range_m, tilt_range_rad
    for _ in range(3):
        inl = np.abs(dd - (a * v + c)) <= tol
        if inl.sum() < 2:
            break
        a_new, c_new = np.polyfit(v[inl], dd[inl], 1)
        t_new = math.atan2(c_new, a_new * fy)
        h_new = bf * math.cos(t_new) / (a_new * fy) if a_new > 0 else math.inf
        if not (h_lo <= h_new <= h_hi and t_lo <= t_new <= t_hi):
            break
        a, c = a_new, c_new
    return a, c


def fit_ground_v_disparity(disparity_px, stereo: StereoCamera, *, tolerance_px: float = 1.0,
                           height_range_m: tuple[float, float] = (0.1, 2.0),
                           tilt_range_rad: tuple[float, float] = (-0.35, 1.2), iterations: int = 500,
                           min_inliers: int = 200, rng=0) -> GroundPlane:
    """Fit the floor line ``d = a (v - cy) + c`` of the V-disparity by RANSAC + least squares.

    RANSAC (Labayrade et al. use a Hough transform) draws pairs of at most ``_MAX_SAMPLES`` valid
    pixels, keeps lines with a positive slope and a plausible height and tilt, scores them by the
    pixels within ``tolerance_px`` minus those farther than the line under its horizon (every true
    surface stands on the floor, so a line through the end wall scores low) and refines the best.

    Parameters
    ----------
    disparity_px : ndarray of shape (H, W)
    stereo : StereoCamera
    tolerance_px : float
        Inlier band around the line (pixels of disparity).
    height_range_m, tilt_range_rad : (float, float)
        Plausible camera height above the floor and downward tilt.
    iterations : int
    min_inliers : int
        Fewer inliers is a failure (``success=False``).
    rng : numpy.random.Generator, int or None

    Returns
    -------
    GroundPlane
        ``method="v_disparity"``, roll 0, ``line_px=(a, c)``.
    """
    d = np.asarray(disparity_px, dtype=np.float64)
    if d.ndim != 2:
        raise ValueError(f"disparity_px must have shape (H, W), got {d.shape}")
    _checks.instance("stereo", stereo, StereoCamera)
    tol = _checks.finite_number("tolerance_px", tolerance_px, positive=True)
    iterations = _checks.positive_int("iterations", iterations)
    min_inliers = _checks.positive_int("min_inliers", min_inliers)
    rng = _checks.rng(rng)
    d = d + stereo.doffs_px
    valid = np.isfinite(d) & (d > 0)
    v_all, _ = np.nonzero(valid)
    if v_all.size < max(min_inliers, 2):
        return _failed("v_disparity", f"only {v_all.size} valid disparities", v_all.size)
    pick = _subsample(v_all.size, _MAX_SAMPLES, rng)
    v = v_all[pick].astype(np.float64) - stereo.cy_px
    dd = d[valid][pick]
    i = rng.integers(0, v.size, size=(iterations, 2))
    dv = v[i[:, 1]] - v[i[:, 0]]
    ok = np.abs(dv) >= 2.0
    a = np.where(ok, (dd[i[:, 1]] - dd[i[:, 0]]) / np.where(ok, dv, 1.0), np.nan)
    c = dd[i[:, 0]] - a * v[i[:, 0]]
    ok &= a > 0
    fx, fy = stereo.focal_px, float(stereo.left.P[1, 1])
    h_lo, h_hi = _checks.ordered_pair("height_range_m", height_range_m)
    t_lo, t_hi = _checks.ordered_pair("tilt_range_rad", tilt_range_rad)
    with np.errstate(invalid="ignore", divide="ignore"):
        tilt_h = np.arctan2(c, a * fy)
        height_h = stereo.baseline_m * fx * np.cos(tilt_h) / (a * fy)
    ok &= (height_h >= h_lo) & (height_h <= h_hi) & (tilt_h >= t_lo) & (tilt_h <= t_hi)
    if not ok.any():
        return _failed("v_disparity", "no line with a floor-like slope (positive, plausible height and tilt)", 0)
    a, c = a[ok], c[ok]
    best = int(np.argmax(_line_scores(a, c, v, dd, tol, _BELOW_PENALTY)))
    a_best, c_best = _refine_line(a[best], c[best], v, dd, tol, bf=stereo.baseline_m * fx, fy=fy,
                                  height_range_m=(h_lo, h_hi), tilt_range_rad=(t_lo, t_hi))
    inl = np.abs(dd - (a_best * v + c_best)) <= tol
    n_inl = int(round(inl.sum() * v_all.size / v.size))
    if n_inl < min_inliers or a_best <= 0:
        return _failed("v_disparity", f"floor line has only {n_inl} supporting pixels (< {min_inliers})", n_inl)
    tilt = math.atan2(c_best, a_best * fy)
    height = stereo.baseline_m * fx * math.cos(tilt) / (a_best * fy)
    z_inl = stereo.baseline_m * fx / dd[inl]                  # eq. (14)-(16) of the supporting pixels
    off = height - (math.cos(tilt) * v[inl] * z_inl / fy + math.sin(tilt) * z_inl)
    return GroundPlane(height_m=float(height), tilt_rad=float(tilt), roll_rad=0.0, success=True,
                       message=f"V-disparity line d = {a_best:.4f} (v - cy) + {c_best:.3f} from {n_inl} pixels",
                       method="v_disparity", n_inliers=n_inl, line_px=(float(a_best), float(c_best)),
                       inlier_share=float(inl.mean()), residual_m=float(np.sqrt(np.mean(off ** 2))))


def fit_ground_plane(points_cam, *, height_range_m: tuple[float, float] = (0.1, 2.0),
                     tilt_range_rad: tuple[float, float] = (-0.35, 1.2), max_range_m: float = FLOOR_FIT_RANGE_M,
                     iterations: int = 1500, min_inliers: int = 200, rng=0) -> GroundPlane:
    """Fit the floor plane to camera-frame points by RANSAC (3 points) + least squares.

    Only planes below the camera with a plausible height, tilt and roll (``_MAX_ROLL_RAD``) count (not walls or
    the ceiling); hypotheses are drawn among the points below the optical centre, scored on at most
    4000 points (inliers within ``_PLANE_THRESHOLD_M``) and the winner refined on all.

    Parameters
    ----------
    points_cam : ndarray of shape (N, 3) or (H, W, 3)
        Camera-frame points; NaN rows are ignored.
    height_range_m, tilt_range_rad : (float, float)
    max_range_m : float
        Farther points (depth) are not used: their triangulation error exceeds the threshold.
    iterations, min_inliers, rng
        As in :func:`fit_ground_v_disparity`.

    Returns
    -------
    GroundPlane
        ``method="plane"``.
    """
    p = np.asarray(points_cam, dtype=np.float64).reshape(-1, 3)
    thr, max_roll = _PLANE_THRESHOLD_M, _MAX_ROLL_RAD
    t_lo, t_hi = _checks.ordered_pair("tilt_range_rad", tilt_range_rad)
    max_range = _checks.finite_number("max_range_m", max_range_m, positive=True)
    iterations = _checks.positive_int("iterations", iterations)
    min_inliers = _checks.positive_int("min_inliers", min_inliers)
    rng = _checks.rng(rng)
    ahead = np.empty_like(p)
    p = ahead[:_kernels.points_ahead(p, max_range, ahead)]
    if p.shape[0] < max(min_inliers, 3):
        return _failed("plane", f"only {p.shape[0]} valid points", p.shape[0])
    n_all = p.shape[0]
    p = p[_subsample(n_all, _MAX_SAMPLES, rng)]
    below_centre = p[p[:, 1] > 0]
    pool = below_centre if below_centre.shape[0] >= max(min_inliers, 3) else p
    tri = pool[rng.integers(0, pool.shape[0], size=(iterations, 3))]
    score_pts = p[_subsample(p.shape[0], 4000, rng)]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(n, axis=1)
    ok = norm > 1e-9
    n = n[ok] / norm[ok, None]
    n *= np.where(n[:, 1] < 0, -1.0, 1.0)[:, None]          # downward normal: +y in the camera frame
    dist = np.einsum("ij,ij->i", n, tri[ok, 0])
    h_lo, h_hi = _checks.ordered_pair("height_range_m", height_range_m)
    tilt_h = np.arcsin(np.clip(n[:, 2], -1.0, 1.0))
    roll_h = np.arctan2(n[:, 0], n[:, 1])
    ok2 = (dist >= h_lo) & (dist <= h_hi) & (tilt_h >= t_lo) & (tilt_h <= t_hi) & (np.abs(roll_h) <= max_roll)
    if not ok2.any():
        return _failed("plane", "no plane below the camera with a floor-like normal", 0)
    n, dist = n[ok2], dist[ok2]
    scores = np.empty(n.shape[0], dtype=np.float64)
    _kernels.plane_scores(*np.ascontiguousarray(score_pts.T), np.ascontiguousarray(n), np.ascontiguousarray(dist),
                          thr, _BELOW_PENALTY, scores)
    best = int(np.argmax(scores))
    normal, h = n[best], dist[best]
    for _ in range(3):                                        # total least squares on the inliers
        inl = np.abs(p @ normal - h) <= thr
        if inl.sum() < 3:
            break
        centre = p[inl].mean(axis=0)
        _, _, vt = np.linalg.svd(p[inl] - centre, full_matrices=False)
        n_new = vt[-1] * (1.0 if vt[-1][1] >= 0 else -1.0)
        h_new = float(n_new @ centre)
        t_new, r_new = math.asin(float(np.clip(n_new[2], -1, 1))), math.atan2(float(n_new[0]), float(n_new[1]))
        if not (h_lo <= h_new <= h_hi and t_lo <= t_new <= t_hi and abs(r_new) <= max_roll):
            break                                             # keep the last plausible plane
        normal, h = n_new, h_new
    inl = np.abs(p @ normal - h) <= thr
    n_inl = int(round(inl.sum() * n_all / p.shape[0]))
    if n_inl < min_inliers or h <= 0:
        return _failed("plane", f"floor plane has only {n_inl} supporting points (< {min_inliers})", n_inl)
    tilt = math.asin(float(np.clip(normal[2], -1.0, 1.0)))
    roll = math.atan2(float(normal[0]), float(normal[1]))
    res = p[inl] @ normal - h
    return GroundPlane(height_m=float(h), tilt_rad=float(tilt), roll_rad=float(roll), success=True,
                       message=f"plane fit with {n_inl} supporting points", method="plane",
                       n_inliers=n_inl, inlier_share=float(inl.mean()),
                       residual_m=float(np.sqrt(np.mean(res ** 2))))


def estimate_ground(disparity_px, stereo: StereoCamera, *, method: str = "v_disparity",
                    prior: CameraMount | GroundPlane | None = None, prior_height_tolerance_m: float = 0.15,
                    prior_tilt_tolerance_rad: float = 0.1, rng=0, **options) -> GroundPlane:
    """Estimate the floor from a disparity map by ``"v_disparity"`` or ``"plane"`` (with roll).

    Parameters
    ----------
    disparity_px : ndarray of shape (H, W)
    stereo : StereoCamera
    method : {"v_disparity", "plane"}
    prior : CameraMount or GroundPlane, optional
        A roughly known mount (or its floor): only floors within the tolerances of its height and
        tilt are considered.
    prior_height_tolerance_m, prior_tilt_tolerance_rad : float
    rng : numpy.random.Generator, int or None
    **options
        Passed to :func:`fit_ground_v_disparity` or :func:`fit_ground_plane`.
    """
    _checks.instance("stereo", stereo, StereoCamera)
    if prior is not None:
        if isinstance(prior, CameraMount):
            prior = ground_from_mount(prior, R_rect_from_cam=stereo.left.R)
        if not isinstance(prior, GroundPlane):
            raise TypeError(f"prior must be a CameraMount or a GroundPlane, got {type(prior).__name__}")
        if not prior.success:
            raise ValueError(f"prior must be a found floor, got one that failed: {prior.message}")
        dh = _checks.finite_number("prior_height_tolerance_m", prior_height_tolerance_m, positive=True)
        dt = _checks.finite_number("prior_tilt_tolerance_rad", prior_tilt_tolerance_rad, positive=True)
        options["height_range_m"] = (max(prior.height_m - dh, 1e-3), prior.height_m + dh)
        options["tilt_range_rad"] = (prior.tilt_rad - dt, prior.tilt_rad + dt)
    if method == "v_disparity":
        return fit_ground_v_disparity(disparity_px, stereo, rng=rng, **options)
    if method == "plane":
        pts = points_cam_from_disparity(disparity_px, focal_px=stereo.focal_px, baseline_m=stereo.baseline_m,
                                        cx_px=stereo.cx_px, cy_px=stereo.cy_px,
                                        fy_px=float(stereo.left.P[1, 1]), doffs_px=stereo.doffs_px)
        return fit_ground_plane(pts, rng=rng, **options)
    raise ValueError(f"method must be 'v_disparity' or 'plane', got {method!r}")
