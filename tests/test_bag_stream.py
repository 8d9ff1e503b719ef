"""ROS bags read as streams of in-memory frames (BagSource): the same frames as the exported dataset, no file
written while reading, memory that does not grow with the length of the bag."""
from __future__ import annotations

import os
import tempfile
import tracemalloc

import numpy as np
import pytest

from mrstereo.camera import Camera, StereoCamera
from mrstereo.cli import entry
from mrstereo.recordings import StereoFrame, open_recording
from mrstereo.recordings.bag import BagSource, export_bag
from mrstereo.recordings.frames import RecordingSource
from mrstereo.recordings.manifest import read_manifest
from mrstereo.recordings.sources import open_source

from _bags import DT_NS, T0_NS, TOPICS, BagWriter, write_bag


@pytest.fixture(scope="module")
def dataset(synthetic_dataset):
    return read_manifest(synthetic_dataset(seed=4, n_frames=6, width=160, height=120, supersample=1))


def _assert_same_frames(stream, exported):
    frames = list(stream)
    expected = list(exported)
    assert len(frames) == len(expected) > 0
    for a, b in zip(frames, expected):
        assert isinstance(a, StereoFrame)
        assert a.index == b.index and a.stamp_s == b.stamp_s and a.rectified == b.rectified
        assert a.left.dtype == b.left.dtype and a.right.dtype == b.right.dtype
        np.testing.assert_array_equal(a.left, b.left)
        np.testing.assert_array_equal(a.right, b.right)
        np.testing.assert_array_equal(a.T_world_from_base, b.T_world_from_base)
        assert a.pan_rad == b.pan_rad
    return frames


@pytest.mark.parametrize("ros1, storage, compressed, poses", [
    (False, "sqlite3", False, dict(use_tf=True, camera_frame="stereo_link")),
    (True, "sqlite3", True, dict(odom_topic="/odom")),
    (False, "mcap", True, dict(use_tf=True))])
def test_bag_stream_equals_the_exported_dataset_frame_by_frame(dataset, tmp_path, ros1, storage, compressed, poses):
    bag = write_bag(tmp_path / ("run.bag" if ros1 else "run"), dataset, ros1=ros1, storage=storage,
                    odom="odom_topic" in poses, tf="use_tf" in poses, compressed=compressed)
    export_bag(bag, tmp_path / "exported", **TOPICS, progress=False, **poses)
    exported = read_manifest(tmp_path / "exported")
    with BagSource(bag, **TOPICS, **poses) as source:
        assert source.n_frames == len(dataset.frames) and source.layout == "ROS bag" and source.has_poses
        assert source.stamps_ns == tuple(T0_NS + k * DT_NS for k in range(len(dataset.frames)))
        assert source.calibration.size == dataset.calibration.size
        assert source.rate_hz == pytest.approx(1e9 / DT_NS)
        frames = _assert_same_frames(source, RecordingSource(exported))
    # the robot's poses and the pans of the panning head are the ones the bag was written from
    np.testing.assert_allclose([f.T_world_from_base for f in frames],
                               [r.T_world_from_base for r in dataset.frames], atol=1e-8)
    if "camera_frame" in poses:
        np.testing.assert_allclose([f.pan_rad for f in frames], [r.pan_rad for r in dataset.frames], atol=1e-8)
    # the left images are the manifest's raw images, gray
    first = dataset.frames[0]
    with RecordingSource(dataset, prefer_raw=True) as raw:
        np.testing.assert_array_equal(frames[0].left, next(iter(raw)).left)
    assert first.has_raw


