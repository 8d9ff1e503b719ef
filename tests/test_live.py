"""The live loop: frame sources (cameras through VideoCapture on real video files), the newest-frame-wins
slot, the loop's map, trajectory and metrics, Ctrl-C, and its memory over a long replay."""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from mrstereo.camera import write_stereo
from mrstereo.cli import entry
from mrstereo.mapping import GridSpec, read_ros_map
from mrstereo.odometry.trajectory import read_tum, trajectory_metrics
from mrstereo._executor import LatestFrame
from mrstereo.evaluation.outputs import LIVE_FILES
from mrstereo.pipeline.live import LiveConfig, run_live
from mrstereo.pipeline.run import PipelineConfig
from mrstereo.recordings import read_recording
from mrstereo.recordings.samples import data_root
from mrstereo.recordings.sources import (FrameSource, RecordingSource, StereoFrame, VideoSource, open_source,
                                         paced)

FOURCC = "FFV1"           # lossless in this OpenCV build (tested below): the videos hold the images exactly
SMALL = PipelineConfig(grid=GridSpec())        # the map on the paper's 12 m x 6 m corridor region


def write_videos(images_left, images_right, folder: Path, rate_hz: float = 10.0) -> dict[str, Path]:
    """Two videos (left, right) and a side-by-side one of the same frames, lossless."""
    folder.mkdir(parents=True, exist_ok=True)
    h, w = images_left[0].shape[:2]
    paths = {"left": folder / "left.mkv", "right": folder / "right.mkv", "sbs": folder / "sbs.mkv"}
    writers = {k: cv2.VideoWriter(str(p), cv2.VideoWriter_fourcc(*FOURCC), rate_hz,
                                  (2 * w if k == "sbs" else w, h), isColor=False) for k, p in paths.items()}
    assert all(wr.isOpened() for wr in writers.values())
    for left, right in zip(images_left, images_right):
        writers["left"].write(left)
        writers["right"].write(right)
        writers["sbs"].write(np.hstack([left, right]))
    for wr in writers.values():
        wr.release()
    return paths


def raw_images(manifest, n=None):
    frames = manifest.frames[:n]
    return ([cv2.imread(str(f.left), cv2.IMREAD_GRAYSCALE) for f in frames],
            [cv2.imread(str(f.right), cv2.IMREAD_GRAYSCALE) for f in frames])


@pytest.fixture(scope="module")
def sequence(synthetic_dataset, shared_data):
    """A rendered s-curve drive (12 frames, 320x240, 10 Hz) and its two lossless videos plus a side-by-side one
    (made once per test run: read them, never change them)."""
    dataset = synthetic_dataset(n_frames=12, supersample=1, path="s-curve", step_m=0.1)
    manifest = read_recording(dataset)
    folder = shared_data("live-videos", lambda new: write_videos(*raw_images(manifest), new))
    videos = {name: folder / f"{name}.mkv" for name in ("left", "right", "sbs")}
    return dataset, manifest, videos


# ----------------------------------------------------------------------------- sources
def test_video_sources_give_the_recorded_frames_and_stamps(sequence):
    _, manifest, videos = sequence
    left, right = raw_images(manifest)
    with VideoSource(videos["left"], videos["right"]) as two, VideoSource(videos["sbs"], side_by_side=True) as sbs:
        assert not two.realtime and two.rate_hz == pytest.approx(10.0) and two.n_frames == 12
        frames_two, frames_sbs = list(two), list(sbs)
    assert len(frames_two) == len(frames_sbs) == 12
    for k, (a, b) in enumerate(zip(frames_two, frames_sbs)):
        assert a.index == b.index == k
        assert a.stamp_s == pytest.approx(k * 0.1, abs=1e-6) and a.stamp_s == b.stamp_s
        np.testing.assert_array_equal(a.left, left[k])          # FFV1: every pixel back exactly
        np.testing.assert_array_equal(a.right, right[k])
        np.testing.assert_array_equal(b.left, left[k])
        np.testing.assert_array_equal(b.right, right[k])
        assert not a.rectified and a.T_world_from_base is None


