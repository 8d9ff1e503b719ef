"""The camera mount: the pose of the left optical frame in the robot base frame.

The stereo head carries the left camera's optical centre at ``height_m`` above the floor on the
robot's vertical axis; the head pans by ``pan_rad`` about that axis (positive to the left) and the
camera is tilted down by ``tilt_rad``. That is the paper's rig, the special case of a general
:class:`CameraMount`: the 6-DoF pose ``T_base_from_cam`` of the left optical frame in the robot
base frame (whose x-y plane is the floor). Conventions: docs/conventions.md (Frames).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .. import _checks
from ..transforms import R_BODY_FROM_OPTICAL, T_robot_from_cam, _rot_z, rotation_from_rpy, rpy_from_rotation

__all__ = ["RigMount", "CameraMount", "read_mount_entry", "mount_entry", "T_base_from_cam_of"]


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


class CameraMount:
    """Pose of the left camera's optical frame in the robot base frame: ``T_base_from_cam`` (4, 4).

    The physical (raw) left camera, as TF publishes it; points triangulated in the rectified
    frame are turned back by the calibration's rectification ``R`` first
    (:func:`mrstereo.geometry.ground.ground_from_mount`).

    The base frame is REP 103 (x forward, y left, z up) with its x-y plane on
    the floor (ROS ``base_footprint``; ``base_link`` of most wheeled robots).
    The optical frame is x right, y down, z forward. Built from

    * :meth:`from_xyz_rpy`: ``xyz`` [m] and ``rpy`` [rad] of the camera *body*
      frame (x forward, y left, z up) in the base frame, REP 103 fixed axes
      (``R = Rz(yaw) Ry(pitch) Rx(roll)``; positive pitch looks down); the
      optical frame is the body frame turned by :data:`R_BODY_FROM_OPTICAL`.
      All zeros: a level camera on the floor looking along the robot's x axis;
    * :meth:`from_rig`: the paper's rig ``(height_m, tilt_rad)`` = ``xyz = (0, 0,
      height_m)``, ``rpy = (0, tilt_rad, 0)``;
    * a TF lookup (:mod:`mrstereo.recordings.bag`) or a 4x4 matrix.

    Head pan (positive left) turns the mount about the base z axis:
    :meth:`T_base_from_cam_panned`.
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
        T = np.eye(4)
        T[:3, :3] = rotation_from_rpy(*rpy) @ R_BODY_FROM_OPTICAL
        T[:3, 3] = xyz
        return cls(T)

    @classmethod
    def from_rig(cls, rig) -> CameraMount:
        """The paper's rig (``RigMount(height_m, tilt_rad)``) as a mount: exactly :func:`T_robot_from_cam`."""
        return cls(T_robot_from_cam(height_m=rig.height_m, tilt_rad=rig.tilt_rad))

    @property
    def T_base_from_cam(self) -> np.ndarray:
        """4x4 transform taking left optical-frame points into the base frame (read-only)."""
        return self._T

    @property
    def xyz(self) -> tuple[float, float, float]:
        """Optical centre in the base frame [m]."""
        return tuple(float(v) for v in self._T[:3, 3])

    @property
    def rpy(self) -> tuple[float, float, float]:
        """Roll, pitch, yaw [rad] of the camera body frame (inverse of :meth:`from_xyz_rpy`)."""
        return tuple(float(v) for v in rpy_from_rotation(self._T[:3, :3] @ R_BODY_FROM_OPTICAL.T))

    @property
    def height_m(self) -> float:
        """Height of the optical centre above the floor."""
        return float(self._T[2, 3])

    @property
    def tilt_rad(self) -> float:
        """Downward angle of the optical axis below the horizontal (positive = looking down)."""
        return math.asin(float(np.clip(-self._T[2, 2], -1.0, 1.0)))

    def T_base_from_cam_panned(self, pan_rad: float = 0.0) -> np.ndarray:
        """``Rz(pan) @ T_base_from_cam``: the head turned by ``pan_rad`` about the base z axis."""
        pan = _checks.finite_number("pan_rad", pan_rad)
        if pan == 0.0:
            return self._T.copy()
        Rz = np.eye(4)
        Rz[:3, :3] = _rot_z(pan)
        return Rz @ self._T

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


def read_mount_entry(data: dict, *, where: str):
    """The camera mount of a stereo YAML or manifest mapping: its ``mount:`` or ``rig:`` entry.

    ``mount: {xyz: [x, y, z], rpy: [roll, pitch, yaw]}`` gives a :class:`CameraMount`;
    the paper's ``rig: {height_m, tilt_rad}`` a :class:`mrstereo.camera.RigMount`; neither
    None. Both at once is an error.
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
            return RigMount(height_m=r["height_m"], tilt_rad=r.get("tilt_rad", 0.0))
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{where}: rig: {exc}") from None
    return None


def mount_entry(mount) -> dict:
    """The YAML entry of a mount: ``{"mount": {...}}``, ``{"rig": {...}}`` or ``{}`` for None."""
    if mount is None:
        return {}
    if isinstance(mount, CameraMount):
        return {"mount": mount.to_dict()}
    return {"rig": {"height_m": float(mount.height_m), "tilt_rad": float(mount.tilt_rad)}}


def T_base_from_cam_of(rig, pan_rad: float = 0.0, *, stereo=None) -> np.ndarray:
    """The left *rectified* camera's mount on the base, with the head's pan.

    ``rig``: the paper's ``RigMount`` (height, tilt: the rectified frame, as the mapping chain
    uses it), a 6-DoF ``CameraMount`` of the raw camera (turned into the rectified frame with
    ``stereo.left.R``), or None (a level camera on the floor: the base is the camera's REP 103
    body frame).
    """
    if rig is None:
        rig = CameraMount.from_xyz_rpy((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    if isinstance(rig, CameraMount):
        T = rig.T_base_from_cam_panned(pan_rad)
        if stereo is not None:
            T_cam_from_rect = np.eye(4)
            T_cam_from_rect[:3, :3] = np.asarray(stereo.left.R, dtype=np.float64).T
            T = T @ T_cam_from_rect
        return T
    return T_robot_from_cam(height_m=rig.height_m, tilt_rad=rig.tilt_rad, pan_rad=pan_rad)