def _write_pairs(path, left, right, encoding: str, *, n: int = 3, lag_ns: int = 2_000_000, late_ns: int = 0,
                 ros1: bool = False):
    """A bag of ``n`` pairs of ``left + k % 50``, ``right + k % 50`` (Image of ``encoding``) and camera_info; the right
    images stamped ``lag_ns`` after the left ones and recorded ``late_ns`` after them."""
    cal = StereoCamera.ideal(Camera(width=left.shape[1], height=left.shape[0], fx=50.0, fy=50.0,
                                    cx=left.shape[1] / 2, cy=left.shape[0] / 2), 0.2)
    topics = {"/cam/left/image": "sensor_msgs/msg/Image", "/cam/right/image": "sensor_msgs/msg/Image",
              "/cam/left/camera_info": "sensor_msgs/msg/CameraInfo",
              "/cam/right/camera_info": "sensor_msgs/msg/CameraInfo"}
    with BagWriter(path, ros1, topics) as bag:
        m = bag.msgs
        for k in range(n):
            t = T0_NS + k * DT_NS
            for side, image, stamp, late in (("left", left, t, 0), ("right", right, t + lag_ns, late_ns)):
                data = np.ascontiguousarray(image + image.dtype.type(k % 50)).view(np.uint8).ravel()
                msg = m.T["sensor_msgs/msg/Image"](header=m.header(stamp, side), height=image.shape[0],
                                                   width=image.shape[1], encoding=encoding, is_bigendian=0,
                                                   step=image.shape[1] * image.itemsize, data=data)
                bag.put(f"/cam/{side}/camera_info", m.camera_info(getattr(cal, side), stamp, side), stamp)
                bag.put(f"/cam/{side}/image", msg, stamp + late)
    return path


def test_16_bit_bag_stream_keeps_every_level_and_equals_the_export(tmp_path):
    rng = np.random.default_rng(3)
    left = rng.integers(0, 60000, size=(12, 20), dtype=np.uint16)
    right = rng.integers(0, 60000, size=(12, 20), dtype=np.uint16)
    bag = _write_pairs(tmp_path / "deep", left, right, "mono16")
    export_bag(bag, tmp_path / "exported", progress=False)
    with open_recording(bag) as source:
        assert isinstance(source, BagSource) and not source.has_poses
        frames = _assert_same_frames(source, RecordingSource(read_manifest(tmp_path / "exported")))
    assert frames[1].left.dtype == np.float32                        # 16-bit levels kept, on the 8-bit scale
    np.testing.assert_allclose(frames[1].left * 257.0, left + 1, atol=1e-2)
    assert [f.stamp_s for f in frames] == [(T0_NS + k * DT_NS) / 1e9 for k in range(3)]


def test_pairs_come_out_in_stamp_order_when_messages_are_late(tmp_path):
    """Right images recorded 2.5 frames after their left ones: every pair still has its own right image
    (paired by header stamp), handed out in frame order."""
    left = np.arange(8 * 10, dtype=np.uint8).reshape(8, 10)
    bag = _write_pairs(tmp_path / "late", left, left + 100, "mono8", n=6, late_ns=int(2.5 * DT_NS))
    with BagSource(bag) as source:
        frames = list(source)
    assert [f.index for f in frames] == list(range(6))
    for k, f in enumerate(frames):
        np.testing.assert_array_equal(f.left, left + k)
        np.testing.assert_array_equal(f.right, left + 100 + k)


@pytest.fixture
def empty_tmpdir(tmp_path, monkeypatch):
    """The temporary directory of this process and its children: an empty folder."""
    folder = tmp_path / "tmp"
    folder.mkdir()
    monkeypatch.setenv("TMPDIR", str(folder))
    monkeypatch.setattr(tempfile, "tempdir", str(folder))
    return folder


def _files(folder):
    return sorted(p for p in folder.rglob("*") if p.is_file())


def test_reading_a_bag_writes_no_file(dataset, tmp_path, empty_tmpdir, capsys):
    bag = write_bag(tmp_path / "run", dataset, ros1=False, odom=True)
    before = _files(tmp_path)
    with open_source([str(bag)]) as source:
        assert isinstance(source, BagSource)
        n = sum(1 for _ in source)
    assert n == len(dataset.frames)
    assert entry(["info", str(bag)]) == 0
    out = capsys.readouterr().out
    assert "ROS bag" in out and f"{len(dataset.frames)}, raw" in out and "/stereo/left/image_raw" in out
    assert "odometry /odom" in out and "160x120" in out
    assert _files(tmp_path) == before and _files(empty_tmpdir) == []


def _peak_bytes(bag) -> int:
    tracemalloc.start()
    try:
        with BagSource(bag) as source:
            for frame in source:
                assert frame.left.shape == (96, 128)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def _long_bag(path, n: int):
    rng = np.random.default_rng(n)
    left = rng.integers(0, 200, size=(96, 128), dtype=np.uint8)
    return _write_pairs(path, left, left, "mono8", n=n, lag_ns=0)


