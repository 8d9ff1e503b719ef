"""ROS bags -> datasets and maps: bags written with rosbags from a synthetic dataset must map exactly
like the dataset itself; pairing, odometry / TF interpolation, image decoding; bad input."""
from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from mrstereo.cli import entry
from mrstereo.geometry.ground import ground_from_mount
from mrstereo.io import read_image
from mrstereo.pipeline.mapper import StereoMapper
from mrstereo.pipeline.run import build_map
from mrstereo.recordings.sources import recording_source
from mrstereo.recordings.bag import (TfTree, TransformTrack, bag_topics, camera_info_from_message, export_bag,
                                     image_from_message, pair_by_stamp, stereo_from_camera_info)
from mrstereo.recordings.manifest import read_manifest, write_manifest
from mrstereo.transforms import planar_from_T

from _bags import DT_NS, T0_NS, TOPICS, BagWriter, Msgs, typestore, write_bag

@pytest.fixture(scope="module")
def dataset(synthetic_dataset):
    return read_manifest(synthetic_dataset(seed=4, n_frames=6, width=160, height=120, supersample=1))


@pytest.fixture(scope="module")
def reference(dataset):
    """The map of the raw pairs of the manifest; without its true map, a map that grows as a bag's does."""
    import dataclasses

    return build_map(dataclasses.replace(dataset, ground_truth_map=None), prefer_raw=True, progress=False).grid.log_odds


def _same(a, b) -> bool:
    return np.array_equal(a, b, equal_nan=True)


def _rig_options(dataset):
    return {"mount": dataset.mount}


def _rig(dataset):
    """The paper's rig of a dataset: its rectified left camera's height and tilt."""
    return ground_from_mount(dataset.mount, R_rect_from_cam=dataset.calibration.left.R)


# ------------------------------------------------------------------------------------ end to end

def test_ros2_bag_with_tf_maps_exactly_like_the_manifest(dataset, reference, tmp_path):
    bag = write_bag(tmp_path / "run2", dataset, ros1=False, odom=False, tf=True)
    assert bag_topics(bag)["/tf"] == "tf2_msgs/msg/TFMessage"
    export_bag(bag, tmp_path / "exported", **TOPICS, use_tf=True, camera_frame="stereo_link", progress=False,
               **_rig_options(dataset))
    manifest = read_manifest(tmp_path / "exported")
    assert [f.pose for f in manifest.frames] == [f.pose for f in dataset.frames]
    assert [f.pan_rad for f in manifest.frames] == [f.pan_rad for f in dataset.frames]
    run = build_map(manifest, progress=False)
    assert run.grid.n_updates == len(dataset.frames)
    assert _same(run.grid.log_odds, reference)


def test_ros1_bag_with_odometry_maps_like_the_manifest_subset(dataset, tmp_path):
    front = [0, 3]                                  # the frames looking ahead (pan 0): odometry gives no pan
    bag = write_bag(tmp_path / "run1.bag", dataset, ros1=True, odom=True, frames=front)
    subset = tmp_path / "subset.yaml"
    write_manifest(subset, calibration=str(dataset.calibration_path), mount=dataset.mount,
                   frames=[{"left": str(dataset.frames[k].left), "right": str(dataset.frames[k].right),
                            "pose": list(dataset.frames[k].pose)} for k in front])
    expected = build_map(subset, progress=False).grid.log_odds
    images = {k: TOPICS[k] for k in ("left_topic", "right_topic")}      # camera_info found beside the images
    export_bag(bag, tmp_path / "exported", **images, odom_topic="/odom", progress=False, **_rig_options(dataset))
    run = build_map(tmp_path / "exported", progress=False)
    assert _same(run.grid.log_odds, expected)


def test_mcap_compressed_bag_and_export_then_map(dataset, reference, tmp_path):
    bag = write_bag(tmp_path / "runmcap", dataset, ros1=False, storage="mcap", odom=False, tf=True,
                    compressed=True)
    out = tmp_path / "exported"
    result = export_bag(bag, out, **TOPICS, use_tf=True, camera_frame="stereo_link", progress=False,
                        **_rig_options(dataset))
    assert result.n_frames == 6 and result.pose_source == "tf map <- base_link"
    assert result.stamps_ns == tuple(T0_NS + k * DT_NS for k in range(6))
    data = yaml.safe_load((out / "manifest.yaml").read_text())
    assert data["calibration"] == "stereo.yaml" and data["source"]["left_topic"] == TOPICS["left_topic"]
    manifest = read_manifest(out)
    for a, b in zip(manifest.frames, dataset.frames):             # lossless PNG round trip
        assert np.array_equal(read_image(a.left), read_image(b.left))
    assert _same(build_map(out, progress=False).grid.log_odds, reference)


