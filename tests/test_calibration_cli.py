"""CLI: calibrate, stereo-calibrate, rectify; clear one-line errors."""

import numpy as np
import pytest

from mrstereo.calibration import planar_grid, pose_looking_at, synthetic_view
from mrstereo.camera import Camera, read_camera_info, read_stereo
from mrstereo.cli import entry
from mrstereo.io import read_image
from mrstereo.recordings.samples import local_path

DATA = local_path("opencv-stereo-chessboard")
needs_data = pytest.mark.sample_data("opencv-stereo-chessboard")


def test_calibrate_from_points_csv(tmp_path, capsys):
    cam = Camera(width=640, height=400, fx=500.0, fy=500.0, cx=322.0, cy=198.0, k1=-0.1)
    grid = planar_grid(11, 8, 0.04)
    T = pose_looking_at(grid.mean(0), distance_m=0.8, tilt_x_rad=0.4, tilt_y_rad=-0.3, focal_px=500.0)
    view = synthetic_view(cam, grid, T, noise_px=0.05, rng=0)
    csv = tmp_path / "pts.csv"
    lines = ["# units: mm", "X,Y,Z,u,v"] + [f"{x * 1000},{y * 1000},{z * 1000},{u},{v}"
                                           for (x, y, z), (u, v) in zip(view.points_target, view.uv)]
    csv.write_text("\n".join(lines) + "\n")
    out = tmp_path / "cam.yaml"
    code = entry(["calibrate", "--points", str(csv), "--image-size", "640x400", "--method", "ga+lm",
                  "--generations", "150", "-o", str(out)])
    assert code == 0, capsys.readouterr().err
    info = read_camera_info(out)
    assert info.camera.width == 640 and abs(info.camera.cx - 322.0) < 15
    for name in ("cam_report.json", "cam_report.md", "cam_residuals.png"):
        assert (tmp_path / name).is_file()


@needs_data
def test_calibrate_stereo_and_rectify_real(tmp_path, capsys):
    out = tmp_path / "stereo.yaml"
    code = entry(["stereo-calibrate", "--left", str(DATA / "left0[1-7].jpg"), "--right",
                  str(DATA / "right0[1-7].jpg"), "--method", "lm", "-o", str(out)])
    assert code == 0, capsys.readouterr().err
    st = read_stereo(out)
    assert st.baseline_m > 0 and st.right.P[0, 3] < 0
    assert (tmp_path / "stereo_report.json").is_file()
    code = entry(["rectify", "--calib", str(out), str(DATA / "left01.jpg"), str(DATA / "right01.jpg"),
                  "-o", str(tmp_path / "rect")])
    assert code == 0
    assert read_image(tmp_path / "rect" / "left01.jpg").shape[:2] == (480, 640)
    code = entry(["calibrate", "--images", str(DATA / "left0[1-4].jpg"), "--method", "lm",
                  "-o", str(tmp_path / "left.yaml")])
    assert code == 0 and read_camera_info(tmp_path / "left.yaml").camera.fx > 0


@needs_data
@pytest.mark.parametrize("args, message", [
    (["calibrate", "--images", "/nonexistent/*.jpg"], "no images match"),
    (["calibrate", "--images", str(DATA / "left*.jpg"), "--square", "nan"], "--square"),
    (["calibrate", "--images", str(DATA / "left01.jpg"), "--board", "7x7"], "not found in any"),
    (["calibrate", "--images", str(DATA / "left0[12].jpg")], "found in 2 image(s)"),
    (["stereo-calibrate", "--left", str(DATA / "left0*.jpg"), "--right", str(DATA / "right*.jpg")],
     "9 left images but 13 right"),
])
def test_bad_input_is_one_line(tmp_path, capsys, args, message):
    code = entry(args + ["-o", str(tmp_path / "x.yaml")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and err[-1].startswith("mrstereo: error:") and message in err[-1]
    assert not (tmp_path / "x.yaml").exists()


def test_rectify_corrupt_yaml(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("left: [\n")
    img = tmp_path / "a.png"
    import cv2
    cv2.imwrite(str(img), np.zeros((10, 10), np.uint8))
    code = entry(["rectify", "--calib", str(bad), str(img), str(img), "-o", str(tmp_path / "r")])
    assert code == 2 and "not valid YAML" in capsys.readouterr().err


@needs_data
@pytest.mark.parametrize("left, right, message", [
    ("right0[1-6].jpg", "left0[1-6].jpg", r"^mrstereo: error: stereo-calibrate: the left and right views look swapped: "
                                          r"the camera given as right sits 0\.0\d+ m to the LEFT of the one given as "
                                          r"left; exchange --left and --right"),
    ("left0[1-6].jpg", "left0[1-6].jpg", r"^mrstereo: error: stereo-calibrate: the baseline is zero .*are the same "
                                         r"images given as --left and --right\?$"),
])
def test_stereo_calibrate_refuses_swapped_and_identical_views(tmp_path, capsys, left, right, message):
    import re
    out = tmp_path / "stereo.yaml"
    code = entry(["stereo-calibrate", "--left", str(DATA / left), "--right", str(DATA / right), "--method", "lm",
                  "-o", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and re.search(message, err[-1]), err
    assert not any(tmp_path.iterdir())                                   # nothing written


@pytest.mark.parametrize("points, message", [
    ([(0.01 * i, 0.02 * i, 0.0, 100.0 + 5 * i, 80.0 + 7 * i) for i in range(20)], "are collinear"),
    ([(0.1, 0.2, 0.0, 320.0, 240.0)] * 30, "coincide"),
])
def test_calibrate_refuses_degenerate_points(tmp_path, capsys, points, message):
    csv = tmp_path / "pts.csv"
    csv.write_text("X,Y,Z,u,v\n" + "\n".join(",".join(str(v) for v in p) for p in points) + "\n")
    out = tmp_path / "cam.yaml"
    code = entry(["calibrate", "--points", str(csv), "--image-size", "640x480", "--generations", "5",
                  "-o", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("mrstereo: error: view pts.csv:") and message in err[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pts.csv"]


@needs_data
def test_calibrate_with_a_richer_model_writes_it(tmp_path, capsys):
    out = tmp_path / "left.yaml"
    code = entry(["calibrate", "--images", str(DATA / "left0[1-5].jpg"), "--method", "lm", "--model", "plumb_bob",
                  "-o", str(out)])
    text = capsys.readouterr().out
    assert code == 0 and "plumb_bob k1=" in text and " p1=" in text
    cam = read_camera_info(out).camera
    assert cam.distortion_model == "plumb_bob" and cam.D.size == 5 and np.all(cam.D[2:] != 0)
    import json
    report = json.loads((tmp_path / "left_report.json").read_text())
    assert report["model"] == "plumb_bob" and set(report["sigmas"]) >= {"p1", "p2", "k3"}
    code = entry(["calibrate", "--images", str(DATA / "left0[1-5].jpg"), "--method", "ga", "--model", "fisheye",
                  "-o", str(tmp_path / "x.yaml")])
    assert code == 2 and "--method ga fits the paper's k1k2 model only" in capsys.readouterr().err