def test_recording_source_stamps_poses_and_rectified_images(sequence):
    _, manifest, _ = sequence
    source = open_source([str(manifest.root)])
    assert isinstance(source, RecordingSource) and source.has_poses and source.calibration is not None
    frames = list(source)
    assert [f.stamp_s for f in frames] == [f.stamp_s for f in manifest.frames]
    assert all(f.rectified for f in frames)
    np.testing.assert_array_equal(frames[3].T_world_from_base, manifest.frames[3].T_world_from_base)
    np.testing.assert_array_equal(frames[3].left, cv2.imread(str(manifest.frames[3].left_rect), cv2.IMREAD_GRAYSCALE))
    raw = list(RecordingSource(manifest, prefer_raw=True))
    assert not raw[0].rectified


def test_open_source_names_what_is_wrong(sequence, tmp_path):
    _, _, videos = sequence
    with pytest.raises(ValueError, match="side_by_side"):
        open_source([str(videos["sbs"])])
    with pytest.raises(ValueError, match="takes one source"):
        open_source([str(videos["left"]), str(videos["right"])], side_by_side=True)
    with pytest.raises(FileNotFoundError, match="nothere.avi"):
        open_source([str(tmp_path / "nothere.avi"), str(videos["right"])])
    bad = tmp_path / "bad.avi"
    bad.write_text("not a video")
    with pytest.raises(ValueError, match="not a video file"):
        open_source([str(bad)], side_by_side=True)
    with pytest.raises(ValueError, match="camera 37 cannot be opened"):
        open_source(["37"], side_by_side=True)
    with pytest.raises(ValueError, match="both be cameras or both video"):
        VideoSource("0", str(videos["right"]))
    with pytest.raises(ValueError, match="one or two sources"):
        open_source([])
    # the video codecs here round a width down to even: an odd frame (a camera's) is checked directly
    with VideoSource(videos["sbs"], side_by_side=True) as source, pytest.raises(ValueError, match="even width"):
        source._split([np.zeros((20, 65), np.uint8)], 3)


def test_paced_hands_frames_out_at_their_stamps():
    now = [100.0]
    slept = []

    def sleep(s):
        slept.append(s)
        now[0] += s

    frames = [StereoFrame(index=k, stamp_s=5.0 + 0.25 * k, left=None, right=None) for k in range(4)]
    out = list(paced(frames, speed=2.0, clock=lambda: now[0], sleep=sleep))
    assert [f.index for f in out] == [0, 1, 2, 3]
    np.testing.assert_allclose(slept, [0.125, 0.125, 0.125])        # 0.25 s of stamps at twice the speed
    with pytest.raises(ValueError, match="speed"):
        list(paced(frames, speed=0.0))


def test_paced_does_not_wait_out_a_jump_of_the_stamps():
    """A bag whose clock jumps 15 years (forth, then back) is replayed with one warning per jump, not a wait of
    years; the pacing restarts at the frame after the jump."""
    now, slept = [0.0], []

    def sleep(s):
        slept.append(s)
        now[0] += s

    years = 15 * 365.25 * 86400.0
    stamps = [0.0, 0.1, 0.1 + years, 0.2 + years, 0.3, 0.4]
    frames = [StereoFrame(index=k, stamp_s=s, left=None, right=None) for k, s in enumerate(stamps)]
    with pytest.warns(UserWarning, match=r"the stamps jump by") as caught:
        out = list(paced(frames, clock=lambda: now[0], sleep=sleep))
    assert [f.index for f in out] == list(range(6))
    assert [str(w.message).split(" (")[0].rsplit(" s ", 1)[1] for w in caught] == [
        "from frame 1 to frame 2", "from frame 3 to frame 4"]
    np.testing.assert_allclose(slept, [0.1, 0.1, 0.1], atol=1e-6)


def test_paced_stops_waiting_when_asked():
    """A slow video (a frame every 50 s): setting ``stop`` ends the wait at once, and the replay."""
    stop = threading.Event()
    frames = [StereoFrame(index=k, stamp_s=50.0 * k, left=None, right=None) for k in range(3)]
    got = []

    def replay():
        got.extend(f.index for f in paced(frames, stop=stop))

    thread = threading.Thread(target=replay, daemon=True)
    thread.start()
    deadline = time.monotonic() + 30.0
    while not got and time.monotonic() < deadline:
        time.sleep(0.01)
    stop.set()
    thread.join(timeout=30.0)
    assert not thread.is_alive() and got == [0]


