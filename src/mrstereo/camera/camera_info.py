"""ROS camera_info YAML and the stereo calibration file every command reads.

A stereo file holds ``left:`` and ``right:``, each with the ROS camera_info
fields (camera_calibration_parsers layout), plus an optional
``rig: {height_m, tilt_rad}`` mount of the left camera above the floor.
``K``/``D`` describe the raw camera, ``R`` rotates the raw camera frame into the
rectified frame and ``P`` is the rectified projection; for the right camera
``P[0, 3] = -fx * baseline_m``. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import yaml

from .. import _checks
from ..io import atomic_write
from .model import Camera

__all__ = ["CameraInfo", "RigMount", "StereoCamera", "read_camera_info", "write_camera_info",
           "read_stereo", "write_stereo"]


@dataclass(frozen=True)
class CameraInfo:
    """One camera as ROS sensor_msgs/CameraInfo: raw intrinsics + rectification."""

    camera: Camera
    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    P: np.ndarray | None = None
    name: str = "camera"

    def __post_init__(self) -> None:
        object.__setattr__(self, "R", _checks.matrix("R", self.R, (3, 3)))
        P = np.hstack([self.camera.K, np.zeros((3, 1))]) if self.P is None else self.P
        object.__setattr__(self, "P", _checks.matrix("P", P, (3, 4)))

    def to_dict(self) -> dict:
        """ROS camera_info fields as plain Python types."""
        cam = self.camera
        return {
            "image_width": cam.width, "image_height": cam.height, "camera_name": self.name,
            "camera_matrix": {"rows": 3, "cols": 3, "data": [float(v) for v in cam.K.ravel()]},
            "distortion_model": "plumb_bob",
            "distortion_coefficients": {"rows": 1, "cols": 5, "data": [float(v) for v in cam.dist_coeffs]},
            "rectification_matrix": {"rows": 3, "cols": 3, "data": [float(v) for v in self.R.ravel()]},
            "projection_matrix": {"rows": 3, "cols": 4, "data": [float(v) for v in self.P.ravel()]},
        }

    @classmethod
    def from_dict(cls, data, *, where: str = "camera_info") -> CameraInfo:
        """Parse ROS camera_info fields; raises ``ValueError`` naming what is wrong."""
        if not isinstance(data, dict):
            raise ValueError(f"{where}: expected a mapping of camera_info fields")

        def mat(key, rows, cols, default=None):
            if key not in data:
                if default is not None:
                    return default
                raise ValueError(f"{where}: missing field '{key}'")
            entry = data[key]
            values = entry.get("data") if isinstance(entry, dict) else entry
            try:
                arr = np.asarray(values, dtype=np.float64)
            except (TypeError, ValueError):
                raise ValueError(f"{where}: field '{key}' is not numeric") from None
            if arr.size != rows * cols:
                raise ValueError(f"{where}: field '{key}' needs {rows * cols} values, got {arr.size}")
            if not np.isfinite(arr).all():
                raise ValueError(f"{where}: field '{key}' contains NaN or inf")
            return arr.reshape(rows, cols)

        for key in ("image_width", "image_height"):
            if not isinstance(data.get(key), int):
                raise ValueError(f"{where}: field '{key}' must be an integer")
        model = data.get("distortion_model", "plumb_bob")
        if model not in ("plumb_bob", "rational_polynomial"):
            raise ValueError(f"{where}: distortion_model '{model}' is not supported (plumb_bob)")
        K = mat("camera_matrix", 3, 3)
        D = np.ravel(data.get("distortion_coefficients", {}).get("data", [0.0] * 5)
                     if isinstance(data.get("distortion_coefficients"), dict)
                     else data.get("distortion_coefficients", [0.0] * 5)).astype(float)
        if not np.isfinite(D).all():
            raise ValueError(f"{where}: field 'distortion_coefficients' contains NaN or inf")
        D = np.concatenate([D, np.zeros(max(0, 5 - D.size))])
        if np.any(np.abs(D[2:]) > 0):
            raise ValueError(f"{where}: only radial k1, k2 are supported; p1, p2, k3 must be 0")
        try:
            camera = Camera(width=data["image_width"], height=data["image_height"], fx=K[0, 0],
                            fy=K[1, 1], cx=K[0, 2], cy=K[1, 2], k1=D[0], k2=D[1])
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{where}: {exc}") from None
        return cls(camera=camera, R=mat("rectification_matrix", 3, 3, np.eye(3)),
                   P=mat("projection_matrix", 3, 4, np.hstack([K, np.zeros((3, 1))])),
                   name=str(data.get("camera_name", "camera")))


@dataclass(frozen=True)
class RigMount:
    """Mount of the left camera on the robot: height above the floor and downward tilt.

    ``height_m`` is the optical centre above the floor; ``tilt_rad`` > 0 tilts
    the optical axis down toward the floor.
    """

    height_m: float
    tilt_rad: float = 0.0

    def __post_init__(self) -> None:
        _checks.finite_number("height_m", self.height_m, positive=True)
        _checks.finite_number("tilt_rad", self.tilt_rad)
        if abs(self.tilt_rad) >= math.pi / 2:
            raise ValueError(f"tilt_rad must be within (-pi/2, pi/2), got {self.tilt_rad}")


@dataclass(frozen=True)
class StereoCamera:
    """A calibrated stereo pair: the format every command reads."""

    left: CameraInfo
    right: CameraInfo
    rig: RigMount | None = None

    def __post_init__(self) -> None:
        if self.left.camera.size != self.right.camera.size:
            raise ValueError("left and right cameras must have the same image size")
        if self.baseline_m <= 0:
            raise ValueError("right projection_matrix must have P[0,3] = -fx * baseline_m < 0 "
                             f"(got P[0,3] = {self.right.P[0, 3]})")

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
    def rectified_camera(self) -> Camera:
        """The rectified left camera (no distortion)."""
        P = self.left.P
        return Camera(width=self.size[0], height=self.size[1], fx=P[0, 0], fy=P[1, 1], cx=P[0, 2], cy=P[1, 2])

    @property
    def is_rectified(self) -> bool:
        """True when the raw images already are the rectified ones (identity maps)."""
        return all(np.allclose(info.R, np.eye(3)) and info.camera.k1 == 0 and info.camera.k2 == 0
                   and np.allclose(info.P[:3, :3], info.camera.K) for info in (self.left, self.right))

    def rectification_maps(self) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """One ``cv2.remap`` map pair per camera: undistort and rectify in one step."""
        return tuple(info.camera.undistort_rectify_maps(R=info.R, P=info.P) for info in (self.left, self.right))

    def rectify(self, left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rectify a raw pair (bilinear, border replicated)."""
        _checks.image("left", left)
        _checks.image("right", right)
        _checks.same_shape("left", left, "right", right)
        if (left.shape[1], left.shape[0]) != self.size:
            raise ValueError(f"images are {left.shape[1]}x{left.shape[0]} but the calibration is "
                             f"{self.size[0]}x{self.size[1]}")
        (lx, ly), (rx, ry) = self.rectification_maps()
        return (cv2.remap(left, lx, ly, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE),
                cv2.remap(right, rx, ry, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE))

    def to_dict(self) -> dict:
        out = {"left": self.left.to_dict(), "right": self.right.to_dict()}
        if self.rig is not None:
            out["rig"] = {"height_m": float(self.rig.height_m), "tilt_rad": float(self.rig.tilt_rad)}
        return out

    @classmethod
    def from_dict(cls, data, *, where: str = "stereo calibration") -> StereoCamera:
        if not isinstance(data, dict) or "left" not in data or "right" not in data:
            raise ValueError(f"{where}: expected 'left:' and 'right:' camera_info sections")
        rig = None
        if data.get("rig") is not None:
            r = data["rig"]
            if not isinstance(r, dict) or "height_m" not in r:
                raise ValueError(f"{where}: 'rig' needs height_m (and optional tilt_rad)")
            try:
                rig = RigMount(height_m=r["height_m"], tilt_rad=r.get("tilt_rad", 0.0))
            except (TypeError, ValueError) as exc:
                raise ValueError(f"{where}: rig: {exc}") from None
        try:
            return cls(left=CameraInfo.from_dict(data["left"], where=f"{where}: left"),
                       right=CameraInfo.from_dict(data["right"], where=f"{where}: right"), rig=rig)
        except TypeError as exc:
            raise ValueError(f"{where}: {exc}") from None

    @classmethod
    def ideal(cls, camera: Camera, baseline_m: float, *, rig: RigMount | None = None) -> StereoCamera:
        """An already rectified pair of identical distortion-free cameras."""
        baseline_m = _checks.finite_number("baseline_m", baseline_m, positive=True)
        P_left = np.hstack([camera.K, np.zeros((3, 1))])
        P_right = P_left.copy()
        P_right[0, 3] = -camera.fx * baseline_m
        return cls(left=CameraInfo(camera, P=P_left, name="left"),
                   right=CameraInfo(camera, P=P_right, name="right"), rig=rig)


