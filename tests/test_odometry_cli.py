"""``mrstereo odometry``: TUM trajectory, figure, metrics; bad input is one line and exit 2."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from mrstereo.cli import entry
from mrstereo.odometry.trajectory import read_tum, trajectory_metrics, umeyama_alignment, write_tum
from mrstereo.recordings.manifest import read_manifest
from mrstereo.transforms import T_from_planar
from mrstereo.world.dataset import write_synthetic_dataset


@pytest.fixture(scope="module")
def sequence(tmp_path_factory):
    out = tmp_path_factory.mktemp("odo") / "seq"
    return write_synthetic_dataset(out, n_frames=6, supersample=1, path="s-curve", step_m=0.1,
                                   odometry_noise=(0.03, math.radians(2)), progress=False)


def test_tum_round_trip_and_bad_files(tmp_path):
    rng = np.random.default_rng(4)
    T = np.stack([T_from_planar(*rng.normal(size=3)) for _ in range(5)])
    T[:, 2, 3] = rng.normal(size=5)
    write_tum(tmp_path / "t.txt", np.arange(5) * 0.1, T, comment="two\nlines")
    stamps, back = read_tum(tmp_path / "t.txt")
    np.testing.assert_allclose(stamps, np.arange(5) * 0.1)
    np.testing.assert_allclose(back, T, atol=1e-8)
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
    assert "would overwrite" in capsys.readouterr().err
    assert entry(["odometry", "-o", str(tmp_path / "t.txt")]) == 2
    assert "DATASET or --bag" in capsys.readouterr().err
    assert not (tmp_path / "t.txt").exists()


def test_align_points_recovers_a_known_offset():
    from mrstereo.mapping import GridSpec
    from mrstereo.odometry.alignment import AlignConfig, align_points, likelihood_field

    grid = GridSpec(width_m=6.0, height_m=4.0, origin_x_m=-1.0, origin_y_m=-2.0)
    # an L of walls and a box: a wall along x at y = 1.0, one along y at x = 3.0, a box corner
    occupied = np.zeros(grid.shape, bool)
    xy = grid.cell_centres()
    occupied |= np.abs(xy[..., 1] - 1.0) < 0.03
    occupied |= (np.abs(xy[..., 0] - 3.0) < 0.03) & (xy[..., 1] < 1.0)
    occupied |= (np.abs(xy[..., 0] - 1.5) < 0.03) & (np.abs(xy[..., 1] + 0.8) < 0.3)
    field = likelihood_field(occupied, grid, sigma_m=0.05)
    # points on those walls in the robot frame of the true pose
    rng = np.random.default_rng(2)
    world = np.concatenate([np.column_stack([rng.uniform(0, 2.9, 300), np.full(300, 1.0)]),
                            np.column_stack([np.full(200, 3.0), rng.uniform(-1.5, 1.0, 200)]),
                            np.column_stack([np.full(100, 1.5), rng.uniform(-1.1, -0.5, 100)])])
    world = world + rng.normal(scale=0.01, size=world.shape)
    true = (0.2, -0.1, 0.05)
    c, s = math.cos(true[2]), math.sin(true[2])
    d = world - true[:2]
    robot = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])
    prior = (0.26, -0.05, 0.05 + math.radians(1.2))                   # odometry 8 cm and 1.2 degrees off
    loose = np.diag([0.1 ** 2, 0.1 ** 2, math.radians(3.0) ** 2])
    config = AlignConfig(min_cell_points=1, effective_points=300)
    result = align_points(robot, prior, field, grid, prior_covariance=loose, config=config)
    assert result.applied and result.score > result.prior_score
    assert math.hypot(result.pose[0] - true[0], result.pose[1] - true[1]) < 0.01
    assert abs(result.pose[2] - true[2]) < math.radians(0.2)
    assert result.correction_m == pytest.approx(math.hypot(result.pose[0] - prior[0], result.pose[1] - prior[1]))
    sd = np.sqrt(np.diag(result.covariance))
    assert (sd < np.sqrt(np.diag(loose)) / 3).all()                  # the scan is worth more than the prior
    # a tight prior (odometry trusted) keeps the pose near it: the posterior weighs both
    tight = align_points(robot, prior, field, grid, prior_covariance=loose / 400, config=config)
    assert tight.correction_m < 0.5 * result.correction_m
    # nothing to align to: the prior is kept
    empty = likelihood_field(np.zeros(grid.shape, bool), grid, sigma_m=0.05)
    kept = align_points(robot, prior, empty, grid)
    assert not kept.applied and kept.pose == prior
    with pytest.raises(ValueError, match="points_robot_xy"):
        align_points(np.zeros(5), prior, field, grid)
    with pytest.raises(ValueError, match="prior_covariance"):
        align_points(robot, prior, field, grid, prior_covariance=np.eye(2))


def test_align_points_leaves_a_corridor_axis_to_the_odometry():
    """Two parallel walls say nothing along their axis: the correction there is the prior's."""
    from mrstereo.mapping import GridSpec
    from mrstereo.odometry.alignment import AlignConfig, align_points, likelihood_field

    grid = GridSpec(width_m=8.0, height_m=4.0, origin_x_m=-1.0, origin_y_m=-2.0)
    xy = grid.cell_centres()
    occupied = (np.abs(xy[..., 1] - 0.8) < 0.03) | (np.abs(xy[..., 1] + 1.1) < 0.03)
    field = likelihood_field(occupied, grid, sigma_m=0.05)
    rng = np.random.default_rng(5)
    wall_x = rng.uniform(0.5, 4.0, 400)
    world = np.column_stack([wall_x, np.where(np.arange(400) % 2, 0.8, -1.1)]) + rng.normal(scale=0.01, size=(400, 2))
    true = (1.0, 0.1, 0.0)
    robot = world - true[:2]
    prior = (1.06, 0.14, math.radians(0.8))                           # 6 cm along, 4 cm across, 0.8 degrees
    P = np.diag([0.05 ** 2, 0.05 ** 2, math.radians(2.0) ** 2])
    result = align_points(robot, prior, field, grid, prior_covariance=P,
                          config=AlignConfig(min_cell_points=1, effective_points=300))
    assert abs(result.pose[1] - true[1]) < 0.01 and abs(result.pose[2] - true[2]) < math.radians(0.2)
    assert abs(result.pose[0] - prior[0]) < 0.01                      # not moved along the corridor
    sd = np.sqrt(np.diag(result.covariance))
    assert sd[0] > 0.8 * 0.05 and sd[1] < 0.3 * sd[0]                 # the posterior knows it


