"""Virtual laser scan, top view and their files."""
import csv
import json
import math

import numpy as np
import pytest

from mrstereo.camera import Camera, StereoCamera
from mrstereo.geometry import (LaserScan, laser_scan_from_points, plot_top_view, read_scan_json,
                               scan_angles_of_camera, top_view, write_scan_csv, write_scan_json)


def test_nearest_point_per_bearing_and_rep103_sign():
    pts = np.array([[2.0, 0.0, 0.3],                    # straight ahead, 2 m
                    [3.0, 0.0, 0.5],                    # behind it on the same ray: hidden
                    [1.0, 1.0, 0.2],                    # 45 deg to the LEFT: positive angle
                    [1.0, -math.sqrt(3), 0.2],          # 60 deg to the right, 2 m
                    [0.05, 0.0, 0.2],                   # closer than range_min
                    [np.nan, 1.0, 0.0]])
    scan = laser_scan_from_points(pts, angle_min_rad=-math.radians(60), angle_max_rad=math.radians(60),
                                  angle_increment_rad=math.radians(1.0), range_min_m=0.1, range_max_m=5.0)
    assert scan.ranges_m.size == 121
    assert scan.angle_max_rad == pytest.approx(math.radians(60))
    i0 = int(round((0 - scan.angle_min_rad) / scan.angle_increment_rad))
    assert scan.ranges_m[i0] == pytest.approx(2.0)
    assert scan.ranges_m[i0 + 45] == pytest.approx(math.sqrt(2))
    assert scan.ranges_m[0] == pytest.approx(2.0)
    assert np.isfinite(scan.ranges_m).sum() == 3
    xy = scan.points_robot()
    assert sorted(map(tuple, np.round(xy, 6))) == sorted(
        [(2.0, 0.0), (1.0, 1.0), (round(1.0, 6), round(-math.sqrt(3), 6))])


def test_min_points_takes_the_kth_nearest_and_drops_thin_rays():
    pts = np.array([[1.0, 0.0, 0.2], [2.0, 0.0, 0.2], [2.5, 0.0, 0.2], [3.0, 0.0, 0.2],   # ray 0: 4 points
                    [0.0, 1.5, 0.2]])                                                   # ray at +90 deg: 1 point
    kw = dict(angle_min_rad=0.0, angle_max_rad=math.pi / 2, angle_increment_rad=math.pi / 4)
    np.testing.assert_allclose(laser_scan_from_points(pts, **kw).ranges_m, [1.0, np.nan, 1.5])
    np.testing.assert_allclose(laser_scan_from_points(pts, min_points=3, **kw).ranges_m, [2.5, np.nan, np.nan])
    with pytest.raises(ValueError, match="min_points"):
        laser_scan_from_points(pts, min_points=0, **kw)


def test_camera_fov_angles():
    cam = Camera(width=320, height=240, fx=200.0, fy=200.0, cx=100.0, cy=120.0)
    stereo = StereoCamera.ideal(cam, 0.1)
    lo, hi = scan_angles_of_camera(stereo)
    assert lo == pytest.approx(-math.atan2(219.0, 200.0)) and hi == pytest.approx(math.atan2(100.0, 200.0))
    lo2, hi2 = scan_angles_of_camera(stereo, pan_rad=0.5)
    assert (lo2, hi2) == pytest.approx((lo + 0.5, hi + 0.5))


def test_json_and_csv_round_trip(tmp_path):
    scan = LaserScan(angle_min_rad=-0.5, angle_max_rad=0.5, angle_increment_rad=0.25, range_min_m=0.1,
                     range_max_m=8.0, ranges_m=np.array([1.5, np.nan, 2.25, np.nan, 3.0]))
    write_scan_json(tmp_path / "s.json", scan)
    raw = json.loads((tmp_path / "s.json").read_text())
    assert raw["ranges"] == [1.5, None, 2.25, None, 3.0]
    assert set(raw) == {"angle_min", "angle_max", "angle_increment", "range_min", "range_max", "ranges"}
    back = read_scan_json(tmp_path / "s.json")
    np.testing.assert_array_equal(back.ranges_m, scan.ranges_m)
    assert back.angle_increment_rad == 0.25
    write_scan_csv(tmp_path / "s.csv", scan)
    rows = list(csv.reader(open(tmp_path / "s.csv")))
    assert rows[0] == ["angle_rad", "range_m"] and rows[2] == ["-0.250000", ""] and rows[5] == ["0.500000", "3.0000"]


