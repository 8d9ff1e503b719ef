"""One stereo pair -> obstacles / point cloud / laser scan, on a synthetic corridor frame (320x240)."""
import json
import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from mrstereo.camera import write_stereo
from mrstereo.cli import entry
from mrstereo.geometry import (ObstacleConfig, ground_from_mount, laser_scan_from_points, points_robot_from_disparity,
                               read_ply, read_scan_json)
from mrstereo.io import write_image
from mrstereo.geometry.pair import obstacles_from_pair, scan_from_pair
from mrstereo.world import LABEL_FLOOR, default_scene, default_stereo, is_obstacle_label, render_stereo_frame

POSE, PAN = (1.2, -0.3, 0.0), 0.35


@pytest.fixture(scope="module")
def frame():
    stereo = default_stereo()          # 320x240, the paper's image size
    fr = render_stereo_frame(default_scene(), stereo, pose=POSE, pan_rad=PAN, seed=3, supersample=1)
    return stereo, fr


def _gt_band_points(stereo, fr):
    cfg = ObstacleConfig()
    T = stereo.mount.T_base_from_rectified(stereo.left.R, PAN)
    gt = points_robot_from_disparity(fr.disparity_px, stereo, T).reshape(-1, 3)
    return gt[(gt[:, 2] > cfg.min_obstacle_height_m) & (gt[:, 2] <= cfg.max_obstacle_height_m)]


def test_obstacles_from_rectified_pair_match_ground_truth(frame):
    stereo, fr = frame
    out = obstacles_from_pair(fr.left_rect, fr.right_rect, stereo, rectified=True, pan_rad=PAN)
    obs = out.obstacles
    assert obs.success and obs.ground.method == "mount"
    labels = fr.labels
    obstacle_px = obs.obstacle_mask
    assert obstacle_px.sum() > 5000
    # Detected obstacle pixels lie on obstacles or walls, seldom on the floor (edge fattening at the feet).
    assert (obstacle_px & (labels == LABEL_FLOOR)).sum() < 0.06 * obstacle_px.sum()
    assert (obstacle_px & is_obstacle_label(labels)).sum() > 0.3 * obstacle_px.sum()
    # The points are where the ground truth has surfaces.
    dist, _ = cKDTree(_gt_band_points(stereo, fr)).query(obs.obstacle_points_robot)
    assert np.median(dist) < 0.05 and (dist < 0.10).mean() > 0.85
    # Rejection (eq. 13) only removes pixels, never adds them.
    assert np.isfinite(out.disparity_px).sum() <= np.isfinite(out.raw_disparity_px).sum()
    assert np.array_equal(np.isnan(out.disparity_px), np.isnan(out.raw_disparity_px) | out.rejection.rejected)


def test_raw_pair_is_rectified_first_and_floor_can_be_estimated(frame):
    stereo, fr = frame
    no_mount = type(stereo)(left=stereo.left, right=stereo.right, mount=None)
    out = obstacles_from_pair(fr.raw_left, fr.raw_right, no_mount, pan_rad=PAN)
    g = out.obstacles.ground
    assert out.obstacles.success and g.method == "plane", g.message
    rig = ground_from_mount(stereo.mount, R_rect_from_cam=stereo.left.R)     # the truth
    assert g.height_m == pytest.approx(rig.height_m, abs=0.03)
    assert g.tilt_rad == pytest.approx(rig.tilt_rad, abs=math.radians(3))
    hits = out.obstacles.obstacle_mask
    assert (hits & (fr.labels != LABEL_FLOOR)).sum() > 0.93 * hits.sum()


def test_scan_from_pair_sees_the_nearest_obstacles(frame):
    stereo, fr = frame
    res = scan_from_pair(fr.left_rect, fr.right_rect, stereo, rectified=True, pan_rad=PAN)
    scan = res.scan
    assert scan.angle_min_rad < PAN < scan.angle_max_rad
    truth = laser_scan_from_points(_gt_band_points(stereo, fr), angle_min_rad=scan.angle_min_rad,
                                   angle_max_rad=scan.angle_max_rad,
                                   angle_increment_rad=scan.angle_increment_rad, range_min_m=scan.range_min_m,
                                   range_max_m=scan.range_max_m)
    both = np.isfinite(scan.ranges_m) & np.isfinite(truth.ranges_m)
    assert both.sum() > 0.8 * np.isfinite(truth.ranges_m).sum()
    assert np.median(np.abs(scan.ranges_m[both] - truth.ranges_m[both])) < 0.10


def _files(tmp_path, stereo, fr):
    write_stereo(tmp_path / "stereo.yaml", stereo)
    write_image(tmp_path / "left.png", fr.raw_left)
    write_image(tmp_path / "right.png", fr.raw_right)
    return [str(tmp_path / n) for n in ("left.png", "right.png", "stereo.yaml")]


