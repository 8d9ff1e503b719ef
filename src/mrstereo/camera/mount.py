"""The camera mount: ``T_base_from_cam``, the pose of the raw left optical frame in the robot base frame.

Frames, the ``mount:`` entry and the paper's rig (height and tilt of the *rectified* camera):
docs/conventions.md (Frames).
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .. import _checks
from ..transforms import (R_BODY_FROM_OPTICAL, T_from_R_t, T_robot_from_cam, _rot_z, rotation_from_rpy,
                          rpy_from_rotation)

__all__ = ["CameraMount", "read_mount_entry", "mount_entry"]


class CameraMount:
    """Pose of the left camera's raw optical frame in the robot base frame: ``T_base_from_cam`` (4, 4).

    Built from a 4x4 matrix (e.g. a TF lookup), :meth:`from_xyz_rpy` (the camera body's pose)
    or :meth:`from_rig` (the paper's rig). Points are triangulated in the rectified left frame:
    :meth:`T_base_from_rectified` is the pose the mapping chain uses.
    """

    __slots__ = ("_T",)

    def __init__(self, T_base_from_cam) -> None:
        T = _checks.matrix("T_base_from_cam", T_base_from_cam, (4, 4)).astype(np.float64, copy=True)
        if not np.isfinite(T).all():
            raise ValueError("T_base_from_cam must be finite")
        R = T[:3, :3]
        if not (np.allclose(R @ R.T, np.eye(3), atol=1e-6) and np.linalg.det(R) > 0
                and np.allclose(T[3], [0.0, 0.0, 0.0, 1.0])):
            raise ValueError("T_base_from_cam must be a rigid transform (rotation with det +1, last row 0 0 0 1)")
        T.setflags(write=False)
        self._T = T

    @classmethod
    def from_xyz_rpy(cls, xyz: Sequence[float], rpy: Sequence[float]) -> CameraMount:
        """The mount of a camera body frame at ``xyz`` [m] turned by ``rpy`` [rad] (REP 103)."""
        try:
            xyz = np.asarray(xyz, dtype=np.float64).reshape(-1)
            rpy = np.asarray(rpy, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            raise ValueError(f"xyz and rpy must be 3 numbers each, got {xyz!r}, {rpy!r}") from None
        if xyz.size != 3 or rpy.size != 3 or not (np.isfinite(xyz).all() and np.isfinite(rpy).all()):
            raise ValueError(f"xyz and rpy must be 3 finite numbers each, got {xyz.tolist()}, {rpy.tolist()}")
        return cls(T_from_R_t(rotation_from_rpy(*rpy) @ R_BODY_FROM_OPTICAL, xyz))

    @classmethod
    def from_rectified(cls, T_base_from_rect, R_rect_from_cam=None) -> CameraMount:
        """The mount of a camera whose rectified frame (``p_rect = R p_raw``) has the pose ``T_base_from_rect``."""
        T = _checks.matrix("T_base_from_rect", T_base_from_rect, (4, 4)).astype(np.float64, copy=True)
        if R_rect_from_cam is not None:
            T[:3, :3] = T[:3, :3] @ _checks.matrix("R_rect_from_cam", R_rect_from_cam, (3, 3))
        return cls(T)

    @classmethod
    def from_rig(cls, height_m: float, tilt_rad: float = 0.0, *, R_rect_from_cam=None) -> CameraMount:
        """The paper's rig: the rectified left camera ``height_m`` above the floor on the base's z axis,
        looking along x, tilted down by ``tilt_rad``; ``R_rect_from_cam`` is the calibration's left ``R``."""
        h = _checks.finite_number("height_m", height_m, positive=True)
        tilt = _checks.finite_number("tilt_rad", tilt_rad)
        if abs(tilt) >= math.pi / 2:
            raise ValueError(f"tilt_rad must be within (-pi/2, pi/2), got {tilt}")
        return cls.from_rectified(T_robot_from_cam(height_m=h, tilt_rad=tilt), R_rect_from_cam)

    @property
    def T_base_from_cam(self) -> np.ndarray:
        """4x4 transform taking raw left optical-frame points into the base frame (read-only)."""
        return self._T

    @property
    def xyz(self) -> tuple[float, float, float]:
        """Optical centre in the base frame [m]."""
        return tuple(float(v) for v in self._T[:3, 3])

    @property
    def rpy(self) -> tuple[float, float, float]:
        """Roll, pitch, yaw [rad] of the camera body frame (inverse of :meth:`from_xyz_rpy`)."""
        return tuple(float(v) for v in rpy_from_rotation(self._T[:3, :3] @ R_BODY_FROM_OPTICAL.T))

    def T_base_from_rectified(self, R_rect_from_cam=None, pan_rad: float = 0.0) -> np.ndarray:
        """The rectified left camera's pose with the head's pan: ``Rz(pan) @ T_base_from_cam @ R^T``.

        ``R_rect_from_cam`` is the calibration's left ``R`` (``p_rect = R p_raw``; None: the raw frame).
        """
        pan = _checks.finite_number("pan_rad", pan_rad)
        T = self._T.copy()
        if R_rect_from_cam is not None:
            R = _checks.matrix("R_rect_from_cam", R_rect_from_cam, (3, 3))
            if not np.array_equal(R, np.eye(3)):
                T[:3, :3] = T[:3, :3] @ R.T
        return T if pan == 0.0 else T_from_R_t(_rot_z(pan), np.zeros(3)) @ T

    def to_dict(self) -> dict:
        """``{"xyz": [...], "rpy": [...]}`` (the ``mount:`` entry of a stereo YAML or manifest)."""
        return {"xyz": [float(v) for v in self.xyz], "rpy": [float(v) for v in self.rpy]}

    @classmethod
    def from_dict(cls, data, *, where: str = "mount") -> CameraMount:
        """Read a ``mount: {xyz: [x, y, z], rpy: [roll, pitch, yaw]}`` entry (metres, radians)."""
        if not isinstance(data, dict) or set(data) - {"xyz", "rpy"} or "xyz" not in data:
            raise ValueError(f"{where}: expected {{xyz: [x, y, z], rpy: [roll, pitch, yaw]}} "
                             f"(metres, radians), got {data!r}")
        values = []
        for key in ("xyz", "rpy"):
            v = data.get(key, [0.0, 0.0, 0.0])
            if (not isinstance(v, (list, tuple)) or len(v) != 3
                    or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
                               for x in v)):
                raise ValueError(f"{where}: {key} must be 3 finite numbers, got {v!r}")
            values.append([float(x) for x in v])
        return cls.from_xyz_rpy(*values)

    def __eq__(self, other) -> bool:
        return isinstance(other, CameraMount) and bool(np.array_equal(self._T, other._T))

    def __hash__(self) -> int:
        return hash(self._T.tobytes())

    def __reduce__(self):
        return (CameraMount, (np.array(self._T),))

    def __repr__(self) -> str:
        x, y, z = self.xyz
        r, p, w = self.rpy
        return f"CameraMount(xyz=({x:.3f}, {y:.3f}, {z:.3f}) m, rpy=({r:.4f}, {p:.4f}, {w:.4f}) rad)"


def read_mount_entry(data: dict, *, where: str, R_rect_from_cam=None) -> CameraMount | None:
    """The camera mount of a stereo YAML or manifest mapping: its ``mount:`` or ``rig:`` entry, or None.

    A ``rig:`` is read with the calibration's left ``R_rect_from_cam`` (:meth:`CameraMount.from_rig`);
    both entries at once are an error.
    """
    if data.get("mount") is not None and data.get("rig") is not None:
        raise ValueError(f"{where}: give 'mount:' or 'rig:', not both")
    if data.get("mount") is not None:
        try:
            return CameraMount.from_dict(data["mount"], where=f"{where}: mount")
        except ValueError as exc:
            message = str(exc)
            raise ValueError(message if message.startswith(where) else f"{where}: mount: {message}") from None
    if data.get("rig") is not None:
        r = data["rig"]
        if not isinstance(r, dict) or "height_m" not in r:
            raise ValueError(f"{where}: 'rig' needs height_m (and optional tilt_rad)")
        try:
            return CameraMount.from_rig(r["height_m"], r.get("tilt_rad", 0.0), R_rect_from_cam=R_rect_from_cam)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{where}: rig: {exc}") from None
    return None


def mount_entry(mount: CameraMount | None) -> dict:
    """The YAML entry of a mount: ``{"mount": {xyz, rpy}}``, or ``{}`` for None."""
    if mount is not None and not isinstance(mount, CameraMount):
        raise TypeError(f"mount must be a CameraMount or None, got {type(mount).__name__}")
    return {} if mount is None else {"mount": mount.to_dict()}
