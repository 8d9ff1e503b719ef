"""Dataset manifest: synthetic dataset round trip and validation of bad manifests."""
from __future__ import annotations

import dataclasses
import math
import shutil

import numpy as np
import pytest
import yaml

from mrstereo.io import read_image, read_pfm
from mrstereo.mapping.rosmap import read_ros_map
from mrstereo.recordings.manifest import read_manifest
from mrstereo.world import default_scene, default_stereo, render_stereo_frame
from mrstereo.world.dataset import corridor_path, write_synthetic_dataset


@pytest.fixture(scope="module")
def dataset(synthetic_dataset):
    return synthetic_dataset(seed=2, n_frames=4, width=96, height=72)


def test_round_trip(dataset):
    m = read_manifest(dataset)
    assert m.root == dataset.resolve()
    assert len(m.frames) == 4
    stereo = default_stereo(96, 72)
    assert m.calibration.baseline_m == pytest.approx(stereo.baseline_m)
    np.testing.assert_allclose(m.calibration.left.R, stereo.left.R, atol=1e-12)
    np.testing.assert_allclose(m.mount.T_base_from_cam, stereo.mount.T_base_from_cam, atol=1e-15)
    assert [f.pan_rad for f in m.frames] == pytest.approx([0.0, math.pi / 4, -math.pi / 4, 0.0])
    assert m.frames[0].pose == m.frames[2].pose != m.frames[3].pose
    # Files hold exactly what the renderer gives for that frame.
    k = 1
    frame = render_stereo_frame(default_scene(2), stereo, pose=m.frames[k].pose, pan_rad=m.frames[k].pan_rad,
                                seed=2 * 100003 + k)
    np.testing.assert_array_equal(read_image(m.frames[k].left), frame.raw_left)
    np.testing.assert_array_equal(read_image(m.frames[k].right_rect), frame.right_rect)
    np.testing.assert_array_equal(read_image(m.frames[k].gt_labels), frame.labels)
    np.testing.assert_array_equal(read_pfm(m.frames[k].gt_disparity), frame.disparity_px)
    gt = read_ros_map(m.ground_truth_map)
    assert gt.occupancy.shape == (120, 240)


def test_refuses_non_empty_output(dataset):
    with pytest.raises(ValueError, match="not empty"):
        write_synthetic_dataset(dataset, n_frames=1, width=64, height=48, progress=False)


def test_corridor_path_avoids_obstacles():
    poses = corridor_path(40)
    x, y = poses[:, 0], poses[:, 1]
    assert np.all(~((x > 5.9) & (x < 6.5) & (np.abs(y) < 0.35)))   # around the middle box
    assert poses[0].tolist() == [0.0, 0.0, 0.0]


def _write(root, data):
    path = root / "manifest.yaml"
    path.write_text(yaml.safe_dump(data) if not isinstance(data, str) else data)
    return path


@pytest.fixture()
def copy(dataset, tmp_path):
    dst = tmp_path / "copy"
    shutil.copytree(dataset, dst)
    return dst, yaml.safe_load((dst / "manifest.yaml").read_text())


def test_rectified_only_frame_is_fine(copy):
    root, data = copy
    data["frames"] = [{"left_rect": data["frames"][0]["left_rect"], "right_rect": data["frames"][0]["right_rect"],
                       "pose": [0, 0, 0]}]
    del data["ground_truth_map"]
    m = read_manifest(_write(root, data))
    assert m.frames[0].left is None and m.frames[0].has_rectified and m.ground_truth_map is None


@pytest.mark.parametrize("mutate, error, match", [
    (lambda d: d.update(frames=[]), ValueError, "non-empty list"),
    (lambda d: d["frames"][1].update(pose=[1.0, 2.0]), ValueError, "frame 1: pose"),
    (lambda d: d["frames"][0].update(pose=[1.0, float("nan"), 0.0]), ValueError, "frame 0: pose"),
    (lambda d: d["frames"][0].update(pan_rad="left"), ValueError, "frame 0: pan_rad"),
    (lambda d: [d["frames"][2].pop(k) for k in ("left", "right", "left_rect", "right_rect")], ValueError,
     "frame 2: needs a raw pair"),
    (lambda d: d["frames"][0].pop("right"), ValueError, "'left' and 'right' must be given together"),
    (lambda d: d["frames"][3].update(left="left/missing.png"), FileNotFoundError, "frame 3: left not found"),
    (lambda d: d.update(calibration="nope.yaml"), FileNotFoundError, "calibration not found"),
    (lambda d: d.pop("calibration"), ValueError, "missing 'calibration"),
    (lambda d: (d.pop("mount"), d.update(rig={"tilt_rad": 0.1})), ValueError, "'rig' needs height_m"),
    (lambda d: d.update(rig={"height_m": 0.45}), ValueError, "'mount:' or 'rig:', not both"),
    (lambda d: d["frames"][0].update(colour="red"), ValueError, "unknown field"),
])
def test_bad_manifests(copy, mutate, error, match):
    root, data = copy
    mutate(data)
    with pytest.raises(error, match=match):
        read_manifest(_write(root, data))


def test_missing_and_corrupt_manifest(tmp_path):
    with pytest.raises(FileNotFoundError, match="manifest not found"):
        read_manifest(tmp_path)
    with pytest.raises(ValueError, match="not valid YAML"):
        read_manifest(_write(tmp_path, "frames: [\n  - {left: a.png\n"))
    with pytest.raises(ValueError, match="expected a mapping"):
        read_manifest(_write(tmp_path, "- just\n- a list\n"))


def test_staged_dataset_writes_a_whole_dataset_or_nothing(tmp_path):
    from mrstereo.io import read_disparity
    from mrstereo.recordings.manifest import staged_dataset

    stereo, image = default_stereo(64, 48), np.arange(48 * 64, dtype=np.uint8).reshape(48, 64)
    with pytest.raises(RuntimeError, match="killed"):
        with staged_dataset(tmp_path / "bad", calibration=stereo, mount=stereo.mount) as dataset:
            dataset.write("left", 0, image)
            raise RuntimeError("killed")
    assert list(tmp_path.iterdir()) == []                      # no dataset, no temporary folder
    stereo = dataclasses.replace(stereo, mount=None)
    with staged_dataset(tmp_path / "ok", calibration=stereo, mount=None, extra={"note": "x"}) as dataset:
        for k in range(2):
            dataset.write("left_rect", k, image)
            dataset.write("right_rect", k, image[:, ::-1])
            dataset.write("gt_disparity", k, np.full((48, 64), 2.5 + k, np.float32))
            dataset.add_frame(k, pose=(0.5 * k, 0.0, 0.1), pan_rad=0.2)
        with pytest.raises(ValueError, match="key must be one of"):
            dataset.write("depth", 0, image)
    m = read_manifest(tmp_path / "ok")
    assert m.mount is None and [f.pose for f in m.frames] == [(0.0, 0.0, 0.1), (0.5, 0.0, 0.1)]
    assert m.frames[1].pan_rad == 0.2 and m.frames[1].left is None
    np.testing.assert_array_equal(read_image(m.frames[1].right_rect), image[:, ::-1])
    assert np.all(read_disparity(m.frames[1].gt_disparity) == 3.5)
    assert m.calibration.left.R.tolist() == stereo.left.R.tolist()
    assert yaml.safe_load((tmp_path / "ok" / "manifest.yaml").read_text())["note"] == "x"
    with pytest.raises(ValueError, match="not empty"):
        with staged_dataset(tmp_path / "ok", calibration=stereo, mount=None):
            pass
