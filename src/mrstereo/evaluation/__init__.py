"""Evaluation on real stereo benchmarks: Middlebury/KITTI readers, metrics, OpenCV baselines.

Scene readers (:mod:`~mrstereo.evaluation.datasets`), disparity metrics
(:mod:`~mrstereo.evaluation.metrics`), StereoBM / StereoSGBM (:mod:`~mrstereo.evaluation.baselines`)
and :func:`evaluate_scenes` (:mod:`~mrstereo.evaluation.report`). User guide: docs/evaluation.md.
Conventions: docs/conventions.md.
"""
from .baselines import BMSettings, SGBMSettings, disparity_from_opencv, stereo_bm, stereo_sgbm
from .datasets import LAYOUTS, Scene, load_scene, load_scenes, photometric_error
from .metrics import BAD_THRESHOLDS_PX, DisparityMetrics, ErrorStats, disparity_metrics
from .report import METHODS, EvaluationReport, EvaluationRow, evaluate_scenes, run_method

__all__ = [
    "BAD_THRESHOLDS_PX", "BMSettings", "DisparityMetrics", "ErrorStats", "EvaluationReport", "EvaluationRow",
    "LAYOUTS", "METHODS", "SGBMSettings", "Scene", "disparity_from_opencv", "disparity_metrics",
    "evaluate_scenes", "load_scene", "load_scenes", "photometric_error", "run_method", "stereo_bm", "stereo_sgbm",
]
