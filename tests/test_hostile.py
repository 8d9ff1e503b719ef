"""Hostile files: small on disk, huge when trusted. Each is refused by the command line in one line, fast and with
bounded memory.

Every case runs ``python -m mrstereo`` in a fresh process and measures its CPU time and peak memory (``wait4``'s
``ru_utime + ru_stime`` and ``ru_maxrss``): the promise is a refusal in under 10 s with under 1.5 GB (docs/errors.md).
CPU time, so that other work on the machine does not make a refusal look slow; a hang is killed after 60 s of wall
time. The files are generated here, a few kilobytes each: an image header claiming 10^10 pixels, a real
10000 x 10000 PNG of zeros (100 KB), a YAML alias bomb in every kind of YAML mrstereo reads, a manifest of a million
frames, ROS 1 records claiming more than the file holds and a chunk that decompresses to far more than it claims, a
PNG bomb inside a bag, a Dask "scheduler" that never answers and one that speaks HTTP.
"""
from __future__ import annotations

import http.server
import os
import shutil
import socket
import struct
import subprocess
import sys
import threading
import zlib
from pathlib import Path

import numpy as np
import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
TIME_LIMIT_S = 10.0
MEMORY_LIMIT_MB = 1500.0


# ------------------------------------------------------------------------------------------ running a command

# A small launcher runs the command and reports its rusage: a child forked from this test process would count
# the test process's pages (copied at fork) in its ``ru_maxrss``, a child of the launcher only its own.
LAUNCHER = """
import os, subprocess, sys, threading
proc = subprocess.Popen(sys.argv[3:])
timer = threading.Timer(float(sys.argv[2]), proc.kill)
timer.start()
_, status, usage = os.wait4(proc.pid, 0)
timer.cancel()
with open(sys.argv[1], "w") as f:
    f.write(f"{usage.ru_utime + usage.ru_stime} {usage.ru_maxrss}")
sys.exit(os.waitstatus_to_exitcode(status))
"""


def run_cli(args, workdir: Path, *, env: dict | None = None, timeout_s: float = 600.0):
    """``(exit code, stderr, CPU seconds, peak MB)`` of ``python -m mrstereo ARGS`` in a fresh process.

    ``timeout_s`` (wall clock) only ends a hung command; the limits checked are CPU time and memory (a busy
    machine stretches the wall time of a 10 s refusal past a minute)."""
    environment = dict(os.environ, PYTHONPATH=str(SRC), MPLBACKEND="Agg", **(env or {}))
    out, err, usage = workdir / "stdout.txt", workdir / "stderr.txt", workdir / "usage.txt"
    with open(out, "wb") as fo, open(err, "wb") as fe:
        proc = subprocess.run([sys.executable, "-c", LAUNCHER, str(usage), str(timeout_s), sys.executable, "-m",
                               "mrstereo", *[str(a) for a in args]], stdout=fo, stderr=fe, env=environment, cwd=workdir)
    seconds, peak_kb = (float(v) for v in usage.read_text().split())
    return proc.returncode, err.read_text(errors="replace"), seconds, peak_kb / 1024.0


def refused(args, workdir: Path, *, must: str, env: dict | None = None, time_limit_s: float = TIME_LIMIT_S) -> str:
    """Run, and check the promise: exit 2, one line naming ``must``, under the time and memory limits."""
    code, err, seconds, peak_mb = run_cli(args, workdir, env=env)
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, err
    assert len(lines) == 1 and lines[0].startswith("mrstereo: error: "), err
    assert must in lines[0], lines[0]
    assert seconds < time_limit_s, f"{seconds:.1f} s of CPU"
    assert peak_mb < MEMORY_LIMIT_MB, f"{peak_mb:.0f} MB"
    return lines[0]


# ------------------------------------------------------------------------------------------ generated bombs

def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def png_bomb(width: int, height: int, *, real: bool = True) -> bytes:
    """A gray PNG of ``width`` x ``height`` zeros: with ``real`` its whole image data, compressed (about 1000:1,
    made row by row); else the header alone with a few bytes of data."""
    compressor = zlib.compressobj(9)
    parts = []
    if real:
        row = b"\x00" * (width + 1)
        for _ in range(height):
            parts.append(compressor.compress(row))
    parts.append(compressor.flush())
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", b"".join(parts)) + _chunk(b"IEND", b""))


