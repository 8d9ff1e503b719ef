"""KITTI raw drives read directly: the rectified gray pair of P_rect_00/P_rect_01, real stamps, the OXTS
records as the base's true poses (the devkit's Mercator poses) and the imu -> velo -> cam mount; on the
real sample drive (2011_09_26_drive_0005_sync, 5 frames) and on OXTS records of a known path."""
from __future__ import annotations

import datetime
import json
import math
import shutil

import cv2
import numpy as np
import pytest

from mrstereo.cli import entry
from mrstereo.recordings.samples import data_root
from mrstereo.recordings import open_recording, read_kitti_raw, read_recording
from mrstereo.recordings.frames import RecordingSource
from mrstereo.recordings.kitti_raw import EARTH_RADIUS_M, is_kitti_raw, oxts_poses, oxts_velocity_positions
from mrstereo.recordings.layouts import layout_of

DRIVE = "2011_09_26_drive_0005_sync"


@pytest.fixture(scope="module")
def date():
    root = data_root() / "kitti_raw_sample" / "2011_09_26"
    if not (root / DRIVE).is_dir():
        pytest.skip(f"KITTI raw sample not found under {root} (set MRSTEREO_DATA)")
    return root


def _oxts(date, k):
    return np.loadtxt(date / DRIVE / "oxts" / "data" / f"{k:010d}.txt")


def test_calibration_is_the_rectified_gray_pair(date):
    m = read_kitti_raw(date)
    s = m.calibration
    assert m.layout == "KITTI raw" and m.root.name == DRIVE and len(m.frames) == 5
    assert s.size == (1242, 375)                                     # S_rect_00
    assert s.focal_px == pytest.approx(7.215377e+02)                 # P_rect_00
    assert s.left.P[0, 2] == pytest.approx(6.095593e+02) and s.left.P[1, 2] == pytest.approx(1.728540e+02)
    assert s.baseline_m == pytest.approx(3.875744e+02 / 7.215377e+02)  # -P_rect_01[0, 3] / fx: 0.537 m
    assert all(f.has_rectified and not f.has_raw for f in m.frames)
    assert m.frames[2].left_rect.name == "0000000002.png" and m.frames[2].right_rect.parent.parent.name == "image_01"


def test_stamps_are_the_cameras_utc_times(date):
    m = read_kitti_raw(date / DRIVE)
    first = datetime.datetime(2011, 9, 26, 13, 4, 32, 351950, tzinfo=datetime.timezone.utc).timestamp()
    assert m.frames[0].stamp_s == pytest.approx(first + 0.000000336, abs=1e-6)
    dt = np.diff(m.stamps_s)
    assert np.all((dt > 0.095) & (dt < 0.11)) and np.median(dt) == pytest.approx(0.1033, abs=1e-3)


def test_oxts_poses_start_at_identity_and_follow_the_car(date):
    m = read_kitti_raw(date)
    T = np.array([f.T_world_from_base_true for f in m.frames])
    np.testing.assert_allclose(T[0], np.eye(4), atol=1e-12)
    np.testing.assert_array_equal(T, [f.T_world_from_base for f in m.frames])       # the given poses too
    assert m.has_poses
    steps = np.diff(T[:, :3, 3], axis=0)
    assert np.all(steps[:, 0] > 0.25) and np.all(np.abs(steps[:, 1:]) < 0.05)        # straight ahead (REP 103 x)
    path = float(np.sum(np.linalg.norm(steps, axis=1)))
    assert path == pytest.approx(1.268, abs=0.002)                 # at the images' stamps (the records': 1.290 m)
    # the devkit's poses of the records: their great-circle distance (haversine on the mean earth radius)
    records = np.array([_oxts(date, k) for k in range(5)])
    devkit = float(np.sum(np.linalg.norm(np.diff(oxts_poses(records)[:, :3, 3], axis=0), axis=1)))
    lat, lon = np.radians(records[:, 0]), np.radians(records[:, 1])
    a = np.sin(np.diff(lat) / 2) ** 2 + np.cos(lat[:-1]) * np.cos(lat[1:]) * np.sin(np.diff(lon) / 2) ** 2
    great_circle = float(np.sum(2 * 6371000.0 * np.arcsin(np.sqrt(a))))
    assert devkit == pytest.approx(great_circle, rel=0.02)                         # 1.31 m vs 1.31 m (3-D)
    # the speeds of the records (vf, vl) over the OXTS stamps: 1.45 m; this drive's positions advance 11 %
    # less than its speeds (not RTK: pos_accuracy 0.49 m; the per-frame noise is noted)
    stamps = [datetime.datetime.fromisoformat(line[:26]).timestamp()
              for line in (date / DRIVE / "oxts" / "timestamps.txt").read_text().split("\n") if line]
    speed = [math.hypot(*_oxts(date, k)[8:10]) for k in range(5)]
    integrated = float(np.sum(np.diff(stamps) * (np.array(speed[1:]) + speed[:-1]) / 2))
    assert path == pytest.approx(integrated, rel=0.15)
    # the heading of the motion is the records' heading (yaw, east = 0, counter-clockwise)
    yaw = _oxts(date, 0)[5]
    ve, vn = _oxts(date, 0)[7], _oxts(date, 0)[6]
    assert math.atan2(vn, ve) == pytest.approx(yaw, abs=0.05)


