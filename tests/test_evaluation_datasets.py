"""Scene readers: every layout on the public sample scenes (mrstereo.recordings.samples) and on synthetic mini-datasets."""

import cv2
import numpy as np
import pytest

from mrstereo.evaluation.datasets import load_scene, load_scenes, photometric_error, search_range_px
from mrstereo.io import write_image, write_kitti_disparity, write_pfm
from mrstereo.recordings.samples import local_path

# name, sample data, layout, (H, W), GT min, GT max, valid fraction, max disparity, has mask
REAL = [
    ("tsukuba", "tsukuba", "middlebury2001", (288, 384), 5.0, 14.0, 0.79, 16, True),
    ("venus", "venus", "middlebury2001", (383, 434), 3.0, 19.75, 1.00, 32, True),
    ("teddy", "teddy", "middlebury2003", (375, 450), 12.5, 52.75, 0.98, 64, True),
    ("cones", "cones", "middlebury2003", (375, 450), 5.5, 55.0, 0.97, 64, True),
    ("000070_10", "kitti2012-000070", "kitti2012", (376, 1241), 4.67, 147.02, 0.29, 160, True),
    ("000000_10", "kitti2015-000000", "kitti2015", (375, 1242), 4.62, 64.09, 0.19, 80, False),
]


@pytest.mark.parametrize("name, sample, layout, shape, lo, hi, valid, max_d, has_mask", REAL, ids=[r[0] for r in REAL])
def test_real_scene_matches_sources_md(sample_data, name, sample, layout, shape, lo, hi, valid, max_d, has_mask):
    scene = load_scene(sample_data(sample))
    gt = scene.gt_disparity_px
    assert scene.name == name and scene.layout == layout
    assert scene.shape == shape and scene.left.shape[:2] == shape and scene.right.shape[:2] == shape
    assert scene.left.dtype == np.uint8 and gt.dtype == np.float32
    assert np.nanmin(gt) == pytest.approx(lo, abs=0.01)
    assert np.nanmax(gt) == pytest.approx(hi, abs=0.01)
    assert np.isfinite(gt).mean() == pytest.approx(valid, abs=0.006)
    assert scene.max_disparity_px == max_d
    assert (scene.nonocc_mask is not None) == has_mask
    # The decoded scale is the right one: d warps the right view onto the left far better than d/2 or 2d.
    err = photometric_error(scene.left, scene.right, gt)
    assert err < 0.5 * photometric_error(scene.left, scene.right, 0.5 * gt)
    assert err < 0.5 * photometric_error(scene.left, scene.right, 2.0 * gt)


@pytest.mark.sample_data("tsukuba", "venus", "kitti2012-000070")
def test_middlebury_mask_fraction_and_kitti_noc_region():
    tsukuba = load_scene(local_path("tsukuba"))
    assert tsukuba.nonocc_mask.dtype == np.bool_
    assert tsukuba.nonocc_mask.mean() == pytest.approx(0.773, abs=0.003)
    # Venus GT is 100 % dense, the non-occluded mask removes occlusions and the border.
    assert load_scene(local_path("venus")).nonocc_mask.mean() == pytest.approx(0.887, abs=0.005)
    kitti = load_scene(local_path("kitti2012-000070"))
    noc = kitti.gt_disparity_px[kitti.nonocc_mask]
    assert np.isfinite(noc).all()
    assert noc.max() == pytest.approx(123.04, abs=0.01) and noc.min() == pytest.approx(4.67, abs=0.01)


# ----------------------------------------------------------------------------- synthetic layouts

def _pair(height, width, disparity_px, *, color=True, seed=0):
    """Left and right views of a fronto-parallel textured plane at integer disparity d."""
    rng = np.random.default_rng(seed)
    texture = cv2.GaussianBlur(rng.integers(0, 256, (height, width + disparity_px, 3)).astype(np.uint8), (3, 3), 0)
    left = texture[:, :width]  # left(x) = T(x), right(x) = T(x + d): left(x) = right(x - d)
    right = texture[:, disparity_px:disparity_px + width]
    if not color:
        left, right = left[:, :, 1], right[:, :, 1]
    return np.ascontiguousarray(left), np.ascontiguousarray(right)


def test_middlebury2005_third_and_half_size(tmp_path):
    for height, scale in ((370, 3), (555, 2)):
        folder = tmp_path / f"art{scale}"
        folder.mkdir()
        left, right = _pair(height, 40, 5)
        write_image(folder / "view1.png", left)
        write_image(folder / "view5.png", right)
        raw = np.full((height, 40), 5 * scale, np.uint8)
        raw[:3] = 0
        write_image(folder / "disp1.png", raw)
        scene = load_scene(folder)
        assert scene.layout == "middlebury2005" and scene.nonocc_mask is None
        assert np.isnan(scene.gt_disparity_px[:3]).all()
        assert np.nanmin(scene.gt_disparity_px) == np.nanmax(scene.gt_disparity_px) == 5.0
        assert scene.max_disparity_px == 16