HEADERS = {
    "png": png_bomb(100_000, 100_000, real=False),
    "jpg": b"\xff\xd8\xff\xc0\x00\x0b\x08" + struct.pack(">HH", 60_000, 60_000) + b"\x01\x01\x11\x00\xff\xd9",
    "pgm": b"P5\n100000 100000\n255\n" + b"\x00" * 64,
    "bmp": b"BM" + struct.pack("<IHHI", 0, 0, 0, 54) + struct.pack("<IiiHH", 40, 100_000, -100_000, 1, 8) + bytes(40),
    "tif": b"II*\x00" + struct.pack("<I", 8) + struct.pack("<H", 2) + struct.pack("<HHII", 256, 4, 1, 100_000)
           + struct.pack("<HHII", 257, 4, 1, 100_000) + struct.pack("<I", 0),
    "webp": b"RIFF" + struct.pack("<I", 30) + b"WEBPVP8X" + struct.pack("<I", 10) + b"\x00" * 4
            + (99_999).to_bytes(3, "little") + (99_999).to_bytes(3, "little"),
}

ALIAS_BOMB = "a: &a [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]\n" + "".join(
    f"{chr(98 + i)}: &{chr(98 + i)} [{', '.join([f'*{chr(97 + i)}'] * 10)}]\n" for i in range(8))
"""Nine lines, 10^9 values once the aliases are expanded."""


@pytest.fixture(scope="module")
def ds(synthetic_dataset) -> Path:
    return synthetic_dataset(seed=1, n_frames=3, width=160, height=120, supersample=1)


@pytest.fixture
def pair(ds, tmp_path):
    left, right = tmp_path / "L.png", tmp_path / "R.png"
    shutil.copy(ds / "left_rect" / "000000.png", left)
    shutil.copy(ds / "right_rect" / "000000.png", right)
    return left, right


# ------------------------------------------------------------------------------------------ images

@pytest.mark.parametrize("kind", sorted(HEADERS))
def test_an_image_header_claiming_ten_billion_pixels_is_refused_before_decoding(kind, pair, tmp_path):
    bomb = tmp_path / f"bomb.{kind}"
    bomb.write_bytes(HEADERS[kind])
    line = refused(["disparity", bomb, pair[1], "--max-disparity", "16", "-o", tmp_path / "d.pfm"], tmp_path,
                   must=f"{bomb}: the image header claims")
    assert "MRSTEREO_MAX_IMAGE_PIXELS" in line and not (tmp_path / "d.pfm").exists()


def test_a_real_png_bomb_is_refused_and_the_limit_can_be_raised(pair, tmp_path):
    bomb = tmp_path / "zeros.png"
    bomb.write_bytes(png_bomb(10_000, 10_000))          # 100 Mpx, about 100 KB on disk
    assert bomb.stat().st_size < 200_000
    refused(["disparity", bomb, bomb, "--max-disparity", "16", "-o", tmp_path / "d.pfm"], tmp_path,
            must="10000x10000 pixels")
    # raised: decoded, in a process that starts with it (OpenCV takes its own limit from it when it loads;
    # not the limit this test process handed to its OpenCV, or the pytest-xdist controller to its workers)
    env = {k: v for k, v in os.environ.items() if k != "OPENCV_IO_MAX_IMAGE_PIXELS"}
    env.update(PYTHONPATH=str(SRC), MRSTEREO_MAX_IMAGE_PIXELS=str(10 ** 8))
    read = subprocess.run([sys.executable, "-c", f"from mrstereo.io import read_image; "
                           f"print(read_image({str(bomb)!r}).shape)"], capture_output=True, text=True, env=env)
    assert read.stdout.strip() == "(10000, 10000)", read.stderr


def test_a_corrupt_png_is_one_line_without_libpng_noise(pair, tmp_path):
    data = bytearray(pair[0].read_bytes())
    data[60:80] = b"x" * 20                        # damages the image data: libpng reports a CRC error
    bad = tmp_path / "bad.png"
    bad.write_bytes(bytes(data))
    refused(["disparity", bad, pair[1], "--max-disparity", "16", "-o", tmp_path / "d.pfm"], tmp_path,
            must=f"cannot decode image {bad}")


# ------------------------------------------------------------------------------------------ YAML

