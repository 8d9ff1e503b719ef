"""``mrstereo odometry``: TUM trajectory, figure, metrics; bad input is one line and exit 2."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from mrstereo.cli import entry
from mrstereo.geometry.ground import ground_from_mount
from mrstereo.odometry.trajectory import read_tum, trajectory_metrics, umeyama_alignment, write_tum
from mrstereo.recordings.manifest import read_manifest
from mrstereo.transforms import T_from_planar

from _bags import DT_NS, T0_NS, TOPICS, write_bag


@pytest.fixture(scope="module")
def sequence(synthetic_dataset):
    return synthetic_dataset(n_frames=6, supersample=1, path="s-curve", step_m=0.1,
                             odometry_noise=(0.03, math.radians(2)))


def test_tum_round_trip_and_bad_files(tmp_path):
    rng = np.random.default_rng(4)
    T = np.stack([T_from_planar(*rng.normal(size=3)) for _ in range(5)])
    T[:, 2, 3] = rng.normal(size=5)
    write_tum(tmp_path / "t.txt", np.arange(5) * 0.1, T, comment="two\nlines")
    stamps, back = read_tum(tmp_path / "t.txt")
    np.testing.assert_allclose(stamps, np.arange(5) * 0.1)
    np.testing.assert_allclose(back, T, atol=1e-8)
    # real stamps (a bag's header stamps, seconds since 1970) and full 3-D poses survive the file
    from mrstereo.transforms import rotation_from_rpy

    T3 = np.stack([np.eye(4)] * 3)
    T3[:, :3, :3] = rotation_from_rpy([0.1, -0.2, 0.05], [0.02, 0.3, -0.1], [1.0, -2.5, 3.0])
    T3[:, :3, 3] = [[1.0, 2.0, 0.5], [-3.0, 0.25, 1.75], [10.0, -20.0, -0.125]]
    real = 1317384506.402581 + np.array([0.0, 0.1037, 0.2071])
    write_tum(tmp_path / "real.txt", real, T3)
    stamps3, back3 = read_tum(tmp_path / "real.txt")
    np.testing.assert_allclose(stamps3, real, rtol=0, atol=1e-6)
    np.testing.assert_allclose(back3, T3, atol=1e-8)
    (tmp_path / "bad.txt").write_text("0 1 2 3 0 0 0\n")
    with pytest.raises(ValueError, match="line 1: expected 8"):
        read_tum(tmp_path / "bad.txt")
    with pytest.raises(ValueError, match="stamps_s"):
        write_tum(tmp_path / "x.txt", [0.0], T)


def test_metrics_known_answers():
    x = np.linspace(0, 5, 51)
    truth = np.stack([T_from_planar(v, 0.0, 0.0) for v in x])
    same = trajectory_metrics(truth, truth)
    assert same.ate_rmse_m == 0 and same.end_point_error_m == 0 and same.rpe_translation_per_m == 0
    assert same.path_length_m == pytest.approx(5.0)
    # a 3 % scale error: end point 15 cm off, RPE 3 cm per metre, no rotation error
    scaled = np.stack([T_from_planar(1.03 * v, 0.0, 0.0) for v in x])
    m = trajectory_metrics(scaled, truth)
    assert m.end_point_error_m == pytest.approx(0.15)
    assert m.rpe_translation_per_m == pytest.approx(0.03, rel=1e-6)
    assert m.rpe_rotation_deg_per_m == pytest.approx(0.0, abs=1e-9)
    assert m.ate_rmse_unaligned_m == pytest.approx(0.03 * np.sqrt(np.mean(x ** 2)))
    assert m.ate_rmse_m < m.ate_rmse_unaligned_m           # the alignment centres the error
    # a rigid offset disappears after alignment (SE(3) and SE(2)) but not unaligned
    moved = np.stack([T_from_planar(1.0, 2.0, 0.3) @ t for t in truth])
    for alignment in ("se3", "se2"):
        assert trajectory_metrics(moved, truth, alignment=alignment).ate_rmse_m < 1e-9
    assert trajectory_metrics(moved, truth, alignment="none").ate_rmse_m > 1.0
    A = umeyama_alignment(moved[:, :3, 3], truth[:, :3, 3])
    np.testing.assert_allclose(A @ T_from_planar(1.0, 2.0, 0.3), np.eye(4), atol=1e-9)
    with pytest.raises(ValueError, match="alignment"):
        trajectory_metrics(truth, truth, alignment="sim3")
    with pytest.raises(ValueError, match="same number"):
        trajectory_metrics(truth[:3], truth)


def test_odometry_command(sequence, tmp_path, capsys):
    out, plot, metrics = tmp_path / "traj.txt", tmp_path / "traj.png", tmp_path / "m.json"
    code = entry(["odometry", str(sequence), "-o", str(out), "--plot", str(plot), "--metrics", str(metrics),
                  "--quiet"])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "vs true poses" in text
    stamps, T = read_tum(out)
    np.testing.assert_allclose(stamps, 0.1 * np.arange(6), atol=1e-9)   # the sequence's stamps (10 Hz)
    manifest = read_manifest(sequence)
    true = np.array([f.true_pose for f in manifest.frames])
    np.testing.assert_allclose(T[:, :2, 3], true[:, :2], atol=0.01)  # the visual odometry, not the drifted poses
    data = json.loads(metrics.read_text())
    assert data["reference"] == "true poses" and data["lost"] == 0 and data["ate_rmse_m"] < 0.01
    assert plot.stat().st_size > 10000 and plot.read_bytes()[:4] == b"\x89PNG"
    # --profile: the odometry is a stage of its own, once per frame
    assert entry(["odometry", str(sequence), "-o", str(tmp_path / "p.txt"), "--quiet", "--profile"]) == 0
    rows = {line.split()[0]: line.split() for line in capsys.readouterr().err.splitlines() if line.strip()}
    assert rows["odometry"][2] == "6" and float(rows["odometry"][1]) > 0


def test_odometry_command_bad_input(sequence, tmp_path, capsys):
    assert entry(["odometry", str(tmp_path / "missing"), "-o", str(tmp_path / "t.txt")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("mrstereo: error:") and "missing" in err and err.count("\n") == 1
    assert entry(["odometry", str(sequence), "-o", str(sequence / "manifest.yaml")]) == 2
    assert "--out must end in .txt or .tum" in capsys.readouterr().err
    assert entry(["odometry", str(sequence), "-o", str(sequence / "t.txt")]) == 2
    assert "lies inside the dataset" in capsys.readouterr().err
    assert entry(["odometry", str(sequence), "-o", str(tmp_path / "t.txt"), "--metrics",
                  str(sequence / "calibration.yaml")]) == 2
    assert "--metrics must end in .json" in capsys.readouterr().err
    assert entry(["odometry", "-o", str(tmp_path / "t.txt")]) == 2
    assert "RECORDING or --bag" in capsys.readouterr().err
    assert not (tmp_path / "t.txt").exists()


def test_fusion_of_given_and_visual_odometry():
    """Drifted wheel odometry (3 %, 2 deg/m) with good visual steps: the truth back; lost frames and a
    wrong visual step fall back to the wheels."""
    from mrstereo.odometry.fusion import FusionConfig, fuse_odometry
    from mrstereo.world.paths import drifted_poses, sequence_path

    rng = np.random.default_rng(3)
    true = sequence_path("s-curve", 91, step_m=0.1)
    given = drifted_poses(true, scale_error=0.03, heading_drift_rad_per_m=math.radians(2.0))
    visual = true + rng.normal(scale=[0.0003, 0.0003, math.radians(0.01)], size=true.shape)
    visual = np.stack([T_from_planar(*p) for p in visual])
    visual = np.array([[T[0, 3], T[1, 3], math.atan2(T[1, 0], T[0, 0])]
                       for T in T_from_planar(0.5, -2.0, 1.0) @ visual])      # another world frame: steps only
    tracked = np.ones(len(true), bool)
    fused = fuse_odometry(given, visual, tracked)
    assert fused.visual_used[1:].all() and not fused.visual_rejected.any()
    assert math.hypot(*(given[-1, :2] - true[-1, :2])) > 0.3                      # the wheels' end error
    assert np.hypot(*(fused.poses[:, :2] - true[:, :2]).T).max() < 0.02
    np.testing.assert_array_equal(fused.poses[0], given[0])
    # lost frames: the wheels bridge them (their steps, with their drift over 1 m)
    tracked[30:40] = False
    bridged = fuse_odometry(given, visual, tracked)
    assert not bridged.visual_used[30:41].any() and bridged.visual_used[41:].all()
    assert math.hypot(*(bridged.poses[40, :2] - true[40, :2])) < 0.05            # 1 m of wheels: 3 % + 1 deg
    heading_after = np.degrees(bridged.poses[41:, 2] - true[41:, 2])              # the gap's 2 deg stay
    assert np.abs(heading_after - 2.0).max() < 0.4
    # a visual step 0.5 m off is outside the wheels' drift: rejected
    wrong = visual.copy()
    wrong[60:, 0] += 0.5
    gated = fuse_odometry(given, wrong, np.ones(len(true), bool))
    assert gated.visual_rejected[60] and gated.visual_rejected.sum() == 1
    assert np.hypot(*(gated.poses[:, :2] - true[:, :2]).T).max() < 0.03
    moved, turned = gated.corrections(given)
    assert moved[0] == 0.0 and moved[-1] > 0.3 and turned.shape == (len(true),)
    with pytest.raises(ValueError, match="visual_poses"):
        fuse_odometry(given, visual[:5], tracked)
    with pytest.raises(ValueError, match="gate_sigmas"):
        FusionConfig(gate_sigmas=0.0)


def test_map_with_visual_odometry_and_alignment(sequence, tmp_path, capsys):
    manifest = read_manifest(sequence)
    true = np.array([f.true_pose for f in manifest.frames])
    for options, key in ((["--odometry", "visual"], "visual_odometry"), (["--align"], "alignment")):
        out = tmp_path / key
        code = entry(["map", str(sequence), "-o", str(out), "--quiet", *options])
        text = capsys.readouterr().out
        assert code == 0, text
        data = json.loads((out / "metrics.json").read_text())
        assert data[key]["frames"] == 6 and "precision" in data
        assert data["given_poses_vs_truth"]["end_point_error_m"] > 0.005           # the drifted odometry
        if key == "visual_odometry":
            assert "visual odometry: tracked all 6 frames" in text
            assert data["poses_vs_truth"]["end_point_error_m"] < 0.01
            assert data["poses_vs_truth"]["ate_rmse_unaligned_m"] < 0.01
        else:
            assert "given odometry fused with visual odometry: 5 of 5 steps measured visually" in text
            assert data["alignment"]["visual_steps"] == 5 and data["alignment"]["rejected_visual_steps"] == 0
            assert 0 <= data["alignment"]["mean_correction_m"] <= data["alignment"]["max_correction_m"] < 0.2
            assert data["poses_vs_truth"]["end_point_error_m"] < 0.01
    assert entry(["map", str(sequence), "-o", str(tmp_path / "both"), "--odometry", "visual", "--align"]) == 2
    assert "not with --odometry visual" in capsys.readouterr().err
    # with --workers the visual-odometry map is the same
    code = entry(["map", str(sequence), "-o", str(tmp_path / "w2"), "--quiet", "--odometry", "visual",
                  "--workers", "2"])
    assert code == 0
    np.testing.assert_array_equal(np.load(tmp_path / "w2" / "log_odds.npy"),
                                  np.load(tmp_path / "visual_odometry" / "log_odds.npy"))


def test_a_bag_without_odometry(sequence, tmp_path, capsys):
    """Camera topics only: the odometry command and map --odometry visual work from the images."""
    manifest = read_manifest(sequence)
    rig = ground_from_mount(manifest.mount, R_rect_from_cam=manifest.calibration.left.R)
    bag = write_bag(tmp_path / "cams.bag", manifest, ros1=True, odom=False)
    common = ["--bag", str(bag), "--left-topic", TOPICS["left_topic"], "--right-topic", TOPICS["right_topic"],
              "--camera-info-topics", ",".join(TOPICS["camera_info_topics"]), "--height",
              str(rig.height_m), "--tilt", str(rig.tilt_rad), "--quiet"]
    assert entry(["odometry", *common, "-o", str(tmp_path / "t.txt")]) == 0
    stamps, T = read_tum(tmp_path / "t.txt")
    np.testing.assert_allclose(stamps, (T0_NS + np.arange(6) * DT_NS) / 1e9)      # the image stamps
    true = np.array([f.true_pose for f in manifest.frames])                          # starts at the origin
    np.testing.assert_allclose(T[:, :2, 3], true[:, :2], atol=0.01)
    assert entry(["map", *common, "--odometry", "visual", "-o", str(tmp_path / "m")]) == 0
    out = capsys.readouterr().out
    assert "visual odometry: tracked all 6 frames" in out
    assert (tmp_path / "m" / "map.pgm").is_file()