def test_oxts_poses_of_a_known_path():
    """Records of a car at 49 deg N driving 10 m north per record, heading north (yaw pi/2), then turning
    to east (yaw 0) and driving 10 m east: poses 10 m forward, then 10 m to the right of the first heading."""
    lat0, lon0 = 49.0, 8.4
    records = []
    for k in range(3):
        records.append([lat0 + math.degrees(10.0 * k / EARTH_RADIUS_M), lon0, 100.0, 0.0, 0.0, math.pi / 2])
    lat2 = records[-1][0]
    dlon = math.degrees(10.0 / (EARTH_RADIUS_M * math.cos(math.radians(lat0))))
    records.append([lat2, lon0 + dlon, 101.0, 0.0, 0.0, 0.0])
    T = oxts_poses(np.array(records))
    np.testing.assert_allclose(T[0], np.eye(4), atol=1e-12)
    np.testing.assert_allclose(T[1][:3, 3], [10.0, 0.0, 0.0], atol=2e-4)
    np.testing.assert_allclose(T[2][:3, 3], [20.0, 0.0, 0.0], atol=2e-4)
    np.testing.assert_allclose(T[3][:3, 3], [20.0, -10.0, 1.0], atol=2e-3)            # east is right of north
    np.testing.assert_allclose(T[3][:3, 0], [0.0, -1.0, 0.0], atol=1e-9)              # now facing east


def _drive_with_records(date, tmp_path, records, record_s, image_s):
    """The sample's calibration and images with the given OXTS records and stamps (seconds after 13:04:32)."""
    copy = tmp_path / "2011_09_26"
    shutil.copytree(date, copy)
    drive = copy / DRIVE
    for k, rec in enumerate(records):
        (drive / "oxts" / "data" / f"{k:010d}.txt").write_text(" ".join(f"{v:.12g}" for v in rec) + "\n")
    for path, stamps in ((drive / "oxts" / "timestamps.txt", record_s), (drive / "image_00" / "timestamps.txt", image_s)):
        path.write_text("".join(f"2011-09-26 13:04:{32 + t:012.9f}\n" for t in stamps))
    return drive


def test_oxts_poses_are_moved_to_the_image_stamps(date, tmp_path):
    """A car driving north at 10 m/s, its records stamped +4, -3, +5, -2, 0 ms from the images (the synced
    records are the 100 Hz unit's nearest): the poses at the images' stamps are 1.0 m apart to 0.1 mm (the
    devkit's poses of the records' stamps are off by up to 7 cm); turning in place at 0.5 rad/s, the
    heading at the images' stamps. The velocities integrated give the positions: no noise noted."""
    image_s = 0.1 * np.arange(5)
    record_s = image_s + np.array([4, -3, 5, -2, 0]) * 1e-3
    lat0, lon0 = 49.0, 8.4
    records = []
    for t in record_s:
        rec = np.zeros(30)
        rec[:6] = [lat0 + math.degrees(10.0 * t / EARTH_RADIUS_M), lon0, 100.0, 0.0, 0.0, math.pi / 2]
        rec[6], rec[8] = 10.0, 10.0                                    # vn, vf
        records.append(rec)
    m = read_kitti_raw(_drive_with_records(date, tmp_path, records, record_s, image_s))
    x = np.array([f.T_world_from_base_true[:3, 3] for f in m.frames])
    np.testing.assert_allclose(x, np.column_stack([10.0 * image_s, np.zeros(5), np.zeros(5)]), atol=1e-4)
    devkit = oxts_poses(np.array(records))[:, :3, 3]
    assert np.abs(devkit[:, 0] - 10.0 * image_s).max() > 0.06
    np.testing.assert_allclose(oxts_velocity_positions(np.array(records), record_s), devkit, atol=1e-4)
    assert any("0.0 cm RMS per frame" in n and "5.0 ms off at most" in n for n in m.notes)
    # turning in place, 0.5 rad/s counter-clockwise (wz), the yaw of each record at its own stamp
    for rec, t in zip(records, record_s):
        rec[0], rec[5], rec[6], rec[8], rec[19] = lat0, math.pi / 2 + 0.5 * t, 0.0, 0.0, 0.5
    m = read_kitti_raw(_drive_with_records(date, tmp_path / "turn", records, record_s, image_s))
    yaw = [math.atan2(f.T_world_from_base_true[1, 0], f.T_world_from_base_true[0, 0]) for f in m.frames]
    np.testing.assert_allclose(yaw, 0.5 * image_s, atol=1e-6)      # (the devkit's: up to 2.5 mrad off)


