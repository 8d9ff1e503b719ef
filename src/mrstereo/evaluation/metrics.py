"""Disparity error metrics against ground truth (Middlebury / KITTI style).

On the evaluated region (finite ground truth, inside the non-occluded mask when there is one), a
pixel is bad at threshold ``t`` when ``|d - d_gt| > t`` (Scharstein & Szeliski 2002). ``dense``
counts every evaluated pixel, an invalid estimate as bad and as ``d = 0`` in the errors;
``estimated`` only the pixels with an estimate. Definitions: docs/evaluation.md, "Metrics".
Conventions: docs/conventions.md.

References
----------
D. Scharstein and R. Szeliski, "A taxonomy and evaluation of dense two-frame
stereo correspondence algorithms", IJCV 47(1/2/3):7-42, 2002.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

__all__ = ["BAD_THRESHOLDS_PX", "ErrorStats", "DisparityMetrics", "disparity_metrics"]

BAD_THRESHOLDS_PX = (0.5, 1.0, 2.0, 4.0)


@dataclass(frozen=True)
class ErrorStats:
    """Error statistics over one set of pixels (percentages in 0..100, NaN if the set is empty)."""

    bad_0_5_pct: float
    bad_1_pct: float
    bad_2_pct: float
    bad_4_pct: float
    avg_abs_error_px: float
    rms_error_px: float
    pixel_count: int

    def bad_pct(self, threshold_px: float) -> float:
        """Bad-pixel percentage at one of :data:`BAD_THRESHOLDS_PX`."""
        key = {0.5: "bad_0_5_pct", 1.0: "bad_1_pct", 2.0: "bad_2_pct", 4.0: "bad_4_pct"}.get(float(threshold_px))
        if key is None:
            raise ValueError(f"threshold_px must be one of {BAD_THRESHOLDS_PX}, got {threshold_px}")
        return getattr(self, key)


@dataclass(frozen=True)
class DisparityMetrics:
    """Metrics of one disparity map against ground truth: ``dense`` and ``estimated`` ErrorStats,
    ``density_pct`` (evaluated pixels with an estimate), the sizes ``evaluated_pixels`` and
    ``estimated_pixels``, and ``region`` (``"nonocc"`` with a mask, else ``"all"``).
    """

    dense: ErrorStats
    estimated: ErrorStats
    density_pct: float
    evaluated_pixels: int
    estimated_pixels: int
    region: str

    def to_dict(self) -> dict:
        """Plain nested dict (JSON-ready; NaN stays NaN)."""
        return asdict(self)


def _stats(abs_error: np.ndarray, bad_error: np.ndarray) -> ErrorStats:
    """``abs_error`` for average/RMS, ``bad_error`` (inf = always bad) for the bad-% counts."""
    count = int(abs_error.size)
    if count == 0:
        nan = math.nan
        return ErrorStats(nan, nan, nan, nan, nan, nan, 0)
    bad = [100.0 * float(np.count_nonzero(bad_error > t)) / count for t in BAD_THRESHOLDS_PX]
    err = abs_error.astype(np.float64)
    return ErrorStats(bad[0], bad[1], bad[2], bad[3], float(err.mean()), float(np.sqrt(np.mean(err * err))), count)


def disparity_metrics(disparity_px, gt_disparity_px, *, nonocc_mask=None) -> DisparityMetrics:
    """Compare a disparity map (H, W) with ground truth (NaN or inf: no estimate / unknown).

    ``nonocc_mask`` (bool) is the region evaluated (default: all ground-truth pixels). ValueError
    when the shapes differ or the region holds no ground-truth pixel.
    """
    est = np.asarray(disparity_px, dtype=np.float32)
    gt = np.asarray(gt_disparity_px, dtype=np.float32)
    if est.ndim != 2:
        raise ValueError(f"disparity_px must have shape (H, W), got {est.shape}")
    if gt.shape != est.shape:
        raise ValueError(f"disparity_px and gt_disparity_px must have the same shape, got {est.shape} and {gt.shape}")
    region = np.isfinite(gt)
    region_name = "all"
    if nonocc_mask is not None:
        mask = np.asarray(nonocc_mask)
        if mask.shape != gt.shape:
            raise ValueError(f"nonocc_mask must have shape {gt.shape}, got {mask.shape}")
        if mask.dtype != np.bool_:
            raise TypeError(f"nonocc_mask must be a bool array, got dtype {mask.dtype}")
        region &= mask
        region_name = "nonocc"
    evaluated = int(np.count_nonzero(region))
    if evaluated == 0:
        raise ValueError("no ground-truth pixel to evaluate (ground truth all unknown or outside the mask)")
    gt_r = gt[region].astype(np.float64)
    est_r = est[region].astype(np.float64)
    has = np.isfinite(est_r)
    err_est = np.abs(est_r[has] - gt_r[has])
    dense_abs = np.where(has, np.abs(np.where(has, est_r, 0.0) - gt_r), np.abs(gt_r))
    dense_bad = np.where(has, dense_abs, np.inf)
    estimated = int(np.count_nonzero(has))
    return DisparityMetrics(
        dense=_stats(dense_abs, dense_bad),
        estimated=_stats(err_est, err_est),
        density_pct=100.0 * estimated / evaluated,
        evaluated_pixels=evaluated,
        estimated_pixels=estimated,
        region=region_name,
    )
