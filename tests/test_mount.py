"""Camera mount (6-DoF T_base_from_cam, REP 103) and the floor of a run: known answers, the paper's rig read
into it, YAML entries, --mount on the CLI, floor confidence and the warning on scenes without floor."""
from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from mrstereo.camera import Camera, CameraInfo, StereoCamera, read_stereo, write_stereo
from mrstereo.camera.mount import CameraMount, read_mount_entry
from mrstereo.cli import entry
from mrstereo.geometry import detect_obstacles
from mrstereo.geometry.ground import T_robot_from_cam_ground, ground_from_mount, height_above_ground_m
from mrstereo.geometry.triangulation import disparity_px_from_depth_m
from mrstereo.recordings.manifest import read_manifest, write_manifest
from mrstereo.transforms import T_robot_from_cam, rotation_from_rpy


def test_the_paper_rig_is_the_rectified_camera():
    # rectification identity: the rig is the special case xyz = (0, 0, h), rpy = (0, tilt, 0), bit for bit
    a = CameraMount.from_xyz_rpy((0.0, 0.0, 0.45), (0.0, 0.15, 0.0)).T_base_from_cam
    assert np.array_equal(a, T_robot_from_cam(height_m=0.45, tilt_rad=0.15))
    assert CameraMount.from_rig(0.45, 0.15) == CameraMount(a)
    # a misaligned raw camera (p_rect = R p_raw): the mount is the raw camera's, the rig its rectified frame's
    R = rotation_from_rpy(0.004, -0.006, 0.003)
    m = CameraMount.from_rig(0.45, 0.15, R_rect_from_cam=R)
    np.testing.assert_array_equal(m.T_base_from_cam[:3, :3], a[:3, :3] @ R)
    np.testing.assert_array_equal(m.T_base_from_cam[:3, 3], [0.0, 0.0, 0.45])
    np.testing.assert_allclose(m.T_base_from_rectified(R), a, atol=1e-15)
    g = ground_from_mount(m, R_rect_from_cam=R)
    assert g.method == "mount" and g.height_m == 0.45 and g.tilt_rad == pytest.approx(0.15, abs=1e-15)
    assert g.roll_rad == pytest.approx(0.0, abs=1e-15)
    with pytest.raises(ValueError, match="height_m"):
        CameraMount.from_rig(0.0, 0.1)
    with pytest.raises(ValueError, match="tilt_rad"):
        CameraMount.from_rig(0.5, 2.0)


def test_mount_known_answers_rep103():
    # level camera looking left (yaw +90 deg) at (0.2, 0.1, 0.5): its optical axis is the base's +y
    m = CameraMount.from_xyz_rpy((0.2, 0.1, 0.5), (0.0, 0.0, math.pi / 2))
    T = m.T_base_from_cam
    np.testing.assert_allclose(T[:3, :3] @ [0, 0, 1.0] + T[:3, 3], [0.2, 1.1, 0.5], atol=1e-12)
    np.testing.assert_allclose(T[:3, :3] @ [1.0, 0, 0], [1.0, 0, 0], atol=1e-12)     # image right = base +x
    # positive pitch looks down; roll turns the image right axis about the optical axis
    p = CameraMount.from_xyz_rpy((0, 0, 1.0), (0.0, 0.3, 0.0)).T_base_from_cam
    np.testing.assert_allclose(p[:3, 2], [math.cos(0.3), 0.0, -math.sin(0.3)], atol=1e-12)
    r = CameraMount.from_xyz_rpy((0, 0, 1.0), (0.2, 0.0, 0.0)).T_base_from_cam
    np.testing.assert_allclose(r[:3, 0], [0.0, -math.cos(0.2), -math.sin(0.2)], atol=1e-12)
    # rpy round trip and the dict (YAML) entry
    g = CameraMount.from_xyz_rpy((0.3, -0.2, 0.9), (0.05, 0.2, -0.7))
    assert g.rpy == pytest.approx((0.05, 0.2, -0.7), abs=1e-12) and g.xyz == pytest.approx((0.3, -0.2, 0.9))
    np.testing.assert_allclose(CameraMount.from_dict(g.to_dict()).T_base_from_cam, g.T_base_from_cam, atol=1e-15)
    # pan turns the head about the base z axis
    np.testing.assert_allclose(g.T_base_from_rectified(pan_rad=0.4)[:3, :3],
                               rotation_from_rpy(0, 0, 0.4) @ g.T_base_from_cam[:3, :3])
    R = rotation_from_rpy(0.01, 0.02, -0.03)
    np.testing.assert_allclose(g.T_base_from_rectified(R, 0.4)[:3, :3],
                               rotation_from_rpy(0, 0, 0.4) @ g.T_base_from_cam[:3, :3] @ R.T, atol=1e-15)


