"""ROS camera_info YAML and the stereo calibration file every command reads.

A stereo file holds ``left:`` and ``right:`` with the ROS camera_info fields (camera_calibration_parsers
layout) and an optional camera mount (:mod:`mrstereo.camera.mount`); fields and signs:
docs/conventions.md (Stereo and disparity). Other tools' files are read by
:mod:`mrstereo.camera.formats`. Every calibration read from a file is checked for what would
otherwise fail silently later (a non-rotation ``R``, implausible baseline or projections, rectified
views that do not overlap; bounds in docs/calibration-formats.md).
"""
from __future__ import annotations

import os
import threading
from dataclasses import dataclass, field

import cv2
import numpy as np
import yaml

from .. import _checks
from ..io import atomic_write, read_yaml
from .model import Camera, get_distortion_model
from .mount import CameraMount, mount_entry, read_mount_entry

__all__ = ["CameraInfo", "StereoCamera", "read_camera_info", "write_camera_info",
           "write_stereo", "camera_from_ros", "check_stereo", "overlap_share", "stereo_projections"]

#: Plausible baseline [m]: shorter is one viewpoint twice, longer is almost always millimetres read as metres.
BASELINE_RANGE_M = (1e-4, 20.0)
#: Plausible focal length [px] relative to the larger image side (a 170 deg fisheye to a 0.06 deg telescope).
FOCAL_RANGE_PER_SIDE = (0.01, 1000.0)
#: Largest image side [px] a calibration may describe.
MAX_IMAGE_SIDE_PX = 65535
#: Smallest share of the rectified image that both cameras must see.
MIN_OVERLAP = 0.05
#: Tolerance of ``R R^T = I`` and ``det R = 1``.
ROTATION_TOL = 1e-3

#: Spellings of other tools' files that the model registry does not list as aliases.
_FILE_SPELLINGS = {"radial-tangential": "radtan", "radial_tangential": "radtan", "kannala-brandt": "kannala_brandt"}


def numbers(value, *, where: str, field: str, sizes=None, shape=None) -> np.ndarray:
    """A numeric field of a calibration file as a float array, or a ``ValueError`` naming it.

    ``value`` may be a list, a nested list, an array or a ``{rows, cols, data}``
    mapping (ROS / OpenCV); ``sizes`` lists the accepted numbers of values,
    ``shape`` the shape to return.
    """
    if isinstance(value, dict):
        if "data" not in value:
            raise ValueError(f"{where}: field '{field}' has no 'data'")
        value = value["data"]
    flat = list(np.ravel(np.asarray(value, dtype=object))) if value is not None else []
    for item in flat:
        if isinstance(item, bool) or not isinstance(item, (int, float, np.integer, np.floating)):
            raise ValueError(f"{where}: field '{field}' is not numeric (found {item!r})")
    arr = np.asarray(flat, dtype=np.float64)
    expected = sizes if sizes is not None else ([int(np.prod(shape))] if shape is not None else None)
    if expected is not None and arr.size not in expected:
        want = " or ".join(str(n) for n in expected)
        raise ValueError(f"{where}: field '{field}' needs {want} values, got {arr.size}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{where}: field '{field}' contains NaN or inf")
    return arr.reshape(shape) if shape is not None else arr


def ros_model_name(name, *, where: str) -> str:
    """The ROS name of a distortion model given under any of its names (registry aliases, EuRoC, OpenLORIS)."""
    key = str(name).strip().lower()
    try:
        return get_distortion_model(_FILE_SPELLINGS.get(key, key)).name
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None


