"""``--truth FILE`` and ``--no-truth`` on every recording reader: a broken ground-truth file no longer stops a
EuRoC folder, a TUM or EuRoC csv file of one's own gives the poses (matched by stamp, in the frame the
recording's own truth is of), and a bad file is one line naming it."""
from __future__ import annotations

import shutil

import numpy as np
import pytest

from mrstereo.cli import entry
from mrstereo.recordings.bag import BagSource
from mrstereo.recordings.layouts import read_recording
from mrstereo.recordings.manifest import read_manifest
from mrstereo.recordings.samples import data_root
from mrstereo.recordings.truth import read_poses_file
from mrstereo.transforms import T_from_position_quaternion, quaternion_from_rotation

from _bags import DT_NS, T0_NS, write_bag


def _tum(path, stamps_s, T):
    lines = []
    for t, T_k in zip(stamps_s, T):
        q = quaternion_from_rotation(T_k[:3, :3])
        lines.append(f"{t:.9f} " + " ".join(f"{v:.9f}" for v in (*T_k[:3, 3], *q)))
    path.write_text("# t x y z qx qy qz qw\n" + "\n".join(lines) + "\n")
    return path


def _random_poses(n, seed=3):
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    return np.stack([T_from_position_quaternion(rng.uniform(-5, 5, 3), qk / np.linalg.norm(qk)) for qk in q])


@pytest.fixture()
def euroc(tmp_path):
    source = data_root() / "euroc_asl_sample"
    if not (source / "mav0" / "cam0" / "data.csv").is_file():
        pytest.skip(f"EuRoC sample not found under {source} (set MRSTEREO_DATA)")
    root = tmp_path / "euroc"
    shutil.copytree(source, root)
    return root


def _euroc_stamps_ns(root):
    return np.loadtxt(root / "mav0" / "cam0" / "data.csv", delimiter=",", usecols=0, dtype=np.int64)


def test_tum_and_euroc_csv_give_the_same_poses_and_a_bad_line_is_named(tmp_path):
    T = _random_poses(6)
    stamps_ns = 1403715273262142976 + np.arange(6, dtype=np.int64) * 50_000_000
    _tum(tmp_path / "a.tum", stamps_ns / 1e9, T)
    rows = []
    for t, T_k in zip(stamps_ns, T):
        x, y, z, w = quaternion_from_rotation(T_k[:3, :3])
        rows.append(f"{t},{T_k[0, 3]:.9f},{T_k[1, 3]:.9f},{T_k[2, 3]:.9f},{w:.9f},{x:.9f},{y:.9f},{z:.9f},0,0,0")
    (tmp_path / "b.csv").write_text("#timestamp, p_RS_R_x [m], ...\n" + "\n".join(rows[::-1]) + "\n")
    (s_tum, T_tum), (s_csv, T_csv) = read_poses_file(tmp_path / "a.tum"), read_poses_file(tmp_path / "b.csv")
    assert np.abs(s_csv - stamps_ns).max() == 0 and np.abs(s_tum - stamps_ns).max() < 1000      # (ns; sorted)
    assert np.allclose(T_tum, T, atol=1e-8) and np.allclose(T_csv, T, atol=1e-8)
    (tmp_path / "bad.tum").write_text("0.0 1 2 3 0 0 0 1\n0.1 1 2 3 0 0 0\n")
    with pytest.raises(ValueError, match=r"bad.tum line 2: expected 't x y z qx qy qz qw'"):
        read_poses_file(tmp_path / "bad.tum")
    (tmp_path / "zero.tum").write_text("0.0 1 2 3 0 0 0 0\n")
    with pytest.raises(ValueError, match="zero.tum line 1"):
        read_poses_file(tmp_path / "zero.tum")
    (tmp_path / "empty.csv").write_text("#timestamp\n")
    with pytest.raises(ValueError, match="empty.csv holds no pose"):
        read_poses_file(tmp_path / "empty.csv")


