"""OpenCV StereoBM and StereoSGBM as reference matchers, set up as ROS ``stereo_image_proc`` runs them.

Both match the gray image with ``minDisparity = 0`` and ``numDisparities`` the range rounded up to
16; :func:`disparity_from_opencv` turns OpenCV's int16 x16 output into float32 pixels, NaN invalid.
The settings and why SGBM runs ``MODE_SGBM_3WAY``: docs/evaluation.md, "Baselines".
Conventions: docs/conventions.md.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .. import _checks

__all__ = ["BASELINES", "BMSettings", "SGBMSettings", "stereo_bm", "stereo_sgbm", "disparity_from_opencv",
           "num_disparities"]


@dataclass(frozen=True)
class BMSettings:
    """StereoBM parameters (``window_px = None``: 15, or 9 below 640 px width)."""

    window_px: int | None = None
    prefilter_size: int = 9
    prefilter_cap: int = 31
    texture_threshold: int = 10
    uniqueness_ratio: int = 15
    speckle_window_size: int = 100
    speckle_range: int = 4
    disp12_max_diff: int = 1


@dataclass(frozen=True)
class SGBMSettings:
    """StereoSGBM parameters (P1/P2 from the block size unless given)."""

    block_size: int = 5
    p1: int | None = None
    p2: int | None = None
    uniqueness_ratio: int = 10
    speckle_window_size: int = 100
    speckle_range: int = 2
    disp12_max_diff: int = 1
    prefilter_cap: int = 63
    mode: int = cv2.StereoSGBM_MODE_SGBM_3WAY


def num_disparities(max_disparity_px) -> int:
    """OpenCV ``numDisparities``: ``max_disparity_px`` rounded up to a multiple of 16 (at least 16)."""
    value = _checks.finite_number("max_disparity_px", max_disparity_px, positive=True)
    return int(16 * max(1, -(-int(np.ceil(value)) // 16)))


def disparity_from_opencv(raw, *, min_disparity: int = 0) -> np.ndarray:
    """Convert OpenCV's int16 ``16 * d`` output to float32 pixels, invalid -> NaN.

    Invalid pixels are those below ``min_disparity * 16`` (OpenCV writes
    ``(min_disparity - 1) * 16`` there).
    """
    raw = np.asarray(raw)
    if raw.dtype != np.int16:
        raise TypeError(f"raw must be OpenCV's int16 disparity, got dtype {raw.dtype}")
    out = raw.astype(np.float32) / np.float32(16.0)
    out[raw < min_disparity * 16] = np.nan
    return out


def _gray_u8(name: str, img) -> np.ndarray:
    img = _checks.image(name, img)
    if img.ndim == 3:
        img = cv2.cvtColor(np.ascontiguousarray(img[:, :, :3]), cv2.COLOR_BGR2GRAY) if img.shape[2] == 3 else img[:, :, 0]
    if img.dtype != np.uint8:
        img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    return np.ascontiguousarray(img)


def _inputs(left, right):
    gl, gr = _gray_u8("left", left), _gray_u8("right", right)
    _checks.same_shape("left", gl, "right", gr)
    return gl, gr


def _search(max_disparity_px, exact_max: bool) -> tuple[int, int]:
    """OpenCV ``(minDisparity, numDisparities)``: ``0 .. n - 1`` with ``n`` a multiple of 16, or
    with ``exact_max`` a window of ``n`` ending exactly at ``ceil(max_disparity_px)`` (starting
    at or below 0)."""
    n = num_disparities(max_disparity_px + (1 if exact_max else 0))
    return (int(np.ceil(max_disparity_px)) + 1 - n if exact_max else 0), n


def stereo_bm(left, right, *, max_disparity_px, settings: BMSettings = BMSettings(),
              exact_max: bool = False) -> np.ndarray:
    """Disparity (float32 px, NaN invalid) of OpenCV StereoBM with :class:`BMSettings`.

    Parameters
    ----------
    left, right : ndarray of shape (H, W) or (H, W, 3)
        Rectified views (BGR converted to gray).
    max_disparity_px : float
        Largest disparity to search; rounded up to a multiple of 16.
    exact_max : bool
        Search up to ``ceil(max_disparity_px)`` exactly (a negative ``minDisparity`` fills the multiple).
    settings : BMSettings
    """
    gl, gr = _inputs(left, right)
    window = settings.window_px or (15 if gl.shape[1] >= 640 else 9)
    lowest, n = _search(max_disparity_px, exact_max)
    bm = cv2.StereoBM_create(numDisparities=n, blockSize=window)
    bm.setPreFilterType(cv2.StereoBM_PREFILTER_XSOBEL)
    bm.setPreFilterSize(settings.prefilter_size)
    bm.setPreFilterCap(settings.prefilter_cap)
    bm.setTextureThreshold(settings.texture_threshold)
    bm.setUniquenessRatio(settings.uniqueness_ratio)
    bm.setSpeckleWindowSize(settings.speckle_window_size)
    bm.setSpeckleRange(settings.speckle_range)
    bm.setDisp12MaxDiff(settings.disp12_max_diff)
    bm.setMinDisparity(lowest)
    return disparity_from_opencv(bm.compute(gl, gr), min_disparity=lowest)


def stereo_sgbm(left, right, *, max_disparity_px, settings: SGBMSettings = SGBMSettings(),
                exact_max: bool = False) -> np.ndarray:
    """Disparity (float32 px, NaN invalid) of OpenCV StereoSGBM with :class:`SGBMSettings`.

    Parameters
    ----------
    left, right, max_disparity_px, exact_max :
        As :func:`stereo_bm`.
    settings : SGBMSettings
    """
    gl, gr = _inputs(left, right)
    block = settings.block_size
    lowest, n = _search(max_disparity_px, exact_max)
    sgbm = cv2.StereoSGBM_create(
        minDisparity=lowest, numDisparities=n, blockSize=block,
        P1=settings.p1 if settings.p1 is not None else 8 * block * block,
        P2=settings.p2 if settings.p2 is not None else 32 * block * block,
        disp12MaxDiff=settings.disp12_max_diff, preFilterCap=settings.prefilter_cap,
        uniquenessRatio=settings.uniqueness_ratio, speckleWindowSize=settings.speckle_window_size,
        speckleRange=settings.speckle_range, mode=settings.mode)
    return disparity_from_opencv(sgbm.compute(gl, gr), min_disparity=lowest)


BASELINES = {"StereoBM": stereo_bm, "StereoSGBM": stereo_sgbm}