def test_latest_frame_slot_keeps_the_newest_and_counts_the_dropped():
    stop = threading.Event()
    slot = LatestFrame()
    for k in range(5):
        assert slot.put(k, stop)
    assert slot.dropped == 4
    assert slot.take() == (0, 4)                  # ticket 0, the newest frame
    assert slot.take(timeout_s=0.01) == (None, None)
    slot.put(7, stop)
    slot.close()
    assert slot.take() == (1, 7)
    with pytest.raises(StopIteration):
        slot.take()
    lossless = LatestFrame(lossless=True)
    lossless.put(1, stop)
    t = threading.Timer(0.2, lambda: lossless.take())
    t.start()
    t0 = time.perf_counter()
    lossless.put(2, stop)                          # waits for the taker, drops nothing
    assert time.perf_counter() - t0 > 0.1 and lossless.dropped == 0
    t.join()
    assert lossless.take() == (1, 2)


# ----------------------------------------------------------------------------- the loop
def test_two_videos_side_by_side_and_the_recording_make_the_same_map(sequence, tmp_path):
    _, manifest, videos = sequence
    stereo = manifest.calibration
    live = LiveConfig(odometry="visual", save_every_s=60.0)
    runs = {}
    for name, source in (("two", VideoSource(videos["left"], videos["right"])),
                         ("sbs", VideoSource(videos["sbs"], side_by_side=True)),
                         ("recording", RecordingSource(manifest, prefer_raw=True))):
        with source:
            runs[name] = run_live(source, tmp_path / name, calibration=stereo, mount=manifest.mount, config=SMALL,
                                  live=live)
    np.testing.assert_array_equal(runs["sbs"].grid.log_odds, runs["two"].grid.log_odds)
    np.testing.assert_array_equal(runs["sbs"].T_world_from_base, runs["two"].T_world_from_base)
    assert (tmp_path / "sbs" / "map.pgm").read_bytes() == (tmp_path / "two" / "map.pgm").read_bytes()
    # the recording's first pose (the identity to 1e-17) seeds its odometry: the same drive and map to rounding
    rec = runs["recording"]
    np.testing.assert_allclose(rec.T_world_from_base, runs["two"].T_world_from_base, atol=0.01)
    ours, theirs = (read_ros_map(tmp_path / n / "map.yaml").occupied for n in ("two", "recording"))
    assert (ours & theirs).sum() >= 0.98 * max(ours.sum(), theirs.sum())
    run = runs["two"]
    assert (run.frames_in, run.frames_processed, run.frames_dropped, run.frames_mapped) == (12, 12, 0, 12)
    # the visual odometry follows the true drive (1.1 m of an s-curve) within centimetres
    truth = np.stack([f.T_world_from_base_true if f.true_pose is not None else f.T_world_from_base
                      for f in manifest.frames])
    stamps, T = read_tum(tmp_path / "two" / "trajectory.txt")
    np.testing.assert_allclose(stamps, [f.stamp_s for f in manifest.frames], atol=1e-6)
    assert trajectory_metrics(T, truth).ate_rmse_m < 0.03
    # the map sees the corridor's walls where the ground-truth map has them
    gt = read_ros_map(manifest.ground_truth_map)
    ours = read_ros_map(tmp_path / "two" / "map.yaml")
    assert ours.occupied.sum() > 50
    assert (gt.occupied & ours.occupied).sum() / ours.occupied.sum() > 0.6
    metrics = json.loads((tmp_path / "two" / "metrics.json").read_text())
    for key in ("frames_in", "frames_processed", "frames_dropped", "rate_hz", "peak_memory_mb", "cores_used"):
        assert key in metrics
    assert metrics["frames_in"] == 12 and metrics["stopped"] == "end of source"
    assert 0 < metrics["latency_ms"]["median"] <= metrics["latency_ms"]["p95"]
    assert {"match", "odometry", "grid"} <= set(metrics["stage_ms_per_frame"])
    assert sorted(p.name for p in (tmp_path / "two").iterdir()) == sorted(LIVE_FILES)


def test_the_recordings_own_odometry_is_the_trajectory(sequence, tmp_path):
    _, manifest, _ = sequence
    with open_source([str(manifest.root)]) as source:
        run = run_live(source, tmp_path / "out", config=SMALL, live=LiveConfig(max_frames=5))
    assert run.odometry == "given" and run.stopped == "max frames" and run.frames_in == 5
    stamps, T = read_tum(tmp_path / "out" / "trajectory.txt")
    np.testing.assert_allclose(T, np.stack([f.T_world_from_base for f in manifest.frames[:5]]), atol=1e-8)
    with pytest.raises(ValueError, match="no odometry of its own"):
        run_live(VideoSource(sequence[2]["sbs"], side_by_side=True), tmp_path / "x", calibration=manifest.calibration,
                 live=LiveConfig(odometry="given"))


