"""Camera models: pinhole with lens distortion, paper eq. (1)-(3), and the ROS/OpenCV models.

:class:`Camera` is the OpenCV/ROS parameterization (pixels, distortion on normalized
coordinates), :class:`PaperCamera` the paper's (focal length in mm, pixel densities in px/mm);
they convert exactly. Each distortion model is one small unit (:class:`DistortionModel`: names,
coefficients, ``distort`` and its inverse, OpenCV's map primitive) that only :class:`Camera`
calls. The functions broadcast over leading batch dimensions (a GA population); points are
``(..., N, 3)`` or ``(..., N, 2)``. Models, formulas and frames: docs/conventions.md.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .. import _checks

__all__ = [
    "Camera", "PaperCamera",
    "distort_normalized", "undistort_normalized", "project_points",
    "pixels_from_normalized", "normalized_from_pixels",
    "DistortionModel", "DISTORTION_MODELS", "get_distortion_model",
]


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


def _pairs(a, b) -> np.ndarray:
    """``(a, b)`` broadcast and stacked as (..., 1, 2), to scale (..., N, 2) coordinates."""
    return np.stack(np.broadcast_arrays(np.asarray(a, float), np.asarray(b, float)), -1)[..., None, :]


def pixels_from_normalized(xy_n, fx, fy, cx, cy) -> np.ndarray:
    """Eq. (2): ``u = fx x + cx``, ``v = fy y + cy`` on (..., N, 2)."""
    return np.asarray(xy_n, dtype=np.float64) * _pairs(fx, fy) + _pairs(cx, cy)


def normalized_from_pixels(uv, fx, fy, cx, cy) -> np.ndarray:
    """Inverse of :func:`pixels_from_normalized`."""
    return (np.asarray(uv, dtype=np.float64) - _pairs(cx, cy)) / _pairs(fx, fy)


# -- distortion models ------------------------------------------------------------------------------


class DistortionModel:
    """One lens distortion model on normalized image coordinates (COLMAP-style unit).

    ``name`` the ROS ``distortion_model``, ``aliases`` (Kalibr, OpenCV, short CLI names),
    ``params_info`` the coefficient names in ROS/OpenCV order, ``sizes`` the accepted numbers of
    coefficients (shorter vectors are zero-padded to the first), ``is_fisheye`` for ``cv2.fisheye``.
    """

    name = ""
    aliases: tuple = ()
    params_info: tuple = ()
    sizes: tuple = ()
    is_fisheye = False

    def coefficients(self, D, *, where: str = "D") -> tuple[float, ...]:
        """Validated, zero-padded coefficients in ROS order; ``ValueError`` naming ``where``."""
        try:
            d = np.asarray(D, dtype=np.float64).ravel()
        except (TypeError, ValueError):
            raise ValueError(f"{where}: distortion coefficients must be numbers, got {D!r}") from None
        if not np.isfinite(d).all():
            raise ValueError(f"{where}: distortion coefficients contain NaN or inf")
        fits = [n for n in self.sizes if n == d.size or (n == self.sizes[0] and d.size < n)]
        if not fits:
            if self.name == "plumb_bob" and d.size in (8, 12, 14):
                raise ValueError(f"{where}: plumb_bob takes at most 5 coefficients, got {d.size}; "
                                 "use distortion_model 'rational_polynomial' for 8, 12 or 14")
            raise ValueError(f"{where}: distortion_model '{self.name}' takes "
                             f"{' or '.join(str(n) for n in self.sizes)} coefficients "
                             f"({', '.join(self.params_info[:self.sizes[0]])}), got {d.size}")
        return tuple(float(v) for v in np.concatenate([d, np.zeros(fits[0] - d.size)]))

    def distort(self, xy, D) -> np.ndarray:
        """Distorted normalized coordinates (..., N, 2) of undistorted ones; ``D`` is (..., n)."""
        raise NotImplementedError

    def undistort(self, xy_d, D, *, iterations: int = 40) -> np.ndarray:
        """Invert :meth:`distort` by Newton's method (2x2 Jacobian by central differences).

        Starts at the distorted point; points where it does not converge (beyond
        the fold of a strongly distorting lens) are NaN.
        """
        xy_d = np.asarray(xy_d, dtype=np.float64)
        x = xy_d.copy()
        h = 1e-7
        ex, ey = np.array([h, 0.0]), np.array([0.0, h])
        with np.errstate(all="ignore"):
            for _ in range(iterations):
                f = self.distort(x, D) - xy_d
                jx = (self.distort(x + ex, D) - self.distort(x - ex, D)) / (2 * h)   # d(distorted)/dx
                jy = (self.distort(x + ey, D) - self.distort(x - ey, D)) / (2 * h)
                det = jx[..., 0] * jy[..., 1] - jy[..., 0] * jx[..., 1]
                dx = (jy[..., 1] * f[..., 0] - jy[..., 0] * f[..., 1]) / det
                dy = (jx[..., 0] * f[..., 1] - jx[..., 1] * f[..., 0]) / det
                x = x - np.stack([dx, dy], -1)
                if np.nanmax(np.abs(f), initial=0.0) < 1e-15:
                    break
            err = np.abs(self.distort(x, D) - xy_d).max(axis=-1)
        return np.where((err < 1e-9)[..., None], x, np.nan)

    def undistort_rectify_maps(self, K, D, R, P, size) -> tuple[np.ndarray, np.ndarray]:
        """``cv2.remap`` maps through OpenCV's primitive for this model."""
        return cv2.initUndistortRectifyMap(K, np.asarray(D, np.float64), R, P, size, cv2.CV_32FC1)

    def __repr__(self) -> str:
        return f"<distortion model {self.name}>"


