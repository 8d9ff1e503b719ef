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
    """Every LaserScan field survives JSON; inf / nan / -inf are strings a strict JSON parser reads."""
    scan = LaserScan(angle_min_rad=-0.5, angle_max_rad=0.5, angle_increment_rad=0.25, range_min_m=0.42,
                     range_max_m=8.0, ranges_m=np.array([1.5, np.nan, 2.25, np.inf, -np.inf]),
                     intensities=np.array([120.0, np.nan, 33.0, np.nan, np.nan]), frame_id="base_footprint",
                     stamp_s=1560004885.437324, time_increment_s=0.0, scan_time_s=0.1)
    write_scan_json(tmp_path / "s.json", scan)
    text = (tmp_path / "s.json").read_text()

    def refuse(constant):
        raise AssertionError(f"non-standard JSON constant {constant}")

    raw = json.loads(text, parse_constant=refuse)               # no NaN / Infinity literals
    assert raw["ranges"] == [1.5, "NaN", 2.25, "Infinity", "-Infinity"]
    assert raw["intensities"] == [120.0, "NaN", 33.0, "NaN", "NaN"]
    assert raw["header"]["frame_id"] == "base_footprint" and raw["header"]["stamp"]["sec"] == 1560004885
    assert abs(raw["header"]["stamp"]["nanosec"] - 437324000) < 1000      # a float stamp: microseconds
    assert set(raw) == {"header", "angle_min", "angle_max", "angle_increment", "time_increment", "scan_time",
                        "range_min", "range_max", "ranges", "intensities"}
    np.testing.assert_array_equal(np.array(raw["ranges"], dtype=float), scan.ranges_m)   # as users read it
    back = read_scan_json(tmp_path / "s.json")
    np.testing.assert_array_equal(back.ranges_m, scan.ranges_m)
    np.testing.assert_array_equal(back.intensities, scan.intensities)
    assert (back.frame_id, back.scan_time_s, back.range_min_m) == ("base_footprint", 0.1, 0.42)
    assert back.stamp_s == pytest.approx(scan.stamp_s, abs=1e-6)
    write_scan_csv(tmp_path / "s.csv", scan)
    rows = list(csv.reader(open(tmp_path / "s.csv")))
    assert rows[0] == ["angle_rad", "range_m", "intensity"]
    assert rows[2] == ["-0.250000", "nan", "nan"] and rows[4] == ["0.250000", "inf", "nan"]
    assert rows[5] == ["0.500000", "-inf", "nan"] and rows[1] == ["-0.500000", "1.5000", "120.00"]
    table = np.loadtxt(tmp_path / "s.csv", delimiter=",", skiprows=1)
    np.testing.assert_array_equal(table[:, 1], scan.ranges_m)


def test_null_ranges_and_bad_values():
    with_null = {"angle_min": 0.0, "angle_max": 0.5, "angle_increment": 0.25, "range_min": 0.1, "range_max": 5.0,
                 "ranges": [1.0, None, 2.0]}
    scan = LaserScan.from_dict(with_null)
    assert np.isnan(scan.ranges_m[1]) and scan.frame_id == "base_link" and scan.intensities.size == 0
    with pytest.raises(ValueError, match="'Infinity' or '-Infinity'"):
        LaserScan.from_dict({**with_null, "ranges": [1.0, "inf", 2.0]})
    with pytest.raises(ValueError, match="3 ranges but 2 intensities"):
        LaserScan.from_dict({**with_null, "intensities": [1.0, 2.0]})


def test_seen_clear_to_range_max_is_inf_unseen_is_nan():
    """REP 117: +inf where the bearing was seen clear past range_max, nan where nothing tells."""
    kw = dict(angle_min_rad=-math.pi / 4, angle_max_rad=math.pi / 4, angle_increment_rad=math.pi / 4,
              range_min_m=0.3, range_max_m=4.0)
    obstacles = np.array([[2.0, 0.0, 0.3], [1.0, 0.0, 0.4]])            # ray 1 (ahead): nearest 1.0 m
    seen = np.array([[5.0, 5.0, 0.0],                                     # ray 2 (left): floor at 7 m
                     [1.0, -1.0, 0.0]])                                   # ray 0 (right): floor at 1.4 m only
    scan = laser_scan_from_points(obstacles, observed_points_robot=seen, intensities=[50.0, 80.0], **kw)
    np.testing.assert_array_equal(scan.ranges_m, [np.nan, 1.0, np.inf])
    np.testing.assert_array_equal(scan.intensities, [np.nan, 80.0, np.nan])  # the pixel of the return
    assert laser_scan_from_points(obstacles, min_points=2, intensities=[50.0, 80.0], **kw).intensities[1] == 50.0
    without = laser_scan_from_points(obstacles, **kw)
    np.testing.assert_array_equal(without.ranges_m, [np.nan, 1.0, np.nan])
    assert without.intensities.size == 0
    beyond = laser_scan_from_points([[6.0, 0.0, 0.3]], **kw)              # an obstacle past range_max
    assert beyond.ranges_m[1] == np.inf
    with pytest.raises(ValueError, match="one value per point"):
        laser_scan_from_points(obstacles, intensities=[1.0], **kw)