def test_middlebury2005_full_size_dmin_offset_chosen_photometrically(tmp_path):
    left, right = _pair(1110, 48, 12)
    write_image(tmp_path / "view1.png", left)
    write_image(tmp_path / "view5.png", right)
    write_image(tmp_path / "disp1.png", np.full((1110, 48), 4, np.uint8))  # stored d - dmin
    (tmp_path / "dmin.txt").write_text("8\n")
    scene = load_scene(tmp_path)
    assert np.nanmax(scene.gt_disparity_px) == 12.0
    assert "dmin" in scene.gt_description


def test_middlebury2014_pfm_calib_and_mask(tmp_path):
    left, right = _pair(30, 50, 7)
    write_image(tmp_path / "im0.png", left)
    write_image(tmp_path / "im1.png", right)
    gt = np.full((30, 50), 7.25, np.float32)
    gt[0, :] = np.nan  # written as inf = unknown
    write_pfm(tmp_path / "disp0.pfm", gt)
    mask = np.full((30, 50), 255, np.uint8)
    mask[:, :10] = 128  # occluded
    write_image(tmp_path / "mask0nocc.png", mask)
    (tmp_path / "calib.txt").write_text("cam0=[1 0 1; 0 1 1; 0 0 1]\ndoffs=0\nbaseline=100\nwidth=50\n"
                                        "height=30\nndisp=40\n")
    scene = load_scene(tmp_path)
    assert scene.layout == "middlebury2014"
    assert np.isnan(scene.gt_disparity_px[0]).all() and scene.gt_disparity_px[5, 5] == np.float32(7.25)
    assert scene.max_disparity_px == 48  # ndisp 40 rounded up to a multiple of 16
    assert scene.nonocc_mask[:, :10].sum() == 0 and scene.nonocc_mask[:, 10:].all()


def test_kitti2015_noc_only_and_frame_choice(tmp_path):
    left, right = _pair(20, 60, 9)
    for sub, img in (("image_2", left), ("image_3", right)):
        (tmp_path / sub).mkdir()
        write_image(tmp_path / sub / "000007_10.png", img)
    (tmp_path / "disp_noc_0").mkdir()
    gt = np.full((20, 60), np.nan, np.float32)
    gt[5:15, 20:40] = 9.5
    write_kitti_disparity(tmp_path / "disp_noc_0" / "000007_10.png", gt)
    scene = load_scene(tmp_path)
    assert (scene.name, scene.layout) == ("000007_10", "kitti2015")
    assert scene.left.shape == (20, 60, 3)
    assert np.nanmax(scene.gt_disparity_px) == 9.5 and np.isfinite(scene.gt_disparity_px).sum() == 200
    assert scene.nonocc_mask.sum() == 200
    # A second frame makes the folder ambiguous unless frame= is given.
    write_kitti_disparity(tmp_path / "disp_noc_0" / "000008_10.png", gt)
    with pytest.raises(ValueError, match="expected one KITTI frame.*2 frames"):
        load_scene(tmp_path)
    assert load_scene(tmp_path, frame="000007_10").name == "000007_10"


def test_im2_im6_scale_from_photometry_when_size_is_not_2003(tmp_path):
    left, right = _pair(60, 80, 6, color=False)
    write_image(tmp_path / "im2.png", left)
    write_image(tmp_path / "im6.png", right)
    write_image(tmp_path / "disp2.png", np.full((60, 80), 48, np.uint8))  # 6 px at scale 8 (2001)
    scene = load_scene(tmp_path)
    assert scene.layout == "middlebury2001" and np.nanmax(scene.gt_disparity_px) == 6.0
    write_image(tmp_path / "disp2.png", np.full((60, 80), 24, np.uint8))  # 6 px at scale 4 (2003)
    scene = load_scene(tmp_path)
    assert scene.layout == "middlebury2003" and np.nanmax(scene.gt_disparity_px) == 6.0


def test_search_range_is_multiple_of_16_above_max():
    assert search_range_px(np.array([[14.0, np.nan]])) == 16
    assert search_range_px(np.array([[16.0]])) == 32
    assert search_range_px(np.array([[52.75]])) == 64


