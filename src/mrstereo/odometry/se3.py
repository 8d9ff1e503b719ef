"""Rigid transforms for odometry: rotation vectors, quaternions, planar poses.

4x4 homogeneous matrices ``T_b_from_a`` map frame-a points into frame b (docs/conventions.md).
Quaternions are ``(qx, qy, qz, qw)`` (the TUM and ROS order), unit norm, ``qw >= 0``.
"""
from __future__ import annotations

import math

import cv2
import numpy as np

__all__ = ["T_from_rvec_t", "rvec_t_from_T", "rotation_angle_rad", "quaternion_from_rotation",
           "rotation_from_quaternion", "T_from_planar", "planar_from_T", "T_from_position_quaternion"]


def T_from_rvec_t(rvec, tvec) -> np.ndarray:
    """4x4 transform of an OpenCV rotation vector (Rodrigues) and translation."""
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))[0]
    T[:3, 3] = np.asarray(tvec, dtype=np.float64).ravel()
    return T


def rvec_t_from_T(T) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV ``(rvec, tvec)`` (3x1 each) of a 4x4 transform."""
    T = np.asarray(T, dtype=np.float64)
    return cv2.Rodrigues(T[:3, :3])[0].reshape(3, 1), T[:3, 3].reshape(3, 1).copy()


def rotation_angle_rad(R) -> float:
    """Angle of a rotation matrix, in [0, pi]."""
    c = (np.trace(np.asarray(R, dtype=np.float64)[:3, :3]) - 1.0) / 2.0
    return float(math.acos(min(1.0, max(-1.0, c))))


def quaternion_from_rotation(R) -> np.ndarray:
    """Unit quaternion ``(qx, qy, qz, qw)`` with ``qw >= 0`` of a rotation matrix."""
    R = np.asarray(R, dtype=np.float64)[:3, :3]
    rvec = cv2.Rodrigues(R)[0].ravel()
    angle = float(np.linalg.norm(rvec))
    if angle < 1e-12:
        return np.array([0.0, 0.0, 0.0, 1.0])
    axis = rvec / angle
    q = np.concatenate([axis * math.sin(angle / 2.0), [math.cos(angle / 2.0)]])
    return q if q[3] >= 0 else -q


def rotation_from_quaternion(q) -> np.ndarray:
    """Rotation matrix of a quaternion ``(qx, qy, qz, qw)`` (normalized first)."""
    q = np.asarray(q, dtype=np.float64).ravel()
    n = np.linalg.norm(q) if q.shape == (4,) else 0.0
    if not (n > 0 and math.isfinite(n)):
        raise ValueError(f"quaternion must be 4 finite numbers, not all zero, got {q.tolist()}")
    x, y, z, w = q / n
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def T_from_position_quaternion(position, quaternion) -> np.ndarray:
    """4x4 transform from a position and a quaternion ``(qx, qy, qz, qw)``."""
    T = np.eye(4)
    T[:3, :3] = rotation_from_quaternion(quaternion)
    T[:3, 3] = np.asarray(position, dtype=np.float64).ravel()
    return T


def T_from_planar(x_m: float, y_m: float, yaw_rad: float) -> np.ndarray:
    """4x4 transform of a planar pose ``(x, y, yaw)`` (REP 103, z up)."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[0, 3], T[1, 3] = x_m, y_m
    return T


def planar_from_T(T) -> np.ndarray:
    """``(x_m, y_m, yaw_rad)`` of 4x4 transforms (..., 4, 4): the position and the heading of x."""
    T = np.asarray(T, dtype=np.float64)
    if T.shape[-2:] != (4, 4):
        raise ValueError(f"T must have shape (..., 4, 4), got {T.shape}")
    return np.stack([T[..., 0, 3], T[..., 1, 3], np.arctan2(T[..., 1, 0], T[..., 0, 0])], axis=-1)
