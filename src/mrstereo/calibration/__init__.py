"""Camera calibration: the paper's genetic algorithm (sec. 2.2, eq. 4-8), LM refinement,
multi-view planar targets, stereo calibration and rectification.

Conventions: docs/conventions.md. User guide: docs/calibration.md.
"""
from .calibrate import (METHODS, MODELS, CalibrationResult, calibrate_camera, check_view_geometry,
                        reprojection_residuals, zhang_init)
from .ga import (GENES, MULTIVIEW_GA, GABounds, GAConfig, GAResult, default_bounds, default_pixel_density,
                 ga_calibrate_intrinsics, ga_calibrate_single, paper_bounds)
from .refine import CALIBRATION_MODELS, CalibrationModel, LMFit, calibration_model, refine_views
from .stereo import StereoCalibrationResult, calibrate_stereo, rectified_points, rectified_vertical_error_px
from .targets import (CalibrationView, ChessboardPairs, chessboard_pairs, chessboard_views, detect_chessboard,
                      expand_glob, parse_board, planar_grid, pose_looking_at, read_control_points, synthetic_view)

__all__ = [
    "METHODS", "MODELS", "CalibrationResult", "calibrate_camera", "reprojection_residuals", "zhang_init",
    "check_view_geometry", "CALIBRATION_MODELS", "CalibrationModel", "calibration_model",
    "GENES", "MULTIVIEW_GA", "GABounds", "GAConfig", "GAResult", "default_bounds", "default_pixel_density",
    "ga_calibrate_intrinsics", "ga_calibrate_single", "paper_bounds", "LMFit", "refine_views",
    "StereoCalibrationResult", "calibrate_stereo", "rectified_points", "rectified_vertical_error_px",
    "CalibrationView", "chessboard_views", "detect_chessboard", "expand_glob", "parse_board", "planar_grid",
    "read_control_points", "pose_looking_at", "synthetic_view", "ChessboardPairs", "chessboard_pairs",
]
