"""Rigid transforms: the one place for SE(3), planar poses, roll-pitch-yaw and quaternions.

4x4 matrices ``T_b_from_a`` map frame-a points into frame b; quaternions are ``(qx, qy, qz, qw)``
(the TUM and ROS order). Frames and angles: docs/conventions.md (Frames).
"""
from __future__ import annotations

import math

import cv2
import numpy as np

from . import _checks

__all__ = ["R_BODY_FROM_OPTICAL", "rotation_from_rpy", "rpy_from_rotation",
           "T_robot_from_cam", "transform_points", "T_from_R_t", "T_from_rvec_t", "rvec_t_from_T", "rotation_angle_rad",
           "rotations_from_rvecs", "rotation_jacobian_factor", "scale_motion",
           "quaternion_from_rotation", "rotation_from_quaternion", "slerp", "T_from_position_quaternion",
           "T_from_planar", "planar_from_T", "compose_planar", "relative_planar", "wrap_angle"]

# A camera's optical frame (x right, y down, z forward) in its body frame (x forward, y left, z up):
# optical x -> -y, y -> -z, z -> x. ROS calls the two "<camera>_optical_frame" and "<camera>_link".
R_BODY_FROM_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def _array(name: str, value, tail: tuple[int, ...], *, batch: bool = False) -> np.ndarray:
    """``value`` as a float64 array whose last dimensions are ``tail`` (more in front with ``batch``)."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a numeric array of shape {tail}, got {type(value).__name__}") from None
    if arr.shape[-len(tail):] != tail or (not batch and arr.ndim != len(tail)):
        raise ValueError(f"{name} must have shape {'(..., ' if batch else '('}{', '.join(map(str, tail))}), "
                         f"got {arr.shape}")
    return arr


def _planar(name: str, value) -> tuple[float, float, float]:
    """A planar pose ``(x, y, yaw)`` of finite numbers."""
    arr = _array(name, value, (3,))
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} must be 3 finite numbers (x_m, y_m, yaw_rad), got {arr.tolist()}")
    return float(arr[0]), float(arr[1]), float(arr[2])


def _rot_z(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rot_y(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rotation_from_rpy(roll_rad, pitch_rad, yaw_rad) -> np.ndarray:
    """``Rz(yaw) @ Ry(pitch) @ Rx(roll)``; broadcasts over arrays of angles, returns (..., 3, 3).

    The paper's Euler angles (alpha, beta, gamma) of eq. (1) are these roll, pitch and yaw.
    """
    a, b, g = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (roll_rad, pitch_rad, yaw_rad)))
    ca, sa, cb, sb, cg, sg = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(g), np.sin(g)
    R = np.empty(a.shape + (3, 3))
    R[..., 0, 0] = cg * cb
    R[..., 0, 1] = cg * sb * sa - sg * ca
    R[..., 0, 2] = cg * sb * ca + sg * sa
    R[..., 1, 0] = sg * cb
    R[..., 1, 1] = sg * sb * sa + cg * ca
    R[..., 1, 2] = sg * sb * ca - cg * sa
    R[..., 2, 0] = -sb
    R[..., 2, 1] = cb * sa
    R[..., 2, 2] = cb * ca
    return R


def rpy_from_rotation(R) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inverse of :func:`rotation_from_rpy` for (..., 3, 3): ``(roll, pitch, yaw)``, pitch in
    [-pi/2, pi/2] (0-d arrays for one rotation); at pitch +-pi/2 (gimbal lock) roll is 0."""
    R = _array("R", R, (3, 3), batch=True)
    pitch = np.arcsin(np.clip(-R[..., 2, 0], -1.0, 1.0))
    locked = np.abs(R[..., 2, 0]) > 1.0 - 1e-12
    roll = np.where(locked, 0.0, np.arctan2(R[..., 2, 1], R[..., 2, 2]))
    yaw = np.where(locked, np.arctan2(-R[..., 0, 1], R[..., 1, 1]), np.arctan2(R[..., 1, 0], R[..., 0, 0]))
    return roll, pitch, yaw


def T_robot_from_cam(*, height_m: float, tilt_rad: float = 0.0, pan_rad: float = 0.0) -> np.ndarray:
    """4x4 transform taking left-camera points into the robot frame (the paper's rig).

    ``R = Rz(pan) @ Ry(tilt) @ R_BODY_FROM_OPTICAL``; a positive tilt turns
    the optical axis toward the floor, a positive pan turns it to the left.
    """
    h = _checks.finite_number("height_m", height_m)
    tilt = _checks.finite_number("tilt_rad", tilt_rad)
    pan = _checks.finite_number("pan_rad", pan_rad)
    T = np.eye(4)
    T[:3, :3] = _rot_z(pan) @ _rot_y(tilt) @ R_BODY_FROM_OPTICAL
    T[2, 3] = h
    return T


