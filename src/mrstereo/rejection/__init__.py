"""Rejection of disparity on uniform floor and walls: texture / ground suppression, paper eq. (13).

Conventions: docs/conventions.md.
"""
from .texture import (FloorModel, PatchStatistics, RejectionConfig, RejectionResult, learn_floor_model,
                      patch_statistics, reject_uniform, uniform_mask)

__all__ = ["RejectionConfig", "PatchStatistics", "FloorModel", "RejectionResult", "patch_statistics", "uniform_mask", "learn_floor_model", "reject_uniform"]
