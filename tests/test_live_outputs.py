"""What a run sends besides its map files: the ROS 2 bag read back with rosbags, the viewers' files read back
with their own readers (Rerun's .rrd, Foxglove's MCAP), their servers answering on localhost, the same from
`map` and `odometry`, and the one-line error without the ``viz`` extra."""
from __future__ import annotations

import base64
import json
import os
import socket
import struct
import sys
import urllib.request

import numpy as np
import pytest

from mrstereo.cli import entry
from mrstereo.mapping import GridSpec, read_ros_map
from mrstereo.mapping.rosmap import occupancy_values
from mrstereo.odometry.trajectory import read_tum
from mrstereo.pipeline.live import LiveConfig, run_live
from mrstereo.pipeline.run import PipelineConfig
from mrstereo.recordings import read_recording
from mrstereo.recordings.bag_writer import BAG_TOPICS, LATCHED_TOPICS
from mrstereo.recordings.sources import RecordingSource

CONFIG = PipelineConfig(grid=GridSpec())        # the map on the paper's 12 m x 6 m corridor region
VIZ = "the viewer packages are the optional extra viz: pip install -e \".[viz]\""


def _need(module: str) -> None:
    pytest.importorskip(module, reason=f"{module} not installed ({VIZ})")


@pytest.fixture(scope="module")
def dataset(synthetic_dataset):
    """A rendered s-curve drive: 10 frames, 320x240 (shared: read it, never change it)."""
    return synthetic_dataset(n_frames=10, supersample=1, path="s-curve", step_m=0.1)


class _Kept:
    """A sink keeping what the loop sent (its scans, points, poses), to compare the files with."""

    def __init__(self) -> None:
        self.frames = []

    def frame(self, frame) -> None:
        self.frames.append((frame.index, frame.stamp_s, frame.T_world_from_base.copy(),
                            frame.scan.ranges_m.copy(), frame.obstacle_points_robot.copy()))

    def close(self) -> None:
        pass

    def discard(self) -> None:
        pass


