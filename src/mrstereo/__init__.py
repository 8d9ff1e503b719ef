"""mrstereo: two cameras in, a map of where a mobile robot can drive out.

Implements "Multi-Range Approach of Stereo Vision for Mobile Robot Navigation in
Uncertain Environments" (GA calibration, multi-range NSSD matching, ground
suppression, occupancy grids) and goes beyond it. Conventions (units, frames,
disparity sign): docs/conventions.md.
"""
from __future__ import annotations

from ._limits import _hand_image_limit_to_opencv

__version__ = "0.1.0"

_hand_image_limit_to_opencv()        # before anything loads OpenCV

# Public entry points, imported lazily so that ``import mrstereo`` stays cheap
# (numba kernels compile only when a stage is used).
_LAZY = {
    "compute_disparity": "mrstereo.matching",
}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'mrstereo' has no attribute {name!r}")
