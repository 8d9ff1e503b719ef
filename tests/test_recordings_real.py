"""Recordings as users have them, on the real samples: the EuRoC/ASL folder and KITTI odometry frames
mapped and tracked with one command, a pre-rectified camera from four numbers and a size, a map that
grows (or counts what falls outside its window), a wrong mount warned about and replaced by the floor
seen, and a plan from the robot's own pose."""
from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from mrstereo.cli import entry
from mrstereo.mapping.rosmap import read_ros_map
from mrstereo.recordings.samples import data_root


@pytest.fixture(scope="module")
def euroc():
    root = data_root() / "euroc_asl_sample"
    if not (root / "mav0" / "cam0" / "data.csv").is_file():
        pytest.skip(f"EuRoC sample not found under {root} (set MRSTEREO_DATA)")
    return root


@pytest.fixture(scope="module")
def kitti_seq():
    seq = data_root() / "kitti_odometry_06" / "sequences" / "06"
    if not (seq / "calib.txt").is_file():
        pytest.skip(f"KITTI odometry sample not found under {seq} (set MRSTEREO_DATA)")
    return seq


@pytest.fixture(scope="module")
def euroc_map(euroc, tmp_path_factory):
    """`mrstereo map mav0-folder -o OUT`: no option, no file written by hand."""
    out = tmp_path_factory.mktemp("euroc") / "map"
    assert entry(["map", str(euroc), "-o", str(out), "--quiet"]) == 0
    return out


def _occupied(out) -> int:
    return int(read_ros_map(out / "map.yaml").occupied.sum())