def test_near_limit_range_is_the_depth_of_the_largest_disparity():
    from mrstereo.geometry import near_limit_range_m
    from mrstereo.transforms import T_robot_from_cam

    cam = Camera(width=321, height=241, fx=200.0, fy=200.0, cx=160.0, cy=120.0)
    stereo = StereoCamera.ideal(cam, 0.1)
    level = T_robot_from_cam(height_m=0.5, tilt_rad=0.0)
    assert near_limit_range_m(stereo, level, 40.0) == pytest.approx(200.0 * 0.1 / 40.0)   # f B / d_max
    tilted = near_limit_range_m(stereo, T_robot_from_cam(height_m=0.5, tilt_rad=0.3), 40.0)
    # the bottom image row looks down by 0.3 + atan(120 / 200): nearer on the floor plane
    bottom = 0.5 * (math.cos(0.3) - 120 / 200 * math.sin(0.3))
    assert tilted == pytest.approx(bottom)
    with pytest.raises(ValueError, match="max_disparity_px"):
        near_limit_range_m(stereo, level, 0.0)


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


def test_top_view_marks_bearings_seen_clear_to_range_max(tmp_path):
    from mrstereo.io import read_image

    scan = LaserScan(angle_min_rad=-0.3, angle_max_rad=0.3, angle_increment_rad=0.1, range_min_m=0.3,
                     range_max_m=6.0, ranges_m=np.array([np.inf, np.inf, 2.0, np.nan, np.nan, np.inf, np.inf]))
    plot_top_view(tmp_path / "top.png", scan=scan)
    bgr = read_image(tmp_path / "top.png").astype(int)
    light = (np.abs(bgr[..., 2] - 0x80) < 12) & (np.abs(bgr[..., 1] - 0xa0) < 12) & (np.abs(bgr[..., 0] - 0xe0) < 12)
    assert light.sum() > 20                       # the four +inf bearings (and their legend entry)


def _sorted_scan(points, observed, a0, inc, n, r0, r1, m, values):
    """The scan by sorting every return by (bearing, range) (a stable lexsort: equal ranges in point order)."""
    p = points[np.isfinite(points[:, :2]).all(axis=1)]
    v = values[np.isfinite(points[:, :2]).all(axis=1)]
    r = np.hypot(p[:, 0], p[:, 1])
    k = np.rint((np.arctan2(p[:, 1], p[:, 0]) - a0) / inc).astype(np.int64)
    keep = (r >= r0) & (r <= r1) & (k >= 0) & (k < n)
    ranges, out_values = np.full(n, np.nan), np.full(n, np.nan)
    for ray in range(n):
        sel = np.flatnonzero(keep & (k == ray))
        sel = sel[np.argsort(r[sel], kind="stable")]
        if len(sel) >= m:
            ranges[ray], out_values[ray] = r[sel[m - 1]], v[sel[m - 1]]
    seen = np.concatenate([p[:, :2], observed[:, :2]])
    seen = seen[np.isfinite(seen).all(axis=1)]
    rs = np.hypot(seen[:, 0], seen[:, 1])
    ks = np.rint((np.arctan2(seen[:, 1], seen[:, 0]) - a0) / inc).astype(np.int64)
    far = np.zeros(n, bool)
    far[ks[(ks >= 0) & (ks < n) & (rs >= r1)]] = True
    ranges[np.isnan(ranges) & far] = np.inf
    return ranges, out_values


@pytest.mark.parametrize("m", [1, 3, 7])
def test_the_per_bearing_reduction_is_the_sorted_scan(m):
    """The one-pass kernel (each bearing keeps its m nearest) gives the scan of sorting every return: ranges,
    intensities (equal ranges: the earlier point), +inf where something was seen at range_max, float32 points."""
    rng = np.random.default_rng(m)
    n_pts = 20000
    a = rng.uniform(-1.2, 1.2, n_pts)
    a[(a > 0.2) & (a < 0.4)] += 0.3                                 # bearings 0.2-0.4: seen far (+inf) only
    a[(a > -0.5) & (a < -0.3)] -= 0.3                               # -0.5..-0.3: nothing seen (nan)
    r = np.round(rng.uniform(0.05, 12.0, n_pts), 1)                  # many equal ranges on one bearing
    pts = np.column_stack([r * np.cos(a), r * np.sin(a), rng.uniform(0, 1, n_pts)])
    pts[rng.random(n_pts) < 0.01, 0] = np.nan
    b = rng.uniform(0.2, 0.4, 200)
    observed = np.column_stack([20.0 * np.cos(b), 20.0 * np.sin(b), np.zeros(200)])
    values = rng.uniform(0, 255, n_pts)
    kw = dict(angle_min_rad=-1.0, angle_max_rad=1.0, angle_increment_rad=math.radians(0.7), range_min_m=0.3,
              range_max_m=8.0, min_points=m, intensities=values, observed_points_robot=observed)
    scan = laser_scan_from_points(pts, **kw)
    n = scan.ranges_m.size
    ranges, out_values = _sorted_scan(pts, observed, -1.0, math.radians(0.7), n, 0.3, 8.0, m, values)
    np.testing.assert_array_equal(scan.ranges_m, ranges)
    np.testing.assert_array_equal(scan.intensities, out_values)
    assert np.isinf(scan.ranges_m).sum() >= 10 and np.isnan(scan.ranges_m).sum() >= 10
    assert np.isfinite(scan.ranges_m).sum() > n // 2
    as32 = laser_scan_from_points(pts.astype(np.float32), **kw)
    ranges32, _ = _sorted_scan(pts.astype(np.float32).astype(np.float64), observed, -1.0, math.radians(0.7), n, 0.3,
                               8.0, m, values)
    np.testing.assert_array_equal(as32.ranges_m, ranges32)
