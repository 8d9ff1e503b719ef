"""Odometry sequences of the synthetic world: paths, drifted odometry, the manifest's true poses."""
from __future__ import annotations

import math

import numpy as np
import pytest

from mrstereo.recordings.manifest import read_manifest
from mrstereo.world.dataset import write_synthetic_dataset
from mrstereo.world.paths import drifted_poses, sequence_path


@pytest.mark.parametrize("kind", ["front", "s-curve"])
def test_sequence_path_steps(kind):
    poses = sequence_path(kind, 91, step_m=0.1)
    steps = np.hypot(*np.diff(poses[:, :2], axis=0).T)
    np.testing.assert_allclose(steps, 0.1, atol=1e-3)          # chords of a gentle curve
    np.testing.assert_allclose(poses[0], [0, 0, 0], atol=1e-9)
    # heading is the direction of travel (a chord's direction is the mean of its ends' tangents)
    travel = np.arctan2(*np.diff(poses[:, :2], axis=0).T[::-1])
    mid = (poses[:-1, 2] + poses[1:, 2]) / 2
    assert np.abs(np.remainder(travel - mid + math.pi, math.tau) - math.pi).max() < 0.03
    # it passes the box at x = 6.0..6.4 m (|y| < 0.25) on its right
    at_box = (poses[:, 0] > 5.9) & (poses[:, 0] < 6.5)
    assert (poses[at_box, 1] < -0.5).all()
    with pytest.raises(ValueError, match="do not fit"):
        sequence_path(kind, 500, step_m=0.1)
    with pytest.raises(ValueError, match="kind"):
        sequence_path("circle", 10)


def test_drifted_poses_scale_and_heading():
    true = sequence_path("front", 41, step_m=0.1)             # straight 4 m
    np.testing.assert_allclose(drifted_poses(true, scale_error=0.0, heading_drift_rad_per_m=0.0), true, atol=1e-12)
    scaled = drifted_poses(true, scale_error=0.03, heading_drift_rad_per_m=0.0)
    np.testing.assert_allclose(scaled[-1, 0], 4.0 * 1.03, atol=1e-9)
    turned = drifted_poses(true, scale_error=0.0, heading_drift_rad_per_m=math.radians(2))
    assert turned[-1, 2] == pytest.approx(math.radians(8.0), abs=1e-9)     # 2 deg/m over 4 m
    assert turned[-1, 1] > 0.05                                             # drifted to the left
    with pytest.raises(ValueError, match="poses"):
        drifted_poses(np.zeros((3, 2)), scale_error=0, heading_drift_rad_per_m=0)


def test_synthetic_sequence_with_drifted_odometry(tmp_path):
    out = write_synthetic_dataset(tmp_path / "seq", n_frames=4, width=160, height=120, supersample=1,
                                  path="s-curve", step_m=0.2, odometry_noise=(0.03, math.radians(2)),
                                  progress=False)
    manifest = read_manifest(out)
    true = np.array([f.true_pose for f in manifest.frames])
    given = np.array([f.pose for f in manifest.frames])
    np.testing.assert_allclose(true, sequence_path("s-curve", 4, step_m=0.2), atol=1e-6)
    np.testing.assert_allclose(given, drifted_poses(true, scale_error=0.03, heading_drift_rad_per_m=math.radians(2)),
                               atol=2e-6)
    assert all(f.pan_rad == 0.0 for f in manifest.frames)
    with pytest.raises(ValueError, match="path"):
        write_synthetic_dataset(tmp_path / "bad", n_frames=2, path="zigzag", progress=False)


def test_waypoint_path_and_randomized_front_sequence(tmp_path):
    from mrstereo.world.paths import waypoint_path
    from mrstereo.world.randomize import random_world

    way = np.array([[0.0, -0.2], [3.0, 0.3], [6.0, 0.0]])
    poses = waypoint_path(way, 51, step_m=0.1)
    steps = np.hypot(*np.diff(poses[:, :2], axis=0).T)
    np.testing.assert_allclose(steps, 0.1, atol=1e-3)
    np.testing.assert_allclose(poses[0, :2], way[0], atol=1e-9)
    travel = np.arctan2(*np.diff(poses[:, :2], axis=0).T[::-1])          # yaw follows the curve, smoothly
    assert np.abs(travel - (poses[:-1, 2] + poses[1:, 2]) / 2).max() < 0.01
    assert np.abs(np.diff(poses[:, 2])).max() < math.radians(2.0)
    assert poses[:, 1].min() >= -0.2 - 1e-9 and poses[:, 1].max() <= 0.3 + 1e-9      # no overshoot (PCHIP)
    with pytest.raises(ValueError, match="do not fit"):
        waypoint_path(way, 100, step_m=0.1)
    with pytest.raises(ValueError, match="waypoints_xy"):
        waypoint_path(way[:1], 3)
    out = write_synthetic_dataset(tmp_path / "r", seed=3, n_frames=3, width=64, height=48, supersample=1,
                                  path="front", randomize=True, odometry_noise=(0.03, math.radians(2)),
                                  progress=False)
    true = np.array([f.true_pose for f in read_manifest(out).frames])
    np.testing.assert_allclose(true, waypoint_path(random_world(3, width=64, height=48).waypoints_xy, 3), atol=1e-6)
    with pytest.raises(ValueError, match="s-curve"):
        write_synthetic_dataset(tmp_path / "bad", n_frames=2, path="s-curve", randomize=True, progress=False)