def test_bad_directories(tmp_path):
    with pytest.raises(FileNotFoundError, match="scene directory not found"):
        load_scene(tmp_path / "missing")
    with pytest.raises(ValueError, match=r"matches no known stereo dataset layout; expected .*view1\.png"):
        load_scene(tmp_path)
    (tmp_path / "f.txt").write_text("x")
    with pytest.raises(ValueError, match="must be a directory"):
        load_scene(tmp_path / "f.txt")
    left, right = _pair(30, 40, 3)
    write_image(tmp_path / "im0.png", left)
    write_image(tmp_path / "im1.png", right[:, :30])
    write_pfm(tmp_path / "disp0.pfm", np.ones((30, 40), np.float32))
    with pytest.raises(ValueError, match="differ in size"):
        load_scene(tmp_path)


def test_middlebury_v2_bundle_with_and_without_info(tmp_path):
    left, right = _pair(40, 70, 5)
    write_image(tmp_path / "imL.png", left)
    write_image(tmp_path / "imR.png", right)
    write_image(tmp_path / "groundtruth.png", np.full((40, 70), 80, np.uint8))  # 5 px at scale 16
    scene = load_scene(tmp_path)  # no info.txt: scale found photometrically
    assert scene.layout == "middlebury2001" and np.nanmax(scene.gt_disparity_px) == 5.0
    (tmp_path / "info.txt").write_text("16\n15")
    scene = load_scene(tmp_path)
    assert np.nanmax(scene.gt_disparity_px) == 5.0 and scene.max_disparity_px == 16
    assert "info.txt" in scene.gt_description
    (tmp_path / "info.txt").write_text("sixteen")
    with pytest.raises(ValueError, match="expected two numbers"):
        load_scene(tmp_path)


# ----------------------------------------------------------------------------- mrstereo datasets

@pytest.fixture(scope="module")
def synth_dataset(synthetic_dataset):
    """A 3-frame `mrstereo synth` dataset at 160x120, folder ``corridor1``."""
    return synthetic_dataset(seed=1, n_frames=3, width=160, height=120, supersample=1)


def test_mrstereo_dataset_frames_are_scenes_with_their_pfm_ground_truth(synth_dataset):
    from mrstereo.io import read_image, read_pfm
    from mrstereo.recordings.manifest import read_manifest

    scenes = load_scenes(synth_dataset)
    frames = read_manifest(synth_dataset).frames
    assert [s.name for s in scenes] == ["corridor1/000000", "corridor1/000001", "corridor1/000002"]
    for scene, record in zip(scenes, frames):
        assert scene.layout == "mrstereo" and scene.shape == (120, 160) and scene.nonocc_mask is None
        np.testing.assert_array_equal(scene.left, read_image(record.left_rect))
        np.testing.assert_array_equal(scene.right, read_image(record.right_rect))
        truth = read_pfm(record.gt_disparity)
        np.testing.assert_array_equal(np.isnan(scene.gt_disparity_px), ~np.isfinite(truth))
        assert scene.max_disparity_px == search_range_px(truth) and scene.max_disparity_px % 16 == 0
        # left/right and the disparity sign are right: d warps the right view onto the left
        err = photometric_error(scene.left, scene.right, scene.gt_disparity_px)
        assert err < 0.5 * photometric_error(scene.left, scene.right, 0.5 * scene.gt_disparity_px)
        assert err < 0.5 * photometric_error(scene.left, scene.right, -scene.gt_disparity_px)
    assert load_scene(synth_dataset, frame="000001").name == "corridor1/000001"
    with pytest.raises(ValueError, match="3 frames with ground truth .*pass frame="):
        load_scene(synth_dataset)
    with pytest.raises(ValueError, match="no frame '000009'"):
        load_scene(synth_dataset, frame="000009")


def test_mrstereo_dataset_raw_only_is_rectified_and_no_ground_truth_is_refused(synth_dataset, tmp_path):
    import shutil

    import yaml

    copy = tmp_path / "raw_only"
    shutil.copytree(synth_dataset, copy)
    manifest = yaml.safe_load((copy / "manifest.yaml").read_text())
    for frame in manifest["frames"]:
        frame.pop("left_rect"), frame.pop("right_rect")
    (copy / "manifest.yaml").write_text(yaml.safe_dump(manifest))
    scene = load_scenes(copy)[0]
    ideal = load_scenes(synth_dataset)[0]
    assert "rectified with the dataset's calibration" in scene.gt_description
    # rectified with the true calibration: the ground truth warps its right view onto its left as well
    err = photometric_error(scene.left, scene.right, scene.gt_disparity_px)
    assert err < 1.3 * photometric_error(ideal.left, ideal.right, ideal.gt_disparity_px)
    assert err < 0.5 * photometric_error(scene.left, scene.right, 0.5 * scene.gt_disparity_px)
    for frame in manifest["frames"]:
        frame.pop("gt_disparity")
    (copy / "manifest.yaml").write_text(yaml.safe_dump(manifest))
    with pytest.raises(ValueError, match="no frame with ground-truth disparity"):
        load_scenes(copy)