def _tilt_matrix(tau_x, tau_y) -> np.ndarray:
    """OpenCV's ``computeTiltProjectionMatrix`` (Scheimpflug tilt), broadcast: (..., 3, 3)."""
    cx, sx, cy, sy = np.cos(tau_x), np.sin(tau_x), np.cos(tau_y), np.sin(tau_y)
    z, o = np.zeros_like(cx), np.ones_like(cx)
    rot_x = np.stack([np.stack([o, z, z], -1), np.stack([z, cx, sx], -1), np.stack([z, -sx, cx], -1)], -2)
    rot_y = np.stack([np.stack([cy, z, -sy], -1), np.stack([z, o, z], -1), np.stack([sy, z, cy], -1)], -2)
    rxy = rot_y @ rot_x
    proj_z = np.stack([np.stack([rxy[..., 2, 2], z, -rxy[..., 0, 2]], -1),
                       np.stack([z, rxy[..., 2, 2], -rxy[..., 1, 2]], -1), np.stack([z, z, o], -1)], -2)
    return proj_z @ rxy


class _OpenCVPinhole(DistortionModel):
    """OpenCV's pinhole distortion (``cv2.projectPoints``), up to 14 coefficients.

    ``r2 = x^2 + y^2``,
    ``x' = x (1 + k1 r2 + k2 r2^2 + k3 r2^3) / (1 + k4 r2 + k5 r2^2 + k6 r2^3)
    + 2 p1 x y + p2 (r2 + 2 x^2) + s1 r2 + s2 r2^2``, and ``y'`` alike with
    ``p1 (r2 + 2 y^2) + 2 p2 x y + s3 r2 + s4 r2^2``; then the tilt (tauX, tauY).
    """

    params_info = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6", "s1", "s2", "s3", "s4", "tauX", "tauY")

    def distort(self, xy, D) -> np.ndarray:
        xy = np.asarray(xy, dtype=np.float64)
        D = np.asarray(D, dtype=np.float64)
        c = [D[..., i, None] if i < D.shape[-1] else None for i in range(14)]
        x, y = xy[..., 0], xy[..., 1]
        r2 = x * x + y * y
        r4 = r2 * r2
        radial = 1.0 + c[0] * r2 + c[1] * r4
        if c[4] is not None:
            radial = radial + c[4] * r4 * r2
        if c[5] is not None:
            radial = radial / (1.0 + c[5] * r2 + c[6] * r4 + c[7] * r4 * r2)
        xd = x * radial
        yd = y * radial
        if c[2] is not None:
            xd = xd + 2.0 * c[2] * x * y + c[3] * (r2 + 2.0 * x * x)
            yd = yd + c[2] * (r2 + 2.0 * y * y) + 2.0 * c[3] * x * y
        if c[8] is not None:
            xd = xd + c[8] * r2 + c[9] * r4
            yd = yd + c[10] * r2 + c[11] * r4
        if c[12] is not None:
            M = _tilt_matrix(D[..., 12], D[..., 13])[..., None, :, :]
            w = M[..., 2, 0] * xd + M[..., 2, 1] * yd + M[..., 2, 2]
            xd, yd = ((M[..., 0, 0] * xd + M[..., 0, 1] * yd + M[..., 0, 2]) / w,
                      (M[..., 1, 0] * xd + M[..., 1, 1] * yd + M[..., 1, 2]) / w)
        return np.stack([xd, yd], -1)