def read_bag(path) -> dict[str, list]:
    """Every message of a ROS 2 bag by topic, deserialised with rosbags' own type store."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    out: dict[str, list] = {}
    with Reader(path) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        assert types == {t: BAG_TOPICS[t] for t in types}
        latched = {c.topic for c in reader.connections
                   if any(q.durability.name == "TRANSIENT_LOCAL" for q in c.ext.offered_qos_profiles)}
        assert latched == set(LATCHED_TOPICS) & set(types)
        for conn, stamp_ns, raw in reader.messages():
            out.setdefault(conn.topic, []).append((stamp_ns, store.deserialize_cdr(raw, conn.msgtype)))
    assert set(out) == set(types), "every topic in the bag carries messages"
    return out


def nav2_static_layer(grid_msg) -> np.ndarray:
    """Costs Nav2's static layer gives a nav_msgs/OccupancyGrid with its defaults (trinary_costmap true,
    lethal_cost_threshold 100, unknown_cost_value -1, track_unknown_space true): 254 lethal, 255 no
    information, 0 free (nav2_costmap_2d StaticLayer::interpretValue)."""
    values = np.asarray(grid_msg.data, dtype=np.int8).reshape(grid_msg.info.height, grid_msg.info.width)
    return np.where(values == -1, 255, np.where(values >= 100, 254, 0)).astype(np.uint8)


def _T(position, orientation) -> np.ndarray:
    from mrstereo.transforms import T_from_position_quaternion

    return T_from_position_quaternion([position.x, position.y, position.z],
                                      [orientation.x, orientation.y, orientation.z, orientation.w])


def check_bag(bag: dict, stamps_s, T_world_from_base, final_map=None) -> None:
    """The bag's poses, frames and map against the run's (``final_map``: ``(values, GridSpec)`` of the map,
    or a map_server map to agree with)."""
    n = len(stamps_s)
    odom, tf = bag["/odom"], bag["/tf"]
    assert len(odom) == len(tf) == n
    for (stamp_ns, msg), (_, tf_msg), stamp, T in zip(odom, tf, stamps_s, T_world_from_base):
        assert stamp_ns == round(stamp * 1e9)
        assert msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec == pytest.approx(stamp, abs=1e-9)
        assert (msg.header.frame_id, msg.child_frame_id) == ("odom", "base_link")        # REP 105
        np.testing.assert_allclose(_T(msg.pose.pose.position, msg.pose.pose.orientation), T, atol=1e-6)
        (transform,) = tf_msg.transforms
        assert (transform.header.frame_id, transform.child_frame_id) == ("odom", "base_link")
        np.testing.assert_allclose(_T(transform.transform.translation, transform.transform.rotation), T, atol=1e-6)
    (_, static), = bag["/tf_static"]
    assert [(t.header.frame_id, t.child_frame_id) for t in static.transforms] == \
        [("map", "odom"), ("base_link", "camera_left_optical_frame")]
    camera = _T(static.transforms[1].transform.translation, static.transforms[1].transform.rotation)
    np.testing.assert_allclose(camera[:3, :3] @ [0, 0, 1], [1, 0, 0], atol=0.2)     # optical z looks forward
    if final_map is not None:
        _, grid = bag["/map"][-1]
        assert grid.header.frame_id == "map"
        info = grid.info
        values = np.asarray(grid.data, dtype=np.int8).reshape(info.height, info.width)
        if isinstance(final_map, tuple):
            expected, g = final_map
            np.testing.assert_array_equal(values, expected)
        else:
            same_map(values, final_map)
            g = final_map.grid
        assert info.resolution == pytest.approx(g.resolution_m)
        assert (info.origin.position.x, info.origin.position.y) == pytest.approx((g.origin_x_m, g.origin_y_m))


def same_map(values: np.ndarray, ros_map) -> None:
    """Trinary OccupancyGrid values (-1, 0, 100) tell what a map_server map does: unknown, free, occupied."""
    assert set(np.unique(values)) <= {-1, 0, 100}
    np.testing.assert_array_equal(values == -1, ros_map.unknown)
    np.testing.assert_array_equal(values == 100, ros_map.occupied)
    np.testing.assert_array_equal(values == 0, ros_map.free)


def rrd_rows(path) -> dict[str, list]:
    """Rows of a Rerun recording by entity path: ``{entity: [record batch, ...]}``, read with rerun's reader."""
    from rerun.chunk import RrdReader

    rows: dict[str, list] = {}
    for chunk in RrdReader(str(path)).store().stream().to_chunks():
        rows.setdefault(chunk.entity_path, []).append(chunk.to_record_batch())
    return rows


def rrd_column(rows: dict, entity: str, column: str) -> tuple[list, list]:
    """``(frame indices, values)`` of a column of an entity, in frame order."""
    pairs = []
    for batch in rows[entity]:
        if column in batch.schema.names:
            pairs += zip(batch.column("frame").to_pylist(), batch.column(column).to_pylist())
    pairs.sort(key=lambda p: p[0])
    return [p[0] for p in pairs], [p[1] for p in pairs]