def test_top_view_counts_follow_the_grid_layout():
    pts = np.array([[0.02, -2.99, 0.1], [0.02, -2.99, 0.3], [3.0, 0.51, 0.2], [9.0, 0.0, 0.0], [np.nan, 0, 0]])
    counts = top_view(pts, x_range_m=(0.0, 8.0), y_range_m=(-3.0, 3.0), resolution_m=0.05)
    assert counts.shape == (120, 160)
    assert counts[0, 0] == 2                              # row 0 = lowest y, col 0 = lowest x
    assert counts[70, 60] == 1                            # y 0.51 -> row 70, x 3.0 -> col 60
    assert counts.sum() == 3                              # x = 9 m is outside


def test_plot_top_view_writes_a_png(tmp_path):
    scan = laser_scan_from_points(np.array([[2.0, 0.1, 0.3]]))
    plot_top_view(tmp_path / "top.png", obstacle_points_robot=np.array([[2.0, 0.1, 0.3]]),
                  floor_points_robot=np.array([[1.0, 0.0, 0.0], [1.5, 0.2, 0.0]]), scan=scan)
    assert (tmp_path / "top.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _red_columns(path):
    """Columns of the obstacle colour (#c03020) in a top-view PNG."""
    from mrstereo.io import read_image

    bgr = read_image(path).astype(int)
    red = (np.abs(bgr[..., 2] - 0xc0) < 30) & (np.abs(bgr[..., 1] - 0x30) < 30) & (np.abs(bgr[..., 0] - 0x20) < 30)
    return np.nonzero(red)[1]


def test_top_view_draws_the_robots_left_on_the_left_with_positive_y_ticks(tmp_path):
    """REP 103: +y is left. An obstacle at y = +1.5 m is drawn left of one at y = -1.5 m, and the
    horizontal axis runs from +3 (left edge) to -3 (right edge)."""
    cluster = np.random.default_rng(0).normal(0, 0.05, (400, 3))
    cols = {}
    for y in (1.5, -1.5):
        plot_top_view(tmp_path / f"top{y}.png", obstacle_points_robot=cluster + [3.0, y, 0.3])
        cols[y] = _red_columns(tmp_path / f"top{y}.png")
    width = 600                                           # 6 in at 100 dpi
    assert cols[1.5].size > 50 and cols[-1.5].size > 50
    assert cols[1.5].mean() < width / 2 - 50 < width / 2 + 50 < cols[-1.5].mean()
    import matplotlib.pyplot as plt
    plt.close("all")


def test_bad_input(tmp_path):
    with pytest.raises(ValueError, match="angle_max_rad"):
        laser_scan_from_points(np.zeros((1, 3)), angle_min_rad=0.5, angle_max_rad=0.1)
    with pytest.raises(ValueError, match="angle_increment_rad must be > 0"):
        laser_scan_from_points(np.zeros((1, 3)), angle_increment_rad=0.0)
    with pytest.raises(ValueError, match="points_robot must have shape"):
        laser_scan_from_points(np.zeros((4,)))
    with pytest.raises(ValueError, match="y_range_m"):
        top_view(np.zeros((1, 3)), y_range_m=(1.0, -1.0))
    (tmp_path / "bad.json").write_text("{\"angle_min\": 0}")
    with pytest.raises(ValueError, match="must have the fields"):
        read_scan_json(tmp_path / "bad.json")
    (tmp_path / "junk.json").write_text("not json")
    with pytest.raises(ValueError, match="not a JSON laser scan"):
        read_scan_json(tmp_path / "junk.json")