def test_yaml_alias_bombs_are_refused_in_every_yaml_mrstereo_reads(ds, pair, tmp_path):
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text(ALIAS_BOMB)
    refused(["disparity", *pair, "--calib", bomb, "--rectified", "-o", tmp_path / "d.pfm"], tmp_path,
            must="more than 2,000,000 values (aliases expanded)")
    refused(["plan", bomb, "--start", "1,0", "--goal", "2,0", "-o", tmp_path / "p.json"], tmp_path,
            must="more than 2,000,000 values")
    manifest = tmp_path / "DS"
    shutil.copytree(ds, manifest)
    (manifest / "manifest.yaml").write_text((manifest / "manifest.yaml").read_text() + "bomb:\n" + "".join(
        "  " + line + "\n" for line in ALIAS_BOMB.splitlines()))
    refused(["map", manifest, "-o", tmp_path / "m", "--quiet"], tmp_path, must="manifest")
    opencv = tmp_path / "opencv.yaml"
    opencv.write_text("%YAML:1.0\n---\n" + ALIAS_BOMB)
    refused(["calib", "convert", opencv, "-o", tmp_path / "s.yaml"], tmp_path, must="opencv.yaml")


def test_a_million_frame_manifest_is_refused_fast(ds, tmp_path):
    folder = tmp_path / "BIG"
    folder.mkdir()
    shutil.copy(ds / "calibration.yaml", folder / "calibration.yaml")
    line = "- {left: left.png, right: right.png, pose: [0, 0, 0]}\n"
    (folder / "manifest.yaml").write_text("calibration: calibration.yaml\nframes:\n" + line * 1_000_000)
    # refused after reading 2,000,000 values (the limit, a 100,000-frame manifest's size): 9-11 s of CPU here
    refused(["map", folder, "-o", tmp_path / "m", "--quiet"], tmp_path, must="MRSTEREO_MAX_YAML_NODES",
            time_limit_s=2 * TIME_LIMIT_S)
    small = tmp_path / "SMALL"
    small.mkdir()
    shutil.copy(ds / "calibration.yaml", small / "calibration.yaml")
    (small / "manifest.yaml").write_text("calibration: calibration.yaml\nframes:\n" + line * 2000)
    refused(["map", small, "-o", tmp_path / "m", "--quiet"], tmp_path, must="MRSTEREO_MAX_FRAMES",
            env={"MRSTEREO_MAX_FRAMES": "1000"})


@pytest.mark.parametrize("command", [["synth", "--out", "S", "--frames", "100000000"],
                                     ["demo", "--out", "D", "--frames", "100000000"]])
def test_absurd_frame_counts_are_refused_before_work(command, tmp_path):
    refused(command, tmp_path, must="--frames")
    assert not any(p.name in ("S", "D") for p in tmp_path.iterdir())


# ------------------------------------------------------------------------------------------ bags

def _ros1_record(fields: dict[bytes, bytes], data: bytes, *, data_len: int | None = None) -> bytes:
    header = b"".join(struct.pack("<I", len(k) + 1 + len(v)) + k + b"=" + v for k, v in fields.items())
    return struct.pack("<I", len(header)) + header + struct.pack("<I", len(data) if data_len is None else data_len) \
        + data


def _ros1_bag(chunk: bytes) -> bytes:
    header = _ros1_record({b"op": b"\x03", b"index_pos": struct.pack("<Q", 0), b"conn_count": struct.pack("<I", 0),
                           b"chunk_count": struct.pack("<I", 1)}, b" " * 32)
    return b"#ROSBAG V2.0\n" + header + chunk


BAG_ARGS = ["--left-topic", "/l", "--right-topic", "/r"]


def test_a_ros1_chunk_longer_than_the_file_is_one_line(tmp_path):
    bag = tmp_path / "long.bag"
    bag.write_bytes(_ros1_bag(_ros1_record({b"op": b"\x05", b"compression": b"none",
                                            b"size": struct.pack("<I", 16)}, b"x" * 16, data_len=0x7FFFFFFF)))
    line = refused(["export", "--bag", bag, *BAG_ARGS, "-o", tmp_path / "x"], tmp_path,
                   must="claims 2147483647 bytes of data")
    assert str(bag) in line


def test_a_compressed_chunk_bomb_is_refused_without_inflating_it(tmp_path):
    import lz4.frame

    compressor = lz4.frame.LZ4FrameCompressor()
    zeros = b"\x00" * (1 << 20)
    data = compressor.begin() + b"".join(compressor.compress(zeros) for _ in range(64)) + compressor.flush()
    bag = tmp_path / "bomb.bag"                     # claims 4 KB, inflates to 64 MB (the limit lowered to 8 MB)
    bag.write_bytes(_ros1_bag(_ros1_record({b"op": b"\x05", b"compression": b"lz4",
                                            b"size": struct.pack("<I", 4096)}, data)))
    refused(["export", "--bag", bag, *BAG_ARGS, "-o", tmp_path / "x"], tmp_path, must="decompresses to more",
            env={"MRSTEREO_MAX_MESSAGE_BYTES": str(8 << 20)})