def test_a_broken_euroc_truth_stops_the_folder_unless_no_truth(euroc, tmp_path, capsys):
    (euroc / "mav0" / "state_groundtruth_estimate0").mkdir()
    (euroc / "mav0" / "state_groundtruth_estimate0" / "data.csv").write_text("#timestamp,p_x\n")
    assert entry(["info", str(euroc)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "holds no pose" in err and "--no-truth" in err
    assert entry(["info", str(euroc), "--no-truth"]) == 0
    out = capsys.readouterr().out
    assert "truth:            none" in out and "ground truth not read (--no-truth)" in out
    manifest = read_recording(euroc, truth=False)
    assert not manifest.has_poses and len(manifest.frames) == 5
    assert entry(["odometry", str(euroc), "-o", str(tmp_path / "vo.txt"), "--no-truth", "--quiet"]) == 0
    assert len(np.loadtxt(tmp_path / "vo.txt")) == 5
    assert entry(["map", str(euroc), "-o", str(tmp_path / "map"), "--no-truth", "--quiet"]) == 0
    assert (tmp_path / "map" / "map.yaml").is_file()
    capsys.readouterr()
    assert entry(["map", str(euroc), "-o", str(tmp_path / "m2"), "--no-truth", "--truth", str(tmp_path / "vo.txt")]) == 2
    assert "give --truth FILE or --no-truth, not both" in capsys.readouterr().err


def test_a_truth_file_gives_the_euroc_body_poses_matched_by_stamp(euroc, tmp_path, capsys):
    stamps_ns = _euroc_stamps_ns(euroc)
    T = _random_poses(len(stamps_ns), seed=5)
    offsets_ns = np.array([0, 5_000_000, -19_000_000, 0, 30_000_000])     # the last beyond 20 ms: no pose
    tum = _tum(tmp_path / "body.tum", (stamps_ns + offsets_ns) / 1e9, T)
    manifest = read_recording(euroc, truth=tum)
    assert manifest.has_poses and len(manifest.frames) == 4
    for f, T_k in zip(manifest.frames, T[:4]):
        assert np.allclose(f.T_world_from_base, T_k, atol=1e-7) and np.allclose(f.T_world_from_base_true, T_k,
                                                                                   atol=1e-7)
    T_BS = np.array([[0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975],
                     [0.999557249008, 0.0149672133247, 0.025715529948, -0.064676986768],
                     [-0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949], [0, 0, 0, 1]])
    assert np.allclose(manifest.pose_frame_mount.T_base_from_cam, T_BS, atol=1e-9)    # cam0's T_BS: the body frame
    assert "4 of 5 frames got a pose within 20 ms, 1 left out" in " ".join(manifest.notes)
    # the same file as the folder's own truth gives the same poses
    own = euroc / "mav0" / "state_groundtruth_estimate0"
    own.mkdir()
    rows = [f"{t},{T_k[0, 3]:.9f},{T_k[1, 3]:.9f},{T_k[2, 3]:.9f}," +
            ",".join(f"{v:.9f}" for v in np.roll(quaternion_from_rotation(T_k[:3, :3]), 1))
            for t, T_k in zip(stamps_ns, T)]
    (own / "data.csv").write_text("\n".join(rows) + "\n")
    read_own, read_given = read_recording(euroc), read_recording(euroc, truth=own / "data.csv")
    assert len(read_own.frames) == len(read_given.frames) == 5
    for a, b in zip(read_own.frames, read_given.frames):
        assert np.allclose(a.T_world_from_base, b.T_world_from_base, atol=1e-9)
    assert entry(["info", str(euroc), "--truth", str(tum)]) == 0
    assert "4 of 5 frames got a pose" in capsys.readouterr().out
    far = _tum(tmp_path / "far.tum", (stamps_ns + 10**9) / 1e9, T)
    assert entry(["info", str(euroc), "--truth", str(far)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "far.tum: no pose within 20 ms of any of the 5 frames" in err


@pytest.mark.parametrize("layout", ["KITTI odometry", "KITTI raw"])
def test_a_tum_file_of_the_left_camera_gives_kitti_its_own_truth(layout, tmp_path):
    """The recording's own truth written as a TUM file of the left camera (in the first camera's frame, as
    KITTI's poses/NN.txt) and read back with --truth: the same base poses."""
    path = data_root() / ("kitti_odometry_06" if layout == "KITTI odometry" else "kitti_raw_sample/2011_09_26")
    if not path.is_dir():
        pytest.skip(f"{layout} sample not found under {path} (set MRSTEREO_DATA)")
    own = read_recording(path)
    assert own.layout == layout and own.has_poses
    M = own.mount.T_base_from_cam
    T_cam = [np.linalg.inv(M) @ f.T_world_from_base @ M for f in own.frames]
    tum = _tum(tmp_path / "cam0.tum", own.stamps_s, T_cam)
    given = read_recording(path, truth=tum)
    assert len(given.frames) == len(own.frames)
    for a, b in zip(own.frames, given.frames):
        assert np.allclose(a.T_world_from_base, b.T_world_from_base, atol=1e-6)
        assert np.allclose(b.T_world_from_base_true, b.T_world_from_base)
    none = read_recording(path, truth=False)
    assert not none.has_poses and all(f.true_pose_3d is None for f in none.frames)


def test_a_bag_reads_no_odometry_or_a_truth_file(synthetic_dataset, tmp_path, capsys):
    dataset = read_manifest(synthetic_dataset(seed=4, n_frames=6, width=160, height=120, supersample=1))
    bag = write_bag(tmp_path / "run", dataset, ros1=False, odom=True)
    with BagSource(bag) as source:
        assert source.has_poses and source.pose_source == "odometry /odom"
    with BagSource(bag, truth=False) as source:
        assert not source.has_poses and np.allclose(source.poses, [(0, 0, 0, 0, 0, 0, 1)] * 6)
    T = _random_poses(5, seed=9)
    tum = _tum(tmp_path / "base.tum", (T0_NS + np.arange(5) * DT_NS) / 1e9, T)   # no pose for the 6th frame
    with BagSource(bag, truth=tum) as source:
        assert source.has_poses and source.n_frames == 5 and len(list(source)) == 5
        assert np.allclose(source.true_poses, T, atol=1e-7)
        frames = list(source)
        assert np.allclose([f.T_world_from_base for f in frames], T, atol=1e-7)
    assert entry(["info", str(bag), "--no-truth"]) == 0
    assert "poses from:       none (--no-truth" in capsys.readouterr().out
    dataset_none = read_recording(dataset.root, truth=False)
    assert not dataset_none.has_poses and all(f.pose == (0.0, 0.0, 0.0) for f in dataset_none.frames)