def test_cli_points_and_scan(tmp_path, frame, capsys):
    stereo, fr = frame
    left, right, calib = _files(tmp_path, stereo, fr)
    assert entry(["points", left, right, "--calib", calib, "-o", str(tmp_path / "c.ply"),
                  "--pan", str(PAN), "--which", "obstacles"]) == 0
    cloud = read_ply(tmp_path / "c.ply")
    assert cloud.points.shape[0] > 200 and cloud.intensity is not None
    assert (cloud.points[:, 2] > 0.08).all()
    assert entry(["scan", left, right, "--calib", calib, "-o", str(tmp_path / "s.json"), "--pan", str(PAN),
                  "--plot", str(tmp_path / "top.png")]) == 0
    raw = json.loads((tmp_path / "s.json").read_text())
    assert {"angle_min", "angle_max", "angle_increment", "range_min", "range_max", "ranges", "intensities",
            "header", "time_increment", "scan_time"} <= set(raw)
    scan = read_scan_json(tmp_path / "s.json")
    assert scan.ranges_m.size == len(raw["ranges"]) == len(raw["intensities"])
    # range_min is the matcher's near limit, not the 0.1 m default, and no return is nearer
    assert raw["range_min"] > 0.1 and np.nanmin(np.where(np.isfinite(scan.ranges_m), scan.ranges_m, np.nan)) \
        >= raw["range_min"]
    returns = np.isfinite(scan.ranges_m)
    assert returns.sum() > 20 and np.isfinite(scan.intensities[returns]).all()
    assert (tmp_path / "top.png").stat().st_size > 1000
    assert entry(["scan", left, right, "--calib", calib, "-o", str(tmp_path / "s.csv"), "--height", "0.45",
                  "--tilt", "0.15"]) == 0
    assert (tmp_path / "s.csv").read_text().startswith("angle_rad,range_m,intensity\n")


def test_cli_points_labels_every_point_and_writes_a_depth_png(tmp_path, frame, capsys):
    import cv2
    import plyfile

    stereo, fr = frame
    left, right, calib = _files(tmp_path, stereo, fr)
    assert entry(["points", left, right, "--calib", calib, "-o", str(tmp_path / "all.ply"), "--pan", str(PAN),
                  "--depth-png", str(tmp_path / "depth.png")]) == 0
    cloud = read_ply(tmp_path / "all.ply")
    assert set(np.unique(cloud.label)) == {0, 1, 2}
    z = cloud.points[:, 2]
    cfg = ObstacleConfig()
    obstacle, floor = cloud.label == 1, cloud.label == 2
    assert (z[obstacle] > cfg.min_obstacle_height_m - 1e-4).all() and (z[obstacle] < cfg.max_obstacle_height_m).all()
    assert np.median(np.abs(z[floor])) < 0.02 and floor.sum() > 200
    v = plyfile.PlyData.read(str(tmp_path / "all.ply"))["vertex"]            # an independent reader sees it
    np.testing.assert_array_equal(v["label"], cloud.label)
    assert entry(["points", left, right, "--calib", calib, "-o", str(tmp_path / "o.ply"), "--pan", str(PAN),
                  "--which", "obstacles"]) == 0
    assert len(read_ply(tmp_path / "o.ply").points) == obstacle.sum()
    # the depth image: uint16 millimetres, 0 invalid, within a few percent of the rendered truth
    depth = cv2.imread(str(tmp_path / "depth.png"), cv2.IMREAD_UNCHANGED)
    assert depth.dtype == np.uint16 and depth.shape == fr.depth_m.shape
    both = (depth > 0) & np.isfinite(fr.depth_m)
    assert both.mean() > 0.3
    rel = np.abs(depth[both] / 1000.0 - fr.depth_m[both]) / fr.depth_m[both]
    assert np.median(rel) < 0.03
    assert entry(["points", left, right, "--calib", calib, "-o", str(tmp_path / "x.ply"),
                  "--depth-png", str(tmp_path / "depth.jpg")]) == 2
    assert "--depth-png" in capsys.readouterr().err and not (tmp_path / "x.ply").exists()


def test_cli_points_color_takes_the_colour_left_image_and_refuses_a_gray_one(tmp_path, frame, capsys):
    import cv2

    stereo, fr = frame
    left, right, calib = _files(tmp_path, stereo, fr)
    colour = []
    for path in (left, right):                  # blue = green = the gray level, red its negative
        gray = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
        colour.append(path.replace(".png", "_bgr.png"))
        cv2.imwrite(colour[-1], cv2.merge([gray, gray, 255 - gray]))
    assert entry(["points", *colour, "--calib", calib, "-o", str(tmp_path / "c.ply"), "--color"]) == 0
    rgb = read_ply(tmp_path / "c.ply").colors_rgb.astype(int)
    assert len(rgb) > 200 and (rgb[:, 1] == rgb[:, 2]).all()
    assert (np.abs(rgb[:, 0] + rgb[:, 1] - 255) <= 1).all() and rgb[:, 1].std() > 10     # rectified per channel
    capsys.readouterr()
    assert entry(["points", left, right, "--calib", calib, "-o", str(tmp_path / "g.ply"), "--color"]) == 2
    err = capsys.readouterr().err
    assert err == f"mrstereo: error: --color needs a colour left image, {left} is gray\n"
    assert not (tmp_path / "g.ply").exists()


def test_cli_bad_input_is_one_line(tmp_path, frame, capsys):
    stereo, fr = frame
    left, right, calib = _files(tmp_path, stereo, fr)
    capsys.readouterr()
    cases = [
        (["points", left, str(tmp_path / "nope.png"), "--calib", calib, "-o", str(tmp_path / "c.ply")], "not found"),
        (["points", left, right, "--calib", calib, "-o", str(tmp_path / "c.txt")], "must end in .ply"),
        (["scan", left, right, "--calib", calib, "-o", left], "must end in .json or .csv"),
        (["scan", left, right, "--calib", calib, "-o", str(tmp_path / "s.json"), "--plot", left], "overwrite"),
        (["scan", left, right, "--calib", calib, "-o", str(tmp_path / "s.json"), "--height", "nan"], "finite"),
        (["scan", left, right, "--calib", left, "-o", str(tmp_path / "s.json")], ""),
    ]
    for argv, needle in cases:
        assert entry(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.startswith("mrstereo: error: ") and err.count("\n") == 1 and needle in err, err
    assert not (tmp_path / "s.json").exists() and not (tmp_path / "c.ply").exists()
