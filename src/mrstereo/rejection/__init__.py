"""Rejection of disparity on uniform floor and walls: texture / ground suppression, paper eq. (13).

Conventions: docs/conventions.md.
"""
from .texture import (FloorModel, PatchStatistics, RejectionConfig, RejectionResult, image_noise_sigma,
                      learn_floor_model, patch_statistics, reject_uniform, row_texture)

__all__ = ["RejectionConfig", "PatchStatistics", "FloorModel", "RejectionResult", "patch_statistics",
           "learn_floor_model", "reject_uniform", "image_noise_sigma", "row_texture"]