def test_mount_from_the_calibration_chain(date):
    m = read_kitti_raw(date)
    T = m.mount.T_base_from_cam
    assert T[2, 3] == pytest.approx(1.65, abs=0.02)                 # the camera 1.65 m above the road
    assert T[0, 3] == pytest.approx(1.08, abs=0.02)                 # ahead of the OXTS unit
    np.testing.assert_allclose(T[:3, 2], [1.0, 0.0, 0.0], atol=0.02)  # optical axis forward
    np.testing.assert_allclose(T[:3, 1], [0.0, 0.0, -1.0], atol=0.02)  # image y down


def test_detection_open_and_info(date, capsys):
    assert is_kitti_raw(date) and is_kitti_raw(date / DRIVE) and not is_kitti_raw(date / DRIVE / "image_00")
    assert layout_of(date) == layout_of(date / DRIVE) == "KITTI raw"
    assert read_recording(date).frames == read_kitti_raw(date / DRIVE).frames
    with open_recording(date) as source:
        assert isinstance(source, RecordingSource) and source.rectified and source.n_frames == 5
        frames = list(source)
    assert frames[0].left.shape == (375, 1242) and frames[0].left.dtype == np.uint8
    np.testing.assert_array_equal(frames[4].T_world_from_base_true, source.true_poses[4])
    assert [f.stamp_s for f in frames] == list(source.stamps_s)
    assert entry(["info", str(date)]) == 0
    out = capsys.readouterr().out
    assert "KITTI raw" in out and "1242x375" in out and "baseline 0.5372" in out and "path 1.3 m" in out
    assert "camera 1.660 m above the floor" in out


def test_odometry_metrics_on_the_drive(date, tmp_path, capsys):
    assert entry(["odometry", str(date / DRIVE), "-o", str(tmp_path / "vo.txt"), "--metrics",
                  str(tmp_path / "vo.json"), "--quiet"]) == 0
    metrics = json.loads((tmp_path / "vo.json").read_text())
    assert metrics["reference"] == "true poses" and metrics["lost"] == 0 and metrics["n_poses"] == 5
    assert metrics["path_length_m"] == pytest.approx(1.268, abs=0.005)
    assert metrics["ate_rmse_m"] < 0.05                              # 2.7 cm on 1.27 m
    # per frame: 3.8 cm and 0.04 deg (the truth's own noise: 4.6 cm per frame, in the recording's notes)
    assert metrics["rpe_translation_per_frame_m"] < 0.06 and metrics["rpe_rotation_deg_per_frame"] < 0.1
    assert metrics["mean_step_m"] == pytest.approx(1.268 / 4, abs=0.002)


def test_bad_drives_are_named(date, tmp_path):
    copy = tmp_path / "2011_09_26"
    shutil.copytree(date, copy)
    shutil.copytree(copy / DRIVE, copy / "2011_09_26_drive_0009_sync")
    with pytest.raises(ValueError, match="2 KITTI raw drives.*0005.*0009"):
        read_kitti_raw(copy)
    assert read_kitti_raw(copy, drive="0009").root.name == "2011_09_26_drive_0009_sync"
    raw = copy / "2011_09_26_drive_0009_sync" / "image_00" / "data" / "0000000000.png"
    cv2.imwrite(str(raw), np.zeros((512, 1392), np.uint8))             # an _extract drive's unrectified image
    with pytest.raises(ValueError, match="1392x512.*S_rect_00.*1242x375"):
        read_kitti_raw(copy, drive="0009")
    (copy / DRIVE / "image_00" / "timestamps.txt").write_text("yesterday\n" * 5)
    with pytest.raises(ValueError, match="timestamps.txt"):
        read_kitti_raw(copy / DRIVE)
    (copy / "calib_velo_to_cam.txt").unlink()
    with pytest.raises(FileNotFoundError, match="calib_velo_to_cam.txt"):
        read_kitti_raw(copy / "2011_09_26_drive_0009_sync")