def test_realtime_replay_drops_the_frames_it_cannot_keep_up_with(sequence, tmp_path):
    _, manifest, _ = sequence
    # 40 times the recorded rate (400 frames/s): the chain cannot keep up, the newest frame wins
    with RecordingSource(manifest) as source:
        run = run_live(source, tmp_path / "out", config=SMALL, live=LiveConfig(realtime=True, speed=40.0))
    assert run.frames_in == 12 and run.frames_dropped > 0
    assert run.frames_processed + run.frames_dropped == run.frames_in
    assert np.all(np.diff(run.stamps_s) > 0)
    kept = np.isin(np.round([f.stamp_s for f in manifest.frames], 6), np.round(run.stamps_s, 6))
    assert kept.sum() == run.frames_mapped == run.frames_processed     # the frames mapped are the recording's


def test_a_ros_bag_is_a_recording_source(sequence, tmp_path):
    from _bags import write_bag

    _, manifest, _ = sequence
    bag = write_bag(tmp_path / "run", manifest, ros1=False)
    source = open_source([str(bag)])
    try:
        assert source.layout == "ROS bag" and source.has_poses and source.n_frames == 12
        run = run_live(source, tmp_path / "out", config=SMALL)
    finally:
        source.close()
    assert run.odometry == "given" and run.frames_processed == 12
    assert run.frames_mapped == 12 and run.frames_before_floor == 0      # the frames held for the floor too
    _, T = read_tum(tmp_path / "out" / "trajectory.txt")
    truth = np.stack([f.T_world_from_base for f in manifest.frames])
    np.testing.assert_allclose(T[:, :2, 3], truth[:, :2, 3], atol=1e-6)      # the bag's planar odometry


def test_the_floor_is_estimated_from_the_first_frames_without_a_mount(sequence, tmp_path):
    _, manifest, videos = sequence
    from dataclasses import replace

    stereo = replace(manifest.calibration, mount=None)
    with VideoSource(videos["sbs"], side_by_side=True) as source:
        run = run_live(source, tmp_path / "out", calibration=stereo, config=SMALL)
    assert run.floor is not None and run.floor.method != "mount" and "median of 3" in run.floor.message
    true_floor = manifest.mount.T_base_from_cam[2, 3]
    assert run.floor.height_m == pytest.approx(true_floor, abs=0.03)
    assert run.frames_before_floor == 0 and run.frames_mapped == 12     # held until the floor was known, then mapped


def test_a_frame_of_the_wrong_size_is_an_error_naming_it(sequence, tmp_path):
    _, manifest, _ = sequence
    small = [np.zeros((60, 80), np.uint8)] * 3
    videos = write_videos(small, small, tmp_path / "v")
    with pytest.raises(ValueError, match="frame 0 is 80x60 but the calibration is 320x240"):
        run_live(VideoSource(videos["sbs"], side_by_side=True), tmp_path / "out", calibration=manifest.calibration)


def test_real_kitti_frames_through_video_files_equal_the_recording(tmp_path):
    root = data_root() / "kitti_odometry_06"
    if not (root / "sequences" / "06" / "calib.txt").is_file():
        pytest.skip(f"KITTI odometry sample not found under {root} (set MRSTEREO_DATA)")
    manifest = read_recording(root)
    n = 6
    left = [cv2.imread(str(f.left_rect or f.left), cv2.IMREAD_GRAYSCALE) for f in manifest.frames[:n]]
    right = [cv2.imread(str(f.right_rect or f.right), cv2.IMREAD_GRAYSCALE) for f in manifest.frames[:n]]
    videos = write_videos(left, right, tmp_path / "v", rate_hz=10.0)
    calib = tmp_path / "kitti.yaml"
    write_stereo(calib, manifest.calibration)
    from mrstereo.geometry.obstacles import ObstacleConfig

    # a car sees the road and the parked cars from 6 m on: points up to 30 m
    config = PipelineConfig(obstacles=ObstacleConfig(max_range_m=30.0),
                            grid=GridSpec(width_m=40, height_m=30, resolution_m=0.1, origin_x_m=-5, origin_y_m=-15))
    live = LiveConfig(odometry="visual", save_every_s=60.0)
    with VideoSource(videos["sbs"], side_by_side=True) as source:
        video_run = run_live(source, tmp_path / "video", calibration=manifest.calibration, mount=manifest.mount,
                             config=config, live=live)
    from dataclasses import replace

    first = replace(manifest, frames=manifest.frames[:n])
    with RecordingSource(first) as source:
        rec_run = run_live(source, tmp_path / "rec", config=config, live=live)
    assert video_run.frames_mapped == rec_run.frames_mapped == n
    # the video's stamps are 10 Hz, KITTI's 9.6 Hz: the odometry's time limits differ, the map hardly
    ours, theirs = (run.grid.log_odds > 0 for run in (video_run, rec_run))       # (6 frames: few cells sure yet)
    assert ours.sum() > 100 and (ours & theirs).sum() >= 0.9 * max(ours.sum(), theirs.sum())
    # the car drove about 1.2 m per frame: the visual odometry finds it against KITTI's poses
    truth = np.stack([f.T_world_from_base for f in manifest.frames[:n]])
    moved = np.linalg.norm(video_run.T_world_from_base[-1, :3, 3] - video_run.T_world_from_base[0, :3, 3])
    true_moved = np.linalg.norm(truth[-1, :3, 3] - truth[0, :3, 3])
    assert moved == pytest.approx(true_moved, rel=0.05)


