"""Too near: pixels whose match lies beyond the largest searched disparity get no value but a
``too_near`` flag; the 3D stage treats them fail-safe (issue 15.1). Known answers: a synthetic
plane beyond the search, Tsukuba with a cut search, the real OpenCV chessboard pair."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from mrstereo.camera import Camera, CameraMount, StereoCamera, write_stereo
from mrstereo.cli import entry
from mrstereo.geometry import detect_obstacles
from mrstereo.io import read_disparity
from mrstereo.matching import MatchingConfig, NearGuardConfig, compute_disparity, make_plan
from mrstereo.geometry.pair import scan_from_pair
from mrstereo.recordings.samples import local_path
from mrstereo.viz.plot import colorize_disparity

TSUKUBA = local_path("tsukuba")
CHESSBOARD = local_path("opencv-stereo-chessboard")
TOO_NEAR_BGR = (255, 0, 255)          # magenta (mrstereo.viz.plot.TOO_NEAR_RGB)


def _plane_pair(d_px: int, height: int = 96, width: int = 240, seed: int = 0):
    """A fronto-parallel textured plane at disparity ``d_px`` filling the view."""
    rng = np.random.default_rng(seed)
    tex = cv2.GaussianBlur(rng.uniform(0, 1, (height, width + d_px)).astype(np.float32), (0, 0), 1.2)
    tex = np.round(20 + 215 * (tex - tex.min()) / (tex.max() - tex.min())).astype(np.uint8)
    # x_right = x_left - d: right(x) = texture(x + d) when left(x) = texture(x)
    return tex[:, :width].copy(), tex[:, d_px:d_px + width].copy()


def test_plane_beyond_the_search_is_all_too_near_and_never_valued():
    left, right = _plane_pair(40)
    for d_max in (24, 32, 64 / 3):               # one, two and three levels; 40 px is 1.25-1.9 x the limit
        result = compute_disparity(left, right, max_disparity_px=d_max)
        assert result.near_limit_px == pytest.approx(d_max)
        assert not np.isfinite(result.disparity_px).any()          # none valid anywhere
        seen = result.too_near[6:-6, 40 + 6:-6]                    # pixels whose match is in the image
        assert seen.mean() > 0.95, (d_max, seen.mean())
        assert (result.confidence[result.too_near] == 0).all()
    # the same plane inside the search: values, nothing too near
    inside = compute_disparity(left, right, max_disparity_px=48)
    assert not inside.too_near.any()
    assert np.nanmedian(inside.disparity_px) == pytest.approx(40, abs=0.2)
    # without the guard (the paper) the plane gets wrong, smaller disparities: what the guard prevents
    paper = compute_disparity(left, right, max_disparity_px=24, config=MatchingConfig(near_guard=None))
    assert not paper.too_near.any()


def test_a_plane_just_beyond_the_limit_is_too_near_not_a_value_at_the_band_edge():
    """One pixel past the near limit the band's winner sits on its edge, in the same cost
    minimum as the guard's: the value must lose (its re-scored minimum lies past the limit)."""
    for d_px, d_max in ((7, 6), (11, 10), (27, 24)):            # one, one and two levels
        left, right = _plane_pair(d_px, seed=1)
        result = compute_disparity(left, right, max_disparity_px=d_max)
        seen = (slice(6, -6), slice(d_px + 6, -6))
        assert not np.isfinite(result.disparity_px[seen]).any()
        assert result.too_near[seen].mean() > 0.95, (d_px, result.too_near[seen].mean())


def test_the_guard_is_in_the_plan_and_counted():
    plan = make_plan((640, 480), max_disparity_px=64)
    off = make_plan((640, 480), max_disparity_px=64, config=MatchingConfig(near_guard=None))
    assert plan.levels == off.levels                          # the bands' searches are untouched
    guard = plan.guard
    # D = 64 spans 8 pixels at twice the nearest band's decimation (4): the guard searches at 8,
    # from one level pixel below D to 2 D
    assert guard.decimation == 8 and guard.too_near_above_px == pytest.approx(64 + 4)
    assert guard.search_px == (7, 16) and guard.band_px == (64, 128)
    assert plan.work - off.work == guard.work == 480 * 80 * 10
    assert off.guard is None
    assert "too-near guard" in plan.describe() and "too-near guard" not in off.describe()
    # a small near limit keeps the nearest band's decimation (D = 9: one level at full width)
    small = make_plan((384, 288), max_disparity_px=9)
    assert small.guard.decimation == 1 and small.guard.search_px == (8, 18)
    assert make_plan((640, 480), max_disparity_px=64,
                     config=MatchingConfig(near_guard=NearGuardConfig(decimation=4))).guard.search_px == (15, 32)
    with pytest.raises(ValueError, match="near_guard reach"):
        NearGuardConfig(reach=0.5)
    with pytest.raises(ValueError, match="near_guard decimation"):
        NearGuardConfig(decimation=0)
    with pytest.raises(TypeError, match="near_guard must be a NearGuardConfig or None"):
        MatchingConfig(near_guard=0.0)