def test_floor_of_a_mount_and_obstacle_split_with_a_rolled_offset_camera():
    # a camera 0.8 m up, 0.3 m ahead of the base origin, yawed, pitched down and rolled
    mount = CameraMount.from_xyz_rpy((0.3, -0.1, 0.8), (0.04, 0.35, 0.25))
    ground = ground_from_mount(mount)
    assert np.array_equal(T_robot_from_cam_ground(ground), mount.T_base_from_cam)
    # floor points of the base frame are at height 0 in the camera's floor model
    floor_base = np.array([[1.5, 0.2, 0.0], [2.0, -0.4, 0.0], [3.0, 0.5, 0.0]])
    T_cam_from_base = np.linalg.inv(mount.T_base_from_cam)
    floor_cam = floor_base @ T_cam_from_base[:3, :3].T + T_cam_from_base[:3, 3]
    np.testing.assert_allclose(height_above_ground_m(floor_cam, ground), 0.0, atol=1e-12)
    # a synthetic disparity of the floor triangulates to z = 0 in the base frame with this mount
    cam = Camera(width=160, height=120, fx=100.0, fy=100.0, cx=80.0, cy=60.0)
    stereo = StereoCamera.ideal(cam, 0.1)
    v, u = np.mgrid[0:120, 0:160].astype(float)
    rays = np.stack([(u - 80) / 100, (v - 60) / 100, np.ones_like(u)], axis=-1)
    n = ground.normal_cam
    depth = ground.height_m / (rays @ n)
    depth[(rays @ n) <= 0.05] = np.nan
    d = disparity_px_from_depth_m(depth, focal_px=100.0, baseline_m=0.1)
    result = detect_obstacles(d.astype(np.float32), stereo, mount=mount)
    z = result.points_robot_image[..., 2]
    assert np.nanmax(np.abs(z)) < 1e-5 and result.obstacle_mask.sum() == 0 and result.floor_mask.sum() > 1000


def test_mount_entries_in_stereo_yaml_and_manifest(tmp_path):
    cam = Camera(width=64, height=48, fx=50.0, fy=50.0, cx=32.0, cy=24.0)
    mount = CameraMount.from_xyz_rpy((0.1, 0.0, 0.7), (0.0, 0.2, 0.1))
    write_stereo(tmp_path / "s.yaml", StereoCamera.ideal(cam, 0.1, mount=mount))
    data = yaml.safe_load((tmp_path / "s.yaml").read_text())
    assert set(data["mount"]) == {"xyz", "rpy"} and "rig" not in data
    back = read_stereo(tmp_path / "s.yaml").mount
    np.testing.assert_allclose(back.T_base_from_cam, mount.T_base_from_cam, atol=1e-15)
    # the manifest's mount overrides the calibration's; rig and mount together are refused
    import cv2
    cv2.imwrite(str(tmp_path / "a.png"), np.zeros((48, 64), np.uint8))
    frames = [{"left_rect": "a.png", "right_rect": "a.png", "pose": [0, 0, 0]}]
    other = CameraMount.from_xyz_rpy((0, 0, 0.5), (0, 0, 0))
    write_manifest(tmp_path / "m.yaml", calibration="s.yaml", mount=other, frames=frames)
    assert read_manifest(tmp_path / "m.yaml").mount == CameraMount(other.T_base_from_cam)
    with pytest.raises(ValueError, match="'mount:' or 'rig:', not both"):
        read_mount_entry({"mount": {"xyz": [0, 0, 1]}, "rig": {"height_m": 1}}, where="x")
    with pytest.raises(ValueError, match="rpy must be 3 finite numbers"):
        read_mount_entry({"mount": {"xyz": [0, 0, 1], "rpy": [0, "a", 0]}}, where="x")
    write_manifest(tmp_path / "n.yaml", calibration="s.yaml", mount=None, frames=frames)
    assert "mount" not in yaml.safe_load((tmp_path / "n.yaml").read_text())


def test_a_rig_entry_is_read_as_the_mount_of_the_rectified_camera(tmp_path):
    # rig: {height_m, tilt_rad} in a stereo YAML and in a manifest: the raw camera's mount is T_rig @ R_left
    R = rotation_from_rpy(0.01, -0.005, 0.002)
    cam = Camera(width=64, height=48, fx=50.0, fy=50.0, cx=32.0, cy=24.0, k1=-0.05)
    P_left = np.hstack([np.array([[50.0, 0, 32.0], [0, 50.0, 24.0], [0, 0, 1]]), np.zeros((3, 1))])
    P_right = P_left.copy()
    P_right[0, 3] = -5.0
    stereo = StereoCamera(left=CameraInfo(cam, R=R, P=P_left, name="left"),
                          right=CameraInfo(cam, R=R, P=P_right, name="right"))
    write_stereo(tmp_path / "s.yaml", stereo)
    data = yaml.safe_load((tmp_path / "s.yaml").read_text())
    data["rig"] = {"height_m": 0.6, "tilt_rad": 0.2}
    (tmp_path / "r.yaml").write_text(yaml.safe_dump(data))
    expected = CameraMount.from_rig(0.6, 0.2, R_rect_from_cam=read_stereo(tmp_path / "s.yaml").left.R)
    assert read_stereo(tmp_path / "r.yaml").mount == expected
    import cv2
    cv2.imwrite(str(tmp_path / "a.png"), np.zeros((48, 64), np.uint8))
    manifest = {"calibration": "s.yaml", "rig": {"height_m": 0.6, "tilt_rad": 0.2},
                "frames": [{"left": "a.png", "right": "a.png", "pose": [0, 0, 0]}]}
    (tmp_path / "m.yaml").write_text(yaml.safe_dump(manifest))
    assert read_manifest(tmp_path / "m.yaml").mount == expected
    np.testing.assert_allclose(expected.T_base_from_rectified(R), T_robot_from_cam(height_m=0.6, tilt_rad=0.2),
                               atol=1e-15)
    with pytest.raises(ValueError, match="'rig' needs height_m"):
        read_mount_entry({"rig": {"tilt_rad": 0.1}}, where="x")