def mcap_messages(path) -> dict[str, list]:
    """Every message of a Foxglove MCAP file by topic: ``(schema name, decoded protobuf)``."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    out: dict[str, list] = {}
    with open(path, "rb") as fh:
        for schema, channel, _, proto in make_reader(fh, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            out.setdefault(channel.topic, []).append((schema.name, proto))
    return out


# ----------------------------------------------------------------------------- the live loop
def test_a_live_run_to_a_bag_and_both_viewers_files(dataset, tmp_path):
    for module in ("rerun", "foxglove", "mcap_protobuf"):
        _need(module)
    from mrstereo.pipeline.sinks import open_sinks

    manifest = read_recording(dataset)
    kept = _Kept()
    sinks = open_sinks(manifest.calibration, tmp_path / "out" / "view", viewers=("rerun", "foxglove"),
                       record_bag=tmp_path / "bag", rerun_mode="none", foxglove_port=None)
    with RecordingSource(manifest) as source:
        run = run_live(source, tmp_path / "out", config=CONFIG, live=LiveConfig(odometry="visual"),
                       sinks=[*sinks, kept])
    assert run.frames_mapped == 10 and len(kept.frames) == 10
    final = occupancy_values(run.grid.to_ros_map().occupancy)       # the bag's /map: trinary, as map.pgm
    percent = occupancy_values(run.grid.probability(), trinary=False)     # the viewers': probabilities
    stamps, T = read_tum(tmp_path / "out" / "trajectory.txt")
    np.testing.assert_allclose(T, run.T_world_from_base, atol=1e-6)

    # the ROS 2 bag: the run's poses, scans, points and map
    bag = read_bag(tmp_path / "bag")
    check_bag(bag, stamps, run.T_world_from_base, (final, CONFIG.grid))
    assert len(bag["/scan"]) == len(bag["/points"]) == 10
    for (_, scan), (_, cloud), (index, stamp, _, ranges, points) in zip(bag["/scan"], bag["/points"], kept.frames):
        assert scan.header.frame_id == cloud.header.frame_id == "base_link"
        np.testing.assert_array_equal(scan.ranges, ranges.astype(np.float32))
        assert np.isfinite(scan.ranges).sum() > 10
        xyz = np.frombuffer(np.asarray(cloud.data, np.uint8).tobytes(), np.float32).reshape(-1, 3)
        np.testing.assert_array_equal(xyz, points.astype(np.float32))
        assert (cloud.width, cloud.point_step, [f.name for f in cloud.fields]) == (len(points), 12, ["x", "y", "z"])

    # Rerun: the robot's path, images, disparities, scans on the frames' time line, the last map
    rows = rrd_rows(tmp_path / "out" / "view.rrd")
    frames, translations = rrd_column(rows, "/world/robot", "Transform3D:translation")
    assert frames == list(range(10))
    np.testing.assert_allclose(np.array(translations).reshape(10, 3), run.T_world_from_base[:, :3, 3], atol=1e-6)
    for entity in ("/world/robot/camera/image", "/world/robot/camera/disparity", "/world/robot/scan",
                   "/world/robot/points"):
        assert sum(b.num_rows for b in rows[entity]) == 10, entity
    _, grids = rrd_column(rows, "/world/map", "GridMap:data")
    values = np.frombuffer(bytes(np.concatenate(grids[-1]).astype(np.uint8)), np.int8)
    np.testing.assert_array_equal(values.reshape(percent.shape), percent)

    # Foxglove: its schemas, every frame, the last map
    fox = mcap_messages(tmp_path / "out" / "view.mcap")
    schemas = {topic: {s for s, _ in msgs} for topic, msgs in fox.items()}
    assert schemas["/scan"] == {"foxglove.LaserScan"} and schemas["/map"] == {"foxglove.Grid"}
    assert schemas["/camera/image"] == {"foxglove.RawImage"} and schemas["/points"] == {"foxglove.PointCloud"}
    for topic in ("/tf", "/odom", "/camera/image", "/camera/disparity", "/points", "/scan"):
        assert len(fox[topic]) == 10, topic
    for (_, odom), T in zip(fox["/odom"], run.T_world_from_base):
        np.testing.assert_allclose([odom.pose.position.x, odom.pose.position.y, odom.pose.position.z],
                                   T[:3, 3], atol=1e-9)
    _, grid = fox["/map"][-1]
    np.testing.assert_array_equal(np.frombuffer(grid.data, np.int8).reshape(percent.shape), percent)
    assert sorted(p.name for p in (tmp_path / "out").iterdir() if p.name.startswith(".")) == []   # no temporaries


def test_the_live_command_records_a_bag(dataset, tmp_path, capsys):
    out, bag = tmp_path / "out", tmp_path / "bag"
    code = entry(["live", str(dataset), "-o", str(out), "--record-bag", str(bag), "--size", "12,6", "--origin", "0,-3",
                  "--odometry", "visual", "--quiet"])
    assert code == 0, capsys.readouterr().err
    assert f"the bag to {bag}" in capsys.readouterr().out
    metrics = json.loads((out / "metrics.json").read_text())
    stamps, T = read_tum(out / "trajectory.txt")
    messages = read_bag(bag)
    assert len(messages["/scan"]) == metrics["frames_mapped"] == 10
    check_bag(messages, stamps, T, read_ros_map(out / "map.yaml"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bag", "out"]         # no temporary left
    assert sorted(p.name for p in bag.iterdir()) == ["bag.mcap", "metadata.yaml"]
    code = entry(["live", str(dataset), "-o", str(tmp_path / "again"), "--record-bag", str(bag), "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--record-bag" in err[0] and "exists" in err[0]


# ----------------------------------------------------------------------------- map and odometry
def test_map_and_odometry_send_their_runs_to_the_same_outputs(dataset, tmp_path, capsys):
    for module in ("rerun", "foxglove", "mcap_protobuf"):
        _need(module)
    out = tmp_path / "map"
    code = entry(["map", str(dataset), "-o", str(out), "--viewer", "rerun", "--viewer", "foxglove",
                  "--record-bag", str(tmp_path / "map_bag"), "--quiet"])
    assert code == 0, capsys.readouterr().err
    manifest = read_recording(dataset)
    T_given = np.stack([f.T_world_from_base for f in manifest.frames])
    stamps = [f.stamp_s for f in manifest.frames]
    bag = read_bag(tmp_path / "map_bag")
    check_bag(bag, stamps, T_given, read_ros_map(out / "map.yaml"))
    # Nav2's static layer with its defaults sees map.pgm's obstacles, free cells and unknown cells
    ros_map = read_ros_map(out / "map.yaml")
    costs = nav2_static_layer(bag["/map"][-1][1])
    assert ros_map.occupied.sum() > 20
    np.testing.assert_array_equal(costs == 254, ros_map.occupied)
    np.testing.assert_array_equal(costs == 255, ros_map.unknown)
    np.testing.assert_array_equal(costs == 0, ros_map.free)
    assert len(bag["/scan"]) == len(bag["/points"]) == 10
    rows = rrd_rows(out / "view.rrd")
    frames, translations = rrd_column(rows, "/world/robot", "Transform3D:translation")
    np.testing.assert_allclose(np.array(translations).reshape(-1, 3), T_given[:, :3, 3], atol=1e-6)
    from mrstereo.mapping.occupancy import probability_from_log_odds

    percent = occupancy_values(probability_from_log_odds(np.load(out / "log_odds.npy")), trinary=False)
    fox = mcap_messages(out / "view.mcap")           # viewers show the probabilities
    _, grid = fox["/map"][-1]
    np.testing.assert_array_equal(np.frombuffer(grid.data, np.int8).reshape(percent.shape), percent)

    traj = tmp_path / "odo" / "trajectory.txt"
    code = entry(["odometry", str(dataset), "-o", str(traj), "--record-bag", str(tmp_path / "odo_bag"),
                  "--viewer", "rerun", "--quiet"])
    assert code == 0, capsys.readouterr().err
    stamps, T = read_tum(traj)
    bag = read_bag(tmp_path / "odo_bag")
    check_bag(bag, stamps, T)
    assert set(bag) == {"/odom", "/tf", "/tf_static"}            # poses only: no empty topics
    frames, _ = rrd_column(rrd_rows(traj.with_suffix(".rrd")), "/world/robot", "Transform3D:translation")
    assert frames == list(range(10))


def test_a_replayed_map_run_shows_at_each_frame_the_map_fused_up_to_it(dataset):
    from mrstereo.mapping import fuse
    from mrstereo.mapping.sinks import replay_map_run
    from mrstereo.pipeline.run import build_map

    run = build_map(read_recording(dataset), config=CONFIG, progress=False)
    shown = []

    class Maps(_Kept):
        def frame(self, frame) -> None:
            shown.append(frame.grid.log_odds.copy())

    replay_map_run(run, [Maps()], config=CONFIG)
    assert len(shown) == len(run.observations) == 10
    np.testing.assert_array_equal(shown[-1], run.grid.log_odds)                 # the map as written
    for k in (0, 4, 8):                      # the robot's footprint swept along the path, as mapping.fuse does
        expected = fuse(run.observations[:k + 1], grid=run.grid.grid, config=CONFIG.mapping)
        np.testing.assert_array_equal(shown[k], expected.log_odds)


@pytest.mark.parametrize("stamp_s", [-1.0, 1e12, 2.2e9])
def test_a_stamp_a_bag_cannot_hold_is_one_error_and_no_bag(tmp_path, stamp_s):
    from mrstereo.recordings.bag_writer import BagWriter

    writer = BagWriter(tmp_path / "bag")
    writer.pose(int(1e9), np.eye(4))
    with pytest.raises(ValueError, match="--record-bag: a time stamp of .* cannot be written"):
        writer.pose(int(stamp_s * 1e9), np.eye(4))
    writer.discard()
    assert list(tmp_path.iterdir()) == []


def test_a_viewer_without_its_package_is_a_one_line_error(dataset, tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "rerun", None)            # as if rerun-sdk were not installed
    for command in (["live", str(dataset), "-o", str(tmp_path / "live")],
                    ["map", str(dataset), "-o", str(tmp_path / "map")]):
        code = entry([*command, "--viewer", "rerun", "--quiet"])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1, err
        assert err[0] == "mrstereo: error: --viewer rerun needs rerun-sdk: pip install \"mrstereo[viz]\""
    assert not (tmp_path / "live").exists() and not (tmp_path / "map").exists()     # checked before any work


# ----------------------------------------------------------------------------- servers on localhost
def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _listeners(port: int) -> list[str]:
    """Local addresses listening on ``port`` (``ss -ltn``)."""
    import subprocess

    lines = subprocess.run(["ss", "-Hltn", f"sport = :{port}"], capture_output=True, text=True).stdout.splitlines()
    return [line.split()[3].rsplit(":", 1)[0] for line in lines]


def test_rerun_serves_on_localhost_only_and_its_web_viewer_when_asked(tmp_path):
    _need("rerun")
    from mrstereo.viz.live import RerunLogger

    grpc = _free_port()
    logger = RerunLogger(rrd_path=tmp_path / "a.rrd", mode="serve", grpc_port=grpc)
    try:
        assert logger.url == f"rerun+http://127.0.0.1:{grpc}/proxy"
        assert _listeners(grpc) == ["127.0.0.1"]
        with pytest.raises(ValueError, match=f"--viewer-port: port {grpc} is in use"):   # a second run: one line
            RerunLogger(rrd_path=tmp_path / "b.rrd", mode="serve", grpc_port=grpc)
        assert sorted(p.name for p in tmp_path.iterdir()) == [".a.rrd.%d.tmp" % os.getpid()]   # nothing of b
    finally:
        logger.close()
    web, grpc = _free_port(), _free_port()
    logger = RerunLogger(rrd_path=tmp_path / "view.rrd", mode="web", web_port=web, grpc_port=grpc)
    try:
        assert logger.url == f"http://127.0.0.1:{web}/?url=rerun+http://127.0.0.1:{grpc}/proxy"
        with urllib.request.urlopen(f"http://127.0.0.1:{web}/", timeout=30) as reply:
            page = reply.read().decode("utf-8", "replace")
        assert reply.status == 200 and "rerun" in page.lower()
    finally:
        logger.close()
    assert (tmp_path / "view.rrd").is_file()


def test_a_rerun_viewer_that_went_away_leaves_one_warning_and_no_temporary(tmp_path):
    """rerun's flush fails when the spawned viewer was closed during the run: close() warns once, removes the
    possibly incomplete stream, and raises nothing (the run's map and trajectory stand)."""
    _need("rerun")
    from mrstereo.viz.live import RerunLogger

    logger = RerunLogger(rrd_path=tmp_path / "view.rrd", mode="serve", grpc_port=_free_port())
    real = logger.rec

    class Gone:                                      # the recording stream of a viewer that was closed
        def flush(self):
            raise RuntimeError("gRPC has been unable to connect for 8s\nmore detail")

        def disconnect(self):
            real.disconnect()

    logger.rec = Gone()
    with pytest.warns(UserWarning, match=r"viewer went away during the run \(gRPC has been unable to connect for 8s\)"):
        logger.close()
    assert list(tmp_path.iterdir()) == []           # no view.rrd, no .view.rrd.*.tmp


def test_live_refuses_a_busy_viewer_port_in_one_line_before_any_work(dataset, tmp_path, capsys):
    for module in ("rerun", "foxglove"):
        _need(module)
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = str(busy.getsockname()[1])
        for viewer, option in (("foxglove", "--foxglove-port"), ("rerun", "--viewer-port"),
                               ("rerun", "--viewer-web-port")):
            code = entry(["live", str(dataset), "-o", str(tmp_path / "out"), "--viewer", viewer, option, port,
                          "--quiet"])
            err = capsys.readouterr().err.strip().splitlines()
            assert code == 2 and len(err) == 1 and err[0].startswith(f"mrstereo: error: {option}: port {port} is in use")
            assert not (tmp_path / "out").exists()


def test_a_busy_foxglove_port_is_one_line_before_anything_starts(tmp_path):
    _need("foxglove")
    from mrstereo.viz.live import FoxgloveLogger

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        with pytest.raises(ValueError, match=f"--foxglove-port: port {port} is in use"):
            FoxgloveLogger(mcap_path=tmp_path / "v.mcap", port=port)
    assert list(tmp_path.iterdir()) == []


class _WebSocket:
    """The smallest websocket client (RFC 6455): what a Foxglove app does on connecting."""

    def __init__(self, port: int, protocol: str) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=10)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall(f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                          f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
                          f"Sec-WebSocket-Protocol: {protocol}\r\n\r\n".encode())
        self.buf = b""
        while b"\r\n\r\n" not in self.buf:
            self.buf += self.sock.recv(4096)
        head, self.buf = self.buf.split(b"\r\n\r\n", 1)
        self.head = head.decode()

    def _need(self, n: int) -> None:
        while len(self.buf) < n:
            self.buf += self.sock.recv(65536)

    def receive(self) -> tuple[int, bytes]:
        self._need(2)
        n, off = self.buf[1] & 0x7F, 2
        if n >= 126:
            off = 4 if n == 126 else 10
            self._need(off)
            n = int.from_bytes(self.buf[2:off], "big")
        self._need(off + n)
        opcode, payload, self.buf = self.buf[0] & 0x0F, self.buf[off:off + n], self.buf[off + n:]
        return opcode, payload

    def send_text(self, text: str) -> None:
        data, mask = text.encode(), os.urandom(4)
        size = bytes([0x80 | len(data)]) if len(data) < 126 else bytes([0x80 | 126]) + struct.pack(">H", len(data))
        self.sock.sendall(bytes([0x81]) + size + mask + bytes(b ^ mask[k % 4] for k, b in enumerate(data)))

    def close(self) -> None:
        self.sock.close()


