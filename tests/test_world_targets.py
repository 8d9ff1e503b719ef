"""Rendered calibration targets: exact correspondences and OpenCV detection."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from mrstereo.world import default_stereo
from mrstereo.world.targets import render_calibration_views, render_paper_dot_target, target_points


@pytest.fixture(scope="module")
def stereo():
    return default_stereo(320, 240)


@pytest.fixture(scope="module")
def views(stereo):
    return render_calibration_views(stereo, n_views=3, seed=5)


def test_points_are_projections_of_the_posed_target(views, stereo):
    for v in views:
        assert v.image.shape == (240, 320) and v.image_right.shape == (240, 320)
        np.testing.assert_allclose(v.R @ v.R.T, np.eye(3), atol=1e-12)
        pts_cam = v.points_target @ v.R.T + v.t
        np.testing.assert_allclose(v.points_px, stereo.left.camera.project(pts_cam), atol=1e-9)
        # Right camera: left raw -> rectified (R_L), shift by the baseline, -> right raw (R_R^T).
        pts_right = (pts_cam @ stereo.left.R.T - [stereo.baseline_m, 0.0, 0.0]) @ stereo.right.R
        np.testing.assert_allclose(v.points_px_right, stereo.right.camera.project(pts_right), atol=1e-9)
        np.testing.assert_allclose(v.points_target, target_points((9, 6), 0.03))


def _detect(image, board):
    found, corners = cv2.findChessboardCorners(image, board)
    assert found
    corners = cv2.cornerSubPix(image, corners.reshape(-1, 1, 2).astype(np.float32), (5, 5), (-1, -1),
                               (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3))
    return corners.reshape(-1, 2)


def test_opencv_finds_the_corners_where_they_are(views):
    errors = []
    for v in views:
        for image, px in ((v.image, v.points_px), (v.image_right, v.points_px_right)):
            found = _detect(image, (9, 6))
            dist = np.linalg.norm(found[:, None] - px[None], axis=2)
            assert len(set(dist.argmin(axis=1))) == 54          # one-to-one
            errors.append(dist.min(axis=1))
    errors = np.concatenate(errors)
    assert np.mean(errors) < 0.15 and np.percentile(errors, 95) < 0.3


def test_mono_dots_and_determinism(stereo):
    cam = stereo.left.camera
    a = render_calibration_views(cam, target="dots", board=(7, 5), spacing_m=0.04, n_views=2, seed=1,
                                 supersample=2)
    b = render_calibration_views(cam, target="dots", board=(7, 5), spacing_m=0.04, n_views=2, seed=1,
                                 supersample=2)
    assert a[0].image_right is None and a[0].points_px_right is None
    np.testing.assert_array_equal(a[1].image, b[1].image)
    np.testing.assert_array_equal(a[1].R, b[1].R)
    c = render_calibration_views(cam, target="dots", board=(7, 5), spacing_m=0.04, n_views=2, seed=2,
                                 supersample=2)
    assert not np.allclose(a[0].R, c[0].R)
    # A dot centre is dark, the paper half a pitch away is bright.
    v = a[0]
    u = np.rint(v.points_px).astype(int)
    assert np.median(v.image[u[:, 1], u[:, 0]]) < 80


def test_paper_dot_target_fills_the_image_and_shows_distortion(stereo):
    cam = stereo.left.camera
    v = render_paper_dot_target(cam, grid=(15, 11))
    px = v.points_px
    assert px.min(axis=0)[0] < 0.1 * cam.width and px.max(axis=0)[0] > 0.9 * cam.width
    assert px.min(axis=0)[1] < 0.1 * cam.height and px.max(axis=0)[1] > 0.9 * cam.height
    ideal = cam.undistort_pixels(px)
    shift = np.linalg.norm(ideal - px, axis=1)
    corner = np.argmax(np.linalg.norm(px - [cam.cx, cam.cy], axis=1))
    assert 3.0 < shift[corner] < 12.0 and shift.min() < 0.5      # paper Fig. 3: > 5 px at the corners
    s = render_paper_dot_target(stereo, grid=(15, 11))
    assert s.image_right is not None and np.all(np.isfinite(s.points_px_right))


def test_bad_inputs(stereo):
    with pytest.raises(ValueError, match="target"):
        render_calibration_views(stereo, target="circles")
    with pytest.raises(ValueError, match="board"):
        render_calibration_views(stereo, board=(1, 6))
    with pytest.raises(ValueError, match="spacing_m"):
        render_calibration_views(stereo, spacing_m=-0.03)
    with pytest.raises(TypeError, match="camera_or_stereo"):
        render_calibration_views("left")
    with pytest.raises(RuntimeError, match="could not place"):
        render_calibration_views(stereo, board=(2, 40), n_views=1)   # far too tall