class PlumbBob(_OpenCVPinhole):
    """ROS ``plumb_bob`` (Brown-Conrady, OpenCV's 5 coefficients k1, k2, p1, p2, k3).

    The paper's model (eq. 3) is the special case p1 = p2 = k3 = 0.
    """

    name = "plumb_bob"
    aliases = ("radtan", "pinhole-radtan", "brown", "k1k2")
    sizes = (5,)

    def undistort(self, xy_d, D, *, iterations: int = 40) -> np.ndarray:
        D = np.asarray(D, dtype=np.float64)
        if D.ndim == 1 and not np.any(D[2:]):      # radial k1, k2 only: 1-D Newton on the radius
            return undistort_normalized(xy_d, D[0], D[1])
        return super().undistort(xy_d, D, iterations=iterations)


class RationalPolynomial(_OpenCVPinhole):
    """ROS ``rational_polynomial``: OpenCV's 8 coefficients, or 12 (+ thin prism s1..s4) or 14 (+ tilt)."""

    name = "rational_polynomial"
    aliases = ("rational",)
    sizes = (8, 12, 14)


class Equidistant(DistortionModel):
    """ROS ``equidistant``: OpenCV fisheye / Kannala-Brandt (``cv2.fisheye``).

    ``theta = atan(r)``, ``r = |(x, y)|``;
    ``theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)``;
    ``(x', y') = (theta_d / r) (x, y)``.
    """

    name = "equidistant"
    aliases = ("equi", "fisheye", "pinhole-equi", "kannala_brandt", "kb4")
    params_info = ("k1", "k2", "k3", "k4")
    sizes = (4,)
    is_fisheye = True

    @staticmethod
    def _theta_d(theta, D):
        t2 = theta * theta
        return theta * (1.0 + t2 * (D[..., 0, None] + t2 * (D[..., 1, None] + t2 * (D[..., 2, None]
                                                                                    + t2 * D[..., 3, None]))))

    def distort(self, xy, D) -> np.ndarray:
        xy = np.asarray(xy, dtype=np.float64)
        D = np.asarray(D, dtype=np.float64)
        r = np.hypot(xy[..., 0], xy[..., 1])
        theta_d = self._theta_d(np.arctan(r), D)
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = np.where(r > 1e-12, theta_d / r, 1.0)
        return xy * scale[..., None]

    def undistort(self, xy_d, D, *, iterations: int = 40) -> np.ndarray:
        """Newton on ``theta`` (1-D); NaN where no ``theta < pi/2`` maps to the point."""
        xy_d = np.asarray(xy_d, dtype=np.float64)
        D = np.asarray(D, dtype=np.float64)
        theta_d = np.hypot(xy_d[..., 0], xy_d[..., 1])
        theta = np.minimum(theta_d, 1.5)
        k = [D[..., i, None] for i in range(4)]
        with np.errstate(all="ignore"):
            for _ in range(iterations):
                t2 = theta * theta
                f = self._theta_d(theta, D) - theta_d
                df = 1.0 + t2 * (3 * k[0] + t2 * (5 * k[1] + t2 * (7 * k[2] + t2 * 9 * k[3])))
                step = f / df
                theta = theta - step
                if np.nanmax(np.abs(step), initial=0.0) < 1e-15:
                    break
            ok = (np.abs(self._theta_d(theta, D) - theta_d) < 1e-9) & (theta >= 0) & (theta < np.pi / 2)
            scale = np.where(theta_d > 1e-12, np.tan(theta) / theta_d, 1.0)
        return np.where(ok[..., None], xy_d * scale[..., None], np.nan)

    def undistort_rectify_maps(self, K, D, R, P, size) -> tuple[np.ndarray, np.ndarray]:
        return cv2.fisheye.initUndistortRectifyMap(K, np.asarray(D, np.float64).reshape(4, 1), R, P, size,
                                                   cv2.CV_32FC1)


DISTORTION_MODELS: dict[str, DistortionModel] = {
    m.name: m for m in (PlumbBob(), RationalPolynomial(), Equidistant())}
_BY_ALIAS = {alias: m for m in DISTORTION_MODELS.values() for alias in (m.name,) + m.aliases}