def test_euroc_folder_maps_and_tracks_with_one_command(euroc, euroc_map, tmp_path, capsys):
    metrics = json.loads((euroc_map / "metrics.json").read_text())
    assert metrics["floor"]["confident"] and 0.5 < metrics["floor"]["height_m"] < 1.5     # a MAV on its stand
    assert metrics["map_window"]["points_outside"] == 0                                  # the map grew to them
    assert metrics["visual_odometry"]["lost"] == 0
    assert _occupied(euroc_map) > 300                        # the room's wall 2-3 m ahead of the camera
    assert entry(["odometry", str(euroc / "mav0"), "-o", str(tmp_path / "vo.txt"), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "tracked all 5 frames" in out and "no true or given poses to compare with" in out   # no truth: no ATE
    assert len(np.loadtxt(tmp_path / "vo.txt", ndmin=2)) == 5
    # batch names it after the sequence folder and maps it as `map` does: visual odometry, floor estimated
    assert entry(["batch", str(euroc / "mav0"), "-o", str(tmp_path / "batch"), "--quiet"]) == 0
    np.testing.assert_array_equal(np.load(tmp_path / "batch" / euroc.name / "map" / "log_odds.npy"),
                                  np.load(euroc_map / "log_odds.npy"))


def test_info_names_the_layout_and_an_unknown_folder_what_was_looked_for(euroc, kitti_seq, tmp_path, capsys):
    assert entry(["info", str(euroc)]) == 0
    out = capsys.readouterr().out
    assert "EuRoC/ASL" in out and "752x480" in out and "baseline 0.110" in out and "truth:            none" in out
    assert entry(["info", str(kitti_seq)]) == 0
    out = capsys.readouterr().out
    assert "KITTI odometry" in out and "51" in out and "path 59.8 m" in out
    (tmp_path / "stuff").mkdir()
    assert entry(["map", str(tmp_path / "stuff"), "-o", str(tmp_path / "m"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "mav0" in err[0] and "calib.txt" in err[0] and "manifest" in err[0]


def test_euroc_truth_is_read_when_present(euroc, tmp_path, capsys):
    root = tmp_path / "euroc"
    shutil.copytree(euroc, root)
    stamps = np.loadtxt(euroc / "mav0" / "cam0" / "data.csv", delimiter=",", usecols=0, dtype=np.int64)
    truth = root / "mav0" / "state_groundtruth_estimate0"
    truth.mkdir()
    t = np.linspace(stamps[0] - 10**8, stamps[-1] + 10**8, 50).astype(np.int64)
    x = 0.5 * (t - t[0]) / 1e9                                 # 0.5 m/s along x, level, facing x
    rows = [f"{ti},{xi:.6f},0.0,1.0,1.0,0.0,0.0,0.0" for ti, xi in zip(t, x)]
    (truth / "data.csv").write_text("#timestamp,p_x,p_y,p_z,q_w,q_x,q_y,q_z\n" + "\n".join(rows) + "\n")
    assert entry(["info", str(root)]) == 0
    out = capsys.readouterr().out
    path_m = 0.5 * (stamps[-1] - stamps[0]) / 1e9
    assert f"path {path_m:.1f} m" in out
    assert entry(["odometry", str(root), "-o", str(tmp_path / "vo.txt"), "--quiet"]) == 0
    assert "vs true poses" in capsys.readouterr().out


def test_a_wrong_mount_is_warned_about_and_the_room_still_mapped(euroc, euroc_map, tmp_path, capsys):
    """A mount in the MAV's body frame (the camera 1 cm "above the floor"): the seen floor replaces it."""
    capsys.readouterr()
    out = tmp_path / "map"
    assert entry(["map", str(euroc), "-o", str(out), "--mount", "0.02,0,0.01,0,0,0", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "warning: the camera mount disagrees with the floor seen" in err
    assert "given height 0.010 m" in err and "seen height 0.9" in err and "--base-frame" in err
    assert _occupied(out) == _occupied(euroc_map)              # the same room as with no mount at all
    # kept on request, the wrong mount maps the room elsewhere (the wall's height band is off the floor)
    assert entry(["map", str(euroc), "-o", str(tmp_path / "kept"), "--mount", "0.02,0,0.01,0,0,0",
                  "--no-mount-check", "--quiet"]) == 0
    assert "warning" not in capsys.readouterr().err and _occupied(tmp_path / "kept") != _occupied(euroc_map)
    # a map that saw nothing is an error, never an empty map with exit 0
    assert entry(["map", str(euroc), "-o", str(tmp_path / "none"), "--max-range", "0.3", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "error: the map of 5 frames is empty" in err and not (tmp_path / "none" / "map.pgm").exists()


def test_a_fixed_window_counts_and_warns_about_the_points_outside(euroc, euroc_map, tmp_path, capsys):
    out = tmp_path / "map"
    assert entry(["map", str(euroc), "-o", str(out), "--origin", "-0.5,-1", "--size", "3,2", "--quiet"]) == 0
    err = capsys.readouterr().err
    n = json.loads((out / "metrics.json").read_text())["map_window"]["points_outside"]
    assert n > 1000 and f"warning: {n} points fell outside the map window" in err
    assert 0 < _occupied(out) < _occupied(euroc_map)          # the wall's middle, in the window


def test_plan_from_the_robots_own_pose_on_the_euroc_map(euroc, euroc_map, tmp_path, capsys):
    out = tmp_path / "plan.json"
    assert entry(["plan", str(euroc_map / "map.yaml"), "--start", "0,0", "--goal", "1.5,0.5", "-o", str(out)]) == 0
    plan = json.loads(out.read_text())
    assert 1.5 < plan["length_m"] < 2.5
    # without the footprint the cells under the robot were never seen: the start is refused
    bare = tmp_path / "bare"
    assert entry(["map", str(euroc), "-o", str(bare), "--footprint", "0", "--quiet"]) == 0
    capsys.readouterr()
    assert entry(["plan", str(bare / "map.yaml"), "--start", "0,0", "--goal", "1.5,0.5", "-o",
                  str(tmp_path / "p0.json")]) == 2
    assert "start" in capsys.readouterr().err


def _kitti_frames(kitti_seq, root, n):
    """The first ``n`` KITTI frames as a plain ``left/ right/`` pair of image folders."""
    for sub, name in (("image_0", "left"), ("image_1", "right")):
        (root / name).mkdir(parents=True)
        for k in range(n):
            shutil.copy(kitti_seq / sub / f"{k:06d}.png", root / name / f"{k:06d}.png")
    return root


def test_a_prerectified_camera_from_four_numbers_and_a_size(tmp_path, capsys):
    """KITTI 2012 #70 is a pre-rectified real pair: its numbers give the disparity of its ground truth."""
    import cv2

    from mrstereo.camera import read_stereo
    from mrstereo.io import read_disparity

    scene = data_root() / "kitti2012" / "000070"
    if not (scene / "image_0" / "000070_10.png").is_file():
        pytest.skip("KITTI 2012 sample not found (set MRSTEREO_DATA)")
    calib = tmp_path / "stereo.yaml"
    assert entry(["calib", "convert", "--fx", "718.856", "--cx", "607.1928", "--cy", "185.2157", "--baseline",
                  "0.53717", "--size", "1241x376", "-o", str(calib)]) == 0
    stereo = read_stereo(calib)
    assert stereo.is_rectified and stereo.size == (1241, 376)
    assert stereo.right.P[0, 3] == pytest.approx(-386.1448, abs=0.01)      # calib/000070.txt's P1
    out = tmp_path / "d.pfm"
    assert entry(["disparity", str(scene / "image_0" / "000070_10.png"), str(scene / "image_1" / "000070_10.png"),
                  "--calib", str(calib), "--rectified", "-o", str(out)]) == 0
    d, truth = read_disparity(out), cv2.imread(str(scene / "disp_noc" / "000070_10.png"), -1) / 256.0
    valid = (truth > 0) & np.isfinite(d)
    error = np.abs(d - truth)[valid]
    assert valid.sum() > 0.3 * (truth > 0).sum() and np.median(error) < 0.5 and (error > 3).mean() < 0.03
    # the numbers are checked: all four and the size, a baseline in metres
    assert entry(["calib", "convert", "--fx", "718", "-o", str(tmp_path / "x.yaml")]) == 2
    assert "missing --cx, --cy, --baseline, --size" in capsys.readouterr().err
    assert entry(["calib", "convert", "--fx", "718", "--cx", "600", "--cy", "180", "--baseline", "75", "--size",
                  "640x400", "-o", str(tmp_path / "x.yaml")]) == 2
    assert "millimetres or centimetres" in capsys.readouterr().err and not (tmp_path / "x.yaml").exists()
    for option, value in (("--cx", "5000"), ("--cy", "-3")):          # a principal point off the image
        args = {"--cx": "600", "--cy": "180", option: value}
        assert entry(["calib", "convert", "--fx", "718", "--cx", args["--cx"], "--cy", args["--cy"], "--baseline",
                      "0.5", "--size", "1241x376", "-o", str(tmp_path / "x.yaml")]) == 2
        err = capsys.readouterr().err
        assert option in err and "outside the image" in err and err.count("\n") == 1
        assert not (tmp_path / "x.yaml").exists()


def test_image_folders_with_four_numbers_map_and_track(kitti_seq, tmp_path, capsys):
    """OAK-D style: rectified left/right folders, a calibration from four numbers, a frame rate."""
    from mrstereo.recordings.kitti import read_kitti_odometry

    root = _kitti_frames(kitti_seq, tmp_path / "rec", 8)
    calib = tmp_path / "stereo.yaml"
    assert entry(["calib", "convert", "--fx", "707.0912", "--cx", "601.8873", "--cy", "183.1104", "--baseline",
                  "0.53715", "--size", "1226x370", "-o", str(calib)]) == 0
    traj = tmp_path / "vo.txt"
    assert entry(["odometry", str(root), "--calib", str(calib), "--rate", "10", "-o", str(traj), "--quiet"]) == 0
    assert "tracked all 8 frames" in capsys.readouterr().out
    T = np.loadtxt(traj, ndmin=2)
    truth = read_kitti_odometry(kitti_seq.parent.parent)
    true_x = truth.frames[7].T_world_from_base_true[:3, 3] - truth.frames[0].T_world_from_base_true[:3, 3]
    assert np.linalg.norm(T[7, 1:4] - T[0, 1:4]) == pytest.approx(np.linalg.norm(true_x), rel=0.05)
    out = tmp_path / "map"
    assert entry(["map", str(root), "--calib", str(calib), "--rate", "10", "-o", str(out), "--quiet"]) == 0
    captured = capsys.readouterr()
    assert "floor estimated" in captured.out
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["floor"]["height_m"] == pytest.approx(1.65, abs=0.1)     # KITTI's camera above the road
    assert metrics["map_window"]["points_outside"] == 0 and _occupied(out) > 200


def test_kitti_sequence_maps_with_visual_odometry_in_one_command(kitti_seq, tmp_path, capsys):
    """The KITTI layout read directly: its truth, calibration and mount; the map grows along the road."""
    seq = tmp_path / "sequences" / "06"
    for sub in ("image_0", "image_1"):
        (seq / sub).mkdir(parents=True)
        for k in range(10):
            shutil.copy(kitti_seq / sub / f"{k:06d}.png", seq / sub / f"{k:06d}.png")
    for name in ("calib.txt", "times.txt"):
        shutil.copy(kitti_seq / name, seq / name)
    (tmp_path / "poses").mkdir()
    shutil.copy(kitti_seq.parent.parent / "poses" / "06.txt", tmp_path / "poses" / "06.txt")
    out = tmp_path / "map"
    assert entry(["map", str(seq), "-o", str(out), "--odometry", "visual", "--quiet"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    window = metrics["map_window"]
    assert window["points_outside"] == 0 and window["range_m"] > 15            # a car's rig sees far
    assert window["origin_m"][0] + window["size_m"][0] > 10.0                  # the 10 frames drove ~11 m
    assert metrics["poses_vs_truth"]["ate_rmse_m"] < 0.3 and _occupied(out) > 500
