"""Images of real robots' bags: every supported sensor_msgs/Image encoding (known answers through a bag
written with rosbags and exported), Bayer patterns against OpenCV's naming, 16-bit precision, row padding,
CompressedImage, and a clear error for an unsupported encoding."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from mrstereo.camera import Camera, StereoCamera, write_stereo
from mrstereo.cli import entry
from mrstereo.io import matching_image, read_image
from mrstereo.pipeline.run import build_map
from mrstereo.recordings.bag import SUPPORTED_ENCODINGS, export_bag, image_from_message
from mrstereo.recordings.manifest import read_manifest

from _bags import DT_NS, T0_NS, BagWriter, Msgs, typestore

W, H = 24, 16
BGR = (10, 100, 200)


def _image_msg(m, payload: np.ndarray, encoding: str, stamp: int, *, pad: int = 0, bigendian: bool = False):
    """An Image message whose rows are ``payload`` rows (bytes) followed by ``pad`` junk bytes."""
    rows = payload.reshape(payload.shape[0], -1).view(np.uint8).reshape(payload.shape[0], -1)
    data = np.concatenate([rows, np.full((rows.shape[0], pad), 0xAB, np.uint8)], axis=1)
    return m.T["sensor_msgs/msg/Image"](header=m.header(stamp, "cam"), height=payload.shape[0],
                                        width=payload.shape[1], encoding=encoding, is_bigendian=int(bigendian),
                                        step=data.shape[1], data=np.ascontiguousarray(data).ravel())


def _write(path, ros1: bool, msgs_left, msgs_right, *, compressed: bool = False):
    typ = "sensor_msgs/msg/CompressedImage" if compressed else "sensor_msgs/msg/Image"
    with BagWriter(path, ros1, {"/l/image": typ, "/r/image": typ}) as bag:
        for k, (a, b) in enumerate(zip(msgs_left(bag.msgs), msgs_right(bag.msgs))):
            t = T0_NS + k * DT_NS
            bag.put("/l/image", a, t)
            bag.put("/r/image", b, t)
    return path


def _calib(tmp_path, w=W, h=H):
    path = tmp_path / "stereo.yaml"
    write_stereo(path, StereoCamera.ideal(Camera(width=w, height=h, fx=20.0, fy=20.0, cx=w / 2, cy=h / 2), 0.1))
    from mrstereo.camera import read_stereo
    return read_stereo(path)


def _export_one(tmp_path, name, ros1, make, **kw):
    bag = _write(tmp_path / (name + (".bag" if ros1 else "")), ros1,
                 lambda m: [make(m, T0_NS)], lambda m: [make(m, T0_NS)], **kw)
    out = tmp_path / f"out_{name}"
    export_bag(bag, out, left_topic="/l/image", right_topic="/r/image", calibration=_calib(tmp_path),
               progress=False)
    return read_image(read_manifest(out).frames[0].left)


def _mosaic(pattern: str) -> np.ndarray:
    """A uniform BGR image sampled through the 2x2 colour filter ``pattern`` (ROS order, row-major)."""
    out = np.zeros((H, W), np.uint8)
    channel = {"r": 2, "g": 1, "b": 0}
    for dy in range(2):
        for dx in range(2):
            out[dy::2, dx::2] = BGR[channel[pattern[2 * dy + dx]]]
    return out


@pytest.mark.parametrize("ros1", [True, False])
def test_every_encoding_known_answer_through_a_bag(tmp_path, ros1):
    rng = np.random.default_rng(1)
    gray = rng.integers(0, 256, (H, W), dtype=np.uint8)
    bgr = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    g16 = rng.integers(0, 65536, (H, W), dtype=np.uint16)
    alpha = np.full((H, W, 1), 7, np.uint8)
    cases = {
        "mono8": (gray, gray), "8UC1": (gray, gray),
        "mono16": (g16.astype("<u2"), g16), "16UC1": (g16.astype("<u2"), g16),
        "bgr8": (bgr, bgr), "rgb8": (bgr[:, :, ::-1], bgr), "8UC3": (bgr, bgr),
        "bgra8": (np.concatenate([bgr, alpha], 2), bgr), "rgba8": (np.concatenate([bgr[:, :, ::-1], alpha], 2), bgr),
        "8UC4": (np.concatenate([bgr, alpha], 2), bgr),
    }
    for enc, (payload, expected) in cases.items():
        for pad in (0, 5):                                        # rows padded beyond width * bytes
            got = _export_one(tmp_path, f"{enc}_{pad}", ros1,
                              lambda m, t: _image_msg(m, np.ascontiguousarray(payload), enc, t, pad=pad))
            assert got.dtype == expected.dtype and np.array_equal(got, expected), (enc, pad)
    # 16 bit, big-endian
    got = _export_one(tmp_path, "mono16be", ros1,
                      lambda m, t: _image_msg(m, g16.astype(">u2"), "mono16", t, pad=3, bigendian=True))
    assert np.array_equal(got, g16)
    # Bayer: a uniform colour seen through each ROS pattern comes back as that colour (OpenCV names differ)
    for pattern in ("rggb", "bggr", "gbrg", "grbg"):
        got = _export_one(tmp_path, pattern, ros1, lambda m, t: _image_msg(m, _mosaic(pattern), f"bayer_{pattern}8", t))
        assert got.shape == (H, W, 3)
        assert np.array_equal(got[2:-2, 2:-2], np.broadcast_to(BGR, (H - 4, W - 4, 3))), pattern
    assert set(cases) | {"bayer_rggb8", "bayer_bggr8", "bayer_gbrg8", "bayer_grbg8"} == set(SUPPORTED_ENCODINGS)


def test_compressed_png_16_bit_and_jpeg(tmp_path):
    rng = np.random.default_rng(2)
    g16 = rng.integers(0, 65536, (H, W), dtype=np.uint16)
    smooth = cv2.GaussianBlur(rng.integers(0, 256, (H, W, 3), dtype=np.uint8), (5, 5), 2)

    def compressed(img, fmt):
        def make(m, t):
            ok, buf = cv2.imencode("." + fmt, img)
            return m.T["sensor_msgs/msg/CompressedImage"](header=m.header(t, "cam"), format=fmt, data=buf.ravel())
        return make

    assert np.array_equal(_export_one(tmp_path, "png16", False, compressed(g16, "png"), compressed=True), g16)
    got = _export_one(tmp_path, "jpg", True, compressed(smooth, "jpg"), compressed=True)
    expected = cv2.imdecode(cv2.imencode(".jpg", smooth)[1], cv2.IMREAD_UNCHANGED)      # as OpenCV decodes it
    assert np.array_equal(got, expected)


def test_unsupported_encoding_is_one_clear_line(tmp_path, capsys):
    bag = _write(tmp_path / "f.bag", True,
                 lambda m: [_image_msg(m, np.zeros((H, W), np.float32), "32FC1", T0_NS)],
                 lambda m: [_image_msg(m, np.zeros((H, W), np.float32), "32FC1", T0_NS)])
    write_stereo(tmp_path / "c.yaml", _calib(tmp_path))
    code = entry(["export", "--bag", str(bag), "--left-topic", "/l/image", "--right-topic", "/r/image",
                  "--calib", str(tmp_path / "c.yaml"), "-o", str(tmp_path / "o"), "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert err[0].startswith("mrstereo: error: image encoding '32FC1' is not supported (supported: mono8")
    assert not (tmp_path / "o").exists()
    msg = Msgs(typestore(False), False)
    with pytest.raises(ValueError, match="step 10"):
        bad = _image_msg(msg, np.zeros((H, W), np.uint8), "mono8", T0_NS)
        bad.step = 10
        image_from_message(bad, "sensor_msgs/msg/Image")


def test_16_bit_levels_stay_distinct_and_a_mono16_bag_maps_like_mono8(synthetic_dataset, tmp_path):
    levels = np.arange(65536, dtype=np.uint16).reshape(256, 256)
    scaled = matching_image(levels)
    assert scaled.dtype == np.float32 and np.all(np.diff(scaled.ravel()) > 0)
    assert scaled.max() == 255.0
    assert np.array_equal(matching_image(np.full((2, 3), 257 * 3, np.uint16)), np.full((2, 3), 3.0, np.float32))
    # rectified synthetic pairs as mono8 and as mono16 (x 257): the same map, bit for bit
    data = read_manifest(synthetic_dataset(seed=5, n_frames=3, width=160, height=120, supersample=1))
    frames = data.frames

    def side(attr, wide):
        def make(m):
            out = []
            for k, rec in enumerate(frames):
                img = read_image(getattr(rec, attr))
                img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) if img.ndim == 3 else img
                payload = img.astype("<u2") * 257 if wide else img
                out.append(_image_msg(m, payload, "mono16" if wide else "mono8", T0_NS + k * DT_NS))
            return out
        return make

    maps = []
    for wide in (False, True):
        bag = _write(tmp_path / f"w{int(wide)}", False, side("left_rect", wide), side("right_rect", wide))
        out = tmp_path / f"o{int(wide)}"
        export_bag(bag, out, left_topic="/l/image", right_topic="/r/image", calibration=data.calibration,
                   mount=data.mount, rectified=True, progress=False)
        assert read_image(read_manifest(out).frames[0].left_rect).dtype == (np.uint16 if wide else np.uint8)
        maps.append(build_map(out, progress=False).grid.log_odds)
    assert np.array_equal(maps[0], maps[1], equal_nan=True)
    assert np.isfinite(maps[0]).any() and (maps[0] != 0).any()