def test_cli_map_and_export_from_a_bag(dataset, reference, tmp_path, capsys):
    bag = write_bag(tmp_path / "cli.bag", dataset, ros1=True, odom=False, tf=True)
    common = ["--bag", str(bag), "--left-topic", TOPICS["left_topic"], "--right-topic", TOPICS["right_topic"],
              "--camera-info-topics", ",".join(TOPICS["camera_info_topics"]), "--tf", "--camera-frame",
              "stereo_link", "--height", str(_rig(dataset).height_m), "--tilt", str(_rig(dataset).tilt_rad)]
    assert entry(["map", *common, "-o", str(tmp_path / "m"), "--quiet"]) == 0
    assert _same(np.load(tmp_path / "m" / "log_odds.npy"), reference)
    assert entry(["export", *common, "-o", str(tmp_path / "ds"), "--quiet"]) == 0
    assert entry(["map", str(tmp_path / "ds"), "-o", str(tmp_path / "m2"), "--quiet"]) == 0
    assert _same(np.load(tmp_path / "m2" / "log_odds.npy"), reference)


def test_mount_is_estimated_when_not_given(synthetic_dataset, tmp_path):
    # camera_info carries no mount: the export has none and mapping estimates the floor (320x240 rig)
    data = read_manifest(synthetic_dataset(seed=2, n_frames=5, supersample=1))
    bag = write_bag(tmp_path / "est", data, ros1=False)
    result = export_bag(bag, tmp_path / "out", **TOPICS, odom_topic="/odom", progress=False)
    assert result.mount is None and result.mount_source.startswith("none")
    manifest = read_manifest(tmp_path / "out")
    assert manifest.mount is None
    mapper = StereoMapper(manifest.calibration, manifest.mount)
    with recording_source(manifest) as source:
        mapper.settle(iter(source))                     # the first frames until the floor is known
    mount, floor = mapper.mount, mapper.floor
    assert floor.confident and floor.method == "plane"
    assert floor.height_m == pytest.approx(_rig(data).height_m, abs=0.02)
    assert floor.tilt_rad == pytest.approx(_rig(data).tilt_rad, abs=0.02)
    # the mount is of the raw camera; turned into the rectified frame it is the estimated floor
    seen = ground_from_mount(mount, R_rect_from_cam=manifest.calibration.left.R)
    assert (seen.height_m, seen.tilt_rad, seen.roll_rad) == pytest.approx(
        (floor.height_m, floor.tilt_rad, floor.roll_rad), abs=1e-12)


# ------------------------------------------------------------------------------------- bad input

