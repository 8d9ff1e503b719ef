"""Numba kernels of the eq. (13) rejection (:mod:`mrstereo.rejection`; no validation, preallocated outputs).

Each kernel does per element exactly the arithmetic of the numpy expression it replaces, in
the same order and dtype (no fastmath), so the results are bit-identical; ``nogil`` lets the
per-frame chain run on worker threads.

Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(nogil=True, cache=True)
def square(image, out):
    """``out = image * image`` for (H, W) float64 images."""
    h, w = image.shape
    for v in range(h):
        for u in range(w):
            out[v, u] = image[v, u] * image[v, u]


@njit(nogil=True, cache=True)
def mean_std(mean, mean_sq, mean_out, std_out):
    """``mu = E[I]``, ``sigma = sqrt(max(E[I^2] - mu^2, 0))`` in float64, stored as float32."""
    h, w = mean.shape
    for v in range(h):
        for u in range(w):
            m = mean[v, u]
            var = mean_sq[v, u] - m * m
            if var < 0.0:              # max(var, 0); a NaN stays NaN like np.maximum
                var = 0.0
            mean_out[v, u] = np.float32(m)
            std_out[v, u] = np.float32(math.sqrt(var))


@njit(nogil=True, cache=True)
def mean_std_from_sums(sum1, sum2, scale, mean_out, std_out):
    """As :func:`mean_std` from exact window sums of ``I`` and ``I^2``: ``E[.] = sum * scale`` in float64.

    With integer sums held exactly (float32 below 2**24), ``sum * scale`` is what OpenCV's
    normalized float64 box filter computes (an exact running sum times ``1 / (w * w)``), so the
    results are bit-identical to :func:`square` + ``cv2.boxFilter(CV_64F)`` + :func:`mean_std`.
    """
    h, w = sum1.shape
    for v in range(h):
        for u in range(w):
            m = np.float64(sum1[v, u]) * scale
            var = np.float64(sum2[v, u]) * scale - m * m
            if var < 0.0:
                var = 0.0
            mean_out[v, u] = np.float32(m)
            std_out[v, u] = np.float32(math.sqrt(var))


@njit(nogil=True, cache=True)
def reject(disparity, uniform, rejected):
    """Eq. (13) in place: NaN where ``uniform`` and the float32 disparity is finite (marked in ``rejected``)."""
    h, w = disparity.shape
    for v in range(h):
        for u in range(w):
            r = uniform[v, u] and math.isfinite(disparity[v, u])
            rejected[v, u] = r
            if r:
                disparity[v, u] = np.nan


@njit(nogil=True, cache=True)
def reject_texture_from_sums(sum1, sum2, scale, max_variance, disparity, out, rejected, uniform):
    """Eq. (13), texture test, in one branch-free pass from exact window sums.

    The variance ``E[I^2] - mu^2`` as :func:`mean_std_from_sums` computes it (float64); a patch
    is uniform where it is at most ``max_variance``: the largest float64 ``v`` with
    ``float32(sqrt(v)) <= T`` (:func:`mrstereo.rejection.texture._max_uniform_variance`), so the test is
    ``float32(sigma) <= T`` bit for bit without the square root. ``out`` is ``disparity`` as
    float32 with NaN where uniform and finite (:func:`reject`).
    """
    h, w = sum1.shape
    nan = np.float32(np.nan)
    for v in range(h):
        for u in range(w):
            m = np.float64(sum1[v, u]) * scale
            flat = np.float64(sum2[v, u]) * scale - m * m <= max_variance
            d = np.float32(disparity[v, u])
            r = flat and d == d and abs(d) != np.inf
            uniform[v, u] = flat
            rejected[v, u] = r
            out[v, u] = nan if r else d
