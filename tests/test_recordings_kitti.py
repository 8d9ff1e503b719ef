"""Recordings with stamps and 3-D poses: the KITTI odometry reader on the real sample, the manifest's
``stamp_s`` and 7-number poses, layout detection."""
from __future__ import annotations

import math
import shutil

import numpy as np
import pytest
import yaml

from mrstereo.camera.mount import CameraMount
from mrstereo.recordings import read_recording
from mrstereo.recordings.kitti import KITTI_MOUNT, is_kitti_odometry, read_kitti_odometry
from mrstereo.recordings.manifest import FrameRecord, read_manifest, write_manifest
from mrstereo.recordings.samples import data_root
from mrstereo.transforms import T_from_planar, planar_from_T, rotation_from_rpy


@pytest.fixture(scope="module")
def kitti():
    root = data_root() / "kitti_odometry_06"
    if not (root / "sequences" / "06" / "calib.txt").is_file():
        pytest.skip(f"KITTI odometry sample not found under {root} (set MRSTEREO_DATA)")
    return root


def _kitti_rows(path):
    return np.loadtxt(path, ndmin=2)


def test_kitti_reader_on_the_real_sample(kitti):
    m = read_kitti_odometry(kitti)
    seq = kitti / "sequences" / "06"
    assert len(m.frames) == 51 and m.root == seq.resolve()
    # stamps: times.txt, line by line
    np.testing.assert_array_equal(m.stamps_s, np.loadtxt(seq / "times.txt"))
    assert m.frames[1].stamp_s == pytest.approx(0.1044989)
    # calibration: P0 and P1 of calib.txt as a rectified pair
    lines = {line.split(":")[0]: np.array(line.split(":")[1].split(), float).reshape(3, 4)
             for line in (seq / "calib.txt").read_text().splitlines() if line.startswith(("P0", "P1"))}
    np.testing.assert_array_equal(m.calibration.left.P, lines["P0"])
    np.testing.assert_array_equal(m.calibration.right.P, lines["P1"])
    assert m.calibration.is_rectified and m.calibration.size == (1226, 370)
    assert m.calibration.focal_px == 707.0912
    assert m.calibration.baseline_m == pytest.approx(379.8145 / 707.0912)
    assert all(f.has_rectified and not f.has_raw for f in m.frames)
    assert m.frames[7].left_rect.name == "000007.png" and m.frames[7].right_rect.parent.name == "image_1"
    # truth: KITTI's camera poses conjugated by the mount into the REP 103 base frame
    rows = _kitti_rows(kitti / "poses" / "06.txt")
    M = KITTI_MOUNT.T_base_from_cam
    for k in (0, 25, 50):
        T_cam = np.vstack([rows[k].reshape(3, 4), [0, 0, 0, 1]])
        np.testing.assert_allclose(m.frames[k].T_world_from_base_true, M @ T_cam @ np.linalg.inv(M), atol=1e-6)
    # axes: camera z (forward) -> base x, camera x (right) -> base -y, camera y (down) -> base -z; the base
    # is 1.65 m below the camera, so the car's pitch and roll (under a degree) move it a few cm more
    end = m.frames[50].T_world_from_base_true[:3, 3]
    np.testing.assert_allclose(end, [rows[50, 11], -rows[50, 3], -rows[50, 7]], atol=0.05)
    assert 59.0 < end[0] < 60.5 and abs(end[2]) > 1.0               # the road climbs 1.2 m
    assert m.frames[50].true_pose_3d == m.frames[50].pose_3d       # no odometry: the given pose is the truth
    assert m.mount == KITTI_MOUNT
    # a sequence folder reads the same (poses from ../../poses)
    same = read_kitti_odometry(seq)
    assert same.frames[50].true_pose_3d == m.frames[50].true_pose_3d
    # another mount: the truth is the same motion seen from another base
    tilted = CameraMount.from_xyz_rpy((0.3, 0.0, 1.5), (0.0, 0.05, 0.0))
    other = read_kitti_odometry(kitti, mount=tilted)
    Mt = tilted.T_base_from_cam
    T_cam = np.vstack([rows[30].reshape(3, 4), [0, 0, 0, 1]])
    np.testing.assert_allclose(other.frames[30].T_world_from_base_true, Mt @ T_cam @ np.linalg.inv(Mt), atol=1e-6)