def test_memory_is_flat_however_long_the_bag(tmp_path):
    """Reading 600 pairs takes no more memory than reading 60: nothing is kept but stamps and poses
    (600 pairs held in memory would be 600 * 2 * 12 kB = 15 MB)."""
    short, long = _long_bag(tmp_path / "short", 60), _long_bag(tmp_path / "long", 600)
    grown = _peak_bytes(long) - _peak_bytes(short)
    assert grown < 1_000_000, f"reading 600 pairs took {grown / 1e6:.1f} MB more than reading 60"


def test_bag_options_for_a_folder_and_a_missing_pair_are_named(dataset, tmp_path):
    with pytest.raises(ValueError, match="not a ROS bag.*odom_topic"):
        open_recording(dataset.root, odom_topic="/odom")
    bag = write_bag(tmp_path / "run", dataset, ros1=False, odom=False)
    with pytest.raises(ValueError, match="topic '/nope' is not in the bag"):
        BagSource(bag, left_topic="/nope", right_topic=TOPICS["right_topic"])
    assert os.listdir(tmp_path) == ["run"]


def test_closing_a_source_midway_closes_the_bag(dataset, tmp_path):
    bag = write_bag(tmp_path / "run", dataset, ros1=False, odom=True)
    source = BagSource(bag)
    frames = iter(source)
    assert next(frames).index == 0
    source.close()
    with pytest.raises(StopIteration):
        next(frames)
    assert [f.index for f in source] == list(range(len(dataset.frames)))      # a new pass reads it again


def test_command_options_open_a_bag_or_a_folder_as_a_source(dataset, tmp_path, capsys):
    from mrstereo.cli._bag import opened_source

    bag = write_bag(tmp_path / "run.bag", dataset, ros1=True, odom=True)
    options = dict(left_topic=None, right_topic=None, camera_info_topics=None, odom_topic=None, use_tf=False,
                   world_frame=None, base_frame="base_link", camera_frame=None, sync_tolerance_s=0.02,
                   rectified_images=False, height_m=0.5, tilt_rad=0.1, mount=None)
    with opened_source(bag, None, None, quiet=True, bag_kw=options) as source:
        assert isinstance(source, BagSource) and source.pose_source == "odometry /odom"
        assert source.mount.T_base_from_rectified(source.calibration.left.R)[2, 3] == pytest.approx(0.5)
    assert "bag: 6 stereo pairs" in capsys.readouterr().err
    with opened_source(dataset.root, None, None, quiet=True, bag_kw=options) as source:
        assert isinstance(source, RecordingSource) and source.n_frames == len(dataset.frames)
        assert source.mount.T_base_from_rectified(source.calibration.left.R)[2, 3] == pytest.approx(0.5)
    import click
    with pytest.raises(click.UsageError, match="--odom-topic only with a ROS bag"):
        with opened_source(dataset.root, None, None, quiet=True, bag_kw=dict(options, odom_topic="/odom")):
            pass


class _TmpPeak:
    """Poll a folder while a command runs: its peak size [bytes] and every image file seen in it."""

    def __init__(self, folder):
        import threading

        self.folder, self.peak, self.images = folder, 0, set()
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._poll, daemon=True)

    def _poll(self):
        while True:
            files = _files(self.folder)
            self.peak = max(self.peak, sum(p.stat().st_size for p in files if p.exists()))
            self.images |= {p.name for p in files if p.suffix.lower() in (".png", ".pgm", ".pfm", ".ppm")}
            if self._done.wait(0.005):
                return

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._done.set()
        self._thread.join()


def _image_files(folder, out):
    return sorted(p for p in folder.rglob("*.p[gnf]m") if out not in p.parents) + \
        sorted(p for p in folder.rglob("*.png") if out not in p.parents)


