"""Stereo visual odometry: known motion in the synthetic corridor, standing still, losses, bad input."""
from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from mrstereo.odometry import LOST, OdometryConfig, StereoOdometry, visual_odometry
from mrstereo.transforms import (T_from_planar, T_from_rvec_t, planar_from_T, quaternion_from_rotation,
                                 rotation_angle_rad, rotation_from_quaternion, rvec_t_from_T)
from mrstereo.world import default_scene
from mrstereo.world.paths import sequence_path
from mrstereo.world.render import default_stereo, render_stereo_frame


@pytest.fixture(scope="module")
def corridor():
    """Eight frames 0.1 m apart through the S-bend (heading changes by up to 4 degrees a step)."""
    stereo = default_stereo(320, 240)
    scene = default_scene(3)
    poses = sequence_path("s-curve", 60)[44:52]
    frames = [render_stereo_frame(scene, stereo, pose=p, seed=k, supersample=1) for k, p in enumerate(poses)]
    return stereo, poses, frames


def _run(stereo, frames, poses, **kw):
    mount = stereo.mount.T_base_from_rectified(stereo.left.R)
    return visual_odometry([(f.left_rect, f.right_rect) for f in frames], stereo, T_base_from_cam=mount,
                           T_world_from_base0=T_from_planar(*poses[0]), **kw)


def test_se3_round_trips():
    rng = np.random.default_rng(1)
    for _ in range(5):
        rvec, t = rng.normal(size=3), rng.normal(size=3)
        T = T_from_rvec_t(rvec, t)
        q = quaternion_from_rotation(T[:3, :3])
        assert q[3] >= 0 and abs(np.linalg.norm(q) - 1) < 1e-12
        np.testing.assert_allclose(rotation_from_quaternion(q), T[:3, :3], atol=1e-12)
        r2, t2 = rvec_t_from_T(T)
        np.testing.assert_allclose(T_from_rvec_t(r2, t2), T, atol=1e-12)
        assert rotation_angle_rad(T[:3, :3]) == pytest.approx(np.linalg.norm(rvec) if np.linalg.norm(rvec) <= math.pi
                                                               else 2 * math.pi - np.linalg.norm(rvec), abs=1e-9)
    np.testing.assert_allclose(planar_from_T(T_from_planar(1.5, -0.25, 2.0)), [1.5, -0.25, 2.0], atol=1e-12)
    # a quarter turn about z: (0, 0, sin 45, cos 45)
    np.testing.assert_allclose(quaternion_from_rotation(T_from_planar(0, 0, math.pi / 2)[:3, :3]),
                               [0, 0, math.sqrt(0.5), math.sqrt(0.5)], atol=1e-12)
    with pytest.raises(ValueError, match="quaternion"):
        rotation_from_quaternion([0, 0, 0, 0])


def test_tracks_known_motion(corridor):
    stereo, poses, frames = corridor
    result = _run(stereo, frames, poses)
    assert result.success, result.message
    est = result.poses
    err_m = np.hypot(*(est[:, :2] - poses[:, :2]).T)
    assert err_m.max() < 0.01                                 # 1 cm over 0.7 m
    yaw_err = np.abs(np.remainder(est[:, 2] - poses[:, 2] + math.pi, math.tau) - math.pi)
    assert np.degrees(yaw_err).max() < 0.3
    # the base stays on the floor and level: z, roll, pitch come out of 6-DoF PnP unforced
    assert np.abs(result.T_world_from_base[:, 2, 3]).max() < 0.01
    assert np.abs(result.T_world_from_base[:, 2, :3] - [0, 0, 1]).max() < 0.005
    assert result.status[0] == "keyframe" and (result.n_inliers[1:] >= 20).all()


def test_depth_from_a_given_disparity(corridor):
    """Keyframe depth read from the (true) disparity map instead of the stereo search."""
    stereo, poses, frames = corridor
    result = _run(stereo, frames, poses, disparities=[f.disparity_px for f in frames])
    err_m = np.hypot(*(result.poses[:, :2] - poses[:, :2]).T)
    assert result.success and err_m.max() < 0.01


def test_standing_still_gives_no_motion(corridor):
    stereo, poses, frames = corridor
    same = _run(stereo, [frames[0]] * 20, poses)
    np.testing.assert_allclose(same.T_world_from_base, np.broadcast_to(same.T_world_from_base[0], (20, 4, 4)),
                               atol=1e-6)
    # new sensor noise every frame: jitter, never drift (one keyframe, tracked against it)
    scene, stereo_ = default_scene(3), stereo
    noisy = [render_stereo_frame(scene, stereo_, pose=poses[0], seed=100 + k, supersample=1) for k in range(6)]
    result = _run(stereo, noisy, poses)
    assert result.status.count("keyframe") == 1
    assert np.abs(result.T_world_from_base[:, :3, 3] - result.T_world_from_base[0, :3, 3]).max() < 0.002


def test_lost_frame_is_reported_and_predicted(corridor):
    stereo, poses, frames = corridor
    blank = np.full_like(frames[0].left_rect, 128)
    pairs = [(f.left_rect, f.right_rect) for f in frames]
    pairs.insert(4, (blank, blank))
    mount = stereo.mount.T_base_from_rectified(stereo.left.R)
    result = visual_odometry(pairs, stereo, T_base_from_cam=mount, T_world_from_base0=T_from_planar(*poses[0]))
    assert result.status[4] == LOST and not result.success and "1 of 9" in result.message
    # the motion model's prediction: the last step (0.1 m) again, where the next frame is seen
    assert np.hypot(*(result.poses[4, :2] - poses[4, :2])) < 0.01
    assert result.tracked[5:].all()
    est = np.delete(result.poses, 4, axis=0)
    assert np.hypot(*(est[:, :2] - poses[:, :2]).T).max() < 0.01      # tracking resumed on the keyframe


def test_bad_input(corridor):
    stereo, poses, frames = corridor
    tracker = StereoOdometry(stereo)
    mount = stereo.mount.T_base_from_rectified(stereo.left.R)
    small = cv2.resize(frames[0].left_rect, (160, 120))
    with pytest.raises(ValueError, match="calibration is 320x240"):
        tracker.step(small, small, T_base_from_cam=mount)
    with pytest.raises(ValueError, match="T_base_from_cam"):
        tracker.step(frames[0].left_rect, frames[0].right_rect, T_base_from_cam=np.eye(3))
    with pytest.raises(ValueError, match="disparity_px"):
        tracker.step(frames[0].left_rect, frames[0].right_rect, T_base_from_cam=mount, disparity_px=np.zeros((2, 2)))
    with pytest.raises(TypeError, match="stereo"):
        StereoOdometry("stereo.yaml")
    with pytest.raises(ValueError, match="min_inliers"):
        OdometryConfig(min_inliers=2)
    with pytest.raises(ValueError, match="keyframe_inlier_fraction"):
        OdometryConfig(keyframe_inlier_fraction=1.5)
    with pytest.raises(ValueError, match="empty"):
        visual_odometry([], stereo, T_base_from_cam=mount)
