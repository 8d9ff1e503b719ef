"""Rigid transforms between the camera, robot and world frames.

Camera frame: x right, y down, z forward. Robot and world frames (REP 103):
x forward, y left, z up. The stereo head carries the left camera's optical
centre at ``height_m`` above the floor on the robot's vertical axis; the head
pans by ``pan_rad`` about that axis (positive to the left) and the camera is
tilted down by ``tilt_rad``. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import numpy as np

from .. import _checks

__all__ = ["R_ROBOT_FROM_CAM_LEVEL", "T_robot_from_cam", "T_world_from_robot", "transform_points"]

# Axes of a level, forward-looking camera in the robot frame: cam x -> -y, cam y -> -z, cam z -> x.
R_ROBOT_FROM_CAM_LEVEL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def _rot_z(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rot_y(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def T_robot_from_cam(*, height_m: float, tilt_rad: float = 0.0, pan_rad: float = 0.0) -> np.ndarray:
    """4x4 transform taking left-camera points into the robot frame.

    ``R = Rz(pan) @ Ry(tilt) @ R_ROBOT_FROM_CAM_LEVEL``; a positive tilt turns
    the optical axis toward the floor, a positive pan turns it to the left.
    """
    h = _checks.finite_number("height_m", height_m)
    tilt = _checks.finite_number("tilt_rad", tilt_rad)
    pan = _checks.finite_number("pan_rad", pan_rad)
    T = np.eye(4)
    T[:3, :3] = _rot_z(pan) @ _rot_y(tilt) @ R_ROBOT_FROM_CAM_LEVEL
    T[2, 3] = h
    return T


def T_world_from_robot(x_m: float, y_m: float, yaw_rad: float) -> np.ndarray:
    """4x4 transform of a planar robot pose ``(x, y, yaw)`` in the world frame."""
    T = np.eye(4)
    T[:3, :3] = _rot_z(_checks.finite_number("yaw_rad", yaw_rad))
    T[0, 3] = _checks.finite_number("x_m", x_m)
    T[1, 3] = _checks.finite_number("y_m", y_m)
    return T


def transform_points(T_b_from_a: np.ndarray, points_a) -> np.ndarray:
    """Apply a 4x4 transform to points of shape (..., 3); NaN rows stay NaN."""
    p = np.asarray(points_a, dtype=np.float64)
    T = _checks.matrix("T_b_from_a", T_b_from_a, (4, 4))
    return p @ T[:3, :3].T + T[:3, 3]