def get_distortion_model(name) -> DistortionModel:
    """The :class:`DistortionModel` of a ROS name (or alias); ``ValueError`` listing the supported ones."""
    if isinstance(name, DistortionModel):
        return name
    model = _BY_ALIAS.get(str(name).strip().lower())
    if model is None:
        raise ValueError(f"distortion_model {name!r} is not supported; supported: "
                         f"{', '.join(DISTORTION_MODELS)} (aliases: "
                         f"{', '.join(a for m in DISTORTION_MODELS.values() for a in m.aliases)})")
    return model


def project_points(points_world, *, fx, fy, cx, cy, k1=0.0, k2=0.0, R=None, t=None,
                   distortion_model=None, D=None) -> np.ndarray:
    """Project world points to distorted pixels, eq. (1)-(3).

    ``points_world`` (..., N, 3); ``R`` (..., 3, 3) and ``t`` (..., 3) map world
    to camera (``points_cam = R p + t``); identity/zero when omitted. Points
    behind the camera (Z <= 0) give NaN. The distortion is the paper's ``k1, k2``
    (eq. 3) unless ``distortion_model`` (a name of :data:`DISTORTION_MODELS`)
    and its coefficients ``D`` (..., n) are given.
    """
    p = np.asarray(points_world, dtype=np.float64)
    if R is not None:
        p = np.einsum("...ij,...nj->...ni", np.asarray(R, dtype=np.float64), p)
    if t is not None:
        p = p + np.asarray(t, dtype=np.float64)[..., None, :]
    z = p[..., 2:3]
    with np.errstate(divide="ignore", invalid="ignore"):
        xy = np.where(z > 0, p[..., :2] / z, np.nan)
    if distortion_model is None:
        xy_d = distort_normalized(xy, k1, k2)
    else:
        xy_d = get_distortion_model(distortion_model).distort(xy, D)
    return pixels_from_normalized(xy_d, fx, fy, cx, cy)