def test_odometry_errors_are_estimated_from_the_corrections():
    """A path whose corrections undo a 3 % scale error and 2 deg/m of heading drift tells both."""
    from mrstereo.odometry.alignment import AlignConfig, _odometry_errors
    from mrstereo.world.paths import drifted_poses, sequence_path

    true = sequence_path("s-curve", 61, step_m=0.1)
    given = drifted_poses(true, scale_error=0.03, heading_drift_rad_per_m=math.radians(2.0))
    path = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(given[:, :2], axis=0).T))])
    scale, drift = _odometry_errors(given, true, path, AlignConfig(calibration_window_m=6.0),
                                    variance_m2=1e-6, variance_rad2=1e-8)
    assert scale == pytest.approx(0.03, abs=0.003)
    assert drift == pytest.approx(math.radians(2.0), rel=0.05)
    # no corrections: no error found; too short a window: none either
    assert _odometry_errors(given, given, path, AlignConfig(), variance_m2=1e-6, variance_rad2=1e-8) == (0.0, 0.0)
    assert _odometry_errors(given[:2], true[:2], path[:2], AlignConfig(), variance_m2=1e-6,
                            variance_rad2=1e-8) == (0.0, 0.0)


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
            assert "scan-to-map alignment" in text
            assert 0 <= data["alignment"]["mean_correction_m"] <= data["alignment"]["max_correction_m"] < 0.2
    # with --workers the visual-odometry map is the same
    code = entry(["map", str(sequence), "-o", str(tmp_path / "w2"), "--quiet", "--odometry", "visual",
                  "--workers", "2"])
    assert code == 0
    np.testing.assert_array_equal(np.load(tmp_path / "w2" / "log_odds.npy"),
                                  np.load(tmp_path / "visual_odometry" / "log_odds.npy"))


def test_a_bag_without_odometry(sequence, tmp_path, capsys):
    """Camera topics only: the odometry command and map --odometry visual work from the images."""
    from test_bag_io import DT_NS, T0_NS, TOPICS, write_bag

    manifest = read_manifest(sequence)
    bag = write_bag(tmp_path / "cams.bag", manifest, ros1=True, odom=False)
    common = ["--bag", str(bag), "--left-topic", TOPICS["left_topic"], "--right-topic", TOPICS["right_topic"],
              "--camera-info-topics", ",".join(TOPICS["camera_info_topics"]), "--height",
              str(manifest.rig.height_m), "--tilt", str(manifest.rig.tilt_rad), "--quiet"]
    assert entry(["odometry", *common, "-o", str(tmp_path / "t.txt")]) == 0
    stamps, T = read_tum(tmp_path / "t.txt")
    np.testing.assert_allclose(stamps, (T0_NS + np.arange(6) * DT_NS) / 1e9)      # the image stamps
    true = np.array([f.true_pose for f in manifest.frames])                          # starts at the origin
    np.testing.assert_allclose(T[:, :2, 3], true[:, :2], atol=0.01)
    assert entry(["map", *common, "--odometry", "visual", "-o", str(tmp_path / "m")]) == 0
    out = capsys.readouterr().out
    assert "visual odometry: tracked all 6 frames" in out
    assert (tmp_path / "m" / "map.pgm").is_file()


