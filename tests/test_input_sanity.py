"""Inputs that parse but make no sense: stamps that do not increase or do not fit, two videos that are no stereo
pair (sizes, rates, lengths), poses that are no poses. Nonsense is one line ``mrstereo: error: ...`` before any
work; what is suspicious but legal runs with one line ``mrstereo: warning: ...`` (docs/errors.md).
"""
from __future__ import annotations

import re
import shutil
from pathlib import Path

import cv2
import pytest

from mrstereo.cli import entry


@pytest.fixture(scope="module")
def ds(synthetic_dataset) -> Path:
    return synthetic_dataset(seed=1, n_frames=3, width=160, height=120, supersample=1)


def _lines(capsys) -> tuple[list[str], str]:
    captured = capsys.readouterr()
    return [line for line in captured.err.splitlines() if line.strip()], captured.out


def _error(capsys, args, must: str) -> str:
    """Run the CLI in-process: exit 2 and one line ``mrstereo: error:`` holding ``must``."""
    code = entry([str(a) for a in args])
    err, _ = _lines(capsys)
    assert code == 2 and len(err) == 1 and err[0].startswith("mrstereo: error: "), err
    assert must in err[0], err[0]
    return err[0]


def _with_stamps(ds: Path, folder: Path, stamps_s) -> Path:
    """A copy of the dataset whose frames carry ``stamps_s``."""
    shutil.copytree(ds, folder)
    stamps = iter(stamps_s)
    text = re.sub(r"(  pose: .*\n)", lambda m: m.group(1) + f"  stamp_s: {next(stamps)!r}\n",
                  (folder / "manifest.yaml").read_text())
    (folder / "manifest.yaml").write_text(text)
    return folder


# ------------------------------------------------------------------------------------------ stamps

@pytest.mark.parametrize("stamps", [[5.0, 5.0, 5.0], [5.0, 4.9, 4.8]], ids=["equal", "going back"])
def test_stamps_that_do_not_increase_are_refused_by_every_command(ds, tmp_path, capsys, stamps):
    """Equal stamps were a ZeroDivisionError in ``info``, stamps going back a negative rate."""
    data = _with_stamps(ds, tmp_path / "D", stamps)
    for args in (["info", data], ["map", data, "-o", tmp_path / "m", "--quiet"],
                 ["odometry", data, "-o", tmp_path / "t.txt", "--quiet"]):
        _error(capsys, args, "frame 1 has the stamp")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["D"]
    good = _with_stamps(ds, tmp_path / "G", [5.0, 5.1, 5.2])
    assert entry(["info", str(good)]) == 0
    assert "rate:             10 Hz over 0.2 s" in capsys.readouterr().out


@pytest.mark.sample_data("euroc-asl-sample")
def test_euroc_stamps_beyond_int64_or_repeated_are_one_line(sample_data, tmp_path, capsys):
    for name, stamp, must in (("big", "99999999999999999999", "beyond the 2^63 ns"),
                              ("same", None, "the stamps must increase")):
        euroc = tmp_path / name
        shutil.copytree(sample_data("euroc-asl-sample"), euroc)
        for cam in ("cam0", "cam1"):
            csv = euroc / "mav0" / cam / "data.csv"
            rows = csv.read_text().splitlines()
            first = rows[1].split(",")[0]
            second = rows[2].split(",")[0]
            csv.write_text(csv.read_text().replace(f"{first},", f"{stamp}," if stamp else f"{second},", 1))
        _error(capsys, ["info", euroc], must)


# ------------------------------------------------------------------------------------------ two videos

def _video(path: Path, images, fps: float) -> Path:
    h, w = images[0].shape
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), fps, (w, h), isColor=False)
    for image in images:
        writer.write(image)
    writer.release()
    return path


