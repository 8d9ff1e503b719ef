"""Windowed refinement (bundle adjustment): known answers on small synthetic problems, the sliding window."""
from __future__ import annotations

import numpy as np
import pytest

from mrstereo.odometry.window import Keyframe, LocalMap, refine_window
from mrstereo.transforms import T_from_rvec_t, rotation_jacobian_factor, rotations_from_rvecs, transform_points

K = np.array([[400.0, 0.0, 330.0], [0.0, 410.0, 235.0], [0.0, 0.0, 1.0]])     # off-centre, fx != fy
BASELINE = 0.3


def _problem(rng, n_keyframes=5, n_points=400, stereo_share=0.8):
    """Cameras moving forward and turning left; points in front; every visible projection observed."""
    T = np.stack([np.linalg.inv(T_from_rvec_t([0.0, -0.02 * k, 0.01 * k], [0.1 * k, 0.0, 1.0 * k]))
                  for k in range(n_keyframes)])
    X = np.column_stack([rng.uniform(-8, 8, n_points), rng.uniform(-2, 1.5, n_points),
                         rng.uniform(4, 40, n_points)])
    obs = []
    for k in range(n_keyframes):
        Xc = X @ T[k, :3, :3].T + T[k, :3, 3]
        u = K[0, 0] * Xc[:, 0] / Xc[:, 2] + K[0, 2]
        v = K[1, 1] * Xc[:, 1] / Xc[:, 2] + K[1, 2]
        ur = K[0, 0] * (Xc[:, 0] - BASELINE) / Xc[:, 2] + K[0, 2]
        seen = (Xc[:, 2] > 1) & (u > 0) & (u < 660) & (v > 0) & (v < 470)
        for j in np.flatnonzero(seen):
            obs.append((k, j, u[j], v[j], ur[j] if rng.uniform() < stereo_share else np.nan))
    obs = np.array(obs)
    return T, X, obs[:, 0].astype(int), obs[:, 1].astype(int), obs[:, 2:4], obs[:, 4]


def _perturbed(rng, T, X, fixed, pose_m=0.05, pose_rad=0.005, point_m=0.2):
    T0 = T.copy()
    for k in np.flatnonzero(~fixed):
        T0[k] = T_from_rvec_t(rng.normal(0, pose_rad, 3), rng.normal(0, pose_m, 3)) @ T[k]
    return T0, X + rng.normal(0, point_m, X.shape)


def test_rotation_helpers_match_opencv_and_finite_differences():
    import cv2

    rng = np.random.default_rng(0)
    r = rng.normal(size=(6, 3))
    r[0] = 0.0
    r[1] = [1e-9, 0.0, 0.0]
    R = rotations_from_rvecs(r)
    for k in range(6):
        np.testing.assert_allclose(R[k], cv2.Rodrigues(r[k])[0], atol=1e-14)
    p = rng.normal(size=(6, 3))
    p_cross = np.cross(np.eye(3)[None, :, :], p[:, None, :])      # rows e_i x p: the matrix [p]x
    J = -(R @ p_cross) @ rotation_jacobian_factor(r, R)          # d(R(r) p)/dr = -R [p]x M
    h = 1e-6
    for a in range(3):
        d = np.zeros(3)
        d[a] = h
        numeric = (np.einsum("nij,nj->ni", rotations_from_rvecs(r + d), p)
                   - np.einsum("nij,nj->ni", rotations_from_rvecs(r - d), p)) / (2 * h)
        np.testing.assert_allclose(J[:, :, a], numeric, atol=1e-8)


def test_exact_observations_recover_the_poses_and_points():
    rng = np.random.default_rng(1)
    T, X, kf, pt, uv, ur = _problem(rng)
    fixed = np.array([True, False, False, False, False])
    T0, X0 = _perturbed(rng, T, X, fixed)
    result = refine_window(T0, X0, obs_keyframe=kf, obs_point=pt, obs_uv=uv, obs_u_right=ur, fixed=fixed, K=K,
                           baseline_m=BASELINE)
    assert result.success and result.cost_after < 1e-8 < result.cost_before
    np.testing.assert_allclose(result.T_cam_from_world, T, atol=1e-6)
    constrained = np.bincount(pt, minlength=len(X)) + np.bincount(pt[np.isfinite(ur)], minlength=len(X)) >= 2
    np.testing.assert_allclose(result.points_world[constrained], X[constrained], atol=1e-4)
    assert result.error_px.max() < 1e-4
    np.testing.assert_array_equal(result.T_cam_from_world[0], T0[0])          # the gauge stays


def test_noise_and_outliers_leave_millimetres():
    rng = np.random.default_rng(2)
    T, X, kf, pt, uv, ur = _problem(rng, n_keyframes=6)
    uv = uv + rng.normal(0, 0.3, uv.shape)
    ur = ur + rng.normal(0, 0.3, ur.shape)
    bad = rng.uniform(size=len(kf)) < 0.05                                    # 5 % wrong tracks
    uv[bad] += rng.choice([-1, 1], (bad.sum(), 2)) * rng.uniform(5, 30, (bad.sum(), 2))
    fixed = np.arange(6) < 2
    T0, X0 = _perturbed(rng, T, X, fixed)
    result = refine_window(T0, X0, obs_keyframe=kf, obs_point=pt, obs_uv=uv, obs_u_right=ur, fixed=fixed, K=K,
                           baseline_m=BASELINE, huber_px=1.0)
    before = [np.linalg.norm((T0[k] @ np.linalg.inv(T[k]))[:3, 3]) for k in range(6)]
    after = [np.linalg.norm((result.T_cam_from_world[k] @ np.linalg.inv(T[k]))[:3, 3]) for k in range(6)]
    assert max(before) > 0.03 and max(after) < 0.01                           # 3-8 cm -> under 1 cm
    # the wrong tracks stand out by their error, the right ones fit
    assert np.median(result.error_px[bad]) > 3.0 and np.percentile(result.error_px[~bad], 95) < 1.5