def test_real_euroc_frames_through_a_side_by_side_video(tmp_path):
    root = data_root() / "euroc_asl_sample" / "mav0"
    if not (root / "cam0" / "sensor.yaml").is_file():
        pytest.skip(f"EuRoC sample not found under {root} (set MRSTEREO_DATA)")
    from mrstereo.camera import read_stereo

    names = sorted(p.name for p in (root / "cam0" / "data").glob("*.png"))
    left = [cv2.imread(str(root / "cam0" / "data" / n), cv2.IMREAD_GRAYSCALE) for n in names]
    right = [cv2.imread(str(root / "cam1" / "data" / n), cv2.IMREAD_GRAYSCALE) for n in names]
    videos = write_videos(left, right, tmp_path / "v", rate_hz=20.0)
    with VideoSource(videos["sbs"], side_by_side=True) as source:
        frames = list(source)
    assert len(frames) == len(names) and frames[0].left.shape == (480, 752)
    for k, f in enumerate(frames):
        np.testing.assert_array_equal(f.left, left[k])
        np.testing.assert_array_equal(f.right, right[k])
    stereo = read_stereo(f"{root / 'cam0' / 'sensor.yaml'},{root / 'cam1' / 'sensor.yaml'}")
    from mrstereo.camera import CameraMount

    mount = CameraMount.from_xyz_rpy((0.0, 0.0, 1.0), (0.0, 0.2, 0.0))        # a camera 1 m up, a little down
    with VideoSource(videos["sbs"], side_by_side=True) as source:
        run = run_live(source, tmp_path / "out", calibration=stereo, mount=mount, live=LiveConfig(odometry="visual"))
    assert run.frames_processed == len(names) and run.frames_mapped >= 1
    assert (tmp_path / "out" / "map.yaml").is_file()


# ----------------------------------------------------------------------------- the command
def test_live_command_errors_are_one_line(sequence, tmp_path, capsys):
    dataset, _, videos = sequence
    cases = [
        ([videos["sbs"], "-o", tmp_path / "a", "--calib", dataset / "calibration.yaml"], "right one as a second source"),
        ([videos["left"], videos["right"], "-o", tmp_path / "b"], "need --calib"),
        ([videos["sbs"], "--side-by-side", "-o", tmp_path / "c", "--calib", tmp_path / "none.yaml"], "none.yaml"),
        ([videos["left"], videos["right"], videos["sbs"], "-o", tmp_path / "d"], "one or two SOURCEs"),
        ([dataset, "-o", dataset], "--out"),
        ([dataset, "-o", tmp_path / "e", "--record-bag", dataset], "--record-bag"),
    ]
    for args, words in cases:
        code = entry(["live", *map(str, args)])
        stderr = capsys.readouterr().err
        lines = stderr.strip().splitlines()
        assert code == 2, stderr
        assert len(lines) == 1 and lines[0].startswith("mrstereo: error:") and words in lines[0], stderr


