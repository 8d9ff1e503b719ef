"""Kernels of the windowed refinement (no validation; window.py checks and allocates).

Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["window_residuals", "window_normal_equations", "window_schur",
           "window_back_substitute"]


@njit(nogil=True, cache=True)
def window_residuals(R, t, P, kf, pt, uv, ur, stereo, fx, fy, cx, cy, cxr, b, delta, res):
    """Reprojection residuals ``res`` (n, 3) of the observations (the right column 0 for mono ones);
    returns the Huber cost (threshold ``delta`` on each observation's error)."""
    cost = 0.0
    for i in range(kf.shape[0]):
        k, m = kf[i], pt[i]
        x = R[k, 0, 0] * P[m, 0] + R[k, 0, 1] * P[m, 1] + R[k, 0, 2] * P[m, 2] + t[k, 0]
        y = R[k, 1, 0] * P[m, 0] + R[k, 1, 1] * P[m, 1] + R[k, 1, 2] * P[m, 2] + t[k, 1]
        z = max(R[k, 2, 0] * P[m, 0] + R[k, 2, 1] * P[m, 1] + R[k, 2, 2] * P[m, 2] + t[k, 2], 1e-6)
        res[i, 0] = fx * x / z + cx - uv[i, 0]
        res[i, 1] = fy * y / z + cy - uv[i, 1]
        res[i, 2] = fx * (x - b) / z + cxr - ur[i] if stereo[i] else 0.0
        e = math.sqrt(res[i, 0] ** 2 + res[i, 1] ** 2 + res[i, 2] ** 2)
        cost += 0.5 * e * e if e <= delta else delta * (e - 0.5 * delta)
    return cost


@njit(nogil=True, cache=True)
def window_normal_equations(R, Mrot, t, P, kf, pt, slot, stereo, res, fx, fy, b, delta, Hpp, gp, Hll, gl, Hpl):
    """Accumulate the IRLS-weighted (Huber) normal equations of a window, block by block.

    ``Mrot[k]`` is the rotation-vector factor of keyframe k (``d(R p)/dr = -R [p]x Mrot``);
    ``slot[k]`` its pose block (-1: fixed). Outputs are zeroed first: ``Hpp`` (F, 6, 6), ``gp``
    (F, 6), ``Hll`` (M, 3, 3), ``gl`` (M, 3) and ``Hpl`` (n, 6, 3) per observation.
    """
    Hpp[:] = 0.0
    gp[:] = 0.0
    Hll[:] = 0.0
    gl[:] = 0.0
    Hpl[:] = 0.0
    J = np.zeros((3, 3))
    Jl = np.zeros((3, 3))
    Jp = np.zeros((3, 6))
    D = np.zeros((3, 3))
    for i in range(kf.shape[0]):
        k, m, s = kf[i], pt[i], slot[kf[i]]
        px, py, pz = P[m, 0], P[m, 1], P[m, 2]
        x = R[k, 0, 0] * px + R[k, 0, 1] * py + R[k, 0, 2] * pz + t[k, 0]
        y = R[k, 1, 0] * px + R[k, 1, 1] * py + R[k, 1, 2] * pz + t[k, 1]
        z = max(R[k, 2, 0] * px + R[k, 2, 1] * py + R[k, 2, 2] * pz + t[k, 2], 1e-6)
        iz, iz2 = 1.0 / z, 1.0 / (z * z)
        J[:] = 0.0
        J[0, 0], J[0, 2] = fx * iz, -fx * x * iz2
        J[1, 1], J[1, 2] = fy * iz, -fy * y * iz2
        rows = 2
        if stereo[i]:
            J[2, 0], J[2, 2] = fx * iz, -fx * (x - b) * iz2
            rows = 3
        e = math.sqrt(res[i, 0] ** 2 + res[i, 1] ** 2 + res[i, 2] ** 2)
        w = 1.0 if e <= delta else delta / e
        for a in range(rows):
            for c in range(3):
                Jl[a, c] = J[a, 0] * R[k, 0, c] + J[a, 1] * R[k, 1, c] + J[a, 2] * R[k, 2, c]
        _add_weighted_products(Jl, Jl, rows, w, Hll[m])
        _add_weighted_products(Jl, res[i:i + 1].T, rows, w, gl[m:m + 1].T)
        if s < 0:
            continue
        # d X_c / d r = -R [p]x Mrot: D = [p]x Mrot first, then -R D
        for c in range(3):
            D[0, c] = -pz * Mrot[k, 1, c] + py * Mrot[k, 2, c]
            D[1, c] = pz * Mrot[k, 0, c] - px * Mrot[k, 2, c]
            D[2, c] = -py * Mrot[k, 0, c] + px * Mrot[k, 1, c]
        for a in range(rows):
            for c in range(3):
                acc = 0.0
                for q in range(3):
                    acc -= Jl[a, q] * D[q, c]
                Jp[a, c] = acc
                Jp[a, 3 + c] = J[a, c]
        _add_weighted_products(Jp, Jp, rows, w, Hpp[s])
        _add_weighted_products(Jp, res[i:i + 1].T, rows, w, gp[s:s + 1].T)
        _add_weighted_products(Jp, Jl, rows, w, Hpl[i])


@njit(nogil=True, cache=True, inline="always")
def _add_weighted_products(A, B, rows, w, out):
    """``out += w A[:rows].T @ B[:rows]`` (the weighted Gauss-Newton products of one observation)."""
    for c in range(out.shape[0]):
        for d in range(out.shape[1]):
            acc = 0.0
            for a in range(rows):
                acc += A[a, c] * B[a, d]
            out[c, d] += w * acc


@njit(nogil=True, cache=True)
def _inverse3(A, out):
    a, b, c = A[0, 0], A[0, 1], A[0, 2]
    d, e, f = A[1, 0], A[1, 1], A[1, 2]
    g, h, k = A[2, 0], A[2, 1], A[2, 2]
    det = a * (e * k - f * h) - b * (d * k - f * g) + c * (d * h - e * g)
    if not abs(det) > 1e-300:
        return False
    out[0, 0], out[0, 1], out[0, 2] = (e * k - f * h) / det, (c * h - b * k) / det, (b * f - c * e) / det
    out[1, 0], out[1, 1], out[1, 2] = (f * g - d * k) / det, (a * k - c * g) / det, (c * d - a * f) / det
    out[2, 0], out[2, 1], out[2, 2] = (d * h - e * g) / det, (b * g - a * h) / det, (a * e - b * d) / det
    return True


@njit(nogil=True, cache=True)
def window_schur(Hll, gl, Hpl, obs_slot, point_start, point_obs, lam, S, bs, Hll_inv):
    """Eliminate the landmarks: ``S -= sum Hpl_i inv(Hll) Hpl_j^T`` and ``bs -= sum Hpl_i inv(Hll) gl``
    over the observation pairs of each landmark (``point_obs[point_start[m]:point_start[m+1]]``).

    ``Hll`` is damped by ``lam`` (Marquardt: its diagonal times ``1 + lam``) into ``Hll_inv``'s
    inverse. ``S`` (F, F, 6, 6) and ``bs`` (F, 6) come in holding the pose blocks and are updated
    in place. Returns False if a landmark's block is singular.
    """
    A = np.zeros((6, 3))
    Hd = np.zeros((3, 3))
    posed = np.empty(point_obs.shape[0], np.int64)
    for m in range(point_start.shape[0] - 1):
        for c in range(3):
            for d in range(3):
                Hd[c, d] = Hll[m, c, d]
            Hd[c, c] += lam * Hll[m, c, c] + 1e-9
        if not _inverse3(Hd, Hll_inv[m]):
            return False
        n = 0                                     # the landmark's observations from free keyframes
        for ii in range(point_start[m], point_start[m + 1]):
            if obs_slot[point_obs[ii]] >= 0:
                posed[n] = point_obs[ii]
                n += 1
        for a in range(n):
            i = posed[a]
            si = obs_slot[i]
            for c in range(6):
                for d in range(3):
                    A[c, d] = Hpl[i, c, 0] * Hll_inv[m, 0, d] + Hpl[i, c, 1] * Hll_inv[m, 1, d] \
                        + Hpl[i, c, 2] * Hll_inv[m, 2, d]
                bs[si, c] -= A[c, 0] * gl[m, 0] + A[c, 1] * gl[m, 1] + A[c, 2] * gl[m, 2]
            for b in range(n):
                j = posed[b]
                for c in range(6):
                    for d in range(6):
                        S[si, obs_slot[j], c, d] -= A[c, 0] * Hpl[j, d, 0] + A[c, 1] * Hpl[j, d, 1] \
                            + A[c, 2] * Hpl[j, d, 2]
    return True


@njit(nogil=True, cache=True)
def window_back_substitute(Hll_inv, gl, Hpl, obs_slot, pt, dp, dl):
    """Landmark steps ``dl = -inv(Hll) (gl + sum_i Hpl_i^T dp_i)`` of a pose step ``dp`` (F, 6)."""
    rhs = gl.copy()
    for i in range(pt.shape[0]):
        s = obs_slot[i]
        if s < 0:
            continue
        m = pt[i]
        for d in range(3):
            acc = 0.0
            for c in range(6):
                acc += Hpl[i, c, d] * dp[s, c]
            rhs[m, d] += acc
    for m in range(rhs.shape[0]):
        for c in range(3):
            dl[m, c] = -(Hll_inv[m, c, 0] * rhs[m, 0] + Hll_inv[m, c, 1] * rhs[m, 1] + Hll_inv[m, c, 2] * rhs[m, 2])