_CV_TRANSFORM_MIN_POINTS = 4096      # below this numpy's product is as fast (and what odometry was tuned with)


def transform_points(T_b_from_a: np.ndarray, points_a) -> np.ndarray:
    """Apply a 4x4 transform to points of shape (..., 3); NaN rows stay NaN.

    ``cv2.transform`` (``R p + t`` per point): a BLAS product of (N, 3) by (3, 3) starts the BLAS threads,
    which on a busy machine costs 100 times the arithmetic.
    """
    p = np.asarray(points_a, dtype=np.float64)
    T = _checks.matrix("T_b_from_a", T_b_from_a, (4, 4))
    if p.ndim == 0 or p.shape[-1] != 3 or p.size < 3 * _CV_TRANSFORM_MIN_POINTS:
        return p @ T[:3, :3].T + T[:3, 3]
    return cv2.transform(np.ascontiguousarray(p).reshape(-1, 1, 3), T[:3]).reshape(p.shape)


def T_from_R_t(R, t) -> np.ndarray:
    """4x4 transform of a rotation matrix (3, 3) and a translation (3,)."""
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.ravel(t)
    return T


def T_from_rvec_t(rvec, tvec) -> np.ndarray:
    """4x4 transform of an OpenCV rotation vector (Rodrigues) and translation."""
    return T_from_R_t(cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))[0],
                      np.asarray(tvec, dtype=np.float64))


def rvec_t_from_T(T) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV ``(rvec, tvec)`` (3x1 each) of a 4x4 transform."""
    T = _array("T", T, (4, 4))
    return cv2.Rodrigues(T[:3, :3])[0].reshape(3, 1), T[:3, 3].reshape(3, 1).copy()


def rotations_from_rvecs(rvecs) -> np.ndarray:
    """Rotation matrices (N, 3, 3) of rotation vectors (N, 3) (Rodrigues' formula, as ``cv2.Rodrigues``)."""
    r = np.asarray(rvecs, dtype=np.float64).reshape(-1, 3)
    theta = np.linalg.norm(r, axis=1)
    small = theta < 1e-8
    # series for tiny angles: sin(t)/t -> 1 - t^2/6, (1 - cos t)/t^2 -> 1/2 - t^2/24
    t = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta ** 2 / 6.0, np.sin(t) / t)
    b = np.where(small, 0.5 - theta ** 2 / 24.0, (1.0 - np.cos(t)) / t ** 2)
    K = _skew(r)
    return np.eye(3) + a[:, None, None] * K + b[:, None, None] * (K @ K)