def test_foxglove_streams_the_scan_to_a_client_on_localhost():
    for module in ("foxglove", "google.protobuf"):
        _need(module)
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    from mrstereo.viz.live import FoxgloveLogger

    logger = FoxgloveLogger(mcap_path=None, port=0)
    client = None
    try:
        client = _WebSocket(int(logger.url.rsplit(":", 1)[1]), "foxglove.sdk.v1")
        assert " 101 " in client.head.splitlines()[0]
        assert json.loads(client.receive()[1])["op"] == "serverInfo"
        ranges = np.array([1.5, np.inf, 2.25, np.nan, 3.0])
        logger.frame(stamp_s=2.5, index=0, T_world_from_base=np.eye(4), T_base_from_cam=np.eye(4),
                     scan=(-0.5, 0.5, ranges))
        channels = {}
        while "/scan" not in channels:
            op, payload = client.receive()
            message = json.loads(payload)
            if message["op"] == "advertise":
                channels.update({c["topic"]: c for c in message["channels"]})
        scan = channels["/scan"]
        assert (scan["schemaName"], scan["encoding"]) == ("foxglove.LaserScan", "protobuf")
        client.send_text(json.dumps({"op": "subscribe", "subscriptions": [{"id": 7, "channelId": scan["id"]}]}))
        client.sock.settimeout(0.5)
        payload = None
        for _ in range(60):             # the server takes the subscription in its own time: frames until one comes
            logger.frame(stamp_s=2.6, index=1, T_world_from_base=np.eye(4), T_base_from_cam=np.eye(4),
                         scan=(-0.5, 0.5, ranges))
            try:
                op, data = client.receive()
            except TimeoutError:
                continue
            if op == 2 and data[0] == 1 and struct.unpack("<I", data[1:5])[0] == 7:    # messageData
                payload = data
                break
        assert payload is not None, "no /scan message reached the subscribed client"
        files = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(scan["schema"]))
        pool = descriptor_pool.DescriptorPool()
        for f in files.file:
            pool.Add(f)
        message = message_factory.GetMessageClass(pool.FindMessageTypeByName("foxglove.LaserScan"))()
        message.ParseFromString(payload[13:])
        assert message.frame_id == "base_link" and (message.start_angle, message.end_angle) == (-0.5, 0.5)
        assert message.timestamp.seconds == 2 and message.timestamp.nanos == 600_000_000
        np.testing.assert_array_equal(np.isnan(message.ranges), ~np.isfinite(ranges))
        np.testing.assert_array_equal(np.array(message.ranges)[[0, 2, 4]], [1.5, 2.25, 3.0])
    finally:
        if client is not None:
            client.close()
        logger.close()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("display", [None, ":99"], ids=["served", "viewer-cannot-start"])
