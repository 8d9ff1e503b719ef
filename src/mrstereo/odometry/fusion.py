"""The given odometry fused with visual odometry: a small pose filter on the floor plane.

Wheel odometry drifts but never loses track; visual odometry hardly drifts but can lose track.
Each step between consecutive frames, ``(dx, dy, dyaw)`` in the robot frame of its start, is
measured by both, each with the covariance of its expected error over the step's length ``d``
(``sigma = a d + a0`` along, across and in heading; :class:`FusionConfig`). The fused step is
the information-weighted mean ``(P_g^-1 + P_v^-1)^-1 (P_g^-1 g + P_v^-1 v)``; a visual step
counts only between two tracked frames and within ``gate_sigmas`` (Mahalanobis distance) of the
given one. On a chain of steps this is the least-squares pose graph of both odometries. User
guide: docs/odometry.md. Conventions: docs/conventions.md.

References
----------
S. Thrun, W. Burgard, D. Fox. Probabilistic Robotics, ch. 5.4 (odometry motion model) and 3.2
(the information form of the Gaussian update). 2005.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import _checks
from ..transforms import compose_planar, relative_planar, wrap_angle

__all__ = ["FusionConfig", "FusedOdometry", "fuse_odometry"]


@dataclass(frozen=True)
class FusionConfig:
    """Expected step errors (standard deviations) of the two odometries and the gate.

    ``given_along``, ``given_across`` (per metre travelled), ``given_yaw_rad_per_m`` and the error of
    any step however short, ``given_floor_m``, ``given_floor_rad`` (wheel slip, backlash); the same
    ``visual_*`` for visual odometry; a visual step farther than ``gate_sigmas`` (Mahalanobis distance
    under both covariances) from the given one is not used.
    """

    given_along: float = 0.05
    given_across: float = 0.03
    given_yaw_rad_per_m: float = math.radians(5.0)
    given_floor_m: float = 0.005
    given_floor_rad: float = math.radians(0.2)
    visual_along: float = 0.005
    visual_across: float = 0.005
    visual_yaw_rad_per_m: float = math.radians(0.3)
    visual_floor_m: float = 0.0005
    visual_floor_rad: float = math.radians(0.02)
    gate_sigmas: float = 5.0

    def __post_init__(self) -> None:
        for name in ("given_along", "given_across", "given_yaw_rad_per_m", "given_floor_m", "given_floor_rad",
                     "visual_along", "visual_across", "visual_yaw_rad_per_m", "visual_floor_m", "visual_floor_rad",
                     "gate_sigmas"):
            _checks.finite_number(name, getattr(self, name), positive=True)

    def covariance(self, step, visual: bool) -> np.ndarray:
        """Covariance (3x3) of a step ``(dx, dy, dyaw)`` in the frame of its start."""
        along, across, yaw, floor_m, floor_rad = (
            (self.visual_along, self.visual_across, self.visual_yaw_rad_per_m, self.visual_floor_m,
             self.visual_floor_rad) if visual else
            (self.given_along, self.given_across, self.given_yaw_rad_per_m, self.given_floor_m, self.given_floor_rad))
        d = math.hypot(step[0], step[1])
        heading = math.atan2(step[1], step[0]) if d > 1e-9 else 0.0
        c, s = math.cos(heading), math.sin(heading)
        R = np.array([[c, -s], [s, c]])
        cov = np.zeros((3, 3))
        cov[:2, :2] = R @ np.diag([(along * d + floor_m) ** 2, (across * d + floor_m) ** 2]) @ R.T
        cov[2, 2] = (yaw * d + floor_rad) ** 2
        return cov


@dataclass(frozen=True)
class FusedOdometry:
    """Result of :func:`fuse_odometry`: the fused planar ``poses`` (N, 3) (the first is the given one),
    ``visual_used`` where the step into the frame used visual odometry and ``visual_rejected`` where
    a visual step lay outside the gate.
    """

    poses: np.ndarray
    visual_used: np.ndarray
    visual_rejected: np.ndarray

    def corrections(self, given_poses) -> tuple[np.ndarray, np.ndarray]:
        """Distance (m) and heading difference (rad) of each fused pose from the given one."""
        given = np.asarray(given_poses, dtype=np.float64)
        moved = np.hypot(*(self.poses[:, :2] - given[:, :2]).T)
        turned = np.abs(np.remainder(self.poses[:, 2] - given[:, 2] + math.pi, math.tau) - math.pi)
        return moved, turned


def fuse_odometry(given_poses, visual_poses, visual_tracked, *, config: FusionConfig = FusionConfig()
                  ) -> FusedOdometry:
    """Fuse the given odometry's steps with visual odometry's (information-weighted, gated).

    Parameters
    ----------
    given_poses : ndarray (N, 3)
        The recording's planar poses ``(x_m, y_m, yaw_rad)`` (its odometry).
    visual_poses : ndarray (N, 3)
        Visual odometry's planar poses of the same frames (any world frame: only steps are used).
    visual_tracked : ndarray (N,) bool
        Frames visual odometry measured (not lost).
    config : FusionConfig
    """
    given = np.asarray(given_poses, dtype=np.float64)
    visual = np.asarray(visual_poses, dtype=np.float64)
    tracked = np.asarray(visual_tracked, dtype=bool).ravel()
    if given.ndim != 2 or given.shape[1] != 3 or len(given) == 0 or not np.isfinite(given).all():
        raise ValueError(f"given_poses must be finite (N >= 1, 3), got shape {given.shape}")
    if visual.shape != given.shape or not np.isfinite(visual).all():
        raise ValueError(f"visual_poses must be finite with the shape of given_poses {given.shape}, "
                         f"got {visual.shape}")
    if tracked.shape != (len(given),):
        raise ValueError(f"visual_tracked must be {len(given)} booleans, got shape {tracked.shape}")
    _checks.instance("config", config, FusionConfig)
    out = np.empty_like(given)
    out[0] = given[0]
    used = np.zeros(len(given), bool)
    rejected = np.zeros(len(given), bool)
    gate2 = config.gate_sigmas ** 2
    for k in range(1, len(given)):
        g = np.array(relative_planar(given[k - 1], given[k]))
        step = g
        if tracked[k] and tracked[k - 1]:
            v = np.array(relative_planar(visual[k - 1], visual[k]))
            Pg, Pv = config.covariance(g, visual=False), config.covariance(v, visual=True)
            diff = v - g
            diff[2] = wrap_angle(diff[2])
            if diff @ np.linalg.solve(Pg + Pv, diff) <= gate2:
                Ig, Iv = np.linalg.inv(Pg), np.linalg.inv(Pv)
                step = g + np.linalg.solve(Ig + Iv, Iv @ diff)
                used[k] = True
            else:
                rejected[k] = True
        out[k] = compose_planar(out[k - 1], step)
    return FusedOdometry(poses=out, visual_used=used, visual_rejected=rejected)
