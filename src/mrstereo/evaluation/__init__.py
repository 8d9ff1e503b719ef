"""Evaluation on real stereo benchmarks: Middlebury/KITTI readers, metrics, OpenCV baselines.

- :mod:`~mrstereo.evaluation.datasets`: :func:`load_scene` reads a Middlebury 2001/2003/2005/2014
  or KITTI 2012/2015 scene folder, or a frame of an mrstereo dataset, into a :class:`Scene` (views,
  ground truth in pixels, mask); :func:`load_scenes` every frame of a dataset.
- :mod:`~mrstereo.evaluation.metrics`: :func:`disparity_metrics` (bad-0.5/1/2/4 %, average and
  RMS error, density; dense and among estimated pixels).
- :mod:`~mrstereo.evaluation.baselines`: OpenCV StereoBM / StereoSGBM with ROS-like settings.
- :mod:`~mrstereo.evaluation.report`: :func:`evaluate_scenes` runs methods on scenes and returns an
  :class:`EvaluationReport` (markdown and JSON).

User guide: docs/evaluation.md. Conventions (disparity sign, NaN invalid): docs/conventions.md.
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
