"""Renderer of the synthetic corridor: ground truth against geometry, rectification, determinism."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from mrstereo.camera import CameraMount
from mrstereo.geometry import points_cam_from_disparity
from mrstereo.transforms import transform_points
from mrstereo.world import LABEL_FLOOR, LABEL_OBSTACLE, LABEL_WALL, default_scene, default_stereo, render_stereo_frame


@pytest.fixture(scope="module")
def scene():
    return default_scene(0)


@pytest.fixture(scope="module")
def stereo():
    return default_stereo(160, 120)


@pytest.fixture(scope="module")
def frame(scene, stereo):
    return render_stereo_frame(scene, stereo, pose=(0.3, 0.05, 0.02), pan_rad=0.0, seed=3)


def _points_world(frame, stereo):
    pts = points_cam_from_disparity(frame.disparity_px, focal_px=stereo.focal_px, baseline_m=stereo.baseline_m,
                                    cx_px=stereo.cx_px, cy_px=stereo.cy_px, doffs_px=stereo.doffs_px)
    return pts, transform_points(frame.T_world_from_cam, pts)


def test_frame_shapes_and_types(frame):
    for name in ("raw_left", "raw_right", "left_rect", "right_rect", "labels"):
        arr = getattr(frame, name)
        assert arr.shape == (120, 160) and arr.dtype == np.uint8, name
    assert frame.disparity_px.dtype == np.float32 and frame.depth_m.dtype == np.float32
    assert np.isfinite(frame.disparity_px).all()        # the corridor is closed


def test_triangulated_gt_matches_depth_and_scene(frame, stereo):
    pts, world = _points_world(frame, stereo)
    rel = np.abs(pts[..., 2] - frame.depth_m) / frame.depth_m
    assert np.median(rel) < 0.005
    floor = frame.labels == LABEL_FLOOR
    wall = frame.labels == LABEL_WALL
    assert floor.sum() > 1000 and wall.sum() > 500
    np.testing.assert_allclose(world[floor][:, 2], 0.0, atol=1e-3)         # floor at z = 0
    y_wall = np.abs(world[wall][:, 1])
    on_face = np.abs(y_wall - 1.2) < 1e-3                                   # corridor-facing wall faces
    assert on_face.mean() > 0.9


def test_gt_disparity_warps_right_onto_left(frame):
    h, w = frame.disparity_px.shape
    v, u = np.mgrid[0:h, 0:w].astype(np.float32)
    d = frame.disparity_px
    right = frame.right_rect.astype(np.float32)
    left = frame.left_rect.astype(np.float32)

    def warp(disp):
        return cv2.remap(right, u - disp, v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan)

    # Non-occluded: no left pixel with a larger disparity lands on the same right pixel.
    visible = np.ones((h, w), bool)
    for r in range(h):
        xr = np.rint(u[r] - d[r]).astype(int)
        best = np.full(w, -np.inf)
        ok = (xr >= 0) & (xr < w)
        np.maximum.at(best, xr[ok], d[r][ok])
        visible[r] = ok & (d[r] >= np.where(ok, best[np.clip(xr, 0, w - 1)], np.inf) - 0.5)
    texture = cv2.Laplacian(left, cv2.CV_32F, ksize=3)
    textured = np.abs(texture) > 20
    mask = visible & textured & (u - d > 2) & (frame.labels >= LABEL_OBSTACLE)
    mask[:3], mask[-3:], mask[:, :3], mask[:, -3:] = False, False, False, False
    assert mask.sum() > 200
    err = np.nanmean(np.abs(warp(d) - left)[mask])
    control = np.nanmean(np.abs(warp(d + 2.0) - left)[mask])
    assert err < 6.0
    assert control > 2.0 * err


def test_rectify_raw_reproduces_ideal_rectified(frame, stereo):
    left, right = stereo.rectify(frame.raw_left, frame.raw_right)
    inner = (slice(8, -8), slice(8, -8))
    for got, want, raw in ((left, frame.left_rect, frame.raw_left), (right, frame.right_rect, frame.raw_right)):
        diff = np.abs(got.astype(float) - want)[inner]
        assert np.median(diff) < 3.0
        control = np.abs(raw.astype(float) - want)[inner]     # raw != rectified (not the identity)
        assert diff.mean() < 0.5 * control.mean()


def test_same_seed_same_images_other_seed_differs(scene, stereo, frame):
    again = render_stereo_frame(scene, stereo, pose=(0.3, 0.05, 0.02), seed=3)
    for name in ("raw_left", "raw_right", "left_rect", "right_rect", "labels"):
        np.testing.assert_array_equal(getattr(again, name), getattr(frame, name))
    np.testing.assert_array_equal(again.disparity_px, frame.disparity_px)
    other = render_stereo_frame(scene, stereo, pose=(0.3, 0.05, 0.02), seed=4)
    assert not np.array_equal(other.left_rect, frame.left_rect)
    np.testing.assert_array_equal(other.disparity_px, frame.disparity_px)   # noise only
    retextured = render_stereo_frame(default_scene(1), stereo, pose=(0.3, 0.05, 0.02), seed=3)
    assert np.abs(retextured.left_rect.astype(int) - frame.left_rect).mean() > 1.0


def test_box_straight_ahead_has_disparity_bf_over_z(scene):
    stereo = default_stereo(160, 120, tilt_rad=0.0)
    z_m = 2.0
    # The middle box's near face is the plane x = 6.0 m, 0.5 m wide, 0.6 m high; the left
    # camera looks along +x from 0.45 m height.
    frame = render_stereo_frame(scene, stereo, pose=(6.0 - z_m, 0.0, 0.0), supersample=1)
    face = frame.labels == LABEL_OBSTACLE + 4
    assert face.sum() > 100
    expected = stereo.focal_px * stereo.baseline_m / z_m                 # eq. (14): 6 px
    np.testing.assert_allclose(frame.disparity_px[face], expected, rtol=1e-5)
    np.testing.assert_allclose(frame.depth_m[face], z_m, rtol=1e-6)
    cols = np.nonzero(face.any(axis=0))[0]
    half_width_px = stereo.focal_px * 0.25 / z_m                          # face spans |y| < 0.25 m
    assert abs((cols.max() - cols.min() + 1) - 2 * half_width_px) <= 2


def test_pan_turns_the_view(scene, stereo):
    left = render_stereo_frame(scene, stereo, pose=(4.5, 0.0, 0.0), pan_rad=np.pi / 2, supersample=1)
    _, world = _points_world(left, stereo)
    centre = world[50:70, 70:90].reshape(-1, 3)
    assert np.all(centre[:, 1] > 1.0)          # looking at the left wall (y = +1.2)


def test_bad_inputs(scene, stereo):
    with pytest.raises(ValueError, match="pose"):
        render_stereo_frame(scene, stereo, pose=(1.0, 2.0))
    with pytest.raises(ValueError, match="pose"):
        render_stereo_frame(scene, stereo, pose=(1.0, np.nan, 0.0))
    with pytest.raises(ValueError, match="inside a solid object"):
        low = CameraMount.from_rig(0.3, 0.0, R_rect_from_cam=stereo.left.R)
        render_stereo_frame(scene, stereo, pose=(6.2, 0.0, 0.0), mount=low)
    with pytest.raises(ValueError, match="supersample"):
        render_stereo_frame(scene, stereo, supersample=0)
    with pytest.raises(TypeError, match="scene"):
        render_stereo_frame("corridor", stereo)
    with pytest.raises(TypeError, match="stereo"):
        render_stereo_frame(scene, stereo.left)
