"""Rejection of disparity on uniform image areas: texture / ground suppression, paper eq. (13).

Block matching on a patch without texture (a plain floor, a white wall) finds
a minimum of the NSSD cost (eq. 9) that is decided by noise; the resulting
"ghost points" scatter in depth and show up as false obstacles. Section 3.5 of
the paper models the gray patches of the uniform ground as a Gaussian with a
small standard deviation and rejects the disparity wherever the local patch
statistics ``(mu_patch, sigma_patch)`` fall below an experimental threshold T:

    d(x, y) = invalid   if (mu_patch, sigma_patch) <= T           (13)
              d(x, y)   otherwise

Two readings of ``(mu, sigma) <= T`` are implemented:

* **texture test** (default, no reference image needed): reject where the
  patch standard deviation ``sigma <= texture_threshold`` (T of eq. 13, gray
  levels on a 0-255 scale); optionally only where the patch mean also lies in a
  window ``mean_range`` (e.g. the brightness of the floor), so that a dark but
  textured region is never rejected by its mean alone.
* **learned floor model** (the paper's "we have measured means and standard
  deviations ... with ground areas"): :func:`learn_floor_model` fits a Gaussian
  to ``(mu, sigma)`` over the floor pixels of a reference image of the empty
  floor; a patch is rejected when its mean lies within ``k_sigma`` standard
  deviations of the floor's mean and its standard deviation is no larger than
  the floor's mean sigma plus ``k_sigma`` standard deviations (texture that
  is no richer than the floor's).

Rejected disparities become NaN (the library's "invalid"; the paper writes 0).
Patch statistics use box filters on ``I`` and ``I^2`` (``cv2.boxFilter``), so
the cost is independent of the window size. Conventions: docs/conventions.md.

References
----------
Multi-Range Approach of Stereo Vision for Mobile Robot Navigation in Uncertain
Environments, section 3.5, eq. (13).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np

from .. import _checks
from . import _kernels

__all__ = [
    "RejectionConfig", "PatchStatistics", "FloorModel", "RejectionResult", "patch_statistics",
    "uniform_mask", "learn_floor_model", "reject_uniform",
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
    """Local mean and standard deviation of an image, both (H, W) float32."""

    mean: np.ndarray
    std: np.ndarray
    window_px: int


@dataclass(frozen=True)
class FloorModel:
    """Gaussian model of the patch statistics ``(mu, sigma)`` of the floor (section 3.5).

    ``mu_mean``/``mu_std`` describe the distribution of the patch means over
    the floor, ``sigma_mean``/``sigma_std`` that of the patch standard
    deviations; ``window_px`` is the patch size they were measured with.
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
    left : ndarray of shape (H, W) or (H, W, 3)
        The image the patch statistics are of.
    window_px : int
        Their patch side.
    """

    disparity_px: np.ndarray
    rejected: np.ndarray
    uniform: np.ndarray
    left: np.ndarray
    window_px: int

    @cached_property
    def stats(self) -> PatchStatistics:
        """``mu_patch`` and ``sigma_patch`` of the left image (computed on first use when the test did not
        need the images)."""
        return patch_statistics(self.left, window_px=self.window_px)

    @property
    def n_rejected(self) -> int:
        return int(self.rejected.sum())


def patch_statistics(image, *, window_px: int = 9) -> PatchStatistics:
    """Local mean and standard deviation over ``window_px`` x ``window_px`` patches.

    Box filters on ``I`` and ``I^2`` (``cv2.boxFilter``, borders reflected):
    ``mu = E[I]``, ``sigma = sqrt(max(E[I^2] - mu^2, 0))``. Computed in float64
    so that the difference of large squares does not lose precision. For a uint8
    gray image the window sums are integers that OpenCV's SIMD box filters
    (``cv2.boxFilter`` / ``cv2.sqrBoxFilter`` of the uint8 image) give exactly, in
    float32 while ``255^2 w^2 < 2^24`` (windows up to 15 px) and in float64 beyond;
    the result is bit for bit that of the float64 filters, at less than half the cost.

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
        return _patch_statistics_uint8(image.reshape(image.shape[:2]), w)
    gray = _checks.gray_float32("image", image).astype(np.float64)
    mean = cv2.boxFilter(gray, cv2.CV_64F, (w, w), normalize=True, borderType=cv2.BORDER_REFLECT_101)
    gray_sq = np.empty_like(gray)
    _kernels.square(gray, gray_sq)
    mean_sq = cv2.boxFilter(gray_sq, cv2.CV_64F, (w, w), normalize=True, borderType=cv2.BORDER_REFLECT_101)
    mean32 = np.empty(mean.shape, dtype=np.float32)
    std32 = np.empty(mean.shape, dtype=np.float32)
    _kernels.mean_std(mean, mean_sq, mean32, std32)      # sigma = sqrt(max(E[I^2] - mu^2, 0))
    return PatchStatistics(mean=mean32, std=std32, window_px=w)