def _tsukuba():
    from mrstereo.evaluation.datasets import load_scene
    return load_scene(TSUKUBA)


@pytest.mark.sample_data("tsukuba")
def test_tsukuba_cut_to_9_px_gives_no_value_to_nearer_pixels():
    scene = _tsukuba()
    truth = scene.gt_disparity_px
    result = compute_disparity(scene.left, scene.right, max_disparity_px=9)
    beyond = np.isfinite(truth) & (truth > 10)
    inside = np.isfinite(truth) & (truth < 0.9 * 9)
    valued = np.isfinite(result.disparity_px)
    assert valued[beyond].mean() <= 0.01                       # was 19 % before the guard
    assert result.too_near[beyond].mean() > 0.6
    assert valued[inside].mean() >= 0.5
    assert result.too_near[inside].mean() < 0.03
    before = compute_disparity(scene.left, scene.right, max_disparity_px=9, config=MatchingConfig(near_guard=None))
    assert np.isfinite(before.disparity_px)[beyond].mean() > 0.1


@pytest.mark.sample_data("teddy", "cones")
@pytest.mark.parametrize("name", ["teddy", "cones"])
def test_a_search_covering_the_scene_gives_the_unguarded_values_bit_for_bit(name):
    """The guard searches apart from the bands: where nothing is too near, its stray candidates
    (repeated and plain regions matched past the near limit) change no value."""
    from mrstereo.evaluation.datasets import load_scene
    scene = load_scene(local_path(name))
    guarded = compute_disparity(scene.left, scene.right, max_disparity_px=scene.max_disparity_px)
    unguarded = compute_disparity(scene.left, scene.right, max_disparity_px=scene.max_disparity_px,
                                  config=MatchingConfig(near_guard=None))
    assert guarded.plan.guard is not None and not guarded.too_near.any()
    assert np.array_equal(guarded.disparity_px, unguarded.disparity_px, equal_nan=True)
    assert np.array_equal(guarded.confidence, unguarded.confidence)


@pytest.mark.sample_data("kitti2015-000000")
def test_kitti_car_nearer_than_the_search_is_flagged_and_only_its_surroundings_change():
    """KITTI 2015 #0 searched to 80 px (above every ground-truth disparity, 64 px): the parked car
    at the right border is nearer (86-97 px with a search to 192 px). It is flagged, and values
    change only around it."""
    from mrstereo.evaluation.datasets import load_scene
    scene = load_scene(local_path("kitti2015-000000"))
    result = compute_disparity(scene.left, scene.right, max_disparity_px=80)
    unguarded = compute_disparity(scene.left, scene.right, max_disparity_px=80, config=MatchingConfig(near_guard=None))
    rows, cols = np.nonzero(result.too_near)
    assert rows.size > 3000 and cols.min() > 1000                   # the car's door, nothing else
    wide = compute_disparity(scene.left, scene.right, max_disparity_px=192, config=MatchingConfig(near_guard=None))
    assert np.nanmedian(wide.disparity_px[result.too_near]) > 85       # truly beyond 80 px
    changed = ~((result.disparity_px == unguarded.disparity_px)
                | (np.isnan(result.disparity_px) & np.isnan(unguarded.disparity_px)))
    assert not changed[:, :800].any()                                  # far from the car: bit for bit
    assert not np.isfinite(result.disparity_px[result.too_near]).any()


@pytest.mark.sample_data("opencv-stereo-chessboard")
def test_real_chessboard_at_0_4_m_is_never_placed_farther_than_0_5_m():
    import sys
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from bench_too_near import board_mask

    from mrstereo.calibration import calibrate_stereo, chessboard_pairs, expand_glob

    found = chessboard_pairs(expand_glob(str(CHESSBOARD / "left*.jpg")), expand_glob(str(CHESSBOARD / "right*.jpg")),
                             (9, 6), 0.025)
    stereo = calibrate_stereo(found.left, found.right, width=found.size[0], height=found.size[1],
                              method="lm").stereo
    board, left, right = board_mask(stereo, CHESSBOARD / "left01.jpg", CHESSBOARD / "right01.jpg")
    result = compute_disparity(left, right, calibration=stereo)          # default depth bands 0.5-15 m
    assert result.near_limit_px < 100                                  # the board (103-124 px) is beyond
    d = result.disparity_px[board]
    depth = stereo.baseline_m * stereo.focal_px / (d[np.isfinite(d)] + stereo.doffs_px)
    assert (depth <= 0.5).all(), np.sort(depth)[-5:]                   # was 10.7 % valid at 0.86 m
    assert result.too_near[board].mean() > 0.15
    unguarded = compute_disparity(left, right, calibration=stereo, config=MatchingConfig(near_guard=None))
    assert np.isfinite(unguarded.disparity_px[board]).mean() > 0.02


# ------------------------------------------------------------------ fail-safe in the 3D stage

def _rig(width=240, height=96, f=200.0, height_m=0.6):
    cam = Camera(width=width, height=height, fx=f, fy=f, cx=(width - 1) / 2, cy=(height - 1) / 2)
    return StereoCamera.ideal(cam, 0.1, mount=CameraMount.from_rig(height_m, 0.0))


