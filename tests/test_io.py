"""Disparity and image files: PFM and KITTI round trips, atomic writes, clear errors."""
import os

import cv2
import numpy as np
import pytest

from mrstereo.io import (atomic_write, read_disparity, read_image, read_pfm, refuse_overwrite_input, write_disparity,
                         write_image, write_pfm)


def test_pfm_round_trip_with_nan(tmp_path):
    d = np.arange(12, dtype=np.float32).reshape(3, 4) / 3.0
    d[1, 2] = np.nan
    write_pfm(tmp_path / "d.pfm", d)
    raw = (tmp_path / "d.pfm").read_bytes()
    assert raw.startswith(b"Pf\n4 3\n-1\n")
    # rows are stored bottom-up: the first stored value is the bottom-left pixel
    assert np.frombuffer(raw[len(b"Pf\n4 3\n-1\n"):][:4], "<f4")[0] == d[2, 0]
    assert np.isinf(np.frombuffer(raw[-4 * 4 - 4 * 4:][:16], "<f4")).sum() == 1
    back = read_pfm(tmp_path / "d.pfm")
    np.testing.assert_array_equal(np.isnan(back), np.isnan(d))
    np.testing.assert_array_equal(back[~np.isnan(d)], d[~np.isnan(d)])


def test_kitti_png_round_trip(tmp_path):
    d = np.array([[0.0, 1.5, np.nan], [12.25, 255.99, 3.0]], np.float32)
    write_disparity(tmp_path / "d.png", d)
    raw = read_image(tmp_path / "d.png")
    assert raw.dtype == np.uint16 and raw[0, 1] == 384 and raw[0, 2] == 0 and raw[0, 0] == 0
    back = read_disparity(tmp_path / "d.png")
    assert np.isnan(back[0, 0]) and np.isnan(back[0, 2])
    np.testing.assert_allclose(back[1], d[1], atol=1 / 256)


def test_reads_real_kitti_gt(sample_data):
    d = read_disparity(sample_data("kitti2012-000070") / "disp_noc/000070_10.png")
    assert d.shape == (376, 1241)
    assert 4.6 < np.nanmin(d) < 4.7 and 123.0 < np.nanmax(d) < 123.1


def test_atomic_write_leaves_nothing_on_failure(tmp_path):
    target = tmp_path / "out.txt"
    with pytest.raises(RuntimeError):
        with atomic_write(target) as tmp:
            tmp.write_text("partial")
            raise RuntimeError("boom")
    assert not target.exists() and list(tmp_path.iterdir()) == []


def test_clear_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="image not found"):
        read_image(tmp_path / "nope.png")
    (tmp_path / "corrupt.png").write_bytes(b"\x89PNG garbage")
    with pytest.raises(ValueError, match="cannot decode image"):
        read_image(tmp_path / "corrupt.png")
    (tmp_path / "bad.pfm").write_bytes(b"P6\n1 1\n255\n")
    with pytest.raises(ValueError, match="bad header"):
        read_pfm(tmp_path / "bad.pfm")
    with pytest.raises(ValueError, match=r"\.pfm or \.png"):
        write_disparity(tmp_path / "d.jpg", np.zeros((2, 2), np.float32))
    write_image(tmp_path / "in.png", np.zeros((2, 2), np.uint8))
    with pytest.raises(ValueError, match="would overwrite the input"):
        refuse_overwrite_input(tmp_path / "in.png", [tmp_path / "x.png", tmp_path / "in.png"])


def test_outputs_get_normal_permissions(tmp_path):
    import os
    import stat

    write_pfm(tmp_path / "d.pfm", np.zeros((2, 2), np.float32))
    mode = stat.S_IMODE(os.stat(tmp_path / "d.pfm").st_mode)
    mask = os.umask(0)
    os.umask(mask)
    assert mode == 0o666 & ~mask


def test_the_command_keeps_ffmpegs_log_off_stderr(tmp_path):
    """A damaged MJPG video: FFmpeg prints "[mjpeg @ 0x...]" lines unless the command has quieted it first."""
    import subprocess
    import sys

    writer = cv2.VideoWriter(str(tmp_path / "v.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 10, (64, 48), False)
    rng = np.random.default_rng(0)
    for _ in range(5):
        writer.write(rng.integers(0, 255, (48, 64), dtype=np.uint8))
    writer.release()
    data = bytearray((tmp_path / "v.avi").read_bytes())
    data[3000:-100:97] = bytes(len(data[3000:-100:97]))
    (tmp_path / "bad.avi").write_bytes(bytes(data))
    read = (f"import cv2\nc = cv2.VideoCapture({str(tmp_path / 'bad.avi')!r})\n"
            "while c.grab():\n    c.retrieve()\n")
    env = {k: v for k, v in os.environ.items() if k not in ("OPENCV_FFMPEG_LOGLEVEL", "RUST_LOG")}
    loud = subprocess.run([sys.executable, "-c", read], capture_output=True, text=True, env=env, timeout=120)
    quiet = subprocess.run([sys.executable, "-c", "from mrstereo.io import quiet_decoders\nquiet_decoders()\n" + read],
                           capture_output=True, text=True, env=env, timeout=120)
    assert "[mjpeg @" in loud.stderr                 # the damage is real
    assert "[mjpeg @" not in quiet.stderr and quiet.returncode == 0