@pytest.fixture(scope="module")
def videos(ds, tmp_path_factory) -> dict[str, Path]:
    """The dataset's raw pairs as videos: left, right, and right ones of another size, rate and length."""
    folder = tmp_path_factory.mktemp("videos")
    read = lambda side: [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in sorted((ds / side).glob("*.png"))]  # noqa
    left, right = read("left"), read("right")
    return {"left": _video(folder / "left.mkv", left, 10.0), "right": _video(folder / "right.mkv", right, 10.0),
            "small": _video(folder / "small.mkv", [cv2.resize(im, (80, 60)) for im in right], 10.0),
            "slow": _video(folder / "slow.mkv", right, 2.5),
            "short": _video(folder / "short.mkv", right[:2], 10.0)}


@pytest.mark.parametrize("right, must", [("small", "160x120 and "), ("slow", "at 2.5 fps")],
                         ids=["another size", "another rate"])
def test_two_videos_that_are_no_pair_are_refused_before_work(ds, videos, tmp_path, capsys, right, must):
    """Videos of two sizes gave an empty map and exit 0; 10 and 2.5 fps were paired frame by frame."""
    _error(capsys, ["live", videos["left"], videos[right], "--calib", ds / "calibration.yaml", "-o", tmp_path / "o",
                    "--quiet"], must)
    assert not (tmp_path / "o").exists()


def test_a_shorter_right_video_is_named_when_it_ends(ds, videos, tmp_path, capsys):
    code = entry(["live", str(videos["left"]), str(videos["short"]), "--calib", str(ds / "calibration.yaml"), "-o",
                  str(tmp_path / "o"), "--quiet"])
    err, out = _lines(capsys)
    assert code == 0 and "live (end of source): 2 frames in" in out
    assert err == [f"mrstereo: warning: {videos['short']} ended after 2 frames, {videos['left']} has more: the rest "
                   f"of {videos['left']} is not used"]


def test_an_error_of_the_source_ends_the_live_run_with_it(ds, tmp_path):
    """A source failing at its first frame (two cameras of two sizes) was a run 'stopped' with exit 0."""
    from mrstereo.pipeline.live import LiveConfig, run_live
    from mrstereo.recordings import open_recording
    from mrstereo.recordings.sources import FrameSource

    class Failing(FrameSource):
        def __init__(self, source):
            self.source, self.name, self.realtime, self.has_poses = source, "failing", False, False
            self.calibration, self.mount, self.pose_frame_mount = source.calibration, source.mount, None
            self.ground_truth_map = None

        def __iter__(self):
            raise ValueError("failing: frame 0: the left image is 160x120, the right one 80x60")
            yield

    with open_recording(ds) as source, pytest.raises(ValueError, match="the right one 80x60"):
        run_live(Failing(source), tmp_path / "o", live=LiveConfig())
    assert not (tmp_path / "o" / "map.yaml").exists()


def test_live_config_workers_are_bounded_by_the_cores():
    from mrstereo.pipeline.live import LiveConfig

    with pytest.raises(ValueError, match="workers must be at most .* MRSTEREO_MAX_WORKERS"):
        LiveConfig(workers=10**6)
    assert LiveConfig(workers=2).workers == 2


# ------------------------------------------------------------------------------------------ KITTI

def test_kitti_image_names_must_be_frame_numbers(kitti_two_frames, capsys):
    """``-1.png`` was frame -1: the last line of times.txt and poses."""
    kitti = kitti_two_frames
    for sub in ("image_0", "image_1"):
        (kitti / "sequences" / "06" / sub / "000001.png").rename(kitti / "sequences" / "06" / sub / "-1.png")
    _error(capsys, ["info", kitti], "-1.png: a KITTI image name must be its frame number")


def test_kitti_poses_must_be_rotations(kitti_two_frames, capsys):
    kitti = kitti_two_frames
    assert entry(["info", str(kitti)]) == 0
    capsys.readouterr()
    poses = kitti / "poses" / "06.txt"
    lines = poses.read_text().splitlines()
    lines[1] = "0 0 0 1 0 0 0 2 0 0 0 3"                    # a zero rotation matrix, frame 1
    poses.write_text("\n".join(lines) + "\n")
    _error(capsys, ["info", kitti], "line 2 (frame 1) is no pose: its 3x3 part is not a rotation")


# ------------------------------------------------------------------------------------------ calibration