def _interrupted(dataset, out, *, twice: bool):
    """``live`` on the recording replayed at a tenth of its rate (12 s), Ctrl-C once its third snapshot of the
    outputs is written (and, with ``twice``, again while it stops): ``(returncode, stdout, stderr)``. The run
    signals itself at these points (``MRSTEREO_SIGNAL_AT``, :mod:`mrstereo._interrupt`)."""
    env = dict(os.environ, MRSTEREO_SIGNAL_AT="save:3" + (",stopping:1" if twice else ""))
    proc = subprocess.Popen([sys.executable, "-m", "mrstereo", "live", str(dataset), "-o", str(out), "--realtime",
                             "--speed", "0.1", "--save-every", "0.5", "--size", "12,6", "--origin", "0,-3", "--quiet"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, start_new_session=True)
    try:
        stdout, stderr = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
    return proc.returncode, stdout, stderr


def test_ctrl_c_stops_the_run_and_keeps_whole_outputs(sequence, tmp_path):
    out = tmp_path / "out"
    code, stdout, stderr = _interrupted(sequence[0], out, twice=False)
    assert code == 0, stderr
    assert "stopping" in stderr and "live (stopped)" in stdout
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["stopped"] == "stopped" and 0 < metrics["frames_in"] < 12
    stamps, T = read_tum(out / "trajectory.txt")
    assert len(stamps) == metrics["frames_mapped"]
    assert read_ros_map(out / "map.yaml").occupancy.shape == (120, 240)
    assert sorted(p.name for p in out.iterdir()) == sorted(LIVE_FILES)     # no temporary file left


def test_a_second_ctrl_c_aborts(sequence, tmp_path):
    out = tmp_path / "out"
    code, _, stderr = _interrupted(sequence[0], out, twice=True)
    assert code == 130, stderr
    assert "mrstereo: interrupted" in stderr
    assert json.loads((out / "metrics.json").read_text())["frames_in"] >= 1


# ----------------------------------------------------------------------------- a long run
class _Looped(FrameSource):
    """The frames of a recording driven forth and back, ``n`` in all, with increasing stamps and the poses."""

    def __init__(self, manifest, n: int) -> None:
        self.frames = list(RecordingSource(manifest))
        self.n, self.calibration, self.mount, self.has_poses = n, manifest.calibration, manifest.mount, True
        self.name = "looped"

    def __iter__(self):
        order = list(range(len(self.frames))) + list(range(len(self.frames) - 2, 0, -1))
        for k in range(self.n):
            f = self.frames[order[k % len(order)]]
            yield StereoFrame(index=k, stamp_s=0.1 * k, left=f.left, right=f.right, rectified=True,
                              T_world_from_base=f.T_world_from_base)


@pytest.mark.slow
def test_memory_stays_flat_over_hundreds_of_frames(synthetic_dataset, tmp_path):
    import tracemalloc

    dataset = synthetic_dataset(n_frames=10, width=160, height=120, supersample=1, path="s-curve", step_m=0.05)
    manifest = read_recording(dataset)
    n = 300
    samples = []
    # what the loop keeps (numpy's arrays and Python's objects, as tracemalloc traces them) and the resident
    # memory, which also holds the kernels numba compiles on the way and the allocator's arenas; a sample at
    # each snapshot, every 0.1 s (20-40 samples a stretch below; the snapshots' writing is most of the test's
    # time: every 0.05 s doubled it). An injected leak of 5 kB a frame reads 5.5-6.1 kB a frame here, none 1.1-1.5
    tracemalloc.start()
    try:
        run = run_live(_Looped(manifest, n), tmp_path / "out", config=SMALL,
                       live=LiveConfig(save_every_s=0.1, odometry="visual"),
                       on_save=lambda r: samples.append((r.frames_processed, tracemalloc.get_traced_memory()[0] / 1e6,
                                                         r.memory_mb)))
    finally:
        tracemalloc.stop()
    assert run.frames_processed == n and run.frames_mapped > 0.65 * n
    samples = np.array(samples)
    early = samples[(samples[:, 0] > 0.25 * n) & (samples[:, 0] < 0.5 * n)]
    late = samples[samples[:, 0] > 0.75 * n]
    assert len(early) and len(late), samples
    frames = np.median(late[:, 0]) - np.median(early[:, 0])
    # MB per frame between the two stretches: a frame's disparity alone is 77 kB (160x120 float32); the
    # trajectory (144 B a frame) is held by the loop, the run and the snapshot being written. What is held
    # is the floor under the samples (their 10th percentile): a sample also counts the arrays of the frames
    # in flight in the other threads at that moment, which come and go (up to 20 MB)
    held = [np.percentile(stretch[:, 1], 10) for stretch in (early, late)]
    assert (held[1] - held[0]) / frames < 0.004, samples
    assert (np.median(late[:, 2]) - np.median(early[:, 2])) / frames < 0.1, samples
