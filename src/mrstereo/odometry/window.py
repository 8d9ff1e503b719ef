"""Windowed refinement: bundle adjustment of the last keyframes' poses and the points they see.

Keyframe poses ``T_cam_from_world`` (rotation vector and translation) and world landmarks ``X``
minimize the Huber-robust sum of the reprojection errors of every observation (Triggs et al.;
the local bundle adjustment of ORB-SLAM2's stereo odometry),

    r_left  = (fx X_c / Z_c + cx - u,  fy Y_c / Z_c + cy - v)
    r_right = fx (X_c - b) / Z_c + cx_right - u_right          (a stereo observation)

with ``X_c = R X + t`` in the keyframe's rectified left camera. The right column makes the scale
observable in every keyframe; the oldest keyframes stay fixed (the gauge). Levenberg-Marquardt
on the normal equations with the landmarks eliminated (Schur complement; numba kernels), the
rotation's derivative in Gallego and Yezzi's closed form
(:func:`mrstereo.transforms.rotation_jacobian_factor`). User guide: docs/odometry.md.
Conventions: docs/conventions.md.

References
----------
B. Triggs, P. McLauchlan, R. Hartley, A. Fitzgibbon. Bundle adjustment -- a modern synthesis.
Vision Algorithms: Theory and Practice, 2000. R. Mur-Artal, J. D. Tardos. ORB-SLAM2: an
open-source SLAM system for monocular, stereo and RGB-D cameras. IEEE T-RO 33(5), 2017.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from .. import _checks
from ..transforms import T_from_rvec_t, rotation_jacobian_factor, rotations_from_rvecs, transform_points
from ._kernels import window_back_substitute, window_normal_equations, window_residuals, window_schur

__all__ = ["WindowResult", "refine_window"]


@dataclass(frozen=True)
class WindowResult:
    """Result of :func:`refine_window`: refined ``T_cam_from_world`` (K, 4, 4) and ``points_world``
    (M, 3); ``error_px`` of each observation after it (the larger of its left and right errors);
    ``success``, ``message``; the robust cost (half the Huber-weighted squared residuals, px^2)
    ``cost_before`` and ``cost_after``; ``evaluations``.
    """

    T_cam_from_world: np.ndarray
    points_world: np.ndarray
    error_px: np.ndarray
    success: bool
    message: str
    cost_before: float
    cost_after: float
    evaluations: int


def refine_window(T_cam_from_world, points_world, *, obs_keyframe, obs_point, obs_uv, obs_u_right, fixed,
                  K, baseline_m: float, cx_right_px: float | None = None, huber_px: float = 1.0,
                  max_iterations: int = 10) -> WindowResult:
    """Bundle adjustment of keyframe poses and landmarks over stereo (and mono) observations.

    Parameters
    ----------
    T_cam_from_world : ndarray (K, 4, 4)
        Keyframe poses (rectified left camera), the starting point.
    points_world : ndarray (M, 3)
        Landmarks, the starting point.
    obs_keyframe, obs_point : ndarray (n,) int
        Keyframe and landmark of each observation.
    obs_uv : ndarray (n, 2)
        Left image position ``(u, v)`` of each observation [px].
    obs_u_right : ndarray (n,)
        Right image column of each observation; NaN where the right image did not see it.
    fixed : ndarray (K,) bool
        Keyframes held fixed (at least one: the gauge).
    K : ndarray (3, 3)
        Rectified intrinsics.
    baseline_m : float
    cx_right_px : float, optional
        The right camera's principal point column (default ``cx``).
    huber_px : float
        Huber threshold of the loss [px], on each observation's error (the norm of its residuals).
    max_iterations : int
        Levenberg-Marquardt steps at most.
    """
    T = np.asarray(T_cam_from_world, dtype=np.float64)
    X = np.asarray(points_world, dtype=np.float64)
    if T.ndim != 3 or T.shape[1:] != (4, 4) or not np.isfinite(T).all():
        raise ValueError(f"T_cam_from_world must be finite with shape (K, 4, 4), got {T.shape}")
    if X.ndim != 2 or X.shape[1] != 3 or not np.isfinite(X).all():
        raise ValueError(f"points_world must be finite with shape (M, 3), got {X.shape}")
    kf = np.asarray(obs_keyframe, dtype=np.int64).ravel()
    pt = np.asarray(obs_point, dtype=np.int64).ravel()
    uv = np.asarray(obs_uv, dtype=np.float64).reshape(-1, 2)
    ur_obs = np.asarray(obs_u_right, dtype=np.float64).ravel()
    fixed = np.asarray(fixed, dtype=bool).ravel()
    n = len(kf)
    if not (len(pt) == len(uv) == len(ur_obs) == n) or n == 0:
        raise ValueError(f"the observations must be n >= 1 long each, got {len(kf)}, {len(pt)}, {len(uv)}, "
                         f"{len(ur_obs)}")
    if len(fixed) != len(T) or not fixed.any():
        raise ValueError(f"fixed must be {len(T)} booleans with at least one True (the gauge)")
    if kf.min() < 0 or kf.max() >= len(T) or pt.min() < 0 or pt.max() >= len(X):
        raise ValueError("obs_keyframe / obs_point index outside the keyframes / landmarks")
    if not np.isfinite(uv).all():
        raise ValueError("obs_uv must be finite")
    _checks.finite_number("baseline_m", baseline_m, positive=True)
    huber_px = _checks.finite_number("huber_px", huber_px, positive=True)
    max_iterations = _checks.positive_int("max_iterations", max_iterations)
    K = _checks.matrix("K", K, (3, 3))
    problem = _Problem(kf, pt, uv, ur_obs, fixed, K, float(baseline_m),
                       K[0, 2] if cx_right_px is None else float(cx_right_px), huber_px, len(X))
    rvecs = np.array([cv2.Rodrigues(Tk[:3, :3])[0].ravel() for Tk in T])
    state = (rvecs, T[:, :3, 3].copy(), X.copy())
    res, cost = problem.residuals(*state)
    cost0, lam, message, iterations = cost, 1e-3, "converged", 0
    for iterations in range(1, max_iterations + 1):
        step = problem.step(*state, res, lam)
        if step is None:
            message = "singular normal equations"
            break
        trial = problem.apply(*state, *step)
        trial_res, trial_cost = problem.residuals(*trial)
        if trial_cost < cost:
            gain = (cost - trial_cost) / max(cost, 1e-12)
            state, res, cost = trial, trial_res, trial_cost
            lam = max(lam / 10.0, 1e-9)
            if gain < 1e-6:
                break
        else:
            lam *= 10.0
            if lam > 1e6:
                message = "no step lowers the cost"
                break
    else:
        message = "iteration limit"
    rvecs, tvecs, P = state
    T_out = np.stack([T_from_rvec_t(ri, ti) for ri, ti in zip(rvecs, tvecs)])
    T_out[fixed] = T[fixed]
    return WindowResult(T_cam_from_world=T_out, points_world=P, error_px=np.sqrt(np.sum(res ** 2, axis=1)),
                        success=bool(cost <= cost0), message=message, cost_before=cost0, cost_after=cost,
                        evaluations=iterations)


class _Problem:
    """Residuals and the Schur-complement step of one window (index arrays fixed at build; kernels)."""

    def __init__(self, kf, pt, uv, ur_obs, fixed, K, baseline_m, cx_right, huber_px, n_points):
        self.kf, self.pt, self.uv = kf, pt, np.ascontiguousarray(uv)
        self.stereo = np.isfinite(ur_obs)
        self.ur = np.where(self.stereo, ur_obs, 0.0)
        self.intrinsics = (float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]))
        self.b, self.cxr, self.delta = baseline_m, cx_right, huber_px
        self.free = np.flatnonzero(~fixed)
        slot = np.full(len(fixed), -1, dtype=np.int64)
        slot[self.free] = np.arange(len(self.free))
        self.slot, self.obs_slot = slot, slot[kf]
        order = np.argsort(pt, kind="stable")                    # observations grouped by landmark
        self.point_obs = order
        self.point_start = np.searchsorted(pt[order], np.arange(n_points + 1))
        F, n = len(self.free), len(kf)
        self.Hpp, self.gp = np.empty((F, 6, 6)), np.empty((F, 6))
        self.Hll, self.gl = np.empty((n_points, 3, 3)), np.empty((n_points, 3))
        self.Hpl, self.Hll_inv = np.empty((n, 6, 3)), np.empty((n_points, 3, 3))

    def residuals(self, rvecs, tvecs, P):
        """Residuals (n, 3) (the right column 0 for mono observations) and the robust cost."""
        res = np.empty((len(self.kf), 3))
        fx, fy, cx, cy = self.intrinsics
        cost = window_residuals(rotations_from_rvecs(rvecs), tvecs, P, self.kf, self.pt, self.uv, self.ur,
                                self.stereo, fx, fy, cx, cy, self.cxr, self.b, self.delta, res)
        return res, cost

    def step(self, rvecs, tvecs, P, res, lam):
        """The damped Gauss-Newton step (IRLS Huber weights), landmarks eliminated (Schur complement)."""
        R = rotations_from_rvecs(rvecs)
        fx, fy, _, _ = self.intrinsics
        window_normal_equations(R, rotation_jacobian_factor(rvecs, R), tvecs, P, self.kf, self.pt, self.slot,
                                self.stereo, res, fx, fy, self.b, self.delta, self.Hpp, self.gp, self.Hll, self.gl,
                                self.Hpl)
        F = len(self.free)
        S = np.zeros((F, F, 6, 6))
        d6, f = np.arange(6), np.arange(F)
        damped = self.Hpp.copy()
        damped[:, d6, d6] += lam * self.Hpp[:, d6, d6] + 1e-9       # Marquardt: the diagonal times 1 + lam
        S[f, f] = damped
        bs = self.gp.copy()
        if not window_schur(self.Hll, self.gl, self.Hpl, self.obs_slot, self.point_start, self.point_obs, lam, S, bs,
                            self.Hll_inv):
            return None
        try:
            dp = np.linalg.solve(S.swapaxes(1, 2).reshape(6 * F, 6 * F), -bs.ravel()).reshape(F, 6)
        except np.linalg.LinAlgError:
            return None
        dl = np.empty_like(P)
        window_back_substitute(self.Hll_inv, self.gl, self.Hpl, self.obs_slot, self.pt, dp, dl)
        return dp, dl

    def apply(self, rvecs, tvecs, P, dp, dl):
        r, t = rvecs.copy(), tvecs.copy()
        r[self.free] += dp[:, :3]
        t[self.free] += dp[:, 3:]
        return r, t, P + dl


@dataclass
class Keyframe:
    """A keyframe of the window: its ``frame`` index, ``T_world_from_cam`` (refined while in the
    window), left ``image`` (dropped when it leaves the tracker's archive), and per feature its
    ``landmark`` id (-1: dropped as an outlier), left ``uv`` and right column ``u_right`` (NaN: no
    stereo match; corrected by the tracker's learnt disparity row and column terms,
    ``disparity_slopes_px``, at the time). When it leaves the window, ``points_cam`` holds its
    valid features' landmarks in its camera frame (the window drops them) and ``median_depth_m``
    their median depth.
    """

    frame: int
    T_world_from_cam: np.ndarray
    image: np.ndarray | None
    landmark: np.ndarray
    uv: np.ndarray
    u_right: np.ndarray
    points_cam: np.ndarray | None = None
    median_depth_m: float = 0.0
    disparity_slopes_px: np.ndarray = field(default_factory=lambda: np.zeros(2))

    @property
    def valid(self) -> np.ndarray:
        return self.landmark >= 0


class LocalMap:
    """The sliding window: the last ``size`` keyframes, the landmarks they observe and their refinement.

    Landmarks have global integer ids (``ids`` sorted, positions ``xyz``); those no keyframe of the
    window observes are dropped when a keyframe leaves. ``K``, ``baseline_m`` and ``cx_right_px``
    are the rig; ``fixed``, ``huber_px`` and ``iterations`` go to :func:`refine_window`;
    observations farther than ``outlier_px`` from their landmark's projection after it are dropped.
    """

    def __init__(self, K, baseline_m: float, cx_right_px: float, *, size: int, fixed: int, huber_px: float,
                 iterations: int, outlier_px: float) -> None:
        self.K, self.baseline_m, self.cx_right_px = np.asarray(K, dtype=np.float64), float(baseline_m), cx_right_px
        self.size, self.fixed, self.huber_px = size, fixed, huber_px
        self.iterations, self.outlier_px = iterations, outlier_px
        self.keyframes: list[Keyframe] = []
        self.ids = np.empty(0, np.int64)
        self.xyz = np.empty((0, 3))
        self._next_id = 0

    def clear(self) -> list[Keyframe]:
        """Drop every keyframe and landmark; returns the keyframes dropped (their landmarks kept in them)."""
        gone = self._retire(self.keyframes)
        self.keyframes = []
        self.ids = np.empty(0, np.int64)
        self.xyz = np.empty((0, 3))
        return gone

    def _retire(self, keyframes: list[Keyframe]) -> list[Keyframe]:
        """Keyframes leaving the window keep their landmarks in their own camera frame."""
        for kf in keyframes:
            points = self.points(kf.landmark[kf.valid])
            kf.points_cam = transform_points(np.linalg.inv(kf.T_world_from_cam), points)
            kf.median_depth_m = float(np.median(kf.points_cam[:, 2])) if len(points) else 0.0
        return keyframes

    def add_landmarks(self, points_world: np.ndarray) -> np.ndarray:
        """New landmarks; returns their ids."""
        ids = np.arange(self._next_id, self._next_id + len(points_world), dtype=np.int64)
        self._next_id += len(points_world)
        self.ids = np.concatenate([self.ids, ids])
        self.xyz = np.concatenate([self.xyz, np.asarray(points_world, dtype=np.float64).reshape(-1, 3)])
        return ids

    def points(self, ids: np.ndarray) -> np.ndarray:
        """World positions (N, 3) of landmark ids (all must exist)."""
        return self.xyz[np.searchsorted(self.ids, ids)]

    def add_keyframe(self, keyframe: Keyframe) -> list[Keyframe]:
        """Append a keyframe; returns the keyframes that left the window (with their landmarks)."""
        self.keyframes.append(keyframe)
        gone = self._retire(self.keyframes[:-self.size]) if len(self.keyframes) > self.size else []
        if gone:
            self.keyframes = self.keyframes[-self.size:]
            seen = np.unique(np.concatenate([kf.landmark[kf.valid] for kf in self.keyframes]))
            keep = np.isin(self.ids, seen)
            self.ids, self.xyz = self.ids[keep], self.xyz[keep]
        return gone

    def refine(self) -> WindowResult | None:
        """Bundle-adjust the window (landmarks seen by two keyframes or more); None with fewer than two
        keyframes or nothing shared. Poses, landmarks and outlier observations are updated in place."""
        if len(self.keyframes) < 2:
            return None
        kf_idx = np.concatenate([np.full(int(kf.valid.sum()), k) for k, kf in enumerate(self.keyframes)])
        lm = np.concatenate([kf.landmark[kf.valid] for kf in self.keyframes])
        uv = np.concatenate([kf.uv[kf.valid] for kf in self.keyframes]).astype(np.float64)
        ur = np.concatenate([kf.u_right[kf.valid] for kf in self.keyframes])
        shared, count = np.unique(lm, return_counts=True)
        shared = shared[count >= 2]
        use = np.isin(lm, shared)
        if not use.any():
            return None
        kf_idx, lm, uv, ur = kf_idx[use], lm[use], uv[use], ur[use]
        point = np.searchsorted(shared, lm)
        fixed = np.arange(len(self.keyframes)) < min(self.fixed, len(self.keyframes) - 1)
        T = np.stack([np.linalg.inv(kf.T_world_from_cam) for kf in self.keyframes])
        result = refine_window(T, self.points(shared), obs_keyframe=kf_idx, obs_point=point, obs_uv=uv,
                               obs_u_right=ur, fixed=fixed, K=self.K, baseline_m=self.baseline_m,
                               cx_right_px=self.cx_right_px, huber_px=self.huber_px,
                               max_iterations=self.iterations)
        if not result.success:
            return result
        for kf, T_cam_from_world in zip(self.keyframes, result.T_cam_from_world):
            # the landmarks only this keyframe sees (not refined) move with it: they were made from its pair
            own = kf.landmark[kf.valid]
            own = own[~np.isin(own, shared)]
            if len(own):
                rows = np.searchsorted(self.ids, own)
                moved = np.linalg.inv(T_cam_from_world) @ np.linalg.inv(kf.T_world_from_cam)
                self.xyz[rows] = transform_points(moved, self.xyz[rows])
            kf.T_world_from_cam = np.linalg.inv(T_cam_from_world)
        self.xyz[np.searchsorted(self.ids, shared)] = result.points_world
        bad = result.error_px > self.outlier_px
        for k, kf in enumerate(self.keyframes):
            drop = lm[bad & (kf_idx == k)]
            if len(drop):
                kf.landmark[np.isin(kf.landmark, drop)] = -1
        return result