def _load_yaml(path: str | os.PathLike, what: str):
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{what} not found: {path}")
    try:
        with open(path) as fh:
            return yaml.safe_load(fh)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1})" if mark is not None else ""
        raise ValueError(f"{what} {path} is not valid YAML{where}") from None


def _dump_yaml(path: str | os.PathLike, data: dict) -> None:
    with atomic_write(path) as tmp:
        with open(tmp, "w") as fh:
            yaml.safe_dump(data, fh, sort_keys=False, default_flow_style=None)


def read_camera_info(path: str | os.PathLike) -> CameraInfo:
    """Read a ROS camera_info YAML file."""
    return CameraInfo.from_dict(_load_yaml(path, "camera_info file"), where=str(path))


def write_camera_info(path: str | os.PathLike, info: CameraInfo) -> None:
    """Write a ROS camera_info YAML file (atomically)."""
    _dump_yaml(path, info.to_dict())


def read_stereo(path: str | os.PathLike) -> StereoCamera:
    """Read the stereo calibration YAML (``left:``, ``right:``, optional ``rig:``)."""
    return StereoCamera.from_dict(_load_yaml(path, "stereo calibration"), where=str(path))


def write_stereo(path: str | os.PathLike, stereo: StereoCamera) -> None:
    """Write the stereo calibration YAML (atomically)."""
    _dump_yaml(path, stereo.to_dict())