@dataclass(frozen=True)
class Camera:
    """Intrinsics in the OpenCV/ROS parameterization (pixels, distortion on normalized coordinates).

    ``Camera(width=, height=, fx=, fy=, cx=, cy=, k1=, k2=)`` is the paper's model (eq. 1-3, ROS
    ``plumb_bob`` with p1 = p2 = k3 = 0); any ROS model by :meth:`from_ros` or ``distortion_model=``
    (``plumb_bob``, ``rational_polynomial``, ``equidistant`` or an alias) with ``coefficients=`` (ROS
    order, zero-padded). ``k1, k2`` always equal ``D[0], D[1]`` (radial, eq. 3; for ``equidistant``
    the theta^3 and theta^5 terms).
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    k1: float | None = None
    k2: float | None = None
    distortion_model: str = "plumb_bob"
    coefficients: tuple = ()

    def __post_init__(self) -> None:
        _checks.positive_int("width", self.width)
        _checks.positive_int("height", self.height)
        for name in ("fx", "fy"):
            _checks.finite_number(name, getattr(self, name), positive=True)
        for name in ("cx", "cy"):
            _checks.finite_number(name, getattr(self, name))
        for name in ("k1", "k2"):
            if getattr(self, name) is not None:
                _checks.finite_number(name, getattr(self, name))
        model = get_distortion_model(self.distortion_model)
        object.__setattr__(self, "distortion_model", model.name)
        if self.coefficients is None or len(self.coefficients) == 0:
            k1 = 0.0 if self.k1 is None else float(self.k1)
            k2 = 0.0 if self.k2 is None else float(self.k2)
            coeffs = model.coefficients([k1, k2], where="coefficients")
        else:
            coeffs = model.coefficients(self.coefficients, where="coefficients")
            for i, name in enumerate(("k1", "k2")):
                given = getattr(self, name)
                if given is not None and float(given) != coeffs[i]:
                    raise ValueError(f"{name}={given} disagrees with coefficients[{i}]={coeffs[i]}; "
                                     "give one of them")
        object.__setattr__(self, "coefficients", coeffs)
        object.__setattr__(self, "k1", coeffs[0])
        object.__setattr__(self, "k2", coeffs[1])

    @classmethod
    def from_ros(cls, width: int, height: int, K, distortion_model: str = "plumb_bob", D=()) -> Camera:
        """A camera from ROS camera_info fields: ``K`` (3x3 or 9 values), model name and ``D``."""
        K = np.asarray(K, dtype=np.float64)
        if K.size != 9:
            raise ValueError(f"K must hold 9 values (3x3), got {K.size}")
        K = K.reshape(3, 3)
        if abs(K[0, 1]) > 1e-9 * abs(K[0, 0]):
            raise ValueError(f"K has a skew term K[0,1] = {K[0, 1]}; only zero skew is supported")
        if not np.allclose(K[2], [0.0, 0.0, 1.0]) or K[1, 0] != 0.0:
            raise ValueError(f"K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], got {K.tolist()}")
        return cls(width=width, height=height, fx=float(K[0, 0]), fy=float(K[1, 1]), cx=float(K[0, 2]),
                   cy=float(K[1, 2]), distortion_model=distortion_model, coefficients=tuple(np.ravel(D)))

    @property
    def distortion(self) -> DistortionModel:
        """The :class:`DistortionModel` unit of this camera."""
        return DISTORTION_MODELS[self.distortion_model]

    @property
    def is_fisheye(self) -> bool:
        """True for the ``equidistant`` (OpenCV fisheye) model."""
        return self.distortion.is_fisheye

    @property
    def D(self) -> np.ndarray:
        """Distortion coefficients in ROS order (what camera_info's ``D`` holds)."""
        return np.array(self.coefficients, dtype=np.float64)

    dist_coeffs = D
    """OpenCV's name of :attr:`D` (``cv2.*`` for pinhole models, ``cv2.fisheye.*`` for a fisheye)."""

    @property
    def has_distortion(self) -> bool:
        """False when every coefficient is zero (for ``equidistant`` the projection is still not pinhole)."""
        return bool(np.any(self.D != 0.0)) or self.is_fisheye

    @property
    def K(self) -> np.ndarray:
        """3x3 camera matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def size(self) -> tuple[int, int]:
        """``(width, height)`` as OpenCV expects it."""
        return (self.width, self.height)

    def project(self, points_cam) -> np.ndarray:
        """Distorted pixel coordinates (N, 2) of camera-frame points (N, 3); NaN for Z <= 0."""
        return project_points(_checks.points3("points_cam", points_cam), fx=self.fx, fy=self.fy,
                              cx=self.cx, cy=self.cy, distortion_model=self.distortion, D=self.D)

    def rays(self, uv) -> np.ndarray:
        """Undistorted viewing rays ``(x, y, 1)`` (N, 3) of distorted pixels (N, 2).

        NaN where no ray in front of the camera maps to the pixel (outside a
        fisheye's circle, beyond the fold of a strong barrel lens).
        """
        uv = np.asarray(uv, dtype=np.float64)
        if uv.ndim != 2 or uv.shape[1] != 2:
            raise ValueError(f"uv must have shape (N, 2), got {uv.shape}")
        xy = self.distortion.undistort(normalized_from_pixels(uv, self.fx, self.fy, self.cx, self.cy), self.D)
        return np.concatenate([xy, np.ones((len(xy), 1))], axis=1)

    def undistort_pixels(self, uv) -> np.ndarray:
        """Pixel positions (N, 2) the points would have through a pinhole with the same ``K``."""
        xy = self.rays(uv)[:, :2]
        return pixels_from_normalized(xy, self.fx, self.fy, self.cx, self.cy)

    def undistort_rectify_maps(self, *, R=None, P=None, size=None) -> tuple[np.ndarray, np.ndarray]:
        """``cv2.remap`` maps (float32 map_x, map_y) to a new pinhole view.

        ``R`` rotates the old camera frame into the new one, ``P`` (3x3 or 3x4)
        holds the new intrinsics (default: this camera's ``K`` without
        distortion). Computed by ``cv2.initUndistortRectifyMap`` or, for a
        fisheye, ``cv2.fisheye.initUndistortRectifyMap``.
        """
        R = np.eye(3) if R is None else _checks.matrix("R", R, (3, 3))
        P = self.K if P is None else np.asarray(P, dtype=np.float64)[:3, :3]
        size = self.size if size is None else tuple(int(s) for s in size)
        return self.distortion.undistort_rectify_maps(self.K, self.D, R, P, size)

    def to_paper(self, *, f_mm: float) -> PaperCamera:
        """Exact conversion to the paper's parameterization for a focal length in mm.

        Only for the paper's model (``plumb_bob`` with p1 = p2 = k3 = 0).
        """
        f_mm = _checks.finite_number("f_mm", f_mm, positive=True)
        if self.distortion_model != "plumb_bob" or np.any(self.D[2:]):
            raise ValueError(f"the paper's parameterization holds k1, k2 only; this camera is "
                             f"{self.distortion_model} with D = {list(self.coefficients)}")
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
