"""Eq. (13) texture / ground suppression on hand-made images."""
import cv2
import numpy as np
import pytest

from mrstereo.rejection import FloorModel, RejectionConfig, learn_floor_model, patch_statistics, reject_uniform


def _scene(seed=0, h=60, w=90):
    """Left half: uniform floor (gray 120, noise 1); right half: strong random texture."""
    rng = np.random.default_rng(seed)
    img = 120 + rng.normal(0, 1.0, (h, w))
    img[:, w // 2:] = rng.uniform(0, 255, (h, w - w // 2))
    return np.clip(img, 0, 255).astype(np.uint8)


def test_patch_statistics_matches_brute_force_off_centre():
    rng = np.random.default_rng(1)
    img = rng.uniform(0, 255, (31, 47)).astype(np.float32)
    st = patch_statistics(img, window_px=5)
    for v, u in [(7, 12), (20, 33), (11, 40)]:       # off-centre probes, away from borders
        patch = img[v - 2:v + 3, u - 2:u + 3].astype(np.float64)
        assert st.mean[v, u] == pytest.approx(patch.mean(), abs=1e-3)
        assert st.std[v, u] == pytest.approx(patch.std(), abs=1e-3)
    assert st.mean.shape == img.shape and st.std.dtype == np.float32


def test_patch_statistics_of_constant_image_is_zero_std():
    st = patch_statistics(np.full((20, 30), 200, np.uint8), window_px=7)
    np.testing.assert_allclose(st.mean, 200.0, atol=1e-4)
    np.testing.assert_allclose(st.std, 0.0, atol=1e-3)


def test_reject_uniform_removes_only_the_uniform_half():
    img = _scene()
    d = np.full(img.shape, 7.5, np.float32)
    d[0, 0] = np.nan
    res = reject_uniform(d, img, config=RejectionConfig(window_px=7, texture_threshold=3.0))
    w = img.shape[1]
    assert np.isnan(res.disparity_px[:, : w // 2 - 4]).all()
    assert np.isfinite(res.disparity_px[:, w // 2 + 4:]).all()
    assert res.n_rejected == int(np.isnan(res.disparity_px).sum()) - 1   # the pre-existing NaN is not "rejected"
    assert not res.rejected[0, 0]
    assert np.isfinite(d).sum() == d.size - 1                              # input untouched


def test_threshold_zero_rejects_nothing_and_mean_range_limits_the_test():
    img = _scene()
    d = np.ones(img.shape, np.float32)
    assert reject_uniform(d, img, config=RejectionConfig(texture_threshold=0.0)).n_rejected == 0
    dark_only = RejectionConfig(texture_threshold=3.0, mean_range=(0.0, 100.0))   # floor is at 120
    assert reject_uniform(d, img, config=dark_only).n_rejected == 0
    around_floor = RejectionConfig(texture_threshold=3.0, mean_range=(110.0, 130.0))
    assert reject_uniform(d, img, config=around_floor).n_rejected > 0.4 * d.size


def test_learned_floor_model_rejects_floor_like_patches():
    ref = _scene(seed=2)
    floor = np.zeros(ref.shape, bool)
    floor[:, :40] = True
    model = learn_floor_model(ref, floor_mask=floor, window_px=7)
    assert model.mu_mean == pytest.approx(120.0, abs=1.0)
    assert 0.3 < model.sigma_mean < 1.5
    # A new frame: the floor is a bit brighter but within 3 sigma of the model (mu_std ~ 1/7);
    # a flat wall at 40 is not the floor.
    img = _scene(seed=3).astype(np.float32)
    img[:, :45] += 0.2
    img[:20, :45] = 40
    d = np.ones(img.shape, np.float32)
    cfg = RejectionConfig(window_px=7, texture_threshold=0.0, k_sigma=3.0)
    res = reject_uniform(d, img, config=cfg, floor_model=model)
    assert res.rejected[30:, 5:38].mean() > 0.95          # floor
    assert not res.rejected[:15, 5:38].any()               # uniform but much darker than the floor
    assert not res.rejected[:, 50:].any()                  # textured


def test_floor_model_adds_to_the_texture_test():
    img = _scene()
    d = np.ones(img.shape, np.float32)
    config = RejectionConfig(window_px=5, texture_threshold=3.0)
    only_texture = reject_uniform(d, img, config=config).uniform
    dark = FloorModel(mu_mean=0.0, mu_std=1.0, sigma_mean=0.0, sigma_std=0.1, window_px=5, n_patches=10)
    np.testing.assert_array_equal(only_texture, reject_uniform(d, img, config=config, floor_model=dark).uniform)
    textured = FloorModel(mu_mean=127.0, mu_std=20.0, sigma_mean=70.0, sigma_std=5.0, window_px=5, n_patches=10)
    both = reject_uniform(d, img, config=config, floor_model=textured)
    w = img.shape[1]
    assert both.uniform[:, : w // 2 - 3].all() and both.uniform[:, w // 2 + 3:].mean() > 0.5
    assert (both.uniform >= only_texture).all() and not only_texture[:, w // 2 + 3:].any()


def test_bad_input():
    img = _scene()
    with pytest.raises(ValueError, match="window_px must be odd"):
        RejectionConfig(window_px=8)
    with pytest.raises(ValueError, match="texture_threshold"):
        RejectionConfig(texture_threshold=-1.0)
    with pytest.raises(ValueError, match="mean_range"):
        RejectionConfig(mean_range=(5.0, 1.0))
    with pytest.raises(ValueError, match="same size"):
        reject_uniform(np.ones((10, 10)), img)
    with pytest.raises(ValueError, match=r"disparity_px must have shape \(H, W\)"):
        reject_uniform(np.ones((2, 3, 4)), img)
    with pytest.raises(TypeError, match="config must be a RejectionConfig"):
        reject_uniform(np.ones(img.shape), img, config={"window_px": 5})
    with pytest.raises(ValueError, match="floor_mask must have shape"):
        learn_floor_model(img, floor_mask=np.ones((3, 3), bool))
    with pytest.raises(ValueError, match="NaN or inf"):
        patch_statistics(np.full((5, 5), np.nan, np.float32))


@pytest.mark.parametrize("sigma", [0.5, 2.0, 4.0])
def test_row_texture_is_one_on_noise_along_the_rows_and_high_on_texture_across_them(sigma):
    """Stripes along the rows plus Gaussian noise: the noise estimate is the noise (within 10 %, the stripes'
    shading cancels) and the texture along the rows is the noise's alone (ratio 1 within 10 %); the same stripes
    across the rows give a ratio many times higher; a constant image has the quantization noise."""
    from mrstereo.rejection import image_noise_sigma, row_texture
    from mrstereo.rejection.texture import QUANTIZATION_SIGMA

    rng = np.random.default_rng(11)
    y, x = np.mgrid[0:240, 0:320]
    along = 128 + 40 * np.sin(y / 3.0) + rng.normal(0, sigma, y.shape)
    across = 128 + 40 * np.sin(x / 3.0) + rng.normal(0, sigma, y.shape)
    assert image_noise_sigma(along) == pytest.approx(sigma, rel=0.1)
    assert np.median(row_texture(along)) == pytest.approx(1.0, rel=0.1)
    assert np.percentile(row_texture(across), 5) > 4.0 * np.percentile(row_texture(along), 95)
    # OpenCV on the same input: the Sobel derivative's RMS over 9 x 17 windows, Immerkaer's noise from filter2D
    image = np.clip(across, 0, 255).astype(np.uint8)
    gray = image.astype(np.float32)
    laplacians = cv2.filter2D(gray, cv2.CV_32F, np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32))
    noise = 1.4826 * np.median(np.abs(laplacians[1:-1:4, 1:-1:4])) / 6.0
    assert image_noise_sigma(image) == pytest.approx(noise, rel=1e-6)
    rms = np.sqrt(cv2.sqrBoxFilter(cv2.Sobel(gray, cv2.CV_32F, 1, 0, ksize=3), cv2.CV_32F, (17, 9)))
    np.testing.assert_allclose(row_texture(image), rms / (np.sqrt(12.0) * noise), rtol=1e-5, atol=1e-5)
    assert image_noise_sigma(np.full((50, 60), 90, np.uint8)) == QUANTIZATION_SIGMA
    assert row_texture(np.full((50, 60), 90, np.uint8)).max() == 0.0
    with pytest.raises(ValueError, match="window_px"):
        row_texture(along, window_px=8)
    with pytest.raises(TypeError, match="image"):
        row_texture([[1, 2], [3, 4]])