def _ideal_yaml(path: Path, left: Path) -> Path:
    import cv2
    h, w = cv2.imread(str(left)).shape[:2]
    cam = Camera(width=w, height=h, fx=600.0, fy=600.0, cx=w / 2, cy=h / 2)
    write_stereo(path, StereoCamera.ideal(cam, 0.1))
    return path


def test_points_warns_on_a_scene_without_floor(tmp_path, capsys, sample_data):
    teddy = sample_data("teddy")
    left = teddy / "im2.ppm"
    calib = _ideal_yaml(tmp_path / "c.yaml", left)
    code = entry(["points", str(left), str(teddy / "im6.ppm"), "--calib", str(calib),
                  "--rectified", "-o", str(tmp_path / "t.ply")])
    err = capsys.readouterr().err.splitlines()
    assert code == 0
    warnings = [e for e in err if e.startswith("mrstereo: warning:")]
    assert len(warnings) == 1 and "not confident" in warnings[0]
    floor = [e for e in err if e.startswith("floor (plane)")][0]
    share = float(floor.split("inliers ")[1].split(" %")[0])
    assert share < 12.0                                 # a few percent: no floor in Teddy


@pytest.fixture(scope="module")
def corridor(synthetic_dataset):
    return read_manifest(synthetic_dataset(seed=3, n_frames=4, supersample=1))


def test_points_with_mount_equals_height_and_tilt(corridor, tmp_path, capsys):
    from mrstereo.geometry import read_ply

    rec, cal = corridor.frames[0], corridor.calibration
    rig = ground_from_mount(corridor.mount, R_rect_from_cam=cal.left.R)
    common = [str(rec.left), str(rec.right), "--calib", str(corridor.calibration_path)]
    assert entry(["points", *common, "-o", str(tmp_path / "a.ply"), "--height", str(rig.height_m),
                  "--tilt", str(rig.tilt_rad)]) == 0
    # a mount is the raw camera's pose; the paper's rig is that of the rectified frame (p_rect = R p_raw)
    T = T_robot_from_cam(height_m=rig.height_m, tilt_rad=rig.tilt_rad)
    T[:3, :3] = T[:3, :3] @ cal.left.R
    raw = CameraMount(T)
    assert not np.allclose(cal.left.R, np.eye(3))                    # the synthetic head is misaligned
    values = ",".join(repr(v) for v in (*raw.xyz, *raw.rpy))
    assert entry(["points", *common, "-o", str(tmp_path / "b.ply"), "--mount", values]) == 0
    a, b = read_ply(tmp_path / "a.ply"), read_ply(tmp_path / "b.ply")
    assert a.points.shape == b.points.shape and a.points.shape[0] > 1000
    np.testing.assert_allclose(a.points, b.points, atol=1e-5)
    assert "warning" not in capsys.readouterr().err
    assert entry(["points", *common, "-o", str(tmp_path / "c.ply"), "--mount", "0,0,1"]) == 2
    assert "--mount" in capsys.readouterr().err


def test_map_without_mount_estimates_and_reports_the_floor(corridor, tmp_path, capsys):
    # the same dataset without any mount: calibration and manifest both lack it
    cal = dataclasses.replace(corridor.calibration, mount=None)
    dataset = tmp_path / "ds"
    dataset.mkdir()
    write_stereo(dataset / "cal.yaml", cal)
    frames = [{"left": str(f.left), "right": str(f.right), "pose": list(f.pose), "pan_rad": f.pan_rad}
              for f in corridor.frames]
    write_manifest(dataset / "manifest.yaml", calibration="cal.yaml", mount=None, frames=frames)
    assert read_manifest(dataset).mount is None
    assert entry(["map", str(dataset), "-o", str(tmp_path / "out"), "--quiet"]) == 0
    out = capsys.readouterr()
    assert "floor estimated: median of 3 floor fit(s)" in out.out and "warning" not in out.err
    floor = json.loads((tmp_path / "out" / "metrics.json").read_text())["floor"]
    assert floor["confident"] and floor["method"] == "plane"
    assert floor["height_m"] == pytest.approx(0.45, abs=0.02)     # the synthetic head's truth
    assert floor["tilt_rad"] == pytest.approx(0.15, abs=0.02)
    assert abs(floor["roll_rad"]) < 0.01 and floor["inlier_share"] > 0.12 and floor["residual_m"] < 0.03