def test_kitti_detection_and_read_recording(kitti, tmp_path):
    assert is_kitti_odometry(kitti) and is_kitti_odometry(kitti / "sequences" / "06")
    assert not is_kitti_odometry(kitti / "poses") and not is_kitti_odometry(tmp_path)
    m = read_recording(kitti)
    assert len(m.frames) == 51 and m.frames[0].stamp_s == 0.0
    with pytest.raises(ValueError, match="not a recording"):
        read_recording(tmp_path)
    with pytest.raises(FileNotFoundError, match="not found"):
        read_recording(tmp_path / "missing")


def test_kitti_bad_layouts(kitti, tmp_path):
    seq = tmp_path / "sequences" / "06"
    shutil.copytree(kitti / "sequences" / "06", seq)
    (seq / "calib.txt").write_text("P0: 1 2 3\n")
    with pytest.raises(ValueError, match="P0.*12 numbers"):
        read_kitti_odometry(tmp_path)
    shutil.copy(kitti / "sequences" / "06" / "calib.txt", seq / "calib.txt")
    (seq / "times.txt").write_text("0.0\n0.1\n")
    with pytest.raises(ValueError, match="2 stamps but image_0 has frame 50"):
        read_kitti_odometry(tmp_path)
    (seq / "times.txt").unlink()                          # no stamps, no poses: still a recording
    m = read_kitti_odometry(tmp_path)
    assert m.stamps_s is None and m.frames[3].true_pose is None and m.frames[3].pose == (0.0, 0.0, 0.0)
    shutil.copytree(seq, tmp_path / "sequences" / "07")
    with pytest.raises(ValueError, match="2 sequences"):
        read_kitti_odometry(tmp_path)
    assert len(read_kitti_odometry(tmp_path, sequence="07").frames) == 51
    with pytest.raises(ValueError, match="not a KITTI"):
        read_kitti_odometry(kitti / "poses")


def test_frame_record_3d_pose_and_stamp():
    R = rotation_from_rpy(0.1, -0.05, 0.7)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, (1.5, -2.0, 0.3)
    from mrstereo.recordings.manifest import pose_3d_of

    record = FrameRecord(pose=None, pose_3d=pose_3d_of(T), stamp_s=12.5)
    np.testing.assert_allclose(record.T_world_from_base, T, atol=1e-12)
    np.testing.assert_allclose(record.pose, planar_from_T(T), atol=1e-12)           # the floor projection
    assert record.T_world_from_base_true is None and record.stamp_s == 12.5
    np.testing.assert_allclose(FrameRecord(pose=(1.0, 2.0, 0.5)).T_world_from_base, T_from_planar(1.0, 2.0, 0.5))
    with pytest.raises(ValueError, match="not the floor projection"):
        FrameRecord(pose=(0.0, 0.0, 0.0), pose_3d=pose_3d_of(T))
    with pytest.raises(ValueError, match="pose_3d must be 7"):
        FrameRecord(pose=None, pose_3d=(1.0, 2.0, 3.0))
    with pytest.raises(ValueError, match="needs pose"):
        FrameRecord(pose=None)


