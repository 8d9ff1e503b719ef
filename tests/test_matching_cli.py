"""`mrstereo disparity` command: outputs, --explain, one-line errors."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from mrstereo.cli import entry
from mrstereo.io import read_disparity


def _pair(tmp_path, d=6):
    rng = np.random.default_rng(0)
    img = cv2.GaussianBlur(rng.uniform(0, 255, (40, 120)).astype(np.float32), (0, 0), 1.0)
    img = np.round(20 + 215 * (img - img.min()) / (img.max() - img.min())).astype(np.uint8)
    left, right = img[:, :100], img[:, d:100 + d]
    cv2.imwrite(str(tmp_path / "l.png"), left)
    cv2.imwrite(str(tmp_path / "r.png"), right)
    return str(tmp_path / "l.png"), str(tmp_path / "r.png")


def test_disparity_command_writes_pfm_png_and_explains(tmp_path, capsys):
    left, right = _pair(tmp_path)
    out = tmp_path / "d.pfm"
    assert entry(["disparity", left, right, "--max-disparity", "16", "--explain", "-o", str(out),
                  "--plot", str(tmp_path / "c.png")]) == 0
    assert "single-range" in capsys.readouterr().out
    d = read_disparity(out)
    assert d.shape == (40, 100)
    assert np.nanmedian(d[8:-8, 20:-8]) == np.float32(6.0) or abs(np.nanmedian(d[8:-8, 20:-8]) - 6) < 0.1
    assert (tmp_path / "c.png").is_file()
    png = tmp_path / "d.png"
    assert entry(["disparity", left, right, "--bands", "0:8,8:16", "--preset", "paper", "-o", str(png)]) == 0
    assert abs(np.nanmedian(read_disparity(png)[8:-8, 20:-8]) - 6) < 0.1


def test_preview_is_scaled_to_the_data_not_to_the_search(tmp_path, capsys):
    """Disparities of 5-60 px searched up to 192 px: the colours span the data (robust percentiles),
    so the median is mid-scale turbo (green), not the dark blue of 33/192; invalid is black."""
    import matplotlib

    from mrstereo.viz.plot import colorize_disparity, disparity_range_px

    d = np.tile(np.linspace(5, 60, 200, dtype=np.float32), (50, 1))
    d[:, :3] = np.nan
    low, high = disparity_range_px(d)
    assert low == pytest.approx(np.percentile(d[:, 3:], 1)) and high == pytest.approx(np.percentile(d[:, 3:], 99))
    bgr = colorize_disparity(d)
    turbo = matplotlib.colormaps["turbo"]
    mid = np.nanargmin(np.abs(d[0] - (low + high) / 2))
    np.testing.assert_allclose(bgr[10, mid, ::-1] / 255, turbo(0.5)[:3], atol=0.02)
    assert (bgr[:, :3] == 0).all()
    old = colorize_disparity(d, max_disparity_px=192)          # the search range as the scale
    np.testing.assert_allclose(old[10, mid, ::-1] / 255, turbo(((low + high) / 2) / 192)[:3], atol=0.02)
    # the CLI's preview: a PNG figure (wider than the image: the colour bar) beside the PFM
    left, right = _pair(tmp_path)
    assert entry(["disparity", left, right, "--max-disparity", "16", "-o", str(tmp_path / "d.pfm"),
                  "--plot", str(tmp_path / "p.png")]) == 0
    preview = cv2.imread(str(tmp_path / "p.png"))
    assert preview is not None and preview.shape[1] > 3 * 100      # the 100 px map, enlarged, and its bar
    assert entry(["disparity", left, right, "--max-disparity", "16", "-o", str(tmp_path / "d.pfm"),
                  "--plot", str(tmp_path / "p.jpg")]) == 2
    assert "--plot must end in .png" in capsys.readouterr().err


def test_disparity_command_bad_input_is_one_line(tmp_path, capsys):
    left, right = _pair(tmp_path)
    cases = [
        (["disparity", left, str(tmp_path / "missing.png"), "--max-disparity", "16", "-o", "x.pfm"], "not found"),
        (["disparity", left, right, "--max-disparity", "nan", "-o", str(tmp_path / "x.pfm")], "finite"),
        (["disparity", left, right, "--max-disparity", "-3", "-o", str(tmp_path / "x.pfm")], "not in the range"),
        (["disparity", left, right, "-o", str(tmp_path / "x.pfm")], "--max-disparity"),
        (["disparity", left, right, "--max-disparity", "16", "-o", left], "overwrite"),
    ]
    for argv, message in cases:
        assert entry(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("mrstereo: error:") and message in err[0]
    (tmp_path / "bad.png").write_bytes(b"not an image")
    assert entry(["disparity", left, str(tmp_path / "bad.png"), "--max-disparity", "16", "-o",
                  str(tmp_path / "x.pfm")]) == 2
    cv2.imwrite(str(tmp_path / "small.png"), np.zeros((40, 90), np.uint8))
    assert entry(["disparity", left, str(tmp_path / "small.png"), "--max-disparity", "16", "-o",
                  str(tmp_path / "x.pfm")]) == 2
    assert "differ in size" in capsys.readouterr().err
    assert not (tmp_path / "x.pfm").exists()


def test_disparity_command_no_fill_leaves_holes(tmp_path):
    left, right = _pair(tmp_path)
    img = cv2.imread(right, cv2.IMREAD_GRAYSCALE)
    img[18:22, 40:46] = 128                     # a flat patch: no match there, a hole to fill
    cv2.imwrite(right, img)
    filled, holes = tmp_path / "f.pfm", tmp_path / "h.pfm"
    assert entry(["disparity", left, right, "--max-disparity", "16", "-o", str(filled)]) == 0
    assert entry(["disparity", left, right, "--max-disparity", "16", "--no-fill", "-o", str(holes)]) == 0
    f, h = read_disparity(filled), read_disparity(holes)
    assert np.isfinite(f).sum() > np.isfinite(h).sum()
    np.testing.assert_array_equal(f[np.isfinite(h)], h[np.isfinite(h)])     # filling only adds pixels