def test_without_stereo_the_scale_is_free_and_stereo_fixes_it():
    """Mono observations with one fixed keyframe cannot tell the scale; the right column can."""
    rng = np.random.default_rng(3)
    T, X, kf, pt, uv, ur = _problem(rng, stereo_share=1.0)
    fixed = np.array([True, False, False, False, False])
    T0 = T.copy()
    T0[1:, :3, 3] *= 1.1                                                      # 10 % too long
    centres = np.stack([-Tk[:3, :3].T @ Tk[:3, 3] for Tk in T0])
    X0 = X * 1.1
    stereo = refine_window(T0, X0, obs_keyframe=kf, obs_point=pt, obs_uv=uv, obs_u_right=ur, fixed=fixed, K=K,
                           baseline_m=BASELINE)
    np.testing.assert_allclose(stereo.T_cam_from_world, T, atol=1e-6)
    mono = refine_window(T0, X0, obs_keyframe=kf, obs_point=pt, obs_uv=uv, obs_u_right=np.full_like(ur, np.nan),
                         fixed=fixed, K=K, baseline_m=BASELINE)
    assert mono.cost_after < 1e-8                                            # fits exactly, at the wrong scale
    mono_centres = np.stack([-Tk[:3, :3].T @ Tk[:3, 3] for Tk in mono.T_cam_from_world])
    np.testing.assert_allclose(mono_centres, centres, atol=1e-6)


def test_bad_input():
    rng = np.random.default_rng(4)
    T, X, kf, pt, uv, ur = _problem(rng, n_keyframes=3, n_points=50)
    kw = dict(obs_keyframe=kf, obs_point=pt, obs_uv=uv, obs_u_right=ur, K=K, baseline_m=BASELINE)
    with pytest.raises(ValueError, match="fixed"):
        refine_window(T, X, fixed=np.zeros(3, bool), **kw)
    with pytest.raises(ValueError, match="T_cam_from_world"):
        refine_window(T[:, :3], X, fixed=np.ones(3, bool), **kw)
    with pytest.raises(ValueError, match="index outside"):
        refine_window(T, X[:10], fixed=np.array([True, False, False]), **kw)
    with pytest.raises(ValueError, match="baseline_m"):
        refine_window(T, X, fixed=np.array([True, False, False]), **{**kw, "baseline_m": -1.0})


def test_local_map_slides_and_drops_outliers():
    rng = np.random.default_rng(5)
    T, X, kf, pt, uv, ur = _problem(rng, n_keyframes=4, n_points=200)
    lm = LocalMap(K, BASELINE, K[0, 2], size=3, fixed=1, huber_px=1.0, iterations=10, outlier_px=3.0)
    ids = lm.add_landmarks(X + rng.normal(0, 0.05, X.shape))
    wrong = None
    for k in range(4):
        sel = kf == k
        obs_uv = uv[sel].astype(np.float32).copy()
        if k == 2:
            wrong = ids[pt[sel]][:5]
            obs_uv[:5] += 20.0                                               # five wrong tracks
        if k == 3:
            lm_points_then = lm.points(lm.keyframes[0].landmark[lm.keyframes[0].valid])
        gone = lm.add_keyframe(Keyframe(frame=k, T_world_from_cam=np.linalg.inv(T[k]) if k == 0 else
                                        np.linalg.inv(T_from_rvec_t(rng.normal(0, 0.003, 3), rng.normal(0, 0.03, 3))
                                                      @ T[k]),
                                        image=np.zeros((2, 2), np.uint8), landmark=ids[pt[sel]].copy(), uv=obs_uv,
                                        u_right=ur[sel]))
        lm.refine()
        if k == 3:
            assert [g.frame for g in gone] == [0]
            # it keeps its landmarks in its own camera frame (the window drops them)
            g = gone[0]
            assert len(g.points_cam) == g.valid.sum() and g.median_depth_m == pytest.approx(
                np.median(g.points_cam[:, 2]))
            np.testing.assert_allclose(transform_points(g.T_world_from_cam, g.points_cam), lm_points_then, atol=1e-9)
    assert [kf_.frame for kf_ in lm.keyframes] == [1, 2, 3]
    for kf_ in lm.keyframes:                                                 # 3 cm off -> within 5 mm
        np.testing.assert_allclose(np.linalg.inv(kf_.T_world_from_cam), T[kf_.frame], atol=5e-3)
    dropped = ids[pt[kf == 2]][lm.keyframes[1].landmark == -1]               # the wrong tracks are out
    assert np.isin(wrong, dropped).all() and len(dropped) <= 10
    # landmarks no keyframe of the window sees are forgotten
    seen = np.unique(np.concatenate([k_.landmark[k_.valid] for k_ in lm.keyframes]))
    np.testing.assert_array_equal(np.sort(lm.ids), seen)
