"""Numba kernels of the eq. (13) rejection (:mod:`mrstereo.rejection`; no validation, preallocated outputs).

Each kernel does per element exactly the arithmetic of the numpy expression it stands for, in
the same order and dtype (no fastmath), so that its results do not depend on which image
type supplied the window sums; ``nogil`` lets the per-frame chain run on worker threads.

Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(nogil=True, cache=True, inline="always")
def _moments(sum1, sum2, scale):
    """``(mu, sigma)`` as float32 from the window sums of ``I`` and ``I^2``: ``E[.] = sum * scale``
    and ``sigma = sqrt(max(E[I^2] - mu^2, 0))`` in float64 (a NaN stays NaN, as ``np.maximum``)."""
    m = np.float64(sum1) * scale
    var = np.float64(sum2) * scale - m * m
    var = 0.0 if var < 0.0 else var
    return np.float32(m), np.float32(math.sqrt(var))


@njit(nogil=True, cache=True)
def moments_from_sums(sum1, sum2, scale, mean_out, std_out):
    """``mu_patch`` and ``sigma_patch`` of every pixel (:func:`_moments`)."""
    h, w = sum1.shape
    for v in range(h):
        for u in range(w):
            mean_out[v, u], std_out[v, u] = _moments(sum1[v, u], sum2[v, u], scale)


@njit(nogil=True, cache=True)
def reject_uniform(sum1, sum2, scale, threshold, mean_lo, mean_hi, floor, disparity, out, rejected, uniform):
    """Eq. (13) in one pass over the window sums.

    ``uniform``: the texture reading, ``sigma <= T`` (all False for ``T <= 0``) with ``mean_lo <=
    mu <= mean_hi``, compared in float32 as numpy compares the float32 statistics with Python
    floats; or ``floor`` (a learned floor model's mask; None: none). ``out``: the disparity as
    float32 with NaN where uniform and finite, those pixels marked in ``rejected``.
    """
    h, w = sum1.shape
    t = np.float32(threshold)
    lo = np.float32(mean_lo)
    hi = np.float32(mean_hi)
    on = threshold > 0
    nan = np.float32(np.nan)
    for v in range(h):
        for u in range(w):
            mu, sigma = _moments(sum1[v, u], sum2[v, u], scale)
            flat = on & (sigma <= t) & (mu >= lo) & (mu <= hi)      # branch-free: vectorizes
            if floor is not None:
                flat = flat | floor[v, u]
            d = np.float32(disparity[v, u])
            r = flat & math.isfinite(d)
            uniform[v, u] = flat
            rejected[v, u] = r
            out[v, u] = nan if r else d