def test_too_near_pixels_become_obstacles_at_the_near_limit_never_floor():
    stereo = _rig(height_m=0.1)                        # a low camera: the floor is nearer than 0.5 m below
    h, w = 96, 240
    d = np.full((h, w), np.nan, np.float32)
    too_near = np.zeros((h, w), bool)
    too_near[10:45, 100:140] = True                    # above the centre row: 0.1-0.19 m high at 0.5 m
    too_near[90:96, 100:140] = True                    # bottom rows: the ray meets the floor before 0.5 m
    near_limit_px = 0.1 * 200 / 0.5                     # 40 px: the near limit is 0.5 m
    obs = detect_obstacles(d, stereo, too_near=too_near, near_limit_px=near_limit_px)
    pts = obs.points_robot_image[10:45, 100:140].reshape(-1, 3)
    assert np.allclose(pts[:, 0], 0.5)                    # robot x forward = the near-limit depth (tilt 0)
    assert obs.obstacle_mask[10:45, 100:140].all()
    assert not obs.floor_mask[too_near].any()
    bottom = obs.points_robot_image[90:96, 100:140, 2]
    assert (bottom < 0).all() and not obs.obstacle_mask[90:96].any()   # below the floor: ignored
    assert obs.too_near_obstacle_mask.sum() == 35 * 40
    assert "too near" in obs.message
    without = detect_obstacles(d, stereo)
    assert not without.obstacle_mask.any() and not without.too_near_obstacle_mask.any()
    with pytest.raises(ValueError, match="near_limit_px"):
        detect_obstacles(d, stereo, too_near=too_near)
    with pytest.raises(ValueError, match="too_near"):
        detect_obstacles(d, stereo, too_near=too_near[:10], near_limit_px=40.0)


def test_scan_reports_range_min_where_something_is_too_near():
    stereo = _rig()
    left, right = _plane_pair(64)                      # a wall at 0.31 m; the search ends at 0.5 m (40 px)
    result = scan_from_pair(left, right, stereo, rectified=True, range_min_m=0.1)
    scan, obs = result.scan, result.frame.obstacles
    assert obs.too_near_obstacle_mask.mean() > 0.4
    # the bearings of the columns whose match is inside the right image (x >= 64 + window)
    u = stereo.cx_px - stereo.focal_px * np.tan(scan.angles_rad)
    seen = (u > 64 + 12) & (u < 240 - 8)
    assert seen.sum() > 20
    assert scan.range_min_m == pytest.approx(0.5, abs=0.01)      # the near limit (0.1 asked)
    assert (scan.ranges_m[seen] == scan.range_min_m).all()
    # the near limit itself: no return is ever farther than the wall's fail-safe placement
    assert not (scan.ranges_m[np.isfinite(scan.ranges_m)] > 0.5 + 0.01).any()


# ------------------------------------------------------------------ CLI and preview

def test_preview_colours_too_near_apart_from_no_value():
    d = np.array([[np.nan, 5.0, np.nan]], np.float32)
    tn = np.array([[False, False, True]])
    img = colorize_disparity(d, max_disparity_px=10, too_near=tn)
    assert tuple(img[0, 0]) == (0, 0, 0) and tuple(img[0, 2]) == TOO_NEAR_BGR
    assert tuple(img[0, 1]) != TOO_NEAR_BGR
    assert np.array_equal(colorize_disparity(d, max_disparity_px=10)[0, :2], img[0, :2])
    with pytest.raises(ValueError, match="too_near"):
        colorize_disparity(d, too_near=np.zeros((2, 2), bool))


def test_disparity_command_explains_and_colours_too_near(tmp_path, capsys):
    left, right = _plane_pair(40)
    cv2.imwrite(str(tmp_path / "l.png"), left)
    cv2.imwrite(str(tmp_path / "r.png"), right)
    out, color = tmp_path / "d.pfm", tmp_path / "c.png"
    assert entry(["disparity", str(tmp_path / "l.png"), str(tmp_path / "r.png"), "--max-disparity", "24",
                  "--explain", "-o", str(out), "--plot", str(color)]) == 0
    captured = capsys.readouterr()
    share = float(captured.out.split("no value) ")[1].split("%")[0])
    assert 70 < share <= 100
    assert "too near" in captured.err
    assert not np.isfinite(read_disparity(out)).any()
    img = cv2.imread(str(color))
    assert (img == np.array(TOO_NEAR_BGR, np.uint8)).all(axis=2).sum() > 1000       # the preview shows them
    # with a calibration the explanation gives the near limit in metres
    write_stereo(tmp_path / "rig.yaml", _rig())
    assert entry(["disparity", str(tmp_path / "l.png"), str(tmp_path / "r.png"), "--calib", str(tmp_path / "rig.yaml"),
                  "--rectified", "--explain", "-o", str(out)]) == 0
    assert "nearer than 0.50 m" in capsys.readouterr().out