def test_rerun_writes_no_line_of_its_own_on_stderr(dataset, tmp_path, display):
    """Rerun's Rust logger (coloured lines) and a spawned viewer that cannot open its display ("Error:
    winit ...") stay off the command's stderr: only mrstereo's own lines, the latter one error naming
    --viewer rerun and no output."""
    import subprocess

    _need("rerun")
    env = {k: v for k, v in os.environ.items() if k not in ("RUST_LOG", "DISPLAY", "WAYLAND_DISPLAY")}
    if display is not None:
        env["DISPLAY"] = display                     # a display nobody serves: the viewer cannot start
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-m", "mrstereo", "live", str(dataset), "-o", str(out), "--viewer",
                          "rerun", "--viewer-port", str(_free_port()), "--quiet"], env=env, capture_output=True,
                         text=True, timeout=300)
    lines = [line for line in run.stderr.splitlines() if line.strip()]
    assert "\x1b" not in run.stderr, run.stderr
    assert all(line.startswith("mrstereo: ") for line in lines), run.stderr
    if display is None:
        assert run.returncode == 0, run.stderr
        assert (out / "view.rrd").stat().st_size > 0
    else:
        assert run.returncode == 2 and len(lines) == 1, run.stderr
        assert lines[0].startswith("mrstereo: error: --viewer rerun: the Rerun viewer did not start"), lines
        assert not any(p.is_file() for p in tmp_path.rglob("*")), sorted(tmp_path.rglob("*"))
        assert not out.exists()                      # not even an empty output folder