def _window_sums_uint8(gray: np.ndarray, w: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Exact window sums of ``I`` and ``I^2`` of a uint8 gray image (OpenCV's SIMD box filters) and ``1 / w^2``.

    Float32 holds the integer sums exactly while ``255^2 w^2 < 2^24`` (windows up to 15 px), float64 beyond.
    """
    depth = cv2.CV_32F if 255 * 255 * w * w < 2 ** 24 else cv2.CV_64F
    sum1 = cv2.boxFilter(gray, depth, (w, w), normalize=False, borderType=cv2.BORDER_REFLECT_101)
    sum2 = cv2.sqrBoxFilter(gray, depth, (w, w), normalize=False, borderType=cv2.BORDER_REFLECT_101)
    return sum1, sum2, 1.0 / (w * w)


@functools.lru_cache(maxsize=64)
def _max_uniform_variance(threshold: float) -> float:
    """The largest float64 variance ``v`` with ``float32(sqrt(v)) <= float32(threshold)`` (``threshold > 0``).

    ``sigma <= T`` of eq. (13), with ``sigma`` stored as float32 and compared in float32 (as numpy
    compares a float32 array with a Python float), is ``variance <= v``: both roundings are
    monotonic. Found by bisection over the ordered bit patterns of positive doubles.
    """
    t = np.float32(threshold)
    lo, hi = 0, int(np.float64(4.0 * float(t) ** 2 + 1.0).view(np.int64))     # uniform at lo, not at hi
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if np.float32(np.sqrt(np.int64(mid).view(np.float64))) <= t:
            lo = mid
        else:
            hi = mid
    return float(np.int64(lo).view(np.float64))


def _patch_statistics_uint8(gray: np.ndarray, w: int) -> PatchStatistics:
    """:func:`patch_statistics` of a uint8 gray image from exact integer window sums (same bits)."""
    sum1, sum2, scale = _window_sums_uint8(np.ascontiguousarray(gray), w)
    mean32 = np.empty(gray.shape, dtype=np.float32)
    std32 = np.empty(gray.shape, dtype=np.float32)
    _kernels.mean_std_from_sums(sum1, sum2, scale, mean32, std32)
    return PatchStatistics(mean=mean32, std=std32, window_px=w)


def uniform_mask(stats: PatchStatistics, *, config: RejectionConfig = RejectionConfig(),
                 floor_model: FloorModel | None = None) -> np.ndarray:
    """Eq. (13) test: True where the patch is uniform and its disparity must be rejected.

    Without a floor model: ``sigma <= texture_threshold`` (and ``mu`` inside
    ``mean_range`` when given). With a floor model, its k-sigma region is used
    in addition (a patch is uniform if either test says so).
    """
    if not isinstance(stats, PatchStatistics):
        raise TypeError(f"stats must be a PatchStatistics, got {type(stats).__name__}")
    mask = stats.std <= config.texture_threshold if config.texture_threshold > 0 else \
        np.zeros(stats.std.shape, dtype=bool)
    if config.mean_range is not None:
        lo, hi = config.mean_range
        mask &= (stats.mean >= lo) & (stats.mean <= hi)
    if floor_model is not None:
        mask |= floor_model.uniform_mask(stats, k_sigma=config.k_sigma)
    return mask


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
    out = np.empty(d.shape, dtype=np.float32)
    rejected = np.empty(out.shape, dtype=bool)
    if (floor_model is None and config.mean_range is None and config.texture_threshold > 0
            and image.dtype == np.uint8 and (image.ndim == 2 or image.shape[2] == 1)):
        # the texture test alone on a uint8 image: exact integer window sums, then one fused pass
        gray = np.ascontiguousarray(image.reshape(image.shape[:2]))
        sum1, sum2, scale = _window_sums_uint8(gray, window)
        uniform = np.empty(out.shape, dtype=bool)
        _kernels.reject_texture_from_sums(sum1, sum2, scale, _max_uniform_variance(config.texture_threshold), d,
                                          out, rejected, uniform)
        return RejectionResult(disparity_px=out, rejected=rejected, uniform=uniform, left=left, window_px=window)
    stats = patch_statistics(left, window_px=window)
    uniform = uniform_mask(stats, config=config, floor_model=floor_model)
    out[...] = d
    _kernels.reject(out, uniform, rejected)          # eq. (13): NaN where uniform and valid
    result = RejectionResult(disparity_px=out, rejected=rejected, uniform=uniform, left=left, window_px=window)
    result.__dict__["stats"] = stats                 # already computed: the cached property's value
    return result
