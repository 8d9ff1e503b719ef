"""Rejection of disparity on uniform image areas: texture / ground suppression, paper eq. (13).

Block matching on a patch without texture finds a minimum of the NSSD cost (eq. 9) decided by
noise. Section 3.5 of the paper rejects the disparity wherever the local patch statistics
``(mu_patch, sigma_patch)`` fall below an experimental threshold T:

    d(x, y) = invalid   if (mu_patch, sigma_patch) <= T           (13)
              d(x, y)   otherwise

Two readings of ``(mu, sigma) <= T``: the texture test (``sigma <= texture_threshold``, optionally
only where the mean lies in ``mean_range``) and a learned floor model (:func:`learn_floor_model`,
a Gaussian over the floor's ``(mu, sigma)``). Rejected disparities become NaN. Patch statistics
use box filters on ``I`` and ``I^2``. User guide: docs/obstacles.md; conventions: docs/conventions.md.

References
----------
Multi-Range Approach of Stereo Vision for Mobile Robot Navigation in Uncertain
Environments, section 3.5, eq. (13).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np

from .. import _checks
from . import _kernels

__all__ = [
    "RejectionConfig", "PatchStatistics", "FloorModel", "RejectionResult", "patch_statistics",
    "learn_floor_model", "reject_uniform", "image_noise_sigma", "row_texture",
]


@dataclass(frozen=True)
class RejectionConfig:
    """Options of the eq. (13) rejection.

    Attributes
    ----------
    window_px : int
        Side of the square patch (odd) over which ``mu_patch`` and
        ``sigma_patch`` are measured; about the matcher's window.
    texture_threshold : float
        T of eq. (13) in the texture reading: patches with
        ``sigma_patch <= texture_threshold`` (gray levels, 0-255 scale) are
        rejected. 0 disables the texture test. The default was chosen by
        measurement on the synthetic corridor (benchmarks/bench_obstacles.py).
    mean_range : (float, float) or None
        Optional window on ``mu_patch``: only patches whose mean lies inside it
        are tested (the "mu" half of eq. 13). None tests every patch.
    k_sigma : float
        Width of the acceptance region of a learned :class:`FloorModel`, in
        standard deviations of the floor's ``(mu, sigma)`` distribution.
    """

    window_px: int = 9
    texture_threshold: float = 3.0
    mean_range: tuple[float, float] | None = None
    k_sigma: float = 3.0

    def __post_init__(self) -> None:
        w = _checks.positive_int("window_px", self.window_px, minimum=3)
        if w % 2 == 0:
            raise ValueError(f"window_px must be odd, got {w}")
        _checks.finite_number("texture_threshold", self.texture_threshold, nonnegative=True)
        _checks.finite_number("k_sigma", self.k_sigma, positive=True)
        if self.mean_range is not None:
            lo, hi = _checks.ordered_pair("mean_range", self.mean_range, strict=False)
            object.__setattr__(self, "mean_range", (lo, hi))


@dataclass(frozen=True)
class PatchStatistics:
    """Patch statistics of an image over ``window_px`` x ``window_px`` patches.

    ``sum1 * scale`` and ``sum2 * scale`` are the patch means of ``I`` and ``I^2``; ``mean``
    (``mu_patch``) and ``std`` (``sigma_patch``) are formed from them on first use, float32 (H, W).
    """

    sum1: np.ndarray
    sum2: np.ndarray
    scale: float
    window_px: int

    @cached_property
    def _moments(self) -> tuple[np.ndarray, np.ndarray]:
        mean = np.empty(self.sum1.shape, dtype=np.float32)
        std = np.empty(self.sum1.shape, dtype=np.float32)
        _kernels.moments_from_sums(self.sum1, self.sum2, self.scale, mean, std)
        return mean, std

    @property
    def mean(self) -> np.ndarray:
        return self._moments[0]

    @property
    def std(self) -> np.ndarray:
        return self._moments[1]


@dataclass(frozen=True)
class FloorModel:
    """Gaussian model of the patch statistics ``(mu, sigma)`` of the floor (section 3.5).

    ``mu_mean``/``mu_std`` and ``sigma_mean``/``sigma_std`` describe the floor's patch means and
    standard deviations, measured over ``window_px`` patches.
    """

    mu_mean: float
    mu_std: float
    sigma_mean: float
    sigma_std: float
    window_px: int
    n_patches: int

    def uniform_mask(self, stats: PatchStatistics, *, k_sigma: float = 3.0) -> np.ndarray:
        """True where a patch looks like the floor: eq. (13) with T = the k-sigma region."""
        k = _checks.finite_number("k_sigma", k_sigma, positive=True)
        near_mean = np.abs(stats.mean - self.mu_mean) <= k * max(self.mu_std, 1e-6)
        plain = stats.std <= self.sigma_mean + k * self.sigma_std
        return near_mean & plain


@dataclass(frozen=True)
class RejectionResult:
    """Output of :func:`reject_uniform`.

    Attributes
    ----------
    disparity_px : ndarray of shape (H, W), float32
        The input disparity with rejected pixels set to NaN.
    rejected : ndarray of shape (H, W), bool
        Pixels that had a valid disparity and were rejected.
    uniform : ndarray of shape (H, W), bool
        Pixels whose patch failed the eq. (13) test (whether or not they had a disparity).
    stats : PatchStatistics
        ``mu_patch`` and ``sigma_patch`` of the left image.
    """

    disparity_px: np.ndarray
    rejected: np.ndarray
    uniform: np.ndarray
    stats: PatchStatistics

    @property
    def n_rejected(self) -> int:
        return int(self.rejected.sum())


def patch_statistics(image, *, window_px: int = 9) -> PatchStatistics:
    """Local mean and standard deviation over ``window_px`` x ``window_px`` patches.

    Box filters on ``I`` and ``I^2`` (borders reflected): ``mu = E[I]``,
    ``sigma = sqrt(max(E[I^2] - mu^2, 0))``, formed in float64, stored as float32. A uint8 gray
    image takes OpenCV's box filters of exact integer window sums: bit for bit the same.

    Parameters
    ----------
    image : ndarray of shape (H, W) or (H, W, 3)
        The (rectified left) image; colour is converted to gray (BT.601).
    window_px : int
        Odd patch side.
    """
    image = _checks.image("image", image)
    w = _checks.positive_int("window_px", window_px)
    if w % 2 == 0:
        raise ValueError(f"window_px must be odd, got {w}")
    if image.dtype == np.uint8 and (image.ndim == 2 or image.shape[2] == 1):
        gray = np.ascontiguousarray(image.reshape(image.shape[:2]))
        depth = cv2.CV_32F if 255 * 255 * w * w < 2 ** 24 else cv2.CV_64F
        sum1 = cv2.boxFilter(gray, depth, (w, w), normalize=False, borderType=cv2.BORDER_REFLECT_101)
        sum2 = cv2.sqrBoxFilter(gray, depth, (w, w), normalize=False, borderType=cv2.BORDER_REFLECT_101)
        return PatchStatistics(sum1=sum1, sum2=sum2, scale=1.0 / (w * w), window_px=w)
    gray = _checks.gray_float32("image", image).astype(np.float64)
    mean = cv2.boxFilter(gray, cv2.CV_64F, (w, w), normalize=True, borderType=cv2.BORDER_REFLECT_101)
    mean_sq = cv2.boxFilter(gray * gray, cv2.CV_64F, (w, w), normalize=True, borderType=cv2.BORDER_REFLECT_101)
    return PatchStatistics(sum1=mean, sum2=mean_sq, scale=1.0, window_px=w)


QUANTIZATION_SIGMA = 12 ** -0.5
"""The noise of rounding to whole gray levels (1 / sqrt(12)): the least noise :func:`image_noise_sigma` returns."""


def _gray(image) -> np.ndarray:
    """A checked image as the kernels take it: an 8-bit gray image as it is (no float copy), else float32 gray on
    the 8-bit scale (:func:`mrstereo._checks.gray_float32`)."""
    image = _checks.image("image", image)
    if image.dtype == np.uint8 and image.ndim == 2:
        return np.ascontiguousarray(image)
    return _checks.gray_float32("image", image)


NOISE_STEP = 4
""":func:`image_noise_sigma` samples every this many rows and columns."""


def image_noise_sigma(image) -> float:
    """The image's noise (standard deviation, gray levels of the 8-bit scale): 1.4826 times the median absolute
    response to the difference of two Laplacians, which cancels smooth shading (Immerkaer, "Fast noise variance
    estimation", 1996; its sum of squared weights is 36), over every :data:`NOISE_STEP`-th row and column; at
    least :data:`QUANTIZATION_SIGMA`. Texture raises it somewhat; on the randomized worlds it reads 1.1-1.3
    times the noise they were rendered with (docs/obstacles.md, "Floors without texture along the rows")."""
    gray = _gray(image)
    out = np.empty(((gray.shape[0] - 2 + NOISE_STEP - 1) // NOISE_STEP) * ((gray.shape[1] - 2 + NOISE_STEP - 1)
                                                                         // NOISE_STEP) if min(gray.shape) > 2 else 0)
    n = _kernels.noise_responses(gray, NOISE_STEP, out) if len(out) else 0
    if not n:
        return QUANTIZATION_SIGMA
    # 8-bit gray: the responses are whole numbers up to 16 * 255, counted (the same median, faster)
    median = _kernels.integer_median(out, n, 16 * 255) if gray.dtype == np.uint8 else float(np.median(out[:n]))
    return max(float(1.4826 * median / 6.0), QUANTIZATION_SIGMA)


def row_texture(image, *, window_px: int = 9, first_row: int = 0) -> np.ndarray:
    """Texture along the rows, the only texture that fixes a disparity: the RMS of the horizontal Sobel
    derivative over windows of ``window_px`` rows and ``2 window_px - 1`` columns (the matcher's window on a
    level decimated by 2, where a mobile robot's floor within a few metres is matched), over the RMS the image's
    noise alone gives it (``sqrt(12)`` :func:`image_noise_sigma`), float32 (H, W); borders reflected. About 1
    where the window holds nothing but noise along its rows: plain floor, or planks and stripes that run along
    the rows, on which a match slides along the epipolar line by a pixel or two in streaks (beyond the paper:
    eq. (13) measures all texture, this only the texture across the epipolar line). One numba pass of running
    window sums; the rows above ``first_row`` are NaN, not computed (the rows above the horizon, which show no
    floor: :func:`mrstereo.geometry.obstacles.first_floor_row`)."""
    gray = _gray(image)
    w = _checks.positive_int("window_px", window_px)
    if w % 2 == 0:
        raise ValueError(f"window_px must be odd, got {w}")
    first = _checks.positive_int("first_row", first_row, minimum=0)
    out = np.empty(gray.shape, np.float32)
    _kernels.row_texture(gray, w, 2 * w - 1, 1.0 / (math.sqrt(12.0) * image_noise_sigma(gray)), first, out)
    return out


def learn_floor_model(reference_image, *, floor_mask=None, window_px: int = 9) -> FloorModel:
    """Learn the Gaussian ``(mu, sigma)`` model of the floor from an image of the empty floor.

    Parameters
    ----------
    reference_image : ndarray of shape (H, W) or (H, W, 3)
        A (rectified left) image showing the floor.
    floor_mask : ndarray of shape (H, W), bool, optional
        The floor pixels; default the lower third of the image. Patches that
        touch the mask border are excluded (eroded by half a window) so that
        the model is not widened by the edges of other surfaces.
    window_px : int
        Patch side; use the same as :class:`RejectionConfig` ``window_px``.

    Returns
    -------
    FloorModel
    """
    stats = patch_statistics(reference_image, window_px=window_px)
    h, w = stats.mean.shape
    if floor_mask is None:
        mask = np.zeros((h, w), dtype=bool)
        mask[2 * h // 3:, :] = True
    else:
        mask = np.asarray(floor_mask)
        if mask.shape != (h, w):
            raise ValueError(f"floor_mask must have shape {(h, w)}, got {mask.shape}")
        mask = mask.astype(bool)
    kernel = np.ones((window_px, window_px), np.uint8)
    inner = cv2.erode(mask.astype(np.uint8), kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0)
    inner = inner.astype(bool)
    if not inner.any():
        inner = mask
    n = int(inner.sum())
    if n < 2:
        raise ValueError(f"floor_mask must cover at least 2 pixels, got {n}")
    mu, sigma = stats.mean[inner].astype(np.float64), stats.std[inner].astype(np.float64)
    return FloorModel(mu_mean=float(mu.mean()), mu_std=float(mu.std()), sigma_mean=float(sigma.mean()),
                      sigma_std=float(sigma.std()), window_px=stats.window_px, n_patches=n)


def reject_uniform(disparity_px, left, *, config: RejectionConfig = RejectionConfig(),
                   floor_model: FloorModel | None = None) -> RejectionResult:
    """Eq. (13): set the disparity to NaN where the left image patch is uniform.

    Parameters
    ----------
    disparity_px : ndarray of shape (H, W)
        Disparity of the rectified left image, NaN invalid.
    left : ndarray of shape (H, W) or (H, W, 3)
        The rectified left image the disparity belongs to.
    config : RejectionConfig
        Window and thresholds (``texture_threshold`` is T of eq. 13).
    floor_model : FloorModel, optional
        A floor model from :func:`learn_floor_model` (the paper's learned mode);
        its ``window_px`` then replaces ``config.window_px`` so that the patch
        statistics compare like with like.

    Returns
    -------
    RejectionResult
    """
    if not isinstance(config, RejectionConfig):
        raise TypeError(f"config must be a RejectionConfig, got {type(config).__name__}")
    if floor_model is not None and not isinstance(floor_model, FloorModel):
        raise TypeError(f"floor_model must be a FloorModel, got {type(floor_model).__name__}")
    d = np.asarray(disparity_px)
    if d.ndim != 2:
        raise ValueError(f"disparity_px must have shape (H, W), got {d.shape}")
    image = _checks.image("left", left)
    _checks.same_shape("disparity_px", d, "left", image)
    window = floor_model.window_px if floor_model is not None else config.window_px
    stats = patch_statistics(left, window_px=window)
    floor = None if floor_model is None else floor_model.uniform_mask(stats, k_sigma=config.k_sigma)
    lo, hi = (-np.inf, np.inf) if config.mean_range is None else config.mean_range
    out = np.empty(d.shape, dtype=np.float32)
    rejected = np.empty(d.shape, dtype=bool)
    uniform = np.empty(d.shape, dtype=bool)
    _kernels.reject_uniform(stats.sum1, stats.sum2, stats.scale, config.texture_threshold, lo, hi, floor, d, out,
                            rejected, uniform)
    return RejectionResult(disparity_px=out, rejected=rejected, uniform=uniform, stats=stats)
