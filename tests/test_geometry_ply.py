"""PLY writer/reader checked against a hand-computed byte layout."""
import struct

import numpy as np
import pytest

from mrstereo.geometry import read_ply, write_ply


def test_binary_layout_with_intensity_is_exactly_as_specified(tmp_path):
    pts = np.array([[1.0, -2.0, 0.5], [np.nan, 0, 0], [0.25, 3.0, -1.5]])
    n = write_ply(tmp_path / "c.ply", pts, intensity=np.array([10, 20, 255]), comment="test")
    assert n == 2
    raw = (tmp_path / "c.ply").read_bytes()
    header = (b"ply\nformat binary_little_endian 1.0\ncomment test\nelement vertex 2\n"
              b"property float x\nproperty float y\nproperty float z\nproperty uchar intensity\nend_header\n")
    assert raw[:len(header)] == header
    body = raw[len(header):]
    assert len(body) == 2 * 13                                     # 3 float32 + 1 uchar, packed
    assert struct.unpack("<fffB", body[:13]) == (1.0, -2.0, 0.5, 10)
    assert struct.unpack("<fffB", body[13:]) == (0.25, 3.0, -1.5, 255)
    back = read_ply(tmp_path / "c.ply")
    np.testing.assert_array_equal(back.points, np.float32([[1.0, -2.0, 0.5], [0.25, 3.0, -1.5]]))
    np.testing.assert_array_equal(back.intensity, [10, 255]) and back.colors_rgb is None


def test_rgb_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(50, 3)).astype(np.float32)
    rgb = rng.integers(0, 256, (50, 3)).astype(np.uint8)
    write_ply(tmp_path / "c.ply", pts, colors_rgb=rgb)
    raw = (tmp_path / "c.ply").read_bytes()
    assert b"property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n" in raw
    assert len(raw) - raw.index(b"end_header\n") - len(b"end_header\n") == 50 * 15
    back = read_ply(tmp_path / "c.ply")
    np.testing.assert_array_equal(back.points, pts)
    np.testing.assert_array_equal(back.colors_rgb, rgb)


def test_empty_cloud_and_bad_input(tmp_path):
    assert write_ply(tmp_path / "e.ply", np.zeros((0, 3))) == 0
    assert read_ply(tmp_path / "e.ply").points.shape == (0, 3)
    with pytest.raises(ValueError, match="points must have shape"):
        write_ply(tmp_path / "x.ply", np.zeros((3, 2)))
    with pytest.raises(ValueError, match="not both"):
        write_ply(tmp_path / "x.ply", np.zeros((1, 3)), intensity=[1], colors_rgb=[[1, 2, 3]])
    with pytest.raises(ValueError, match="intensity must have shape"):
        write_ply(tmp_path / "x.ply", np.zeros((2, 3)), intensity=[1])
    (tmp_path / "a.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1\n")
    with pytest.raises(ValueError, match="only binary_little_endian"):
        read_ply(tmp_path / "a.ply")
    (tmp_path / "t.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 5\n"
                                     b"property float x\nproperty float y\nproperty float z\nend_header\n" + b"\0" * 12)
    with pytest.raises(ValueError, match="truncated"):
        read_ply(tmp_path / "t.ply")
    (tmp_path / "n.ply").write_bytes(b"hello")
    with pytest.raises(ValueError, match="not a PLY"):
        read_ply(tmp_path / "n.ply")


def test_independent_reader_agrees(tmp_path):
    import plyfile
    pts = np.array([[0.5, -1.0, 2.0], [3.0, 0.25, -0.5]])
    write_ply(tmp_path / "c.ply", pts, colors_rgb=[[255, 0, 10], [1, 2, 3]])
    v = plyfile.PlyData.read(str(tmp_path / "c.ply"))["vertex"]
    np.testing.assert_array_equal(np.stack([v["x"], v["y"], v["z"]], axis=1), pts.astype(np.float32))
    np.testing.assert_array_equal(np.stack([v["red"], v["green"], v["blue"]], axis=1), [[255, 0, 10], [1, 2, 3]])


def test_labels_round_trip_and_are_named_in_the_header(tmp_path):
    pts = np.array([[0.5, -1.0, 2.0], [3.0, 0.25, -0.5], [np.nan, 0, 0], [1.0, 1.0, 0.0]])
    assert write_ply(tmp_path / "l.ply", pts, intensity=[1, 2, 3, 4], label=[1, 2, 1, 0]) == 3
    cloud = read_ply(tmp_path / "l.ply")
    np.testing.assert_array_equal(cloud.label, [1, 2, 0])          # the NaN point dropped with its label
    np.testing.assert_array_equal(cloud.intensity, [1, 2, 4])
    header = (tmp_path / "l.ply").read_bytes().split(b"end_header")[0].decode()
    assert "property uchar label" in header and "label 0 other, 1 obstacle, 2 floor" in header
    with pytest.raises(ValueError, match="label"):
        write_ply(tmp_path / "m.ply", pts, label=[1, 2])