@pytest.mark.sample_data("opencv-stereo-chessboard")
def test_a_camera_calibration_from_one_view_is_refused(sample_data, tmp_path, capsys):
    """A flat board in one image does not determine a camera: refused before the fit, nothing written."""
    one = sample_data("opencv-stereo-chessboard") / "left01.jpg"
    _error(capsys, ["calibrate", "--images", one, "-o", tmp_path / "one.yaml", "--quiet"],
           "a flat board seen from fewer than 3 angles does not determine a camera")
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------------------------------ bags

@pytest.mark.parametrize("ros1", [False, True], ids=["ROS 2", "ROS 1"])
def test_a_camera_info_that_changes_mid_bag_is_named(ds, tmp_path, capsys, ros1):
    """The calibration is the bag's first camera_info: a later one that differs (a zoom, a recalibration) was
    silently ignored; now a warning names the topic and the message."""
    from _bags import write_bag

    from mrstereo.camera import StereoCamera
    from mrstereo.recordings.manifest import read_manifest

    manifest = read_manifest(ds)
    steady = write_bag(tmp_path / ("steady.bag" if ros1 else "steady"), manifest, ros1=ros1)
    assert entry(["info", str(steady)]) == 0
    assert _lines(capsys)[0] == []
    from dataclasses import replace

    cal = manifest.calibration                   # the left camera's focal length 1.5 times longer from frame 2 on
    other = StereoCamera(left=replace(cal.left, camera=replace(cal.left.camera, fx=1.5 * cal.left.camera.fx)),
                         right=cal.right)
    bag = write_bag(tmp_path / ("zoom.bag" if ros1 else "zoom"), manifest, ros1=ros1, recalibrated=(2, other))
    assert entry(["info", str(bag)]) == 0
    err, out = _lines(capsys)
    assert len(err) == 1, err
    assert err[0].startswith("mrstereo: warning: camera_info /stereo/left/camera_info changes at its message 2 ")
    assert "frames:           3" in out


# ------------------------------------------------------------------------------------------ given poses

def test_given_poses_that_jump_kilometres_in_a_frame_are_named(ds, tmp_path, capsys):
    """Odometry jumping 5 km between two frames was mapped without a word (live and map read it alike)."""
    data = tmp_path / "D"
    shutil.copytree(ds, data)
    text = (data / "manifest.yaml").read_text()
    poses = re.findall(r"  pose: .*\n", text)
    assert len(poses) == 3
    head, _, tail = text.rpartition(poses[2])
    (data / "manifest.yaml").write_text(head + "  pose: [5000.0, 0.0, 0.0]\n" + tail)
    warning = ("mrstereo: warning: dataset {}: the given poses jump 5000 m from frame 1 to frame 2: the odometry is "
               "broken there".format(data.resolve()))
    for args in (["info", data], ["map", data, "-o", tmp_path / "m", "--size", "20,20", "--origin", "-10,-10",
                                  "--quiet"]):
        assert entry([str(a) for a in args]) == 0
        err, _ = _lines(capsys)
        assert [line for line in err if "given poses" in line] == [line for line in err if line.startswith(warning)]
        assert len([line for line in err if line.startswith(warning)]) == 1, err
    assert entry(["info", str(ds)]) == 0 and _lines(capsys)[0] == []


@pytest.mark.parametrize("first_s", [-1.0, 1e12], ids=["negative", "year 33658"])
def test_stamps_a_bag_cannot_hold_are_refused_before_any_output(ds, tmp_path, capsys, first_s):
    """``--record-bag`` of a recording whose stamps a ROS 2 bag cannot hold: one line naming the stamp before
    work, not after the map was written (a run half done: the map there, the bag missing)."""
    data = _with_stamps(ds, tmp_path / "D", [first_s, first_s + 0.1, first_s + 0.2])
    for args in (["map", data, "-o", tmp_path / "m"], ["odometry", data, "-o", tmp_path / "t.txt"]):
        _error(capsys, [*args, "--record-bag", tmp_path / "bag", "--quiet"], f"a time stamp of {first_s:.10g} s")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["D"]