def _skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices (N, 3, 3) of vectors (N, 3): ``_skew(v) @ p = v x p``."""
    K = np.zeros(v.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    K[..., 1, 0], K[..., 2, 0], K[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return K


def rotation_jacobian_factor(rvecs, R) -> np.ndarray:
    """``M`` (N, 3, 3) of ``d(R(r) p) / dr = -R [p]x M`` per rotation vector ``r`` (N, 3) with rotation ``R``.

    Gallego and Yezzi's closed form ``M = (r r^T + (R^T - I) [r]x) / |r|^2``, and ``I`` at ``r = 0``.

    References
    ----------
    G. Gallego, A. Yezzi. A compact formula for the derivative of a 3-D rotation in exponential
    coordinates. J. Math. Imaging Vis. 51, 2015.
    """
    r = np.asarray(rvecs, dtype=np.float64).reshape(-1, 3)
    n2 = np.einsum("ij,ij->i", r, r)
    M = (r[:, :, None] * r[:, None, :] + (np.swapaxes(R, 1, 2) - np.eye(3)) @ _skew(r)) / \
        np.where(n2 < 1e-16, 1.0, n2)[:, None, None]
    M[n2 < 1e-16] = np.eye(3)
    return M


def scale_motion(T, fraction: float) -> np.ndarray:
    """A rigid motion ``T`` (4x4) scaled in time: its rotation vector and translation times ``fraction``.

    The constant-velocity motion model's prediction over another time step (exact for a
    rotation about an axis through the origin, first order otherwise).
    """
    T = _array("T", T, (4, 4))
    fraction = _checks.finite_number("fraction", fraction)
    rvec = cv2.Rodrigues(T[:3, :3])[0].ravel()
    return T_from_rvec_t(rvec * fraction, T[:3, 3] * fraction)


def rotation_angle_rad(R) -> float:
    """Angle of a rotation matrix, in [0, pi]."""
    R = np.asarray(R, dtype=np.float64)
    if R.ndim != 2 or R.shape[0] < 3 or R.shape[1] < 3:
        raise ValueError(f"R must be a 3x3 rotation (or a 4x4 transform), got shape {R.shape}")
    c = (np.trace(R[:3, :3]) - 1.0) / 2.0
    return float(math.acos(min(1.0, max(-1.0, c))))


def quaternion_from_rotation(R) -> np.ndarray:
    """Unit quaternion ``(qx, qy, qz, qw)`` with ``qw >= 0`` of a rotation matrix."""
    R = np.asarray(R, dtype=np.float64)
    if R.shape not in ((3, 3), (4, 4)) or not np.isfinite(R).all():
        raise ValueError(f"R must be a finite 3x3 rotation (or a 4x4 transform), got shape {R.shape}")
    rvec = cv2.Rodrigues(R[:3, :3])[0].ravel()
    angle = float(np.linalg.norm(rvec))
    if angle < 1e-12:
        return np.array([0.0, 0.0, 0.0, 1.0])
    axis = rvec / angle
    q = np.concatenate([axis * math.sin(angle / 2.0), [math.cos(angle / 2.0)]])
    return q if q[3] >= 0 else -q


def rotation_from_quaternion(q) -> np.ndarray:
    """Rotation matrix of a quaternion ``(qx, qy, qz, qw)`` of any non-zero norm."""
    q = np.asarray(q, dtype=np.float64).ravel()
    n = float(q @ q) if q.shape == (4,) else 0.0
    if not (n > 1e-12 and math.isfinite(n)):
        raise ValueError(f"quaternion must be 4 finite numbers, not all zero, got {q.tolist()}")
    x, y, z, w = (float(v) for v in q)
    s = 2.0 / n
    return np.array([[1 - s * (y * y + z * z), s * (x * y - z * w), s * (x * z + y * w)],
                     [s * (x * y + z * w), 1 - s * (x * x + z * z), s * (y * z - x * w)],
                     [s * (x * z - y * w), s * (y * z + x * w), 1 - s * (x * x + y * y)]])


def slerp(q0, q1, fraction: float) -> np.ndarray:
    """Spherical linear interpolation of two quaternions (``fraction`` 0 gives ``q0``, 1 ``q1``)."""
    q0, q1 = _array("q0", q0, (4,)), _array("q1", q1, (4,))
    for name, q in (("q0", q0), ("q1", q1)):
        if not np.isfinite(q).all() or np.linalg.norm(q) < 1e-12:
            raise ValueError(f"{name} must be a finite quaternion of non-zero length, got {q.tolist()}")
    q0, q1 = q0 / np.linalg.norm(q0), q1 / np.linalg.norm(q1)
    dot = float(np.dot(q0, q1))
    if dot < 0.0:
        q1, dot = -q1, -dot
    if dot > 0.9995:
        q = q0 + fraction * (q1 - q0)
        return q / np.linalg.norm(q)
    theta = math.acos(min(dot, 1.0))
    return (math.sin((1 - fraction) * theta) * q0 + math.sin(fraction * theta) * q1) / math.sin(theta)


def T_from_position_quaternion(position, quaternion) -> np.ndarray:
    """4x4 transform from a position and a quaternion ``(qx, qy, qz, qw)``."""
    return T_from_R_t(rotation_from_quaternion(quaternion), np.asarray(position, dtype=np.float64))


def T_from_planar(x_m: float, y_m: float, yaw_rad: float) -> np.ndarray:
    """4x4 transform of a planar pose ``(x, y, yaw)`` (a rotation about z)."""
    yaw = _checks.finite_number("yaw_rad", yaw_rad)
    c, s = math.cos(yaw), math.sin(yaw)
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[0, 3] = _checks.finite_number("x_m", x_m)
    T[1, 3] = _checks.finite_number("y_m", y_m)
    return T


def planar_from_T(T) -> np.ndarray:
    """``(x_m, y_m, yaw_rad)`` of 4x4 transforms (..., 4, 4): the position and the heading of x."""
    T = np.asarray(T, dtype=np.float64)
    if T.shape[-2:] != (4, 4):
        raise ValueError(f"T must have shape (..., 4, 4), got {T.shape}")
    return np.stack([T[..., 0, 3], T[..., 1, 3], np.arctan2(T[..., 1, 0], T[..., 0, 0])], axis=-1)


def compose_planar(a, b) -> tuple[float, float, float]:
    """``a * b`` of planar poses ``(x, y, yaw)``."""
    a, b = _planar("a", a), _planar("b", b)
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], wrap_angle(a[2] + b[2]))


def relative_planar(a, b) -> tuple[float, float, float]:
    """``inv(a) * b`` of planar poses."""
    a, b = _planar("a", a), _planar("b", b)
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return (c * dx + s * dy, -s * dx + c * dy, wrap_angle(b[2] - a[2]))


def wrap_angle(angle_rad: float) -> float:
    """The angle in [-pi, pi]."""
    return math.remainder(angle_rad, math.tau)