def test_manifest_round_trip_of_stamps_and_3d_poses(tmp_path):
    from mrstereo.camera import StereoCamera, write_stereo
    from mrstereo.io import write_image
    from mrstereo.world.render import default_stereo

    write_stereo(tmp_path / "calib.yaml", default_stereo(64, 48))
    image = np.zeros((48, 64), np.uint8)
    for name in ("l.png", "r.png"):
        write_image(tmp_path / name, image)
    pose = [1.0, 2.0, 0.25, 0.0, 0.0, math.sin(0.2), math.cos(0.2)]     # yaw 0.4 rad, 25 cm up
    frames = [{"left_rect": "l.png", "right_rect": "r.png", "stamp_s": 1700000000.123456789, "pose": pose,
               "true_pose": [1.1, 2.0, 0.4]},
              {"left_rect": "l.png", "right_rect": "r.png", "pose": [0.0, 0.0, 0.0]}]
    write_manifest(tmp_path / "manifest.yaml", calibration="calib.yaml", mount=None, frames=frames)
    m = read_manifest(tmp_path)
    f = m.frames[0]
    assert f.stamp_s == 1700000000.123456789 and m.frames[1].stamp_s is None and m.stamps_s is None
    assert f.pose_3d == tuple(pose) and f.pose == pytest.approx((1.0, 2.0, 0.4))
    assert f.T_world_from_base[2, 3] == 0.25 and f.true_pose == (1.1, 2.0, 0.4) and f.true_pose_3d is None
    data = yaml.safe_load((tmp_path / "manifest.yaml").read_text())
    for bad, match in ((dict(stamp_s="noon"), "stamp_s must be a finite number"),
                       (dict(pose=[0, 0, 0, 0, 0, 0, 0]), "zero quaternion"),
                       (dict(pose=[0, 0, 0, 1]), r"\[x, y, z, qx, qy, qz, qw\]")):
        broken = {**data, "frames": [{**data["frames"][0], **bad}]}
        (tmp_path / "manifest.yaml").write_text(yaml.safe_dump(broken))
        with pytest.raises(ValueError, match=match):
            read_manifest(tmp_path)
    assert isinstance(m.calibration, StereoCamera)


def test_odometry_command_on_kitti(kitti, tmp_path, capsys):
    """`mrstereo odometry` on the KITTI folder: every frame tracked, a 3-D TUM file with times.txt's stamps."""
    from mrstereo.cli import entry
    from mrstereo.odometry.trajectory import read_tum

    out, metrics = tmp_path / "traj.txt", tmp_path / "m.json"
    assert entry(["odometry", str(kitti), "-o", str(out), "--metrics", str(metrics), "--quiet"]) == 0
    assert "tracked all 51 frames" in capsys.readouterr().out
    stamps, T = read_tum(out)
    np.testing.assert_array_equal(stamps, np.loadtxt(kitti / "sequences" / "06" / "times.txt"))
    truth = read_kitti_odometry(kitti)
    assert abs(T[-1, 2, 3] - truth.frames[-1].T_world_from_base_true[2, 3]) < 0.3     # it climbs with the road
    import json

    data = json.loads(metrics.read_text())
    assert data["lost"] == 0 and data["reference"] == "true poses" and data["ate_percent"] < 0.5


def test_map_command_on_a_kitti_folder(kitti_two_frames, tmp_path, capsys):
    """`mrstereo map` reads a KITTI folder directly (two frames of it here)."""
    from mrstereo.cli import entry

    root = kitti_two_frames                # the folder named: no output inside it
    assert entry(["map", str(root), "-o", str(root / "map"), "--quiet"]) == 2
    assert "is inside the KITTI odometry recording" in capsys.readouterr().err
    code = entry(["map", str(root), "-o", str(tmp_path / "map"), "--size", "30,20", "--origin", "0,-10",
                  "--resolution", "0.1", "--quiet"])
    assert code == 0, capsys.readouterr()
    assert "map of 2 frames" in capsys.readouterr().out and (tmp_path / "map" / "map.pgm").is_file()
    # the default map keeps points within 4 m (a robot's); a car sees the road from 6 m on: with 30 m, the
    # parked cars and the road come out through the mount 1.65 m up, on the floor plane
    from mrstereo.geometry.obstacles import ObstacleConfig
    from mrstereo.mapping import GridSpec
    from mrstereo.pipeline.run import PipelineConfig, build_map

    config = PipelineConfig(obstacles=ObstacleConfig(max_range_m=30.0),
                            grid=GridSpec(width_m=30.0, height_m=20.0, resolution_m=0.1, origin_x_m=0.0,
                                          origin_y_m=-10.0))
    run = build_map(root, config=config, progress=False)
    occupancy = run.grid.probability()
    assert (occupancy > 0.5).sum() > 20 and (occupancy < 0.5).sum() > 1000
    obstacles = np.concatenate([o.obstacle_points_world for o in run.observations])
    assert np.median(obstacles[:, 2]) > 0.1                     # above the road, not under it
