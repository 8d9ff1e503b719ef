"""Odometry on roads it was not tuned on: a rig whose disparity is off by a pixel, a frame that
cannot be placed, a reference keyframe that fails, and metrics that compare one body with evo's
numbers."""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from mrstereo.odometry import KEYFRAME, LOST, OdometryConfig, StereoOdometry
from mrstereo.odometry.trajectory import moved_to_body, read_tum, rpe_segments, trajectory_metrics
from mrstereo.transforms import T_from_planar, T_from_rvec_t
from mrstereo.world.paths import speed_path
from mrstereo.world.render import render_stereo_frame
from mrstereo.world.street import street_world

DATA = Path(__file__).parent / "data" / "odometry_rpe"


@pytest.fixture(scope="module")
def drive():
    """24 frames of the street world speeding up to 1 m per frame (10 m/s at 12.5 m/s^2), turning up to 3 degrees per frame."""
    world = street_world(3, width=320, height=240, length_m=40.0)
    poses = speed_path(24, step_m=1.0, standstill_frames=0, accel_frames=8, turn_rad_per_frame=math.radians(3.0))
    frames = [render_stereo_frame(world.scene, world.stereo, pose=tuple(p), seed=k, supersample=1,
                                  sensors=world.sensors) for k, p in enumerate(poses)]
    truth = np.stack([T_from_planar(*p) for p in poses])
    return world, truth, [(f.left_rect, f.right_rect) for f in frames]


def _run(world, truth, pairs, stereo=None, **config):
    tracker = StereoOdometry(stereo or world.stereo, truth[0], OdometryConfig(**config))
    mount = world.stereo.mount.T_base_from_rectified(world.stereo.left.R)
    status = [tracker.step(left, right, T_base_from_cam=mount, stamp_s=0.1 * k).status
              for k, (left, right) in enumerate(pairs)]
    return tracker, status, tracker.trajectory()


def test_disparity_offset_is_learnt_from_the_motion(drive):
    """The calibration's right principal point 1 px off (every depth too far, far ones most): without
    the offset learnt the path is bent and the ATE is ~5 %; learnt, the offset comes out near 1 px."""
    world, truth, pairs = drive
    P = world.stereo.right.P.copy()
    P[0, 2] -= 1.0
    wrong = dataclasses.replace(world.stereo, right=dataclasses.replace(world.stereo.right, P=P))
    fixed, _, T_fixed = _run(world, truth, pairs, wrong, calibrate_disparity_offset=False)
    learnt, status, T_learnt = _run(world, truth, pairs, wrong)
    assert LOST not in status
    assert 0.6 < learnt._offset_px < 1.3 and fixed._offset_px == 0.0
    ate_fixed = trajectory_metrics(T_fixed, truth).ate_percent
    ate_learnt = trajectory_metrics(T_learnt, truth).ate_percent
    assert ate_fixed > 3.0 and ate_learnt < ate_fixed / 3
    # a right rig learns (almost) nothing
    right, _, _ = _run(world, truth, pairs)
    assert abs(right._offset_px) < 0.2


def test_one_unplaceable_frame_is_no_jump(drive):
    """A blank pair in the middle: that frame is lost (the prediction), the next ones are measured
    again against the window's keyframes, and the trajectory after it stays on the truth."""
    world, truth, pairs = drive
    blank = np.full_like(pairs[0][0], 128)
    broken = list(pairs)
    broken[12] = (blank, blank)
    _, status, T = _run(world, truth, broken)
    assert [k for k, s in enumerate(status) if s == LOST] == [12]
    err = np.linalg.norm(T[13:, :3, 3] - truth[13:, :3, 3], axis=1)
    assert err.max() < 0.25


def test_a_failed_reference_is_relocalized_then_retried_from_scratch(drive, monkeypatch):
    """The reference keyframe's tracking forced to fail on frame 10: the frame is placed against
    another keyframe of the window; with every keyframe failing, from fresh features PnP'd into the
    reference keyframe's image (a keyframe that starts a new window, at the measured pose)."""
    world, truth, pairs = drive
    original = StereoOdometry._track

    def failing(everything):
        def track(self, left, T_pred, dt, kf=None):
            if self._n_frames == 10 and (everything or kf is None):
                return LOST, None, 0, 0, None
            return original(self, left, T_pred, dt, kf)
        return track

    for everything, expected in ((False, None), (True, KEYFRAME)):
        monkeypatch.setattr(StereoOdometry, "_track", failing(everything))
        _, status, T = _run(world, truth, pairs)
        assert LOST not in status
        if expected is not None:
            assert status[10] == expected
        err = np.linalg.norm(T[:, :3, 3] - truth[:, :3, 3], axis=1)
        assert err[10] < 0.1 and err.max() < 0.3


def test_rpe_matches_evo():
    """``evo_rpe tum truth.txt estimate.txt --delta D --delta_unit m --pairs_from_reference`` (evo
    1.38.1) on the files in tests/data/odometry_rpe: RMSE of the translation part (m) and of the
    angle (deg); ``evo_ape ... -a``: 0.072291 m."""
    _, Q = read_tum(DATA / "truth.txt")
    _, P = read_tum(DATA / "estimate.txt")
    for delta, trans_m, angle_deg in ((1.0, 0.055587, 2.645370), (0.5, 0.029358, 1.840143)):
        m = trajectory_metrics(P, Q, delta_m=delta)
        assert m.rpe_translation_per_m * delta == pytest.approx(trans_m, abs=2e-6)
        assert m.rpe_rotation_deg_per_m * delta == pytest.approx(angle_deg, abs=2e-6)
    assert trajectory_metrics(P, Q).ate_rmse_m == pytest.approx(0.072291, abs=2e-6)
    assert rpe_segments(Q[:3], 100.0) == [0]


def test_estimate_moved_to_the_truths_body():
    """A hand-held body (EuRoC's) and a robot base on the same camera: the base's exact poses compared
    with the body's truth give a large rotation RPE; moved to the body through the mounts, none."""
    rng = np.random.default_rng(3)
    T_body_from_cam = T_from_rvec_t(np.array([0.3, -1.2, 0.5]), np.array([-0.02, 0.06, 0.01]))
    T_base_from_cam = T_from_rvec_t(np.array([-1.2, 0.0, -1.2]), np.array([0.1, 0.0, 0.5]))
    body = [np.eye(4)]
    for _ in range(40):
        body.append(body[-1] @ T_from_rvec_t(rng.normal(0, 0.05, 3), np.array([0.1, 0.0, 0.0]) + rng.normal(0, 0.02, 3)))
    body = np.stack(body)
    world_shift = T_from_rvec_t(np.array([0.0, 0.0, 0.4]), np.array([2.0, -1.0, 0.3]))   # another start
    base = world_shift @ body @ T_body_from_cam @ np.linalg.inv(T_base_from_cam)
    assert trajectory_metrics(base, body).rpe_rotation_deg_per_m > 5.0           # two bodies compared
    moved = moved_to_body(base, T_base_from_cam, T_body_from_cam, body[0])
    np.testing.assert_allclose(moved, body, atol=1e-9)
    assert trajectory_metrics(moved, body).rpe_rotation_deg_per_m < 1e-6