@pytest.mark.parametrize("ros1", [True, False], ids=["ros1", "ros2"])
def test_a_png_bomb_inside_a_bag_is_refused(ros1, tmp_path):
    from _bags import BagWriter

    bomb = png_bomb(10_000, 10_000)
    topics = {"/l": "sensor_msgs/msg/CompressedImage", "/r": "sensor_msgs/msg/CompressedImage"}
    bag = tmp_path / ("b.bag" if ros1 else "b2")
    with BagWriter(bag, ros1, topics) as writer:
        for topic in topics:
            msg = writer.msgs.T["sensor_msgs/msg/CompressedImage"](
                header=writer.msgs.header(10 ** 18, "cam"), format="png", data=np.frombuffer(bomb, np.uint8))
            writer.put(topic, msg, 10 ** 18)
    calib = tmp_path / "c.yaml"
    _write_calibration(calib)
    refused(["export", "--bag", bag, *BAG_ARGS, "--calib", calib, "-o", tmp_path / "x", "--quiet"], tmp_path,
            must="the image header claims 10000x10000 pixels")


def test_a_huge_bag_metadata_file_is_refused_unparsed(ds, tmp_path):
    """A ROS 2 bag whose metadata.yaml is padded to 4 MB (the reader's YAML parser would take a minute)."""
    from _bags import write_bag

    from mrstereo.recordings.manifest import read_manifest

    bag = write_bag(tmp_path / "b2", read_manifest(ds), ros1=False, odom=True)
    meta = bag / "metadata.yaml"
    pad = "".join(f"  - x{i}\n" for i in range(400_000))
    meta.write_text(meta.read_text().replace("  ros_distro:", "  padding:\n" + pad + "  ros_distro:"))
    refused(["info", bag], tmp_path, must="metadata.yaml has more bytes")


def _write_calibration(path: Path) -> None:
    from mrstereo.camera import write_stereo
    from mrstereo.world.render import default_stereo

    write_stereo(path, default_stereo(160, 120))


# ------------------------------------------------------------------------------------------ schedulers, workers

def _silent_server():
    """A TCP server that accepts connections and never answers: (address, stop)."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    held, stop = [], threading.Event()

    def accept():
        server.settimeout(0.2)
        while not stop.is_set():
            try:
                held.append(server.accept()[0])
            except OSError:
                continue
    threading.Thread(target=accept, daemon=True).start()

    def close():
        stop.set()
        for conn in held:
            conn.close()
        server.close()
    return f"tcp://127.0.0.1:{server.getsockname()[1]}", close


def _http_server():
    httpd = http.server.HTTPServer(("127.0.0.1", 0), http.server.SimpleHTTPRequestHandler)
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    return f"tcp://127.0.0.1:{httpd.server_address[1]}", httpd.shutdown


@pytest.mark.extra("scale")
@pytest.mark.parametrize("server", [_silent_server, _http_server], ids=["silent", "http"])
def test_a_scheduler_that_is_no_dask_scheduler_is_one_line_within_seconds(server, ds, tmp_path):
    address, stop = server()
    try:
        refused(["map", ds, "-o", tmp_path / "m", "--scheduler", address, "--quiet"], tmp_path,
                must="no Dask scheduler at")
    finally:
        stop()


def test_more_workers_than_cores_are_refused_unless_allowed(ds, tmp_path):
    refused(["map", ds, "-o", tmp_path / "m", "--workers", "10000", "--processes", "--quiet"], tmp_path,
            must="--workers")
    from mrstereo import _checks
    with pytest.raises(ValueError, match="MRSTEREO_MAX_WORKERS"):
        _checks.workers("workers", 10_000)
    os.environ["MRSTEREO_MAX_WORKERS"] = "10000"
    try:
        assert _checks.workers("workers", 10_000) == 10_000
    finally:
        del os.environ["MRSTEREO_MAX_WORKERS"]


def test_a_grid_larger_than_the_available_memory_is_refused(ds, tmp_path):
    from mrstereo._checks import memory_limit_bytes
    from mrstereo.mapping.grid import BYTES_PER_CELL

    side = int(((memory_limit_bytes() / BYTES_PER_CELL) ** 0.5) * 0.05 * 2)      # 4x the memory available
    refused(["map", ds, "-o", tmp_path / "m", "--size", f"{side},{side}", "--origin", "0,0", "--quiet"], tmp_path,
            must="available on this machine")
