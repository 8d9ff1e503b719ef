"""Odometry at car speed in the street world: from a standstill to 1.5 m per frame with 3 degree turns,
and plausibility limits that come from the stamps' time steps, not from a fixed step."""
from __future__ import annotations

import math

import numpy as np
import pytest

from mrstereo.odometry import KEYFRAME, LOST, TRACKED, OdometryConfig, visual_odometry
from mrstereo.transforms import T_from_planar
from mrstereo.world.paths import speed_path
from mrstereo.world.render import render_stereo_frame
from mrstereo.world.street import street_world


@pytest.fixture(scope="module")
def street():
    world = street_world(3, width=256, height=192, length_m=30.0)
    poses = speed_path(12, step_m=1.5, standstill_frames=2, accel_frames=5, turn_rad_per_frame=math.radians(3.0))
    frames = [render_stereo_frame(world.scene, world.stereo, pose=tuple(p), seed=k, supersample=1,
                                  sensors=world.sensors) for k, p in enumerate(poses)]
    return world, poses, [(f.left_rect, f.right_rect) for f in frames]


def _run(world, pairs, pose0, stamps, **config):
    mount = world.stereo.mount.T_base_from_rectified(world.stereo.left.R)
    return visual_odometry(pairs, world.stereo, T_base_from_cam=mount,
                           T_world_from_base0=T_from_planar(*pose0), stamps_s=stamps,
                           config=OdometryConfig(**config))


def test_speed_path():
    poses = speed_path(40, step_m=1.5, standstill_frames=3, accel_frames=10, turn_rad_per_frame=math.radians(3.0))
    steps = np.hypot(*np.diff(poses[:, :2], axis=0).T)
    np.testing.assert_allclose(steps[:2], 0.0, atol=1e-12)                       # standing still
    assert np.all(np.diff(steps[2:13]) > 0) and steps[13:] == pytest.approx(1.5, abs=2e-3)
    turns = np.degrees(np.abs(np.diff(poses[:, 2])))
    assert 2.8 < turns.max() <= 3.0 + 1e-6                                       # 3 degrees per frame at most
    assert poses[:, 1].min() > -1e-9 and poses[:, 1].max() <= 2.0 + 1e-6         # within max_offset_m
    travel = np.arctan2(*np.diff(poses[13:, :2], axis=0).T[::-1])                # heading follows the path
    assert np.abs(travel - (poses[13:-1, 2] + poses[14:, 2]) / 2).max() < 2e-3
    np.testing.assert_allclose(speed_path(5, step_m=1.0, turn_rad_per_frame=0.0)[:, 1:], 0.0)
    with pytest.raises(ValueError, match="step_m"):
        speed_path(5, step_m=0.0)


def test_tracks_from_standstill_to_car_speed_through_turns(street):
    world, poses, pairs = street
    result = _run(world, pairs, poses[0], 0.1 * np.arange(len(pairs)))
    assert result.success, result.message
    np.testing.assert_allclose(result.stamps_s, 0.1 * np.arange(len(pairs)))
    np.testing.assert_allclose(result.T_world_from_base[1], result.T_world_from_base[0], atol=1e-3)   # at rest
    err = np.hypot(*(result.poses[:, :2] - poses[:, :2]).T)
    assert err.max() < 0.2                                                        # over 10.5 m at 15 m/s
    yaw_err = np.abs(np.remainder(result.poses[:, 2] - poses[:, 2] + math.pi, math.tau) - math.pi)
    assert np.degrees(yaw_err).max() < 0.5
    # the online poses (as known at each frame) are the refined ones' first estimate
    assert np.hypot(*(result.T_world_from_base_online[:, :2, 3] - poses[:, :2]).T).max() < 0.3


def test_plausibility_limits_come_from_the_time_step(street):
    """1.5 m from a standstill: impossible in 0.1 s (150 m/s^2), an easy start over a second."""
    world, poses, pairs = street
    k = int(np.argmin(np.abs(poses[:, 0] - 1.5)))                                 # the frame 1.5 m on
    jump = [pairs[0], pairs[0], pairs[k]]
    fast = _run(world, jump, poses[0], [0.0, 0.1, 0.2])
    assert fast.status[2] == LOST and "motion model" in fast.message
    slow = _run(world, jump, poses[0], [0.0, 0.1, 1.1])
    assert slow.status[2] in (TRACKED, KEYFRAME)
    assert np.hypot(*(slow.poses[2, :2] - poses[k, :2])) < 0.05
    # the absolute limits too: 1.5 m in 1 s is over a 1 m/s speed limit
    capped = _run(world, jump, poses[0], [0.0, 0.1, 1.1], max_speed_mps=1.0)
    assert capped.status[2] == LOST
    with pytest.raises(ValueError, match="increasing"):
        _run(world, jump, poses[0], [0.0, 0.1, 0.1])