def test_map_odometry_and_batch_read_a_bag_as_a_stream(dataset, tmp_path, empty_tmpdir):
    """``map``, ``odometry`` and ``batch`` on a bag write nothing to the temporary directory and no image outside
    their outputs; the map and the trajectory are those of the exported dataset, batch's map is map's."""
    bag = write_bag(tmp_path / "run", dataset, ros1=False, odom=False, tf=True)
    from mrstereo.geometry.ground import ground_from_mount

    rig = ground_from_mount(dataset.mount, R_rect_from_cam=dataset.calibration.left.R)
    common = ["--tf", "--camera-frame", "stereo_link", "--height", str(rig.height_m), "--tilt", str(rig.tilt_rad),
              "--quiet"]
    with _TmpPeak(empty_tmpdir) as tmp:
        assert entry(["map", str(bag), "-o", str(tmp_path / "out" / "map"), *common]) == 0
        assert entry(["odometry", str(bag), "-o", str(tmp_path / "out" / "vo.txt"), *common]) == 0
        assert entry(["batch", str(bag), str(dataset.root), "-o", str(tmp_path / "out" / "batch"), "--quiet"]) == 0
    assert tmp.peak == 0 and not tmp.images and _image_files(tmp_path, tmp_path / "out") == []
    export_bag(bag, tmp_path / "exported", **TOPICS, use_tf=True, camera_frame="stereo_link", progress=False,
               mount=dataset.mount)
    assert entry(["map", str(tmp_path / "exported"), "-o", str(tmp_path / "ref" / "map"), "--quiet"]) == 0
    assert entry(["odometry", str(tmp_path / "exported"), "-o", str(tmp_path / "ref" / "vo.txt"), "--quiet"]) == 0
    map_pgm = (tmp_path / "out" / "map" / "map.pgm").read_bytes()
    assert map_pgm == (tmp_path / "ref" / "map" / "map.pgm").read_bytes()
    np.testing.assert_array_equal(np.load(tmp_path / "out" / "map" / "log_odds.npy"),
                                  np.load(tmp_path / "ref" / "map" / "log_odds.npy"))
    np.testing.assert_allclose(np.loadtxt(tmp_path / "out" / "vo.txt"), np.loadtxt(tmp_path / "ref" / "vo.txt"),
                               atol=1e-9)
    # batch with the bag's defaults (its odometry: here TF is not picked, so the map of `map BAG` without --tf)
    assert entry(["map", str(bag), "-o", str(tmp_path / "out" / "plain"), "--quiet"]) == 0
    assert (tmp_path / "out" / "batch" / "run" / "map" / "map.pgm").read_bytes() == \
        (tmp_path / "out" / "plain" / "map.pgm").read_bytes()
    assert entry(["batch", str(bag), "-o", str(tmp_path / "out" / "batch"), "--quiet"]) == 0     # kept whole
    summary = (tmp_path / "out" / "batch" / "summary.json").read_text()
    assert '"map": "kept"' in summary and '"computed": 0' in summary


def test_mapping_the_euroc_bag_writes_no_image_file(tmp_path, empty_tmpdir):
    """EuRoC frames (752x480) as a ROS 2 bag: `map` leaves the temporary directory empty (the export of these
    12 pairs, its 5 frames forth and back, is 4.4 MB of PNG files) and writes no image outside its output folder."""
    from mrstereo.recordings import read_recording
    from mrstereo.recordings.samples import data_root

    euroc = read_recording(data_root() / "euroc_asl_sample")
    bag = write_bag(tmp_path / "euroc", euroc, ros1=False, odom=False, frames=[0, 1, 2, 3, 4, 3, 2, 1, 0, 1, 2, 3])
    with _TmpPeak(empty_tmpdir) as tmp:
        assert entry(["map", str(bag), "-o", str(tmp_path / "out"), "--quiet"]) == 0
    assert tmp.peak < 5_000_000 and not tmp.images, (tmp.peak, tmp.images)
    assert _image_files(tmp_path, tmp_path / "out") == [] and (tmp_path / "out" / "map.pgm").is_file()


def _map_peak_bytes(bag, mount) -> int:
    from mrstereo.pipeline.run import build_map

    tracemalloc.start()
    try:
        run = build_map(BagSource(bag, mount=mount), progress=False, keep_points=False)
        assert len(run.observations) > 0
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_mapping_memory_is_flat_however_long_the_bag(dataset, tmp_path):
    """Mapping 30 pairs of a bag takes no more memory than mapping 6 (24 more pairs held would be 0.92 MB):
    the frames are read, mapped and dropped one by one (docs/dataset.md: 2,000 pairs against 100 with
    `benchmarks/bench_bag_stream.py --map`)."""
    order = [0, 1, 2, 3, 4, 5, 4, 3, 2, 1]
    short, long = (write_bag(tmp_path / f"run{n}", dataset, ros1=False, odom=True,
                             frames=[order[k % len(order)] for k in range(n)]) for n in (6, 30))
    _map_peak_bytes(short, dataset.mount)                   # (first use: caches filled)
    grown = _map_peak_bytes(long, dataset.mount) - _map_peak_bytes(short, dataset.mount)
    assert grown < 600_000, f"mapping 30 pairs took {grown / 1e6:.2f} MB more than mapping 6"