def test_bad_bag_input_gives_clear_errors(dataset, tmp_path, capsys):
    bag = write_bag(tmp_path / "bad", dataset, ros1=False, frames=[0, 1])
    with pytest.raises(FileNotFoundError, match="bag not found"):
        export_bag(tmp_path / "missing.bag", tmp_path / "o1", **TOPICS)
    with pytest.raises(ValueError, match="topic '/nope' is not in the bag; topics: .*/odom"):
        export_bag(bag, tmp_path / "o2", **{**TOPICS, "left_topic": "/nope"})
    with pytest.raises(ValueError, match="type sensor_msgs/msg/CameraInfo, expected"):
        export_bag(bag, tmp_path / "o3", **{**TOPICS, "left_topic": "/stereo/left/camera_info"})
    with pytest.raises(ValueError, match="no left/right image pairs within 0.001 s"):
        export_bag(bag, tmp_path / "o4", **TOPICS, sync_tolerance_s=0.001, progress=False)
    with pytest.raises(ValueError, match="TF requested but the bag has no /tf"):
        export_bag(bag, tmp_path / "o5", **TOPICS, use_tf=True)
    assert not any(p.name.startswith(("o", ".o")) for p in tmp_path.iterdir())      # nothing half-written
    (tmp_path / "corrupt.bag").write_text("hello")
    with pytest.raises(ValueError, match="cannot read bag .*corrupt.bag: File magic is invalid"):
        bag_topics(tmp_path / "corrupt.bag")
    (tmp_path / "notabag.txt").write_text("hello")
    code = entry(["export", "--bag", str(tmp_path / "notabag.txt"), "--left-topic", "/a", "--right-topic", "/b",
                  "-o", str(tmp_path / "o6")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "is not a bag" in err[0]
    code = entry(["map", "--bag", str(bag), "--left-topic", "/nope", "--right-topic", TOPICS["right_topic"],
                  "-o", str(tmp_path / "o7")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("mrstereo: error: left topic: topic '/nope'")


# ------------------------------------------------------------------------------------- unit parts

def test_pair_by_stamp_is_one_to_one_and_closest_first():
    left = [0, 100, 200, 300]
    right = [5, 96, 104, 390]
    assert pair_by_stamp(left, right, tolerance_ns=10) == [(0, 0), (1, 1)]   # 104 is farther from 100 than 96
    assert pair_by_stamp(left, right, tolerance_ns=100) == [(0, 0), (1, 1), (2, 2), (3, 3)]
    assert pair_by_stamp(left, [], tolerance_ns=10) == []


def test_odometry_interpolation_and_yaw_wrap():
    q = lambda yaw: (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))  # noqa: E731
    track = TransformTrack.from_samples([(1000, (1.0, 2.0, 0.0), q(3.0)), (0, (0.0, 0.0, 0.0), q(-3.0))])
    T = track.at(250)
    assert T[0, 3] == pytest.approx(0.25) and T[1, 3] == pytest.approx(0.5)
    # from -3.0 to 3.0 rad the short way goes through +-pi: a quarter of the 0.283 rad step
    expected = -3.0 - 0.25 * (2 * math.pi - 6.0)
    assert planar_from_T(T)[2] == pytest.approx(expected, abs=1e-9)
    assert planar_from_T(track.at(-50))[2] == pytest.approx(-3.0)          # held before the first sample
    assert track.at(5000)[0, 3] == 1.0                                     # and after the last


def test_tf_chain_composes_static_and_dynamic_edges():
    tree = TfTree()
    c, s = math.cos(math.pi / 2), math.sin(math.pi / 2)
    tree.add("map", "odom", 0, (10.0, 0.0, 0.0), (0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4)))
    tree.add("odom", "base_link", 0, (1.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
    tree.add("odom", "base_link", 100, (3.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
    T = tree.lookup("map", "base_link", 50)                 # base at x=2 in odom; odom turned 90 deg in map
    assert T[:2, 3] == pytest.approx([10.0, 2.0])
    assert planar_from_T(T)[2] == pytest.approx(math.pi / 2)
    assert (c, s) == pytest.approx((0.0, 1.0))
    with pytest.raises(ValueError, match="no chain from 'map' down to 'camera'"):
        tree.lookup("map", "camera", 0)


def test_image_messages_decode_to_opencv_layout():
    ts = typestore(False)
    m = Msgs(ts, False)
    rgb = np.zeros((3, 4, 3), np.uint8)
    rgb[..., 0] = 200                                      # red in RGB order
    padded = np.zeros((3, 16), np.uint8)
    padded[:, :12] = rgb.reshape(3, 12)                     # step 16 > width * 3
    msg = ts.types["sensor_msgs/msg/Image"](header=m.header(0, "c"), height=3, width=4, encoding="rgb8",
                                            is_bigendian=0, step=16, data=padded.ravel())
    bgr = image_from_message(msg, "sensor_msgs/msg/Image")
    assert bgr.shape == (3, 4, 3) and (bgr[..., 2] == 200).all() and (bgr[..., :2] == 0).all()
    msg16 = ts.types["sensor_msgs/msg/Image"](header=m.header(0, "c"), height=3, width=4, encoding="32FC1",
                                              is_bigendian=0, step=16, data=np.zeros(48, np.uint8))
    with pytest.raises(ValueError, match="encoding '32FC1' is not supported"):
        image_from_message(msg16, "sensor_msgs/msg/Image")
    gray = np.arange(12, dtype=np.uint8).reshape(3, 4)
    assert np.array_equal(image_from_message(m.image(gray, 0, "c", compressed=True),
                                             "sensor_msgs/msg/CompressedImage"), gray)


def test_camera_info_messages_round_trip_the_calibration(dataset):
    for ros1 in (True, False):
        m = Msgs(typestore(ros1), ros1)
        cal = dataset.calibration
        stereo = stereo_from_camera_info(m.camera_info(cal.left, 0, "l"), m.camera_info(cal.right, 0, "r"))
        for a, b in ((stereo.left, cal.left), (stereo.right, cal.right)):
            assert np.array_equal(a.P, b.P) and np.array_equal(a.R, b.R) and np.array_equal(a.camera.K, b.camera.K)
            assert (a.camera.k1, a.camera.k2) == (b.camera.k1, b.camera.k2)
        assert stereo.baseline_m == pytest.approx(cal.baseline_m)
    bad = m.camera_info(cal.left, 0, "l")
    bad.p[3] = 0.0
    with pytest.raises(ValueError, match="P\\[0,3\\]"):
        stereo_from_camera_info(bad, bad)
    assert camera_info_from_message(m.camera_info(cal.left, 0, "l")).camera.width == 160


# ------------------------------------------------------------------------------ camera mount from TF

@pytest.mark.parametrize("ros1", [True, False])
def test_mount_from_tf_chains_3d_frames_to_the_optical_frame(dataset, tmp_path, ros1):
    from mrstereo.camera.mount import CameraMount
    from mrstereo.transforms import R_BODY_FROM_OPTICAL, rotation_from_rpy

    def pose(xyz, rpy):
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = rotation_from_rpy(*rpy), xyz
        return T

    T_base_mast = pose((0.10, -0.05, 0.60), (0.02, -0.03, 0.2))           # base -> mast (3-D)
    T_mast_body = pose((0.05, 0.03, 0.30), (0.01, 0.25, -0.1))            # mast -> camera body
    T_body_opt = np.eye(4)
    T_body_opt[:3, :3] = R_BODY_FROM_OPTICAL                               # REP 103 optical frame
    path = tmp_path / ("tf.bag" if ros1 else "tf2")
    topics = {"/l/image_raw": "sensor_msgs/msg/Image", "/r/image_raw": "sensor_msgs/msg/Image",
              "/l/camera_info": "sensor_msgs/msg/CameraInfo", "/r/camera_info": "sensor_msgs/msg/CameraInfo",
              "/tf_static": "tf2_msgs/msg/TFMessage"}
    with BagWriter(path, ros1, topics) as bag:
        m = bag.msgs
        bag.put("/tf_static", m.tf_3d([("base_link", "mast", T_base_mast), ("mast", "cam_link", T_mast_body),
                                       ("cam_link", "cam_optical_frame", T_body_opt)], T0_NS), T0_NS)
        rec, cal = dataset.frames[0], dataset.calibration
        for k in range(2):
            t = T0_NS + k * DT_NS
            bag.put("/l/camera_info", m.camera_info(cal.left, t, "l"), t)
            bag.put("/r/camera_info", m.camera_info(cal.right, t, "r"), t)
            bag.put("/l/image_raw", m.image(read_image(rec.left), t, "l"), t)
            bag.put("/r/image_raw", m.image(read_image(rec.right), t, "r"), t)
    expected = T_base_mast @ T_mast_body @ T_body_opt
    for frame in ("cam_optical_frame", "cam_link"):          # the optical frame, or the body frame it derives from
        out = tmp_path / f"out_{frame}"
        result = export_bag(path, out, left_topic="/l/image_raw", right_topic="/r/image_raw", camera_frame=frame,
                            progress=False)
        assert isinstance(result.mount, CameraMount) and result.mount_source == f"tf base_link <- {frame}"
        np.testing.assert_allclose(result.mount.T_base_from_cam, expected, atol=1e-9)
        manifest = read_manifest(out)
        np.testing.assert_allclose(manifest.mount.T_base_from_cam, expected, atol=1e-9)   # via mount: xyz, rpy
        assert [f.pan_rad for f in manifest.frames] == [0.0, 0.0]


def test_mount_from_tf_of_a_panning_head_is_the_rig_and_the_pans(dataset, tmp_path):
    # the synthetic rig as TF: base_link -> stereo_link (pan) -> left_optical (height, tilt)
    from mrstereo.camera.mount import CameraMount

    bag = write_bag(tmp_path / "pan", dataset, ros1=False, odom=False, tf=True)
    # stereo_link is a body frame on the floor: its mount is (0, 0, 0) and the rig's height and tilt are lost,
    # so a real robot publishes the optical frame; here the body frame's heading gives the pan
    result = export_bag(bag, tmp_path / "o", **TOPICS, use_tf=True, camera_frame="stereo_link", progress=False)
    assert isinstance(result.mount, CameraMount) and result.mount.xyz == (0.0, 0.0, 0.0)
    manifest = read_manifest(tmp_path / "o")
    first = dataset.frames[0].pan_rad
    assert [f.pan_rad for f in manifest.frames] == pytest.approx([f.pan_rad - first for f in dataset.frames],
                                                                 abs=1e-9)