def camera_from_ros(width, height, K, distortion_model, D, *, where: str) -> Camera:
    """The one place a calibration file's camera becomes a :class:`Camera`.

    ``K`` (3, 3), ``distortion_model`` a ROS name (or an alias: radtan,
    fisheye, Kannala-Brandt, ...), ``D`` in ROS order.
    """
    for name, value in (("image_width", width), ("image_height", height)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise ValueError(f"{where}: field '{name}' must be an integer, got {value!r}")
        if not 1 <= value <= MAX_IMAGE_SIDE_PX:
            raise ValueError(f"{where}: field '{name}' must be within 1..{MAX_IMAGE_SIDE_PX}, got {value}")
    K = numbers(K, where=where, field="camera_matrix", shape=(3, 3))
    model = ros_model_name(distortion_model, where=where)
    D = numbers(D, where=where, field="distortion_coefficients")
    _check_pinhole(K, width, height, what=f"{where}: camera_matrix", names=("fx", "fy", "cx", "cy"))
    if np.any(np.abs(D) > 1e6):
        raise ValueError(f"{where}: field 'distortion_coefficients' has an implausible value "
                         f"{D[np.argmax(np.abs(D))]:g}")
    try:
        return Camera.from_ros(int(width), int(height), K, model, D)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None


def _check_pinhole(M: np.ndarray, width: int, height: int, *, what: str, names: tuple[str, ...]) -> None:
    """Plausible focal lengths and principal point of a camera or projection matrix ``M``
    (3x3 or 3x4) for a ``width`` x ``height`` image; ``names`` label fx, fy, cx, cy in messages."""
    side = max(width, height)
    lo, hi = FOCAL_RANGE_PER_SIDE[0] * side, FOCAL_RANGE_PER_SIDE[1] * side
    for name, value in ((names[0], M[0, 0]), (names[1], M[1, 1])):
        if not lo <= value <= hi:
            raise ValueError(f"{what} {name} = {value:g} px is implausible for a {width}x{height} image "
                             f"(expected {lo:g}..{hi:g} px)")
    for name, value, size in ((names[2], M[0, 2], width), (names[3], M[1, 2], height)):
        if abs(value - size / 2.0) > 10.0 * side:
            raise ValueError(f"{what} {name} = {value:g} px is far outside the {width}x{height} image")


def _given(value, default):
    """``value`` unless it is None or an empty list (arrays are never "or"-ed)."""
    return default if value is None or (isinstance(value, (list, tuple)) and not value) else value


def _rotation_error(R: np.ndarray) -> float:
    return max(float(np.abs(R @ R.T - np.eye(3)).max()), abs(float(np.linalg.det(R)) - 1.0))


@dataclass(frozen=True)
class CameraInfo:
    """One camera as ROS sensor_msgs/CameraInfo: raw intrinsics + rectification."""

    camera: Camera
    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    P: np.ndarray | None = None
    name: str = "camera"

    def __post_init__(self) -> None:
        _checks.instance("camera", self.camera, Camera)
        R = _checks.matrix("R", self.R, (3, 3))
        if _rotation_error(R) > ROTATION_TOL:
            raise ValueError(f"R must be a rotation (orthonormal, det +1), got det {np.linalg.det(R):.4g}")
        object.__setattr__(self, "R", R)
        P = np.hstack([self.camera.K, np.zeros((3, 1))]) if self.P is None else self.P
        object.__setattr__(self, "P", _checks.matrix("P", P, (3, 4)))

    def to_dict(self) -> dict:
        """ROS camera_info fields as plain Python types."""
        cam = self.camera
        return {
            "image_width": cam.width, "image_height": cam.height, "camera_name": self.name,
            "camera_matrix": {"rows": 3, "cols": 3, "data": [float(v) for v in cam.K.ravel()]},
            "distortion_model": cam.distortion_model,
            "distortion_coefficients": {"rows": 1, "cols": len(cam.coefficients),
                                        "data": [float(v) for v in cam.D]},
            "rectification_matrix": {"rows": 3, "cols": 3, "data": [float(v) for v in self.R.ravel()]},
            "projection_matrix": {"rows": 3, "cols": 4, "data": [float(v) for v in self.P.ravel()]},
        }

    @classmethod
    def from_dict(cls, data, *, where: str = "camera_info") -> CameraInfo:
        """Parse ROS camera_info fields; raises ``ValueError`` naming the field that is wrong."""
        if not isinstance(data, dict):
            raise ValueError(f"{where}: expected a mapping of camera_info fields")
        for key in ("image_width", "image_height", "camera_matrix"):
            if key not in data:
                raise ValueError(f"{where}: missing field '{key}'")
        camera = camera_from_ros(data["image_width"], data["image_height"], data["camera_matrix"],
                                 data.get("distortion_model") or "plumb_bob",
                                 _given(data.get("distortion_coefficients"), [0.0] * 5), where=where)
        R = np.eye(3)
        if data.get("rectification_matrix") is not None:
            R = numbers(data["rectification_matrix"], where=where, field="rectification_matrix", shape=(3, 3))
            if _rotation_error(R) > ROTATION_TOL:
                raise ValueError(f"{where}: field 'rectification_matrix' is not a rotation (orthonormal "
                                 f"with det +1; its det is {np.linalg.det(R):.4g})")
        P = data.get("projection_matrix")
        if P is not None:
            P = numbers(P, where=where, field="projection_matrix", shape=(3, 4))
        return cls(camera=camera, R=R, P=P, name=str(data.get("camera_name", "camera")))


def _maps_key(info: CameraInfo) -> tuple:
    """What the rectification maps of a camera depend on, hashable: model, size, K, D, R, P."""
    camera = info.camera
    arrays = (camera.K, camera.dist_coeffs, info.R, info.P)
    return (type(camera).__name__, bool(getattr(camera, "is_fisheye", False)), tuple(camera.size),
            *(np.asarray(a, dtype=np.float64).tobytes() for a in arrays))


_MAPS_CACHE: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
_MAPS_CACHE_SIZE = 16
_MAPS_LOCK = threading.Lock()


def _rectification_maps(info: CameraInfo) -> tuple[np.ndarray, np.ndarray]:
    """The ``cv2.remap`` maps of ``info``, built once per :func:`_maps_key` and process; read-only."""
    key = _maps_key(info)
    maps = _MAPS_CACHE.get(key)
    if maps is None:
        maps = info.camera.undistort_rectify_maps(R=info.R, P=info.P)
        for m in maps:
            m.setflags(write=False)
        with _MAPS_LOCK:
            _MAPS_CACHE[key] = maps
            while len(_MAPS_CACHE) > _MAPS_CACHE_SIZE:      # oldest first (dicts keep insertion order)
                del _MAPS_CACHE[next(iter(_MAPS_CACHE))]
    return maps


@dataclass(frozen=True)
class StereoCamera:
    """A calibrated stereo pair: the format every command reads."""

    left: CameraInfo
    right: CameraInfo
    mount: CameraMount | None = None

    def __post_init__(self) -> None:
        _checks.instance("left", self.left, CameraInfo)
        _checks.instance("right", self.right, CameraInfo)
        if self.left.camera.size != self.right.camera.size:
            raise ValueError("left and right cameras must have the same image size")
        if self.mount is not None and not isinstance(self.mount, CameraMount):
            raise TypeError(f"mount must be a CameraMount, got {type(self.mount).__name__}")
        _check_projections(self.left, self.right)

    @property
    def focal_px(self) -> float:
        """Rectified focal length (pixels)."""
        return float(self.left.P[0, 0])

    @property
    def cx_px(self) -> float:
        return float(self.left.P[0, 2])

    @property
    def cy_px(self) -> float:
        return float(self.left.P[1, 2])

    @property
    def baseline_m(self) -> float:
        """Baseline from the right projection matrix, ``-P[0,3] / fx``."""
        return float(-self.right.P[0, 3] / self.right.P[0, 0])

    @property
    def doffs_px(self) -> float:
        """Difference of the rectified principal points ``cx_right - cx_left``."""
        return float(self.right.P[0, 2] - self.left.P[0, 2])

    @property
    def size(self) -> tuple[int, int]:
        return self.left.camera.size

    @property
    def is_rectified(self) -> bool:
        """True when the raw images already are the rectified ones (identity maps)."""
        return all(np.allclose(info.R, np.eye(3)) and not info.camera.has_distortion
                   and np.allclose(info.P[:3, :3], info.camera.K) for info in (self.left, self.right))

    def rectification_maps(self) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """One ``cv2.remap`` map pair per camera: undistort and rectify in one step.

        Built once per calibration and process (:func:`_rectification_maps`, keyed on the
        numbers: copies of the calibration in other threads or pickled into workers share
        them); the arrays are read-only.
        """
        return tuple(_rectification_maps(info) for info in (self.left, self.right))

    def rectify(self, left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rectify a raw pair (bilinear, border replicated); uint8, uint16, float32 or float64 images."""
        _checks.image_dtype("left", left)
        _checks.image_dtype("right", right)
        _checks.same_shape("left", left, "right", right)
        if (left.shape[1], left.shape[0]) != self.size:
            raise ValueError(f"images are {left.shape[1]}x{left.shape[0]} but the calibration is "
                             f"{self.size[0]}x{self.size[1]}")
        (lx, ly), (rx, ry) = self.rectification_maps()
        return (cv2.remap(left, lx, ly, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE),
                cv2.remap(right, rx, ry, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE))

    def to_dict(self) -> dict:
        return {"left": self.left.to_dict(), "right": self.right.to_dict(), **mount_entry(self.mount)}

    @classmethod
    def from_dict(cls, data, *, where: str = "stereo calibration") -> StereoCamera:
        if not isinstance(data, dict) or "left" not in data or "right" not in data:
            raise ValueError(f"{where}: expected 'left:' and 'right:' camera_info sections")
        left = CameraInfo.from_dict(data["left"], where=f"{where}: left")
        right = CameraInfo.from_dict(data["right"], where=f"{where}: right")
        mount = read_mount_entry(data, where=where, R_rect_from_cam=left.R)
        try:
            stereo = cls(left=left, right=right, mount=mount)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{where}: {exc}") from None
        return check_stereo(stereo, where=where)

    @classmethod
    def ideal(cls, camera: Camera, baseline_m: float, *, mount: CameraMount | None = None) -> StereoCamera:
        """An already rectified pair of identical distortion-free cameras."""
        baseline_m = _checks.finite_number("baseline_m", baseline_m, positive=True)
        P_left, P_right = stereo_projections(camera.K, baseline_m)
        return cls(left=CameraInfo(camera, P=P_left, name="left"),
                   right=CameraInfo(camera, P=P_right, name="right"), mount=mount)


def stereo_projections(A, baseline_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Rectified projections of a pair with intrinsics ``A`` (3, 3): ``A [I | 0]`` and
    ``A [I | (-b, 0, 0)]`` (the right ``P[0, 3] = -fx * baseline_m``)."""
    P_left = np.hstack([A, np.zeros((3, 1))])
    P_right = P_left.copy()
    P_right[0, 3] = -A[0, 0] * baseline_m
    return P_left, P_right


def _check_projections(left: CameraInfo, right: CameraInfo) -> None:
    """Ranges of the rectified projections: a named ``ValueError`` for what later code cannot use."""
    width, height = left.camera.size
    for label, info in (("left", left), ("right", right)):
        P = info.P
        _check_pinhole(P, width, height, what=f"{label} projection_matrix",
                       names=("P[0,0] (fx)", "P[1,1] (fy)", "P[0,2] (cx)", "P[1,2] (cy)"))
        off = np.abs([P[0, 1], P[1, 0], P[2, 0], P[2, 1], P[2, 2] - 1.0])
        if np.any(off > 1e-6 * np.array([P[0, 0], P[1, 1], 1.0, 1.0, 1.0])):
            raise ValueError(f"{label} projection_matrix must be [fx 0 cx Tx; 0 fy cy Ty; 0 0 1 0] "
                             f"(rectified pinhole), got {np.round(P, 6).tolist()}")
    if np.any(np.abs(left.P[:, 3]) > 1e-9):
        raise ValueError(f"left projection_matrix P[:,3] must be 0 (the left camera is the reference), "
                         f"got {left.P[:, 3].tolist()}")
    tx, ty, tz = right.P[:, 3]
    if abs(tz) > 1e-9 or abs(ty) > 1e-6 * max(abs(tx), 1.0):
        raise ValueError(f"right projection_matrix P[1,3] = {ty:g}, P[2,3] = {tz:g}: only horizontal "
                         "stereo is supported (both must be 0)")
    if tx == 0:
        raise ValueError("right projection_matrix P[0,3] = 0: no baseline (P[0,3] = -fx * baseline_m; "
                         "a camera_info of a single camera carries no stereo extrinsics)")
    baseline_m = -tx / right.P[0, 0]
    if baseline_m < 0:
        raise ValueError(f"right projection_matrix P[0,3] = {tx:g} > 0 puts the right camera "
                         f"{-baseline_m:.4g} m to the left of the left one: the views look swapped, "
                         "exchange left and right (P[0,3] = -fx * baseline_m < 0)")
    if not BASELINE_RANGE_M[0] <= baseline_m <= BASELINE_RANGE_M[1]:
        raise ValueError(f"right projection_matrix P[0,3] = {tx:g} gives a baseline of {baseline_m:.4g} m, "
                         f"outside the plausible {BASELINE_RANGE_M[0]:g}..{BASELINE_RANGE_M[1]:g} m "
                         "(P[0,3] = -fx * baseline_m, in metres)")


def overlap_share(stereo: StereoCamera) -> float:
    """Share of the rectified image that both raw images really see (on a grid of 160 px at most).

    A rectified pixel counts for a camera when its rectification map lands in
    the raw image *and* the raw pixel's viewing ray maps back to it: far outside
    the field of view a distortion polynomial folds back, and the map then
    points into the image although the camera cannot see that direction.
    """
    width, height = stereo.size
    scale = min(1.0, 160 / max(width, height))
    size = (max(2, round(width * scale)), max(2, round(height * scale)))
    A_small = np.diag([scale, scale, 1.0])
    grid = np.stack(np.meshgrid(np.arange(size[0], dtype=float), np.arange(size[1], dtype=float)), -1)
    valid = np.ones((size[1], size[0]), bool)
    for info in (stereo.left, stereo.right):
        P_small = A_small @ info.P[:3, :3]
        map_x, map_y = info.camera.undistort_rectify_maps(R=info.R, P=P_small, size=size)
        seen = (map_x >= 0) & (map_x <= width - 1) & (map_y >= 0) & (map_y <= height - 1)
        if seen.any():
            uv = np.stack([map_x[seen], map_y[seen]], 1).astype(np.float64)
            with np.errstate(all="ignore"):
                h = info.camera.rays(uv) @ (P_small @ info.R).T
                back = h[:, :2] / h[:, 2:3]
                ok = (h[:, 2] > 0) & (np.abs(back - grid[seen]).max(axis=1) < 0.5)
            seen[seen] = ok
        valid &= seen
    return float(valid.mean())


def check_stereo(stereo: StereoCamera, *, where: str = "stereo calibration") -> StereoCamera:
    """Refuse a calibration whose two rectified views do not overlap; returns ``stereo``.

    Run on every calibration read from a file (the constructor already checks
    ``R`` and the projection ranges). An all-black rectified image or 0 %
    valid disparity is the silent symptom this prevents.
    """
    share = overlap_share(stereo)
    if share < MIN_OVERLAP:
        raise ValueError(f"{where}: the rectified views of the two cameras overlap on {100 * share:.1f} % "
                         f"of the image (at least {100 * MIN_OVERLAP:.0f} % needed): check "
                         "rectification_matrix and projection_matrix")
    return stereo


def _load_yaml(path: str | os.PathLike, what: str):
    return read_yaml(path, what)


def _dump_yaml(path: str | os.PathLike, data: dict) -> None:
    with atomic_write(path) as tmp:
        with open(tmp, "w") as fh:
            yaml.safe_dump(data, fh, sort_keys=False, default_flow_style=None)


def read_camera_info(path: str | os.PathLike) -> CameraInfo:
    """Read a ROS camera_info YAML file."""
    return CameraInfo.from_dict(_load_yaml(path, "camera_info file"), where=str(path))


def write_camera_info(path: str | os.PathLike, info: CameraInfo) -> None:
    """Write a ROS camera_info YAML file (atomically)."""
    _checks.instance("info", info, CameraInfo)
    _dump_yaml(path, info.to_dict())


def write_stereo(path: str | os.PathLike, stereo: StereoCamera) -> None:
    """Write the stereo calibration YAML (atomically)."""
    _checks.instance("stereo", stereo, StereoCamera)
    _dump_yaml(path, stereo.to_dict())
