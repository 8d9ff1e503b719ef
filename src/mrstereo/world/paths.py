"""Robot paths through the synthetic worlds: the mapping stops and odometry sequences.

``stops`` (paper Sec. 5.2), ``front``, ``s-curve``, a randomized world's waypoints and the
``street`` drive; :func:`drifted_poses` corrupts a path as wheel odometry would. Each path:
docs/world.md and docs/odometry.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math

import numpy as np

from .. import _checks
from ..transforms import relative_planar, wrap_angle

__all__ = ["PATH_KINDS", "sequence_path", "waypoint_path", "speed_path", "drifted_poses"]

PATH_KINDS = ("stops", "front", "s-curve", "street")

_BEND_X_M = (4.4, 5.8, 6.6, 8.0)    # the S-bend around the box at x = 6.0..6.4 m: down, hold, up
_BEND_Y_M = -0.7
_WEAVE_AMPLITUDE_M, _WEAVE_PERIOD_M = 0.15, 3.0
_END_X_M = 13.5


def _smoothstep(t: np.ndarray) -> np.ndarray:
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _centre_y(x: np.ndarray, weave: bool) -> np.ndarray:
    a, b, c, d = _BEND_X_M
    y = _BEND_Y_M * (_smoothstep((x - a) / (b - a)) - _smoothstep((x - c) / (d - c)))
    if weave:
        y = y + _WEAVE_AMPLITUDE_M * (1.0 - np.cos(2.0 * math.pi * x / _WEAVE_PERIOD_M))
    return y


def sequence_path(kind: str, n_frames: int, *, step_m: float = 0.1) -> np.ndarray:
    """Robot poses ``(n_frames, 3)`` ``(x_m, y_m, yaw_rad)``, ``step_m`` apart along the ``"front"`` or
    ``"s-curve"`` centre line (yaw its tangent); ``(n_frames - 1) * step_m`` must fit (about 13.5 m).
    """
    if kind not in ("front", "s-curve"):
        raise ValueError(f"kind must be 'front' or 's-curve', got {kind!r}")
    n_frames = _checks.positive_int("n_frames", n_frames)
    step = _checks.finite_number("step_m", step_m, positive=True)
    weave = kind == "s-curve"
    # the centre line densely sampled, then resampled at equal arc length
    x = np.linspace(0.0, _END_X_M, 27001)
    y = _centre_y(x, weave)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))])
    length = (n_frames - 1) * step
    if length > s[-1]:
        raise ValueError(f"{n_frames} frames {step} m apart ({length:.2f} m) do not fit the corridor path "
                         f"({s[-1]:.2f} m): use fewer frames or a smaller step_m")
    s_k = np.arange(n_frames) * step
    x_k = np.interp(s_k, s, x)
    h = 1e-4
    dy = (_centre_y(x_k + h, weave) - _centre_y(x_k - h, weave)) / (2 * h)
    return np.column_stack([x_k, _centre_y(x_k, weave), np.arctan2(dy, 1.0)])


def waypoint_path(waypoints_xy, n_frames: int, *, step_m: float = 0.1) -> np.ndarray:
    """Robot poses ``(n_frames, 3)`` ``step_m`` apart along a smooth curve through waypoints (K, 2).

    A monotone cubic (PCHIP) per coordinate over the chord length: it does not overshoot the
    waypoints sideways, so obstacles clear of the polyline stay clear; the yaw is its tangent.
    """
    from scipy.interpolate import PchipInterpolator

    way = np.asarray(waypoints_xy, dtype=np.float64)
    if way.ndim != 2 or way.shape[1] != 2 or len(way) < 2 or not np.isfinite(way).all():
        raise ValueError(f"waypoints_xy must be (K >= 2, 2) finite numbers, got shape {way.shape}")
    n_frames = _checks.positive_int("n_frames", n_frames)
    step = _checks.finite_number("step_m", step_m, positive=True)
    chord = np.hypot(*np.diff(way, axis=0).T)
    if (chord <= 0).any():
        raise ValueError("waypoints_xy must not repeat a point")
    curve = PchipInterpolator(np.concatenate([[0.0], np.cumsum(chord)]), way, axis=0)
    t = np.linspace(0.0, chord.sum(), 20001)                 # densely sampled, resampled at equal arc length
    xy = curve(t)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    length = (n_frames - 1) * step
    if length > s[-1] + 1e-9:
        raise ValueError(f"{n_frames} frames {step} m apart ({length:.2f} m) do not fit the path through the "
                         f"waypoints ({s[-1]:.2f} m): use fewer frames or a smaller step_m")
    t_k = np.interp(np.arange(n_frames) * step, s, t)
    tangent = curve(t_k, 1)
    return np.column_stack([curve(t_k), np.arctan2(tangent[:, 1], tangent[:, 0])])


def speed_path(n_frames: int, *, step_m: float, turn_rad_per_frame: float = math.radians(3.0),
               standstill_frames: int = 3, accel_frames: int = 10, max_offset_m: float = 2.0) -> np.ndarray:
    """Robot poses ``(n_frames, 3)`` of a drive from a standstill up to ``step_m`` per frame, weaving.

    The heading is ``psi(s) = Psi sin(2 pi s / P)`` with ``P = pi sqrt(2 max_offset_m step_m / turn)``
    and ``Psi = turn P / (2 pi step_m)``: at full speed it turns by ``turn_rad_per_frame`` per frame at
    most and stays between the x axis and ``y = max_offset_m``.

    Parameters
    ----------
    n_frames : int
    step_m : float
        Path length per frame at full speed.
    turn_rad_per_frame : float
        Largest heading change per frame at full speed (0: straight).
    standstill_frames, accel_frames : int
        Frames standing at the origin, then frames of linear acceleration.
    max_offset_m : float
        Largest distance from the x axis (to the left).
    """
    n_frames = _checks.positive_int("n_frames", n_frames)
    step = _checks.finite_number("step_m", step_m, positive=True)
    turn = _checks.finite_number("turn_rad_per_frame", turn_rad_per_frame, nonnegative=True)
    still = _checks.positive_int("standstill_frames", standstill_frames, minimum=0)
    accel = _checks.positive_int("accel_frames", accel_frames, minimum=0)
    offset = _checks.finite_number("max_offset_m", max_offset_m, positive=True)
    k = np.arange(1, n_frames)
    steps = step * np.clip((k - still + 1) / (accel + 1), 0.0, 1.0)
    s = np.concatenate([[0.0], np.cumsum(steps)])
    if turn > 0:
        period = math.pi * math.sqrt(2.0 * offset * step / turn)
        amplitude = turn * period / (2.0 * math.pi * step)
    else:
        period, amplitude = 1.0, 0.0
    # the heading as a function of path length, integrated finely into positions
    fine = np.linspace(0.0, max(s[-1], 1e-9), max(2, int(s[-1] / 0.01) + 2))
    psi = amplitude * np.sin(2.0 * math.pi * fine / period)
    ds = np.diff(fine)
    mid = 0.5 * (psi[1:] + psi[:-1])
    x = np.concatenate([[0.0], np.cumsum(ds * np.cos(mid))])
    y = np.concatenate([[0.0], np.cumsum(ds * np.sin(mid))])
    return np.column_stack([np.interp(s, fine, x), np.interp(s, fine, y),
                            amplitude * np.sin(2.0 * math.pi * s / period)])


def drifted_poses(poses, *, scale_error: float, heading_drift_rad_per_m: float) -> np.ndarray:
    """Dead-reckoned poses with a scale error and a heading drift, as from wheel odometry.

    Each step ``(dx, dy, dyaw)`` between true poses is integrated again with its translation scaled
    by ``1 + scale_error`` and ``heading_drift_rad_per_m`` times its length added to its rotation.
    """
    p = np.asarray(poses, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or not np.isfinite(p).all():
        raise ValueError(f"poses must be finite (N, 3) (x_m, y_m, yaw_rad), got shape {p.shape}")
    scale = 1.0 + _checks.finite_number("scale_error", scale_error)
    drift = _checks.finite_number("heading_drift_rad_per_m", heading_drift_rad_per_m)
    out = p.copy()
    for k in range(1, len(p)):
        dx, dy, dyaw = relative_planar(p[k - 1], p[k])               # step in the previous robot frame
        dist = math.hypot(dx, dy)
        yaw = out[k - 1, 2]
        c, s = math.cos(yaw), math.sin(yaw)
        out[k, 0] = out[k - 1, 0] + scale * (c * dx - s * dy)
        out[k, 1] = out[k - 1, 1] + scale * (s * dx + c * dy)
        out[k, 2] = wrap_angle(yaw + dyaw + drift * dist)
    return out