def test_fuse_aligned_undoes_odometry_drift_on_synthetic_scans():
    """Scans of a corridor with boxes, seen from the true poses, fused at drifted odometry poses:
    the aligned trajectory stays near the truth (the drifted one ends 1 m off)."""
    from mrstereo.mapping import GridSpec
    from mrstereo.mapping.fusion import FrameObservation
    from mrstereo.odometry.alignment import AlignConfig, fuse_aligned
    from mrstereo.world.paths import drifted_poses, sequence_path

    rng = np.random.default_rng(7)
    # walls at y = +-1 m with door recesses, and boxes: outlines sampled every 2 cm
    outline = [np.column_stack([x, np.full_like(x, y)]) for y in (1.0, -1.0)
               for x in [np.arange(0.0, 12.0, 0.02)]]
    for x0, y0, y1 in ((2.0, 1.0, 0.6), (4.5, -1.0, -0.5), (7.0, 1.0, 0.7), (9.5, -1.0, -0.6)):
        outline += [np.column_stack([np.linspace(x0, x0 + 0.4, 20), np.full(20, y1)]),
                    np.column_stack([np.full(20, x0), np.linspace(y0, y1, 20)]),
                    np.column_stack([np.full(20, x0 + 0.4), np.linspace(y0, y1, 20)])]
    world = np.concatenate(outline)
    true = sequence_path("s-curve", 81, step_m=0.1)
    true[:, 1] *= 0.5                                         # keep the weave inside the 2 m corridor
    given = drifted_poses(true, scale_error=0.03, heading_drift_rad_per_m=math.radians(2.0))
    observations = []
    for k, (t, g) in enumerate(zip(true, given)):
        c, s = math.cos(t[2]), math.sin(t[2])
        d = world - t[:2]
        robot = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])
        seen = (robot[:, 0] > 0.3) & (robot[:, 0] < 4.0) & (np.abs(robot[:, 1]) < 0.8 * robot[:, 0])
        robot = robot[seen] + rng.normal(scale=0.015, size=(seen.sum(), 2))
        robot = np.repeat(robot, 3, axis=0) + rng.normal(scale=0.003, size=(3 * len(robot), 2))
        c, s = math.cos(g[2]), math.sin(g[2])
        at_given = np.column_stack([g[0] + c * robot[:, 0] - s * robot[:, 1], g[1] + s * robot[:, 0] + c * robot[:, 1],
                                    np.full(len(robot), 0.5)]).astype(np.float32)
        observations.append(FrameObservation(index=k, pose=tuple(g), pan_rad=0.0, obstacle_points_world=at_given,
                                             floor_points_world=np.empty((0, 3), np.float32), n_valid_disparity=0,
                                             ground_message=""))
    grid = GridSpec(width_m=12.5, height_m=3.0, origin_x_m=-0.25, origin_y_m=-1.5)
    _, corrected, alignments = fuse_aligned(observations, grid=grid, align=AlignConfig())
    est = np.array([o.pose for o in corrected])
    drifted_end = math.hypot(*(given[-1, :2] - true[-1, :2]))
    assert drifted_end > 0.5
    err = np.hypot(*(est[:, :2] - true[:, :2]).T)
    yaw_err = np.degrees(np.abs(np.remainder(est[:, 2] - true[:, 2] + math.pi, math.tau) - math.pi))
    assert err.max() < 0.05 and err[-1] < 0.04 and yaw_err.max() < 0.3, (err.max(), err[-1], yaw_err.max())   # 2.3 cm, 1.1 cm, 0.08 deg
    assert sum(a.applied for a in alignments) == len(alignments) - 1            # all but the first frame
    # without estimating the odometry's scale and heading drift, the per-frame matches alone lag behind
    _, lagging, _ = fuse_aligned(observations, grid=grid, align=AlignConfig(calibrate_odometry=False))
    assert math.hypot(*(np.array(lagging[-1].pose[:2]) - true[-1, :2])) > 2 * err[-1]
    # without the scans' information (a huge likelihood width) the drift stays
    _, kept, _ = fuse_aligned(observations, grid=grid, align=AlignConfig(effective_points=1e-6))
    assert math.hypot(*(np.array(kept[-1].pose[:2]) - true[-1, :2])) > 0.5
